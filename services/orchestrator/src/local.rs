//! The stages in-process, over the libraries: the mock camera on a bin set-up, the estimator
//! (SDF refinement and the entropy planner). The servers wrap exactly these.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use glint_camera::capture::CaptureTruth;
use glint_camera::setup::BinSetup;
use glint_estimation::multiview::{self, MultiviewError};
use glint_estimation::nbv::{NbvError, PosePrior, plan_next_view, pose_entropy_nats};
use glint_estimation::refine::SdfRefineConfig;
use glint_estimation::view::{ViewError, ViewMeasurement, ViewPoints, ViewSigma};
use glint_geometry::sdf::{SdfConfig, SdfGrid};
use nalgebra::{Isometry3, Matrix6};
use rayon::prelude::*;

use crate::stages::{
    CameraInfo, CameraStage, CandidateInformation, CapturedView, EstimationStage, PredictedMaps,
    PredictionObject, PredictionRequest, PredictionSigma, PredictionStage, RefineSettings,
    Refinement, SessionObject, StageError, ViewPlan,
};
use glint_uncertainty::{
    HypothesisScene, PredictionError, PredictionSettings, SigmaModel, candidate_seed,
    predict_candidate_in,
};

/// The mock structured-light camera looking at a bin of parts.
pub struct MockCamera {
    /// The simulated bin, rig and capture settings (its part poses are the truth no session
    /// reads).
    pub setup: BinSetup,
}

impl MockCamera {
    /// [`CameraStage::capture`] and, for evaluations only, what the simulator knows of it
    /// (each left pixel's true depth and instance label).
    pub fn capture_with_truth(
        &self,
        t_w_c: &Isometry3<f64>,
        seed: u64,
    ) -> Result<(CapturedView, CaptureTruth), StageError> {
        let started = Instant::now();
        let camera = self.setup.camera();
        let (capture, noise_shots, truth) = camera
            .capture_with_noise_shots(t_w_c, seed, true)
            .map_err(|e| StageError::Internal(format!("capture: {e}")))?;
        let left = capture.shot_images(0).into_iter().cloned().collect();
        let right = capture.shot_images(1).into_iter().cloned().collect();
        let view = CapturedView {
            measurement: ViewMeasurement {
                t_w_c: *t_w_c,
                stereo: self.setup.rig.stereo,
                depth: capture.depth,
                left,
                right,
                noise_shots,
                max_dn: camera.config.sensor.max_dn(),
            },
            capture_ms: started.elapsed().as_secs_f64() * 1e3,
        };
        Ok((view, truth))
    }
}

impl CameraStage for MockCamera {
    fn info(&self) -> Result<CameraInfo, StageError> {
        let config = &self.setup.config;
        Ok(CameraInfo {
            stereo: self.setup.rig.stereo,
            rig: self.setup.rig,
            max_dn: config.sensor.max_dn(),
            shots: config.shots,
            window_radius_px: config.matcher.window_radius_px,
            exposure_s: f64::from(config.sensor.exposure_s),
            pattern_fill: config.pattern_fill,
        })
    }

    fn candidate_views(&self, count: usize) -> Result<Vec<Isometry3<f64>>, StageError> {
        if !(1..=1000).contains(&count) {
            return Err(StageError::invalid(
                "count",
                format!("is {count}; 1 to 1000 views"),
            ));
        }
        Ok(self.setup.views(count))
    }

    fn capture(&self, t_w_c: &Isometry3<f64>, seed: u64) -> Result<CapturedView, StageError> {
        self.capture_with_truth(t_w_c, seed).map(|(view, _)| view)
    }
}

/// SDF grids built once per mesh, keyed by the mesh's content hash, with the refiner's voxel.
pub struct SdfCache {
    /// How grids are built: by default the refiner's
    /// ([`glint_estimation::refine::refine_grid_config`]).
    pub config: SdfConfig,
    grids: Mutex<HashMap<String, Arc<SdfGrid>>>,
}

impl Default for SdfCache {
    fn default() -> Self {
        Self {
            config: glint_estimation::refine::refine_grid_config(),
            grids: Mutex::new(HashMap::new()),
        }
    }
}

impl SdfCache {
    /// An empty cache building grids with `config`.
    pub fn with_config(config: SdfConfig) -> Self {
        Self {
            config,
            grids: Mutex::new(HashMap::new()),
        }
    }

    /// The SDF grid of `object`, built on first use.
    pub fn grid(&self, object: &SessionObject) -> Result<Arc<SdfGrid>, StageError> {
        let poisoned = |_| StageError::Internal("the SDF cache's lock was poisoned".into());
        if let Some(grid) = self
            .grids
            .lock()
            .map_err(poisoned)?
            .get(&object.mesh_sha256_hex)
        {
            return Ok(grid.clone());
        }
        let grid = Arc::new(
            SdfGrid::build(&object.mesh, &self.config)
                .map_err(|e| StageError::invalid("mesh", format!("SDF grid: {e}")))?,
        );
        self.grids
            .lock()
            .map_err(poisoned)?
            .insert(object.mesh_sha256_hex.clone(), grid.clone());
        Ok(grid)
    }
}

/// The estimator in-process.
#[derive(Default)]
pub struct LocalEstimation {
    /// The SDF refiner's settings.
    pub refine: SdfRefineConfig,
    /// The Gaussian pose prior added to every information before its entropy (eq 20, 23).
    pub prior: PosePrior,
    /// The session objects' SDF grids.
    pub grids: SdfCache,
}

/// The render workers in-process: candidate predictions in parallel (and each render parallel
/// inside).
pub struct LocalPrediction {
    /// Thresholds and render settings; the request's σ model, seed and maps override theirs,
    /// the object's camera its shots and window.
    pub settings: PredictionSettings,
    /// The session objects' SDF grids.
    pub grids: SdfCache,
}

impl Default for LocalPrediction {
    /// The default settings, grids as the render workers build them
    /// ([`glint_uncertainty::predict::prediction_grid_config`]).
    fn default() -> Self {
        Self {
            settings: PredictionSettings::default(),
            grids: SdfCache::with_config(glint_uncertainty::predict::prediction_grid_config()),
        }
    }
}

impl PredictionStage for LocalPrediction {
    fn predict(
        &self,
        object: &PredictionObject,
        request: &PredictionRequest,
    ) -> Result<Vec<CandidateInformation>, StageError> {
        let predictor = object.predictor(self.grids.grid(&object.object)?);
        let settings = PredictionSettings {
            sigma: match request.sigma {
                PredictionSigma::Rendered => SigmaModel::Rendered,
                PredictionSigma::Constant { sigma_z_m } => SigmaModel::Constant { sigma_z_m },
            },
            shots: object.shots,
            pattern_fill: object.pattern_fill,
            window_radius_px: object.window_radius_px,
            with_maps: request.with_maps,
            ..self.settings
        };
        let prediction_error = |e| match e {
            PredictionError::Input { field, message } => StageError::invalid(field, message),
            other => StageError::Internal(other.to_string()),
        };
        // One scene for the hypothesis, shared by the candidates.
        let hypothesis =
            HypothesisScene::build(&predictor, &request.t_w_o).map_err(prediction_error)?;
        // Candidates in parallel: each one's crop is small, so one render alone leaves cores idle.
        request
            .candidates
            .par_iter()
            .map(|&(index, t_w_c)| {
                let started = Instant::now();
                let p = predict_candidate_in(
                    &predictor,
                    &hypothesis,
                    &t_w_c,
                    &settings,
                    candidate_seed(request.seed, index),
                )
                .map_err(prediction_error)?;
                Ok(CandidateInformation {
                    index,
                    information: p.information,
                    part_pixels: p.counts.part_pixels,
                    predicted_points: p.counts.kept,
                    missing_ratio: p.counts.missing_ratio,
                    missing_sigma: p.counts.missing_sigma,
                    not_in_view: p.not_in_view,
                    maps: match (p.sigma_z_m, p.cause, p.crop) {
                        (Some(sigma_z_m), Some(cause), Some(crop)) => Some(PredictedMaps {
                            sigma_z_m,
                            cause,
                            roi_u0_px: crop.u_min,
                            roi_v0_px: crop.v_min,
                        }),
                        _ => None,
                    },
                    predict_ms: started.elapsed().as_secs_f64() * 1e3,
                })
            })
            .collect()
    }
}

fn stage_error(e: ViewError) -> StageError {
    match e {
        ViewError::Input { field, message } => StageError::invalid(field, message),
        other => StageError::FailedPrecondition(other.to_string()),
    }
}

/// A multi-view refinement's error as a stage's: bad input names its field, anything else is a
/// precondition the data did not meet (too few points, noise shots that differ).
pub fn refinement_error(e: MultiviewError) -> StageError {
    match e {
        MultiviewError::Input { field, message } => StageError::invalid(field, message),
        other => StageError::FailedPrecondition(other.to_string()),
    }
}

/// A planner's error as a stage's, naming the matrix at fault (`collected`, `candidates[2]`).
pub fn plan_error(e: NbvError) -> StageError {
    let field = match &e {
        NbvError::NotSymmetric { which } | NbvError::NotPositive { which } => which.clone(),
        NbvError::TakenOutOfRange { .. } | NbvError::AllTaken => "taken".into(),
        NbvError::BadPrior => "prior".into(),
        NbvError::NoCandidates | NbvError::NoViewTaken => "candidates".into(),
    };
    StageError::invalid(field, e.to_string())
}

/// A view's σ_z as `settings` asks for it (eq 1–5 from its pattern images, or constant).
pub fn sigma_of_view(
    view: &ViewMeasurement,
    settings: &RefineSettings,
) -> Result<ViewSigma, StageError> {
    multiview::sigma_of_view(view, settings).map_err(stage_error)
}

/// A view's part points in the silhouette of the hypothesis `t_w_o` grown by `margin_m`,
/// without the known background, with the view's σ_z `sigma`.
pub fn points_of_view(
    object: &SessionObject,
    view: &ViewMeasurement,
    sigma: &ViewSigma,
    t_w_o: &Isometry3<f64>,
    margin_m: f64,
    settings: &RefineSettings,
) -> Result<ViewPoints, StageError> {
    multiview::points_of_view(&object.mesh, view, sigma, t_w_o, margin_m, settings)
        .map_err(stage_error)
}

impl EstimationStage for LocalEstimation {
    fn refine(
        &self,
        object: &SessionObject,
        views: &[&CapturedView],
        t_w_o: &Isometry3<f64>,
        settings: &RefineSettings,
    ) -> Result<Refinement, StageError> {
        let grid = self.grids.grid(object)?;
        let views: Vec<&ViewMeasurement> = views.iter().map(|v| &v.measurement).collect();
        multiview::refine_views(&object.mesh, &grid, &views, t_w_o, settings, &self.refine)
            .map_err(refinement_error)
    }

    fn plan(
        &self,
        collected: &Matrix6<f64>,
        candidates: &[Matrix6<f64>],
        taken: &[usize],
    ) -> Result<ViewPlan, StageError> {
        let plan = plan_next_view(collected, candidates, taken, &self.prior).map_err(plan_error)?;
        Ok(ViewPlan {
            chosen: plan.chosen,
            entropies_nats: plan.entropies_nats,
        })
    }

    fn entropy_nats(&self, information: &Matrix6<f64>) -> Result<f64, StageError> {
        pose_entropy_nats(information, &self.prior).map_err(plan_error)
    }
}
