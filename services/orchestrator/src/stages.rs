//! The stages a session drives, as traits: the camera, the estimator (refine and plan) and the
//! render workers (candidate prediction). Each has an in-process implementation over the
//! libraries ([`crate::local`]); gRPC ones come with the servers, so the demo and a deployment
//! will run the same session code.
//!
//! Frames: `t_w_c` left camera → world, `t_w_o` object → world. Information matrices are over
//! the left perturbation of `t_o_w`, translation first (as `glint_estimation::refine`).

use std::sync::Arc;

use glint_estimation::view::ViewMeasurement;
use glint_geometry::TriMesh;
use glint_geometry::camera::StereoRig;
use glint_geometry::image::Image;
use nalgebra::{Isometry3, Matrix6};

/// Why a stage could not do what a session asked. The variants are what a caller acts on
/// differently (and what gRPC codes map to).
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
pub enum StageError {
    /// The request is wrong: fix `field` (INVALID_ARGUMENT over gRPC).
    #[error("{field}: {message}")]
    InvalidArgument {
        /// The request's field at fault, as a path (`candidates_t_w_c[2]`,
        /// `refine.mask_margin_m`).
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// The stage lacks something it must be given first (e.g. an object by its hash), or
    /// the session named is unknown (NOT_FOUND).
    #[error("not found: {0}")]
    NotFound(String),
    /// The request is valid but the data cannot give an answer (e.g. too few points)
    /// (FAILED_PRECONDITION).
    #[error("{0}")]
    FailedPrecondition(String),
    /// The stage could not be reached or did not answer in time; another replica may
    /// (UNAVAILABLE).
    #[error("unavailable: {0}")]
    Unavailable(String),
    /// The session was cancelled (CANCELLED).
    #[error("cancelled")]
    Cancelled,
    /// Too much work is under way: try again after `retry_after_ms` (RESOURCE_EXHAUSTED
    /// with gRPC's retry pushback).
    #[error("{message} (retry after {retry_after_ms} ms)")]
    Overloaded {
        /// What is at its bound.
        message: String,
        /// How long to wait before asking again, milliseconds.
        retry_after_ms: u64,
    },
    /// Kept data is damaged or missing (a session store's record or blob): nothing is
    /// served from it (DATA_LOSS).
    #[error("data loss: {0}")]
    DataLoss(String),
    /// Anything else (INTERNAL).
    #[error("{0}")]
    Internal(String),
}

impl StageError {
    /// An [`StageError::InvalidArgument`]: `field` is wrong, `message` says how.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::InvalidArgument {
            field: field.into(),
            message: message.into(),
        }
    }
}

/// The part a session refines: what a real system knows of it.
#[derive(Clone, Debug)]
pub struct SessionObject {
    /// A name for logs and reports.
    pub name: String,
    /// The mesh, metres, in the object's frame.
    pub mesh: Arc<TriMesh>,
    /// SHA-256 of the mesh (lowercase hex): its key in every stage's cache.
    pub mesh_sha256_hex: String,
}

impl SessionObject {
    /// The part `name` with `mesh` (metres, object frame), keyed by the mesh's hash.
    pub fn new(name: impl Into<String>, mesh: TriMesh) -> Self {
        Self {
            name: name.into(),
            mesh_sha256_hex: mesh.content_sha256_hex(),
            mesh: Arc::new(mesh),
        }
    }
}

/// What a camera tells about itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraInfo {
    /// The left camera's rectified rig.
    pub stereo: StereoRig,
    /// The full rig (cameras and projector), for prediction.
    pub rig: glint_render::rig::SliRig,
    /// Full scale of the read-out's digital numbers.
    pub max_dn: u16,
    /// Pattern shots per capture.
    pub shots: u32,
    /// The stereo matcher's window radius, px.
    pub window_radius_px: u32,
    /// Exposure time of the pattern captures, seconds (the Δt of eq 14).
    pub exposure_s: f64,
    /// Fraction of lit projector pixels in the random-dot patterns.
    pub pattern_fill: f64,
}

/// A capture as the session receives it.
#[derive(Clone, Debug)]
pub struct CapturedView {
    /// The view: pose `t_w_c` (left camera → world), rectified rig, depth, pattern shots and
    /// noise shots.
    pub measurement: ViewMeasurement,
    /// Time the camera took, milliseconds.
    pub capture_ms: f64,
}

/// The structured-light camera (mock or real).
pub trait CameraStage: Send + Sync {
    /// The camera's rig, read-out and pattern settings.
    fn info(&self) -> Result<CameraInfo, StageError>;
    /// A capture from left-camera pose `t_w_c`, with two noise shots for σ_I. `seed` drives a
    /// simulator's noise (a real camera ignores it).
    fn capture(&self, t_w_c: &Isometry3<f64>, seed: u64) -> Result<CapturedView, StageError>;
    /// `count` left-camera poses (camera → world) the robot can reach, for a session's
    /// candidates.
    fn candidate_views(&self, count: usize) -> Result<Vec<Isometry3<f64>>, StageError>;
}

// The refinement's settings and result are the estimation library's (one code path for the
// in-process stage and the estimation server).
pub use glint_estimation::multiview::{RefineSettings, RefineSigma, Refinement};

/// The planner's answer (eq 23).
#[derive(Clone, Debug, PartialEq)]
pub struct ViewPlan {
    /// Index into the candidates given.
    pub chosen: usize,
    /// Predicted entropy of each candidate, nats; `None` for taken views.
    pub entropies_nats: Vec<Option<f64>>,
}

/// Pose estimation: refinement and the next-view choice.
pub trait EstimationStage: Send + Sync {
    /// Refines the part's pose on `views` from the hypothesis `t_w_o`, whose silhouette is the
    /// part's mask in every view.
    fn refine(
        &self,
        object: &SessionObject,
        views: &[&CapturedView],
        t_w_o: &Isometry3<f64>,
        settings: &RefineSettings,
    ) -> Result<Refinement, StageError>;

    /// The candidate whose predicted information, added to `collected`, gives the least pose
    /// entropy; `taken` candidates are not chosen again.
    fn plan(
        &self,
        collected: &Matrix6<f64>,
        candidates: &[Matrix6<f64>],
        taken: &[usize],
    ) -> Result<ViewPlan, StageError>;

    /// Entropy of a pose with information `information` (the planner's prior included), nats.
    fn entropy_nats(&self, information: &Matrix6<f64>) -> Result<f64, StageError>;
}

/// One candidate's predicted contribution.
#[derive(Clone, Debug, PartialEq)]
pub struct CandidateInformation {
    /// Index into the session's candidates.
    pub index: u32,
    /// The Fisher information this view would add (eq 18, 21–22).
    pub information: Matrix6<f64>,
    /// Left-image pixels on the part under the hypothesis (its visible silhouette).
    pub part_pixels: u32,
    /// Part pixels predicted to give a depth: the points of `information`.
    pub predicted_points: u32,
    /// Part pixels predicted missing by the ratio test (eq 16).
    pub missing_ratio: u32,
    /// Part pixels predicted missing by the σ test (eq 17), the ratio test passed.
    pub missing_sigma: u32,
    /// The part projects outside the candidate's image (or behind it); the counts are zero.
    pub not_in_view: bool,
    /// The predicted σ̌_z map and each pixel's cause over the region of interest, when asked.
    pub maps: Option<PredictedMaps>,
    /// Time this candidate's prediction took, milliseconds.
    pub predict_ms: f64,
}

/// A candidate's predicted maps over its region of interest (eq 16–17).
#[derive(Clone, Debug, PartialEq)]
pub struct PredictedMaps {
    /// σ̌_z, metres; NaN where no depth is predicted.
    pub sigma_z_m: Image<f32>,
    /// Why: a [`glint_uncertainty::PixelCause`] per pixel, as its `u8`.
    pub cause: Image<u8>,
    /// Column of the region's top-left pixel in the left camera's image, px.
    pub roi_u0_px: u32,
    /// Row of the region's top-left pixel in the left camera's image, px.
    pub roi_v0_px: u32,
}

/// How a prediction models depth uncertainty.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PredictionSigma {
    /// Rendering-based σ̌_z and missing pixels (eq 14–17), the paper's method.
    Rendered,
    /// A constant σ_z, metres, on every visible part pixel (the constant-σ baseline).
    Constant {
        /// The constant σ_z, metres (positive).
        sigma_z_m: f64,
    },
}

/// What the render workers are asked for one decision.
#[derive(Clone, Debug)]
pub struct PredictionRequest {
    /// The hypothesis, object → world.
    pub t_w_o: Isometry3<f64>,
    /// `(index into the session's candidates, left camera → world)`.
    pub candidates: Vec<(u32, Isometry3<f64>)>,
    /// How depth uncertainty is modelled.
    pub sigma: PredictionSigma,
    /// Seed of the renders; each candidate's is derived from it and its index, so any
    /// worker gives the same answer.
    pub seed: u64,
    /// Return the σ̌_z maps too.
    pub with_maps: bool,
}

/// What a render worker must know of the part and the hardware: never the simulator's truth,
/// only what calibration measured.
#[derive(Clone, Debug)]
pub struct PredictionObject {
    /// The part: its name, mesh and mesh hash (the workers' cache key).
    pub object: SessionObject,
    /// The fitted material (`glint calibrate bsdf`).
    pub material: glint_render::bsdf::PrincipledParams<f32>,
    /// The calibrated response and radiometric scale (`glint calibrate response`, `bsdf`).
    pub camera: glint_uncertainty::CalibratedCamera,
    /// The camera's full rig (cameras and projector).
    pub rig: glint_render::rig::SliRig,
    /// The sensor's noise, fitted from a view's noise shots.
    pub noise: glint_estimation::depth_sigma::NoiseModel,
    /// Known surroundings rendered with the part (the bin), empty for the part alone.
    pub surroundings: Vec<glint_uncertainty::KnownSurface>,
    /// The camera's pattern shots per capture.
    pub shots: u32,
    /// Fraction of lit projector pixels in the random-dot patterns.
    pub pattern_fill: f64,
    /// The stereo matcher's window radius, px.
    pub window_radius_px: u32,
}

/// A part's photometric calibration as the render workers need it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PartCalibration {
    /// The fitted material (`glint calibrate bsdf`).
    pub material: glint_render::bsdf::PrincipledParams<f32>,
    /// The calibrated response (`glint calibrate response`).
    pub response: glint_calibration::response::ResponseTable,
    /// Relative radiance-map units per W·sr⁻¹·m⁻² (the BSDF fit's median per-view scale).
    pub radiometric_scale: f64,
}

impl PartCalibration {
    /// From what `glint calibrate bsdf` and `glint calibrate response` wrote.
    pub fn from_files(
        calibration: &glint_calibration::shipped::Calibration,
    ) -> Result<Self, StageError> {
        let radiometric_scale = calibration.material.radiometric_scale().ok_or_else(|| {
            StageError::FailedPrecondition(
                "the material file's provenance has no per_view[].radiometric_scale: refit it \
                 with glint calibrate bsdf"
                    .into(),
            )
        })?;
        Ok(Self {
            material: calibration
                .material
                .params()
                .map_err(|e| StageError::invalid("material", e.to_string()))?,
            response: calibration.response.clone(),
            radiometric_scale,
        })
    }
}

/// Seed of the noise calibration's capture: apart from every session's capture seeds.
pub const NOISE_CALIBRATION_SEED: u64 = 0x4015E;

/// The sensor's noise σ_I² (eq 2), fitted from two read-outs of one shot from `t_w_c` — a
/// capture of its own, as a cell calibrates its camera once.
pub fn calibrate_noise(
    camera: &dyn CameraStage,
    t_w_c: &Isometry3<f64>,
) -> Result<glint_estimation::depth_sigma::NoiseModel, StageError> {
    let view = camera.capture(t_w_c, NOISE_CALIBRATION_SEED)?;
    glint_estimation::view::noise_model_of(&view.measurement)
        .map_err(|e| StageError::FailedPrecondition(format!("noise calibration: {e}")))
}

impl PredictionObject {
    /// What the render workers know of `object` seen by `camera`: the fitted material, the
    /// calibrated response and radiometric scale (`calibration`), the camera's rig, exposure,
    /// shots and window, the sensor's `noise`, the cell's `surroundings` — never the
    /// simulator's truth.
    pub fn calibrated(
        object: SessionObject,
        calibration: &PartCalibration,
        camera: &CameraInfo,
        noise: glint_estimation::depth_sigma::NoiseModel,
        surroundings: Vec<glint_uncertainty::KnownSurface>,
    ) -> Result<Self, StageError> {
        let calibrated = glint_uncertainty::CalibratedCamera::new(
            calibration.response.clone(),
            calibration.radiometric_scale,
            camera.exposure_s,
        )
        .map_err(|e| StageError::invalid("radiometric_scale", e.to_string()))?;
        let material = calibration.material;
        Ok(Self {
            object,
            material,
            camera: calibrated,
            rig: camera.rig,
            noise,
            surroundings,
            shots: camera.shots,
            pattern_fill: camera.pattern_fill,
            window_radius_px: camera.window_radius_px,
        })
    }

    /// The render workers' view of this object, with the part's SDF grid.
    pub fn predictor(
        &self,
        sdf: Arc<glint_geometry::sdf::SdfGrid>,
    ) -> glint_uncertainty::PredictorObject {
        glint_uncertainty::PredictorObject {
            mesh: self.object.mesh.clone(),
            sdf,
            material: self.material,
            camera: self.camera.clone(),
            rig: self.rig,
            noise: self.noise.clone(),
            surroundings: self.surroundings.clone(),
        }
    }
}

/// The render workers: candidate-view prediction. Stateless towards the caller: every call
/// names its object, which an implementation may cache by content hash.
pub trait PredictionStage: Send + Sync {
    /// Predicts what each of `request`'s candidates would add for `object` (eq 14–17,
    /// 21–22): one [`CandidateInformation`] per candidate, named by its index.
    fn predict(
        &self,
        object: &PredictionObject,
        request: &PredictionRequest,
    ) -> Result<Vec<CandidateInformation>, StageError>;
}
