//! The BSDF fit of a calibration capture, set up end to end — the one code path of
//! `glint calibrate bsdf` and the calibration server's `FitBsdf`: read the capture, check the
//! views, measure each view's radiance with the camera response ([`measured_target`]), choose
//! the loss, fit from every start ([`FitProblem::fit_from_starts`]) and gather the provenance
//! a material file records.
//!
//! The capture's files (BOP scene, rig, reference surface, exposure stacks) are glint-camera's
//! formats, and calibration must not depend on camera: whoever runs the fit hands over a
//! [`CaptureReader`] (the CLI and the server's builder wrap
//! `glint_camera::dataset::calibration_scene`), and receives the capture as a [`Capture`].

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use glint_render::bsdf::PrincipledParams;
use glint_render::integrator::{LightTransport, PixelRendering};
use glint_render::projector::Pattern;
use glint_render::rig::SliRig;
use glint_render::scene::Scene;
use nalgebra::Isometry3;

use super::{
    FitConfig, FitError, FitProblem, FitResult, FitTarget, FitView, Loss, MeasuredTarget, Residual,
    StartFit, StartFits, TargetError, measured_target,
};
use crate::material_map::params_to_map;
use crate::response::{ExposureStack, ResponseError, ResponseTable};

/// One view of a capture.
#[derive(Clone, Debug)]
pub struct CaptureView {
    /// The view's image id in the BOP scene.
    pub im_id: u32,
    /// Left camera → world.
    pub t_w_c: Isometry3<f64>,
    /// The view's white-pattern exposure stack (read by [`CaptureReader::exposure_stack`]).
    pub stack_dir: PathBuf,
}

/// A calibration capture as the BSDF fit sees it: the labelled part instances and the bin (the
/// radiometric reference) as a scene, the rig, the views.
pub struct Capture {
    /// The BOP scene folder read.
    pub scene_dir: PathBuf,
    /// The part's BOP object id.
    pub obj_id: u32,
    /// Part instances are scene indices `part_instances`; the bin is `bin_instance`.
    pub scene: Scene,
    /// Scene indices of the labelled part instances, whose shared material is fitted.
    pub part_instances: Vec<u32>,
    /// Scene index of the bin.
    pub bin_instance: u32,
    /// The bin's known material (the radiometric reference).
    pub reference: PrincipledParams<f32>,
    /// The SLI rig (cameras, projector) as known hardware.
    pub rig: SliRig,
    /// The captured views.
    pub views: Vec<CaptureView>,
}

/// Why a capture or one of its files could not be read: the reader's own error, which names
/// the file.
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct CaptureReadError(pub Box<dyn std::error::Error + Send + Sync>);

/// Reads calibration captures (glint-camera's formats; see the module doc).
pub trait CaptureReader: Send + Sync {
    /// The capture at `dir` (a capture folder or its BOP scene folder).
    fn capture(&self, dir: &Path) -> Result<Capture, CaptureReadError>;
    /// The white-pattern exposure stack in `dir` (a [`CaptureView::stack_dir`]).
    fn exposure_stack(&self, dir: &Path) -> Result<ExposureStack, CaptureReadError>;
}

/// Why a capture could not be fitted; each names what to fix.
#[derive(Debug, thiserror::Error)]
pub enum SceneFitError {
    /// The capture could not be read; the reader's error names the file.
    #[error("{}: {source}", dir.display())]
    Capture {
        /// The capture folder given.
        dir: PathBuf,
        /// The reader's error.
        source: CaptureReadError,
    },
    /// A requested view is not in the capture: pick one of `available`.
    #[error("{}: no view {im_id}; the capture has views {available:?}", scene_dir.display())]
    NoView {
        /// The BOP scene folder read.
        scene_dir: PathBuf,
        /// Index of the view in [`SceneFitConfig::views`].
        index: usize,
        /// The requested image id.
        im_id: u32,
        /// The capture's image ids.
        available: Vec<u32>,
    },
    /// A view is requested twice: name each once.
    #[error("view {im_id} is given twice")]
    RepeatedView {
        /// Index of the repeat in [`SceneFitConfig::views`].
        index: usize,
        /// The repeated image id.
        im_id: u32,
    },
    /// No views were named and the capture has fewer than two, so none is left after holding
    /// out the last: name the views to fit.
    #[error(
        "{}: the capture has only view(s) {available:?}; name the views to fit (by default every view but the last, kept for evaluation)",
        scene_dir.display()
    )]
    NoDefaultViews {
        /// The BOP scene folder read.
        scene_dir: PathBuf,
        /// The capture's image ids.
        available: Vec<u32>,
    },
    /// A view's exposure stack could not be read.
    #[error("view {im_id}: exposure stack {}: {source}", dir.display())]
    Stack {
        /// The view's image id.
        im_id: u32,
        /// The stack's folder.
        dir: PathBuf,
        /// The reader's error.
        source: CaptureReadError,
    },
    /// The response cannot make a radiance map of a view's stack (its bit depth differs from
    /// the stack's): use the response calibrated for this camera.
    #[error("view {im_id}: radiance map: {source}")]
    Radiance {
        /// The view's image id.
        im_id: u32,
        /// Why the radiance map failed.
        source: ResponseError,
    },
    /// A view's radiance map gives no fit target (wrong size, or too little of the reference
    /// surface measured).
    #[error("view {im_id} ({}): {source}", dir.display())]
    Target {
        /// The view's image id.
        im_id: u32,
        /// The view's exposure-stack folder.
        dir: PathBuf,
        /// Why the target failed.
        source: TargetError,
    },
    /// The fit itself failed or was stopped.
    #[error(transparent)]
    Fit(#[from] FitError),
}

/// The loss of a scene fit; the scale of `Ln` and `Huber` comes from the targets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LossChoice {
    /// Σ (r − t)² / Σ t², the paper's.
    L2,
    /// Squared error of ln radiance, ε = 1 % of the mean target.
    Ln,
    /// L2 up to δ = the 90th percentile of the target, linear beyond.
    Huber,
}

/// A scene fit's settings (the flags of `glint calibrate bsdf`, which documents each).
#[derive(Clone, Debug)]
pub struct SceneFitConfig {
    /// Views (image ids) whose radiance enters the loss; empty: every view but the last.
    pub views: Vec<u32>,
    /// Adam iterations per start.
    pub iterations: usize,
    /// Which light paths the fit's renders follow.
    pub transport: LightTransport,
    /// Samples per pixel of multi-path renders.
    pub spp: u32,
    /// Every `pixel_step`-th object pixel in u and v enters the loss.
    pub pixel_step: u32,
    /// How the gradient's residual is estimated with multi-path ([`FitProblem::residual`]).
    pub residual: Residual,
    /// The loss.
    pub loss: LossChoice,
    /// Side of the loss's pixel blocks, pixels ([`FitProblem::block_px`]; 1: single pixels).
    pub block_px: u32,
    /// Fresh random numbers every iteration ([`FitConfig::reseed`]).
    pub reseed: bool,
    /// Roughness floor, in [0, 1], of multi-path vertices after the first at the first
    /// iteration (0: exact renders).
    pub min_indirect_roughness: f32,
    /// The roughness floor of the last iteration, in [0, 1]
    /// ([`FitConfig::final_min_indirect_roughness`]).
    pub final_min_indirect_roughness: f32,
    /// Start value of every free parameter, one fit per start; the best is kept.
    pub starts: Vec<f32>,
    /// The metallic weight when the part's finish is known, held instead of fitted
    /// ([`FitConfig::known_metallic`]).
    pub known_metallic: Option<f32>,
}

impl Default for SceneFitConfig {
    /// The defaults of `glint calibrate bsdf`.
    fn default() -> Self {
        Self {
            views: vec![0],
            iterations: 300,
            transport: LightTransport::MULTI_PATH_DEFAULT,
            spp: 16,
            pixel_step: 3,
            residual: Residual::Decorrelated,
            loss: LossChoice::L2,
            block_px: 1,
            reseed: false,
            min_indirect_roughness: 0.5,
            final_min_indirect_roughness: 0.1,
            starts: vec![0.5],
            known_metallic: None,
        }
    }
}

/// One step of a scene fit.
#[derive(Clone, Debug)]
pub struct FitProgress {
    /// 0-based over all starts.
    pub iteration: usize,
    /// Iterations of all starts.
    pub iterations_total: usize,
    /// The step's loss, at `params`.
    pub loss: f64,
    /// The parameters the loss was evaluated at.
    pub params: PrincipledParams<f32>,
}

/// A scene fit's outcome: what `glint calibrate bsdf` writes and prints.
pub struct SceneFit {
    /// The capture fitted.
    pub capture: Capture,
    /// The views fitted, in order.
    pub im_ids: Vec<u32>,
    /// Per view: the fit's view (pixels on every `pixel_step`-th row and column) and the
    /// measured target it came from.
    pub views: Vec<FitView>,
    /// Per view: the measured target, its radiometric scale and pixel counts.
    pub measured: Vec<MeasuredTarget>,
    /// How the fit rendered pixels (with the first iteration's roughness floor).
    pub rendering: PixelRendering,
    /// How the gradient's residual was estimated.
    pub residual: Residual,
    /// The loss, with its scale from the targets.
    pub loss: Loss,
    /// Side of the loss's pixel blocks, pixels.
    pub block_px: u32,
    /// Every start's fit, in the order of the starts.
    pub starts: Vec<StartFit>,
    /// Index in `starts` of the best fit.
    pub best: usize,
    /// The best start's result.
    pub result: FitResult,
    /// The best start's unbiased L2 (NaN with a single start).
    pub judged_l2: f64,
    /// Wall time of all starts' fits, seconds.
    pub elapsed_s: f64,
    /// The provenance a material file records (settings, starts, per-view measurement,
    /// loss history).
    pub provenance: serde_json::Map<String, serde_json::Value>,
}

impl SceneFit {
    /// The fitted problem, to render the fitted material as the fit did.
    pub fn problem(&self) -> FitProblem<'_> {
        FitProblem {
            scene: &self.capture.scene,
            views: &self.views,
            instances: &self.capture.part_instances,
            rendering: self.rendering,
            residual: self.residual,
            loss: self.loss,
            block_px: self.block_px,
        }
    }
}

impl Capture {
    /// The view with image id `im_id`.
    pub fn view(&self, im_id: u32) -> Result<&CaptureView, SceneFitError> {
        self.views
            .iter()
            .find(|v| v.im_id == im_id)
            .ok_or_else(|| self.no_view(0, im_id))
    }

    fn no_view(&self, index: usize, im_id: u32) -> SceneFitError {
        SceneFitError::NoView {
            scene_dir: self.scene_dir.clone(),
            index,
            im_id,
            available: self.views.iter().map(|v| v.im_id).collect(),
        }
    }

    /// `views` checked (distinct views of this capture), or with none given every view but
    /// the last (kept for evaluation).
    pub fn fitted_views(&self, views: &[u32]) -> Result<Vec<u32>, SceneFitError> {
        if views.is_empty() {
            return match self.views.split_last() {
                Some((_, rest)) if !rest.is_empty() => Ok(rest.iter().map(|v| v.im_id).collect()),
                _ => Err(SceneFitError::NoDefaultViews {
                    scene_dir: self.scene_dir.clone(),
                    available: self.views.iter().map(|v| v.im_id).collect(),
                }),
            };
        }
        for (index, &im_id) in views.iter().enumerate() {
            if !self.views.iter().any(|v| v.im_id == im_id) {
                return Err(self.no_view(index, im_id));
            }
            if views[..index].contains(&im_id) {
                return Err(SceneFitError::RepeatedView { index, im_id });
            }
        }
        Ok(views.to_vec())
    }
}

/// Reads the capture at `dir`.
pub fn read_capture(reader: &dyn CaptureReader, dir: &Path) -> Result<Capture, SceneFitError> {
    reader
        .capture(dir)
        .map_err(|source| SceneFitError::Capture {
            dir: dir.to_path_buf(),
            source,
        })
}

/// Per view (image id) of `views`: the fit's view (camera, projector, object pixels on every
/// `step`-th row and column with their measured radiance) and the measured target it came from.
pub fn fit_views(
    reader: &dyn CaptureReader,
    capture: &Capture,
    table: &ResponseTable,
    views: &[u32],
    rendering: &PixelRendering,
    step: u32,
) -> Result<(Vec<FitView>, Vec<MeasuredTarget>), SceneFitError> {
    let mut fit_views = Vec::with_capacity(views.len());
    let mut measured_views = Vec::with_capacity(views.len());
    for &im_id in views {
        let view = capture.view(im_id)?;
        let stack =
            reader
                .exposure_stack(&view.stack_dir)
                .map_err(|source| SceneFitError::Stack {
                    im_id,
                    dir: view.stack_dir.clone(),
                    source,
                })?;
        let radiance_map = table
            .radiance_map(&stack)
            .map_err(|source| SceneFitError::Radiance { im_id, source })?;
        let [camera, _] = capture.rig.cameras(&view.t_w_c);
        let projector = capture.rig.projector(&view.t_w_c, Pattern::White);
        let measured = measured_target(
            &capture.scene,
            &camera,
            &projector,
            &capture.part_instances,
            capture.bin_instance,
            &capture.reference,
            &radiance_map,
            rendering,
        )
        .map_err(|source| SceneFitError::Target {
            im_id,
            dir: view.stack_dir.clone(),
            source,
        })?;
        let mut target = FitTarget::default();
        for (&(u, v), &r) in measured.target.pixels.iter().zip(&measured.target.radiance) {
            if u % step == 0 && v % step == 0 {
                target.pixels.push((u, v));
                target.radiance.push(r);
            }
        }
        fit_views.push(FitView {
            camera,
            projector,
            target,
        });
        measured_views.push(measured);
    }
    Ok((fit_views, measured_views))
}

/// The loss `choice` with its scale taken from the targets of `views`.
pub fn loss_of(choice: LossChoice, views: &[FitView]) -> Loss {
    match choice {
        LossChoice::L2 => Loss::L2,
        LossChoice::Ln => {
            // ε: 1 % of the mean target radiance (relative errors count above it).
            let (sum, n) = views.iter().flat_map(|v| &v.target.radiance).fold(
                (0.0f64, 0usize),
                |(s, n), &r| {
                    if r.is_finite() {
                        (s + r as f64, n + 1)
                    } else {
                        (s, n)
                    }
                },
            );
            Loss::LnRadiance {
                floor: (0.01 * sum / n.max(1) as f64) as f32,
            }
        }
        LossChoice::Huber => {
            // δ: the 90th percentile of the target radiance.
            let mut all: Vec<f32> = views
                .iter()
                .flat_map(|v| v.target.radiance.iter().copied())
                .filter(|r| r.is_finite())
                .collect();
            all.sort_by(f32::total_cmp);
            Loss::Huber {
                delta: all.get(all.len() * 9 / 10).copied().unwrap_or(1.0),
            }
        }
    }
}

/// Fits the part's material on `capture` (read by [`read_capture`]) with the response `table`:
/// see the module doc. `progress` is called after every iteration of every start; a `Break`
/// stops the fit ([`FitError::Stopped`]).
pub fn fit_scene(
    reader: &dyn CaptureReader,
    capture: Capture,
    table: &ResponseTable,
    config: &SceneFitConfig,
    mut progress: impl FnMut(FitProgress) -> ControlFlow<()>,
) -> Result<SceneFit, SceneFitError> {
    let im_ids = capture.fitted_views(&config.views)?;
    let rendering = PixelRendering::new(
        config.transport.regularised(config.min_indirect_roughness),
        config.spp,
        1,
    );
    let step = config.pixel_step;
    let (views, measured) = fit_views(reader, &capture, table, &im_ids, &rendering, step)?;
    let loss = loss_of(config.loss, &views);
    let problem = FitProblem {
        scene: &capture.scene,
        views: &views,
        instances: &capture.part_instances,
        rendering,
        residual: config.residual,
        loss,
        block_px: config.block_px,
    };
    let fit_config = FitConfig {
        iterations: config.iterations,
        reseed: config.reseed,
        final_min_indirect_roughness: Some(config.final_min_indirect_roughness),
        known_metallic: config.known_metallic,
        ..FitConfig::default()
    };
    let iterations_total = config.iterations * config.starts.len();
    let mut iteration = 0;
    let StartFits { fits, best } =
        problem.fit_from_starts(&fit_config, &config.starts, |_, loss, params| {
            let flow = progress(FitProgress {
                iteration,
                iterations_total,
                loss,
                params: *params,
            });
            iteration += 1;
            flow
        })?;
    let elapsed_s: f64 = fits.iter().map(|f| f.result.elapsed_s).sum();
    let starts: Vec<_> = fits
        .iter()
        .map(|f| {
            serde_json::json!({
                "start": f.start,
                "params": params_to_map(&f.result.params),
                "final_loss": f.result.loss.last(),
                "judged_l2": f.judged_l2,
                "elapsed_s": f.result.elapsed_s,
            })
        })
        .collect();
    let judged_l2 = fits[best].judged_l2;
    let result = fits[best].result.clone();

    let per_view: Vec<_> = im_ids
        .iter()
        .zip(&measured)
        .zip(&views)
        .map(|((im_id, m), v)| {
            serde_json::json!({
                "im_id": im_id,
                "pixels": v.target.pixels.len(),
                "unmeasured_pixels": m.unmeasured_pixels,
                "radiometric_scale": m.scale,
                "reference_pixels": m.reference_pixels,
            })
        })
        .collect();
    // The "loss" key twice, as `glint calibrate bsdf` has always written it: the history wins.
    let provenance = serde_json::json!({
        "scene": capture.scene_dir,
        "obj_id": capture.obj_id,
        "views": im_ids,
        "free": fit_config.fitted_names(),
        "known_metallic": config.known_metallic,
        "transport": format!("{:?}", rendering.transport),
        "samples_per_pixel": rendering.samples_per_pixel,
        "residual": format!("{:?}", config.residual),
        "loss": format!("{loss:?}"),
        "block_px": config.block_px,
        "reseed": config.reseed,
        "final_min_indirect_roughness": config.final_min_indirect_roughness,
        "starts": starts,
        "pixel_step": step,
        "pixels": result.pixels,
        "per_view": per_view,
        "elapsed_s": elapsed_s,
        "loss": result.loss,
        "trajectory": result.trajectory,
    });
    let serde_json::Value::Object(provenance) = provenance else {
        unreachable!("a JSON object literal")
    };
    Ok(SceneFit {
        capture,
        im_ids,
        views,
        measured,
        rendering,
        residual: config.residual,
        loss,
        block_px: config.block_px,
        starts: fits,
        best,
        result,
        judged_l2,
        elapsed_s,
        provenance,
    })
}
