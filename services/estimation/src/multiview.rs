//! A pose refined over every view of a session so far, as an active session (and the
//! estimation service's `Refine`) runs it: per view σ_z from the pattern images (eq 1–5) or a
//! constant, the part's pixels from the silhouette of the hypothesis grown by a margin in
//! metres, the known background plane dropped, world points (eq 6–7), one SDF refinement over
//! all of them (eq 8–11) with its Fisher information and covariance (eq 18–19). An optional
//! second pass re-masks at the first pass's pose with a tighter margin and refines again.
//! With the part's [`PoseErrorModel`] the information reported is what survives the depth
//! errors neighbouring pixels share and the pose error each view shares (the model's), not
//! eq 18's independent pixels.
//!
//! Frames: `t_w_c` left camera → world, `t_w_o` object → world; the information is over the
//! left perturbation of `t_o_w`, translation first (as [`crate::refine`]). Transport-free: the
//! in-process stage and the gRPC server call [`refine_views`] alike.

use std::time::Instant;

use glint_geometry::TriMesh;
use glint_geometry::sdf::SdfGrid;
use nalgebra::{Isometry3, Matrix6};
use rayon::prelude::*;

use crate::depth_alignment::{DepthAlignmentConfig, align_depth};
use crate::depth_sigma::DepthSigmaError;
use crate::pose_error_model::PoseErrorModel;
use crate::refine::{
    RefineError, RefineStatus, SdfRefineConfig, covariance_from_information, refine_sdf,
};
use crate::view::{
    BackgroundPlane, SigmaSource, ViewError, ViewMeasurement, ViewPoints, ViewSigma,
    hypothesis_mask, points_in_mask, view_sigma,
};

/// The largest stereo window radius and mask erosion a refinement accepts, px.
pub const MAX_WINDOW_RADIUS_PX: u32 = 64;

/// Which depth σ a refinement weighs points with.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum RefineSigma {
    /// From each view's pattern images (eq 1–5), the paper's method; the sensor's noise model
    /// is fitted from each view's noise shots.
    PatternImages,
    /// The same σ_z for every point, metres (an unweighted refinement).
    Constant {
        /// The σ_z, metres.
        sigma_z_m: f64,
    },
}

/// How the estimator finds the part's pixels and weighs them.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineSettings {
    /// The hypothesis silhouette grows by this, metres at the part's depth, to hold the part
    /// when the hypothesis is off.
    pub mask_margin_m: f64,
    /// A second pass re-masks at the first pass's pose with this margin (metres) and refines
    /// again, so the wide first mask's neighbours stop pulling; `None`: one pass.
    pub final_mask_margin_m: Option<f64>,
    /// A known plane that is not the part (the bin's floor): its points are dropped.
    pub background: Option<BackgroundPlane>,
    /// Mask erosion before taking points, px (stereo windows straddling the silhouette).
    pub erode_px: u32,
    /// The matcher's window radius, px (eq 2–3 sum over it).
    pub window_radius_px: u32,
    /// Which depth σ the points are weighed with.
    pub sigma: RefineSigma,
    /// Before refining, move the hypothesis along the first view's viewing direction onto that
    /// view's depth ([`crate::depth_alignment::align_depth`], ±30 mm): the worst axis of a
    /// template detector that looked from the first view.
    /// Absent from older journals: off.
    #[serde(default)]
    pub align_depth: bool,
    /// The camera's error model on the part (measured on tuning scenes, `glint eval
    /// refine`): the information and covariance reported are what survive its shared errors.
    /// `None`: eq 18–19's independent pixels. Absent from older journals: none.
    #[serde(default)]
    pub error_model: Option<PoseErrorModel>,
}

/// What a refinement over all views so far gives.
#[derive(Clone, Debug, PartialEq)]
pub struct Refinement {
    /// The refined pose, object → world (the hypothesis when the refinement diverged).
    pub t_w_o: Isometry3<f64>,
    /// Fisher information of the pose under the settings' error model (eq 18 without one;
    /// zero when diverged), over the left perturbation of `t_o_w`.
    pub information: Matrix6<f64>,
    /// The pose covariance, `information⁻¹` (eq 19), in the same coordinates; `None` when
    /// the information is singular or the refinement diverged.
    pub covariance: Option<Matrix6<f64>>,
    /// Eq 18's information, independent pixels (the refiner's weighting), whatever the error
    /// model: `information` itself without one.
    pub pixel_information: Matrix6<f64>,
    /// Depth points of the part per view, in view order.
    pub view_points: Vec<usize>,
    /// Points with whitened residual within `inlier_k` at the solution, over all views.
    pub inliers: usize,
    /// Gauss–Newton/LM iterations of the last pass.
    pub iterations: usize,
    /// "converged", "max_iterations" or "diverged".
    pub status: String,
    /// Robust (Huber) cost at the solution of the last pass (see [`RefineResult::final_cost`]).
    ///
    /// [`RefineResult::final_cost`]: crate::refine::RefineResult::final_cost
    pub final_cost: f64,
    /// Time the refinement took, milliseconds.
    pub refine_ms: f64,
}

/// Why a refinement over views could not give a pose.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MultiviewError {
    /// A setting or a view is wrong: fix `field` (`mask_margin_m`, `views[1].depth`).
    #[error("{field}: {message}")]
    Input {
        /// The offending setting or view field, e.g. `views[1].depth`.
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// A view's σ_z cannot be computed from its images (e.g. its noise shots differ).
    #[error("views[{view}]: σ_z: {source}")]
    Sigma {
        /// Index of the view in `views`.
        view: usize,
        /// Why its σ_z failed.
        #[source]
        source: DepthSigmaError,
    },
    /// The refinement cannot run on the points found (none, too few inliers).
    #[error("refinement: {0}")]
    Refine(#[from] RefineError),
}

fn input(field: impl Into<String>, message: impl Into<String>) -> MultiviewError {
    MultiviewError::Input {
        field: field.into(),
        message: message.into(),
    }
}

/// A view's error as the refinement's, naming the view.
fn of_view(view: usize, e: ViewError) -> MultiviewError {
    match e {
        ViewError::Input { field, message } => input(format!("views[{view}].{field}"), message),
        ViewError::Sigma(
            source @ (DepthSigmaError::SizeMismatch { .. } | DepthSigmaError::ShotCount { .. }),
        ) => input(format!("views[{view}]"), source.to_string()),
        ViewError::Sigma(source) => MultiviewError::Sigma { view, source },
    }
}

impl RefineSettings {
    /// Checks every setting; errors name the field (`mask_margin_m`, `background.normal_w`,
    /// `constant_sigma_z_m`, ...).
    pub fn validate(&self) -> Result<(), MultiviewError> {
        let margin = |field: &str, m: f64| {
            if m.is_finite() && m >= 0.0 {
                Ok(())
            } else {
                Err(input(
                    field,
                    format!("is {m}; a margin must be finite and non-negative (metres)"),
                ))
            }
        };
        margin("mask_margin_m", self.mask_margin_m)?;
        if let Some(m) = self.final_mask_margin_m {
            margin("final_mask_margin_m", m)?;
        }
        if let Some(b) = &self.background {
            if !b.normal_w.iter().all(|c| c.is_finite()) || (b.normal_w.norm() - 1.0).abs() > 1e-6 {
                return Err(input(
                    "background.normal_w",
                    format!(
                        "is {:?}; it must be a finite unit vector",
                        b.normal_w.as_ref()
                    ),
                ));
            }
            if !b.offset_m.is_finite() {
                return Err(input(
                    "background.offset_m",
                    format!("is {}; it must be finite (metres)", b.offset_m),
                ));
            }
            margin("background.clearance_m", b.clearance_m)?;
        }
        for (field, px) in [
            ("erode_px", self.erode_px),
            ("window_radius_px", self.window_radius_px),
        ] {
            if px > MAX_WINDOW_RADIUS_PX {
                return Err(input(
                    field,
                    format!("is {px} px; at most {MAX_WINDOW_RADIUS_PX}"),
                ));
            }
        }
        if let Some(model) = &self.error_model {
            model
                .validate()
                .map_err(|e| input(format!("error_model.{}", e.field), e.message))?;
        }
        if let RefineSigma::Constant { sigma_z_m } = self.sigma
            && !(sigma_z_m.is_finite() && sigma_z_m > 0.0)
        {
            return Err(input(
                "constant_sigma_z_m",
                format!("is {sigma_z_m}; a depth σ must be finite and positive (metres)"),
            ));
        }
        Ok(())
    }
}

/// A view's σ_z as `settings` asks for it (eq 1–5 from its pattern images, or constant).
pub fn sigma_of_view(
    view: &ViewMeasurement,
    settings: &RefineSettings,
) -> Result<ViewSigma, ViewError> {
    let sigma = match settings.sigma {
        RefineSigma::PatternImages => SigmaSource::PatternImages {
            window_radius_px: settings.window_radius_px,
            noise: None,
        },
        RefineSigma::Constant { sigma_z_m } => SigmaSource::Constant { sigma_z_m },
    };
    view_sigma(view, &sigma)
}

/// A view's part points (world frame, eq 6–7) in the silhouette of `mesh` (metres, object
/// frame) at the hypothesis `t_w_o` grown by `margin_m`, without the known background, with
/// the view's σ_z `sigma`.
pub fn points_of_view(
    mesh: &TriMesh,
    view: &ViewMeasurement,
    sigma: &ViewSigma,
    t_w_o: &Isometry3<f64>,
    margin_m: f64,
    settings: &RefineSettings,
) -> Result<ViewPoints, ViewError> {
    let mask = hypothesis_mask(mesh, &view.stereo, &view.t_w_c, t_w_o, margin_m);
    let mut points = points_in_mask(view, &mask, sigma, settings.erode_px)?;
    if let Some(background) = &settings.background {
        points.drop_background(background);
    }
    Ok(points)
}

fn is_finite(t: &Isometry3<f64>) -> bool {
    t.translation.vector.iter().all(|c| c.is_finite())
        && t.rotation.coords.iter().all(|c| c.is_finite())
}

/// Refines the part's pose on `views` from the hypothesis `t_w_o` (object → world): `mesh`
/// (metres) gives each view's hypothesis-silhouette mask, `grid` (its SDF, built with
/// [`crate::refine::REFINE_SDF_VOXEL_MM`]) the residuals (eq 8–11); σ_z per view once, both
/// masking passes use it. A diverged refinement keeps the hypothesis and claims no
/// information.
pub fn refine_views(
    mesh: &TriMesh,
    grid: &SdfGrid,
    views: &[&ViewMeasurement],
    t_w_o: &Isometry3<f64>,
    settings: &RefineSettings,
    config: &SdfRefineConfig,
) -> Result<Refinement, MultiviewError> {
    let started = Instant::now();
    settings.validate()?;
    if views.is_empty() {
        return Err(input("views", "is empty; refine on at least one view"));
    }
    if !is_finite(t_w_o) {
        return Err(input("t_w_o", "the hypothesis is not finite"));
    }
    if let Some(view) = views.iter().position(|v| !is_finite(&v.t_w_c)) {
        return Err(input(format!("views[{view}].t_w_c"), "is not finite"));
    }
    let sigmas: Vec<ViewSigma> = views
        .par_iter()
        .enumerate()
        .map(|(i, v)| sigma_of_view(v, settings).map_err(|e| of_view(i, e)))
        .collect::<Result<_, _>>()?;
    let points_at = |t_w_o: &Isometry3<f64>, margin_m: f64| {
        let per_view: Vec<ViewPoints> = views
            .par_iter()
            .zip(&sigmas)
            .enumerate()
            .map(|(i, (v, sigma))| {
                points_of_view(mesh, v, sigma, t_w_o, margin_m, settings).map_err(|e| of_view(i, e))
            })
            .collect::<Result<_, _>>()?;
        let counts: Vec<usize> = per_view.iter().map(|v| v.points.len()).collect();
        let points: Vec<_> = per_view.into_iter().flat_map(|v| v.points).collect();
        Ok::<_, MultiviewError>((points, counts))
    };
    let refine = |points: &[_], t_w_o: &Isometry3<f64>| {
        refine_sdf(grid, points, &t_w_o.inverse(), config).map_err(MultiviewError::from)
    };
    let (mut points, mut view_points) = points_at(t_w_o, settings.mask_margin_m)?;
    // The hypothesis' own silhouette holds the part's pixels (a detector errs least across the
    // image); only then is it moved along the first view's rays onto that view's depth (the
    // detector's view; other views' rays would spread the search across its accurate axes).
    let start = if settings.align_depth {
        align_depth(
            grid,
            &points[..view_points[0]],
            &t_w_o.inverse(),
            &DepthAlignmentConfig::default(),
        )
        .map_or(*t_w_o, |a| a.t_o_w.inverse())
    } else {
        *t_w_o
    };
    let mut result = refine(&points, &start)?;
    if let Some(margin_m) = settings.final_mask_margin_m
        && result.status != RefineStatus::Diverged
    {
        let first = result.t_o_w.inverse();
        let (final_points, counts) = points_at(&first, margin_m)?;
        result = refine(&final_points, &first)?;
        points = final_points;
        view_points = counts;
    }
    let status = match result.status {
        RefineStatus::Converged => "converged",
        RefineStatus::MaxIterations => "max_iterations",
        RefineStatus::Diverged => "diverged",
    };
    // A diverged pose is not an estimate: keep the hypothesis, claim no information.
    let (t_w_o_refined, information, covariance, pixel_information) =
        if result.status == RefineStatus::Diverged {
            (*t_w_o, Matrix6::zeros(), None, Matrix6::zeros())
        } else if let Some(model) = &settings.error_model {
            let mut start = 0;
            let per_view = views.iter().zip(&view_points).map(|(v, &n)| {
                let of_view = &points[start..start + n];
                start += n;
                (of_view, v.t_w_c)
            });
            let information = model.refined_information(grid, per_view, &result.t_o_w, config);
            (
                result.t_o_w.inverse(),
                information,
                covariance_from_information(&information),
                result.information,
            )
        } else {
            (
                result.t_o_w.inverse(),
                result.information,
                result.covariance,
                result.information,
            )
        };
    Ok(Refinement {
        t_w_o: t_w_o_refined,
        information,
        covariance,
        pixel_information,
        view_points,
        inliers: result.inliers,
        iterations: result.iterations,
        status: status.to_string(),
        final_cost: result.final_cost,
        refine_ms: started.elapsed().as_secs_f64() * 1e3,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Unit, Vector3};

    fn settings() -> RefineSettings {
        RefineSettings {
            mask_margin_m: 10e-3,
            final_mask_margin_m: Some(3e-3),
            background: Some(BackgroundPlane {
                normal_w: Unit::new_normalize(Vector3::z()),
                offset_m: 0.0,
                clearance_m: 2e-3,
            }),
            erode_px: 2,
            window_radius_px: 2,
            sigma: RefineSigma::PatternImages,
            align_depth: false,
            error_model: None,
        }
    }

    #[test]
    fn settings_name_the_bad_field() {
        assert_eq!(settings().validate(), Ok(()));
        let field = |s: RefineSettings| match s.validate() {
            Err(MultiviewError::Input { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        let mut s = settings();
        s.mask_margin_m = f64::NAN;
        assert_eq!(field(s), "mask_margin_m");
        let mut s = settings();
        s.final_mask_margin_m = Some(-1.0);
        assert_eq!(field(s), "final_mask_margin_m");
        let mut s = settings();
        s.background = Some(BackgroundPlane {
            normal_w: Unit::new_unchecked(Vector3::new(0.0, 0.0, 2.0)),
            offset_m: 0.0,
            clearance_m: 0.0,
        });
        assert_eq!(field(s), "background.normal_w");
        let mut s = settings();
        s.window_radius_px = MAX_WINDOW_RADIUS_PX + 1;
        assert_eq!(field(s), "window_radius_px");
        let mut s = settings();
        s.sigma = RefineSigma::Constant { sigma_z_m: 0.0 };
        assert_eq!(field(s), "constant_sigma_z_m");
        let mut s = settings();
        s.error_model = Some(PoseErrorModel {
            depth_error: crate::correlated_error::CorrelatedDepthError::INDEPENDENT,
            view_bias: crate::view_bias::ViewPoseBias::none(),
        });
        assert_eq!(field(s), "error_model.cell_m");
    }
}
