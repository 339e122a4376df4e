//! One candidate view's predicted measurements and their Fisher information (eq 14–17, 21–22).
//!
//! The object alone (its mesh at the hypothesis pose, the fitted material) is rendered from the
//! candidate over a crop holding its projection in both cameras, plus the matcher's window:
//!
//! 1. white-pattern single-path (direct) and multi-path (direct + inter-reflected) radiance of
//!    each camera, through the calibrated response (eq 14–15), both from one multi-path trace
//!    (the single-path image is its paths' first-vertex terms), shaded only where the part is
//!    and the matcher's windows reach around it (the crop's other pixels get centre rays
//!    only; the README's `glint bench nbv` section measures what that saves);
//! 2. a left pixel is **missing by the ratio test** when `I_single / I_multi < τ_I` (eq 16):
//!    inter-reflected light swamps the pattern's direct signal (a projector shadow has
//!    `I_single = 0`);
//! 3. K pattern images per camera are synthesised from the two white renders: the direct
//!    light follows the projector's dot pattern at the pixel's surface point (seen through the
//!    projector, so both cameras see the same dots), the inter-reflected light its mean,
//!    `I_k = g(s Δt (E_single t_k + (E_multi − E_single) t̄))` — the paper's combination of a
//!    strong and a weak white render, with the pattern's contrast reduced where
//!    inter-reflection fills the dark dots;
//! 4. σ̌_z by eq 1–5 with the refiner's own code over the K shots, and a pixel is **missing by
//!    the σ test** when `σ̌_z > τ_σ` (eq 17); a left pixel whose surface point the right camera
//!    does not see (self-occlusion) cannot be matched and is missing too;
//! 5. the kept pixels' points on the hypothesis surface, with σ̌_z, give the candidate's Fisher
//!    information `Σ Jᵢᵀ Jᵢ / Σ_sdf,i` (eq 21–22) by the refiner's Jacobian and weights.
//!
//! The part at the hypothesis among its surroundings is one scene ([`HypothesisScene`]),
//! built once and shared by every candidate predicted from that hypothesis.
//!
//! Everything is seeded by the request (see [`candidate_seed`]): any worker returns the same
//! information for the same request.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3A;
use glint_estimation::depth_sigma::{DepthSigmaError, NoiseModel, depth_sigma_shifted};
use glint_estimation::points::{DepthPoint, DepthSigma, object_points};
use glint_estimation::refine::information_of_points;
use glint_geometry::TriMesh;
use glint_geometry::camera::{PinholeIntrinsics, StereoRig};
use glint_geometry::image::{DepthMap, Image, PixelRect};
use glint_geometry::sdf::{SdfConfig, SdfGrid};
use glint_geometry::silhouette::dilated;
use glint_render::bsdf::PrincipledParams;
use glint_render::integrator::{
    Camera, LightTransport, RenderSettings, render_first_surface, render_with_single_path_where,
};
use glint_render::projector::{Pattern, Projector};
use glint_render::rig::SliRig;
use glint_render::scene::{Scene, SceneError, SceneInstance};
use nalgebra::{Isometry3, Matrix6, Point2, Point3};

use crate::response::CalibratedCamera;

/// The part's label in a [`HypothesisScene`]'s renders (its surroundings have the next ones).
const PART_LABEL: u16 = 1;

/// What a worker knows of the part and the hardware: calibration results, never the truth.
#[derive(Clone, Debug)]
pub struct PredictorObject {
    /// The part's mesh, metres, object frame.
    pub mesh: Arc<TriMesh>,
    /// Its SDF grid, for the Jacobians (the refiner's grid).
    pub sdf: Arc<SdfGrid>,
    /// The fitted material (`glint calibrate bsdf`).
    pub material: PrincipledParams<f32>,
    /// The calibrated response and radiometric scale.
    pub camera: CalibratedCamera,
    /// The camera rig and its projector.
    pub rig: SliRig,
    /// The sensor's intensity noise σ_I² (fitted from two read-outs of one shot).
    pub noise: NoiseModel,
    /// Known static surroundings rendered with the part (the bin, from the cell's
    /// calibration): they occlude it and reflect light onto it. Empty: the part alone, as
    /// the paper renders it.
    pub surroundings: Vec<KnownSurface>,
}

/// A known surface of the scene that is not the part.
#[derive(Clone, Debug)]
pub struct KnownSurface {
    /// The surface's mesh, metres, surface frame.
    pub mesh: Arc<TriMesh>,
    /// Surface → world.
    pub t_w_s: Isometry3<f64>,
    /// Its material in the renders.
    pub material: PrincipledParams<f32>,
}

/// How a prediction models depth uncertainty.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SigmaModel {
    /// Rendering-based missing pixels and σ̌_z (eq 14–17), the paper's method.
    Rendered,
    /// Every part pixel both cameras see, with this σ_z (metres): visibility and Jacobians
    /// only — the paper's constant-σ baseline. Only the pixel centres' rays are traced, for
    /// visibility; nothing is shaded.
    Constant {
        /// σ_z of every kept pixel, metres.
        sigma_z_m: f64,
    },
}

/// How to predict.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PredictionSettings {
    /// Rendered σ̌_z and missing pixels (the paper's method) or a constant σ_z.
    pub sigma: SigmaModel,
    /// τ_I of eq 16: missing where `I_single / I_multi` is below this.
    pub tau_intensity_ratio: f64,
    /// τ_σ of eq 17, metres: missing where σ̌_z is above this.
    pub tau_sigma_m: f64,
    /// Samples per pixel of the white renders (a constant σ_z renders none).
    pub samples_per_pixel: u32,
    /// Pattern shots per capture (the camera's K).
    pub shots: u32,
    /// The camera's matching window radius, px (eq 2–3 sum over it).
    pub window_radius_px: u32,
    /// Fraction of lit projector pixels in the camera's dot patterns.
    pub pattern_fill: f64,
    /// Seed of the synthesised dot patterns: a fixed set, like a projector's, so workers make
    /// them once ([`shot_patterns`]).
    pub pattern_seed: u64,
    /// σ_model of the refiner (eq 11), metres, so predicted information weighs as refined.
    pub model_sigma_m: f64,
    /// A left pixel's surface point counts as seen by the right camera when the right
    /// camera's first surface there is within this of it, metres.
    pub occlusion_tolerance_m: f64,
    /// Return the σ̌_z map and the missing-cause map over the crop.
    pub with_maps: bool,
}

impl Default for PredictionSettings {
    /// τ_I 0.8 and τ_σ 0.03 mm, chosen on tuning seeds 11–13 (Zigzag, 3 views each, the
    /// bin rendered too) by the best balanced accuracy of "usable depth" against the mock
    /// camera's captures (`glint eval thresholds --predict-bin --tau-i 0.5,0.7,0.8,0.85,0.9,0.95
    /// --tau-sigma-mm 0.03,0.05,0.08,0.12,0.2,1000`: 0.766; the part alone peaks at 0.85 /
    /// 0.03 mm with 0.678); the evaluation seeds are disjoint. 2 spp, the default camera's
    /// K = 8 shots, 3×3 windows and half-lit patterns, the refiner's σ_model. τ_σ is for that
    /// 1280×1024 camera: σ̌_z scales as 1/f, so a camera at half the resolution needs twice it.
    fn default() -> Self {
        Self {
            sigma: SigmaModel::Rendered,
            tau_intensity_ratio: 0.8,
            tau_sigma_m: 0.03e-3,
            samples_per_pixel: 2,
            shots: 8,
            window_radius_px: 1,
            pattern_fill: 0.5,
            pattern_seed: 0x9A77_E2D5,
            model_sigma_m: glint_estimation::refine::SdfRefineConfig::default().model_sigma_m,
            occlusion_tolerance_m: 1e-3,
            with_maps: false,
        }
    }
}

/// Why a prediction could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PredictionError {
    /// A setting or pose is out of range or not finite: `field` names it, `message` says what
    /// it must be.
    #[error("{field}: {message}")]
    Input {
        /// The setting or pose at fault, as named here (e.g. `tau_sigma_m`, `t_w_c`).
        field: &'static str,
        /// What its value must be.
        message: String,
    },
    /// The part and its surroundings make no scene to render, e.g. their meshes have no
    /// triangles: register a mesh with faces.
    #[error("the object's scene: {0}")]
    Scene(#[from] SceneError),
    /// σ̌_z (eq 1–5) refused the synthesised pattern images; with validated settings, a bug.
    #[error("σ̌_z: {0}")]
    Sigma(#[from] DepthSigmaError),
    /// A crop or image that does not fit: a bug, reported instead of a panic in a worker.
    #[error("internal: {0}")]
    Internal(&'static str),
}

fn input(field: &'static str, message: impl Into<String>) -> PredictionError {
    PredictionError::Input {
        field,
        message: message.into(),
    }
}

/// Where a left pixel of the crop went. Values of the cause map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum PixelCause {
    /// A predicted measurement.
    Kept = 0,
    /// Missing by eq 16.
    Ratio = 1,
    /// Missing by eq 17.
    Sigma = 2,
    /// The right camera does not see the point.
    RightOccluded = 3,
    /// Not the part (or outside the camera's image).
    NotPart = 255,
}

/// What happened to the part's pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MissingCounts {
    /// Left pixels on the part (its visible silhouette under the hypothesis).
    pub part_pixels: u32,
    /// Missing by the ratio test (eq 16).
    pub missing_ratio: u32,
    /// Missing by the σ test (eq 17), the ratio test passed.
    pub missing_sigma: u32,
    /// Not seen by the right camera.
    pub right_occluded: u32,
    /// Predicted measurements, the points of the information.
    pub kept: u32,
}

/// One candidate's prediction.
#[derive(Clone, Debug)]
pub struct CandidatePrediction {
    /// The Fisher information the view would add (eq 21–22), in the refiner's δ coordinates
    /// (object frame, translation first).
    pub information: Matrix6<f64>,
    /// What became of the part's left pixels (all zero when not in view).
    pub counts: MissingCounts,
    /// The part's projection is outside the candidate's image (or behind it).
    pub not_in_view: bool,
    /// The crop of the left image the maps cover.
    pub crop: Option<PixelRect>,
    /// Column of the right image where the right camera's crop (the left crop's size and
    /// rows) starts, px; it may lie left of the sensor or reach past its right edge (those
    /// pixels are not seen).
    pub right_crop_u_min_px: Option<i64>,
    /// σ̌_z per crop pixel, metres (NaN off the part), when asked.
    pub sigma_z_m: Option<Image<f32>>,
    /// [`PixelCause`] per crop pixel, when asked.
    pub cause: Option<Image<u8>>,
    /// The left camera's images the prediction came from (the paper's Fig. 8), when maps are
    /// asked for and σ̌_z is rendered.
    pub images: Option<PredictionImages>,
    /// Wall time of the scene build and the white renders, milliseconds.
    pub render_ms: f64,
    /// Wall time of the missing-pixel tests and σ̌_z (eq 16–17, 1–5), milliseconds.
    pub sigma_ms: f64,
    /// Wall time of the Fisher information (eq 21–22), milliseconds.
    pub information_ms: f64,
}

/// The left camera's intermediate images of one prediction over its crop, in DN through the
/// calibrated response g (eq 13): what the paper's Fig. 8 shows.
#[derive(Clone, Debug)]
pub struct PredictionImages {
    /// White-pattern single-path (direct only) image (eq 14).
    pub single_path_dn: Image<f32>,
    /// White-pattern multi-path (direct + inter-reflected) image (eq 15).
    pub multi_path_dn: Image<f32>,
    /// The first synthesised random-pattern image (step 3 of the module).
    pub pattern_dn: Image<f32>,
}

impl CandidatePrediction {
    fn empty(not_in_view: bool) -> Self {
        Self {
            information: Matrix6::zeros(),
            counts: MissingCounts::default(),
            not_in_view,
            crop: None,
            right_crop_u_min_px: None,
            sigma_z_m: None,
            cause: None,
            images: None,
            render_ms: 0.0,
            sigma_ms: 0.0,
            information_ms: 0.0,
        }
    }
}

/// The SDF grid predictions are made on: the refiner's voxel
/// ([`glint_estimation::refine::REFINE_SDF_VOXEL_MM`]) and [`SdfConfig`]'s 10 mm padding. A
/// prediction samples the SDF only at predicted surface points, so it needs none of the 30 mm
/// padding the refiner's grid has for far-off initial poses, which costs 5–8× the build time
/// (`glint bench sdf --voxel-mm 0.5 --padding-mm 30`: Eye Bolt 1.5 → 10.2 s). The render
/// workers and the in-process prediction stage both use it, so their Fisher information agrees
/// bit for bit.
pub fn prediction_grid_config() -> SdfConfig {
    SdfConfig {
        voxel_size_m: glint_estimation::refine::REFINE_SDF_VOXEL_MM * 1e-3,
        ..SdfConfig::default()
    }
}

/// The seed of candidate `index` of a request seeded `request_seed`: a worker's renders depend
/// on nothing else, so every worker gives the same answer.
pub fn candidate_seed(request_seed: u64, index: u32) -> u64 {
    let mut x = request_seed ^ (u64::from(index) + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

fn finite_pose(t: &Isometry3<f64>) -> bool {
    t.translation.vector.iter().all(|c| c.is_finite())
        && t.rotation.coords.iter().all(|c| c.is_finite())
}

fn validate(settings: &PredictionSettings) -> Result<(), PredictionError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !(settings.tau_intensity_ratio.is_finite()
        && (0.0..=1.0).contains(&settings.tau_intensity_ratio))
    {
        return Err(input("tau_intensity_ratio", "must be in [0, 1]"));
    }
    if !positive(settings.tau_sigma_m) {
        return Err(input("tau_sigma_m", "must be finite and positive (metres)"));
    }
    if !(1..=1024).contains(&settings.samples_per_pixel) {
        return Err(input("samples_per_pixel", "must be 1 to 1024"));
    }
    if !(1..=64).contains(&settings.shots) {
        return Err(input("shots", "must be 1 to 64"));
    }
    if settings.window_radius_px > 32 {
        return Err(input("window_radius_px", "must be at most 32"));
    }
    if !(settings.pattern_fill > 0.0 && settings.pattern_fill <= 1.0) {
        return Err(input("pattern_fill", "must be in (0, 1]"));
    }
    if !positive(settings.model_sigma_m) {
        return Err(input(
            "model_sigma_m",
            "must be finite and positive (metres)",
        ));
    }
    if !positive(settings.occlusion_tolerance_m) {
        return Err(input(
            "occlusion_tolerance_m",
            "must be finite and positive (metres)",
        ));
    }
    if let SigmaModel::Constant { sigma_z_m } = settings.sigma
        && !positive(sigma_z_m)
    {
        return Err(input("sigma_z_m", "must be finite and positive (metres)"));
    }
    Ok(())
}

/// Where each camera's crop lies: the left crop, clipped to the image, and how many columns
/// left of it the equally sized right crop starts (`right_shift_px`, ≥ the largest disparity,
/// so that a left crop pixel `u` at disparity `d` is right crop column `u − d + shift ≥ u`).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Crops {
    left: PixelRect,
    right_shift_px: i64,
}

/// The crops that hold the part's projection (its bounding box's corners at the hypothesis) in
/// the left camera and, shifted by the disparity, in the right, grown by `margin_px`; `None`
/// when the part is behind the camera or outside the image.
fn crops_of(
    mesh: &TriMesh,
    stereo: &StereoRig,
    t_c_o: &Isometry3<f64>,
    margin_px: u32,
) -> Option<Crops> {
    let (lo, hi) = mesh.aabb()?;
    let k = &stereo.intrinsics;
    let mut u = (f64::INFINITY, f64::NEG_INFINITY);
    let mut v = (f64::INFINITY, f64::NEG_INFINITY);
    let mut d = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..8 {
        let corner = Point3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
        .cast::<f64>();
        let p_c = t_c_o * corner;
        if p_c.z < 0.05 {
            return None; // a part this close (or behind) is not a view to take
        }
        let uv = k.project(&p_c)?;
        let disparity = stereo.disparity_from_depth(p_c.z);
        u = (u.0.min(uv.x), u.1.max(uv.x));
        v = (v.0.min(uv.y), v.1.max(uv.y));
        d = (d.0.min(disparity), d.1.max(disparity));
    }
    let m = margin_px as f64;
    // Wide enough for the right camera's view of the part, whose columns spread by the
    // disparity range.
    let width = (u.1 - u.0) + (d.1 - d.0) + 2.0 * m + 1.0;
    let left = PixelRect::covering(
        u.0 - m,
        v.0 - m,
        u.0 - m + width,
        v.1 + m,
        k.width_px,
        k.height_px,
    )?;
    Some(Crops {
        left,
        right_shift_px: d.1.ceil() as i64,
    })
}

/// The world point a pixel of the crop sees at depth `z_m` (through its centre).
#[inline]
fn surface_point(
    crop_intrinsics: &PinholeIntrinsics,
    t_w_c: &Isometry3<f64>,
    u: u32,
    v: u32,
    z_m: f32,
) -> Point3<f64> {
    t_w_c * crop_intrinsics.unproject(&PinholeIntrinsics::pixel_centre(u, v), z_m as f64)
}

/// The K synthesised pattern intensities of one camera over the crop (step 3 of the module).
#[allow(clippy::too_many_arguments)]
fn pattern_images(
    object: &PredictorObject,
    single: &Image<f32>,
    multi: &Image<f32>,
    depth: &Image<f32>,
    crop_intrinsics: &PinholeIntrinsics,
    t_w_cam: &Isometry3<f64>,
    projector: &Projector,
    patterns: &[Pattern],
    fill: f64,
) -> Result<Vec<Image<f32>>, PredictionError> {
    let (w, h) = (single.width(), single.height());
    let pk = &projector.intrinsics;
    // Per pixel, its surface point's place in the projector image (once for all patterns).
    let coords: Vec<Option<Point2<f64>>> = (0..w * h)
        .map(|i| {
            let (u, v) = (i % w, i / w);
            let z = depth.data()[i as usize];
            z.is_finite().then(|| {
                let p = surface_point(crop_intrinsics, t_w_cam, u, v, z);
                projector.pattern_coordinates(Vec3A::new(p.x as f32, p.y as f32, p.z as f32))
            })?
        })
        .collect();
    patterns
        .iter()
        .map(|pattern| {
            let data = (0..(w * h) as usize)
                .map(|i| {
                    let Some(uv) = coords[i] else { return 0.0 };
                    let (direct, total) = (single.data()[i], multi.data()[i]);
                    let t = pattern.transmittance(uv, pk);
                    let indirect = (total - direct).max(0.0);
                    object.camera.intensity(direct * t + indirect * fill as f32)
                })
                .collect();
            Image::new(w, h, data).map_err(|_| PredictionError::Internal("pattern image size"))
        })
        .collect()
}

/// The K synthesised dot patterns for a projector, made once per process for each
/// (size, K, fill, seed) and shared: drawing them costs more than a candidate's renders.
pub fn shot_patterns(
    projector: &PinholeIntrinsics,
    shots: u32,
    fill: f64,
    seed: u64,
) -> Arc<Vec<Pattern>> {
    type Key = (u32, u32, u32, u64, u64);
    static CACHE: std::sync::Mutex<Vec<(Key, Arc<Vec<Pattern>>)>> =
        std::sync::Mutex::new(Vec::new());
    let key = (
        projector.width_px,
        projector.height_px,
        shots,
        fill.to_bits(),
        seed,
    );
    let make = || {
        Arc::new(
            (0..shots)
                .map(|k| {
                    Pattern::random_dots(
                        projector.width_px,
                        projector.height_px,
                        fill,
                        candidate_seed(seed, k),
                    )
                })
                .collect::<Vec<_>>(),
        )
    };
    // A poisoned lock only means another thread panicked mid-insert: make them afresh.
    let Ok(mut cache) = CACHE.lock() else {
        return make();
    };
    if let Some((_, patterns)) = cache.iter().find(|(k, _)| *k == key) {
        return patterns.clone();
    }
    let patterns = make();
    // A handful of projectors at most; keep the newest few.
    if cache.len() >= 8 {
        cache.remove(0);
    }
    cache.push((key, patterns.clone()));
    patterns
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// What every candidate of one decision renders: the part at the pose hypothesis `t_w_o`
/// (label 1) among its known surroundings (labels 2, 3, … in order), as one scene. Its BVH is
/// built once per hypothesis and shared by all the candidates predicted from it, on every
/// thread.
pub struct HypothesisScene {
    scene: Scene,
    t_w_o: Isometry3<f64>,
    /// Wall time of the build, milliseconds.
    pub build_ms: f64,
}

impl HypothesisScene {
    /// The scene of `object` at the hypothesis `t_w_o` (object → world).
    pub fn build(
        object: &PredictorObject,
        t_w_o: &Isometry3<f64>,
    ) -> Result<Self, PredictionError> {
        if !finite_pose(t_w_o) {
            return Err(input("t_w_o", "must be finite"));
        }
        let started = Instant::now();
        // The part first; the surroundings follow it.
        let mut meshes = vec![(*object.mesh).clone()];
        let mut instances = vec![SceneInstance {
            mesh: 0,
            t_w_o: *t_w_o,
            material: 0,
            label: PART_LABEL,
        }];
        let mut materials = vec![object.material];
        for (i, surface) in object.surroundings.iter().enumerate() {
            meshes.push((*surface.mesh).clone());
            materials.push(surface.material);
            instances.push(SceneInstance {
                mesh: i + 1,
                t_w_o: surface.t_w_s,
                material: i + 1,
                label: PART_LABEL + 1 + i as u16,
            });
        }
        let scene = Scene::build(&meshes, instances, materials)?;
        Ok(Self {
            scene,
            t_w_o: *t_w_o,
            build_ms: ms_since(started),
        })
    }

    /// The pose hypothesis the scene holds the part at (object → world).
    pub fn t_w_o(&self) -> &Isometry3<f64> {
        &self.t_w_o
    }
}

/// One candidate's prediction from the hypothesis `t_w_o`: [`HypothesisScene::build`] then
/// [`predict_candidate_in`], the build's time counted in `render_ms`. A caller predicting
/// several candidates from one hypothesis builds the scene once instead.
pub fn predict_candidate(
    object: &PredictorObject,
    t_w_o: &Isometry3<f64>,
    t_w_c: &Isometry3<f64>,
    settings: &PredictionSettings,
    seed: u64,
) -> Result<CandidatePrediction, PredictionError> {
    validate(settings)?;
    let hypothesis = HypothesisScene::build(object, t_w_o)?;
    let mut prediction = predict_candidate_in(object, &hypothesis, t_w_c, settings, seed)?;
    prediction.render_ms += hypothesis.build_ms;
    Ok(prediction)
}

/// Predicts the measurements of the part from candidate `t_w_c` (left camera → world) under
/// the hypothesis `hypothesis` holds (built from this `object`), and their Fisher information
/// (module doc).
pub fn predict_candidate_in(
    object: &PredictorObject,
    hypothesis: &HypothesisScene,
    t_w_c: &Isometry3<f64>,
    settings: &PredictionSettings,
    seed: u64,
) -> Result<CandidatePrediction, PredictionError> {
    validate(settings)?;
    let t_w_o = &hypothesis.t_w_o;
    if !finite_pose(t_w_c) {
        return Err(input("t_w_c", "must be finite"));
    }
    let stereo = object.rig.stereo;
    let t_c_o = t_w_c.inverse() * t_w_o;
    let Some(crops) = crops_of(&object.mesh, &stereo, &t_c_o, settings.window_radius_px + 2) else {
        return Ok(CandidatePrediction::empty(true));
    };
    let crop = crops.left;
    let internal = |what| PredictionError::Internal(what);
    let crop_intrinsics = stereo
        .intrinsics
        .cropped(&crop)
        .ok_or(internal("the crop is clipped to the image"))?;
    // The right crop: same size, `right_shift_px` columns further left (it may reach past
    // the sensor's edge; those pixels are not seen).
    let right_u0 = i64::from(crop.u_min) - crops.right_shift_px;
    let right_intrinsics = PinholeIntrinsics {
        cx_px: stereo.intrinsics.cx_px - right_u0 as f64,
        ..crop_intrinsics
    };
    let crop_stereo = StereoRig {
        intrinsics: crop_intrinsics,
        ..stereo
    };

    let started = Instant::now();
    let scene = &hypothesis.scene;
    let projector = object.rig.projector(t_w_c, Pattern::White);
    let [left_camera, right_camera] = object.rig.cameras(t_w_c);
    // Each camera cropped to its crop: crop-sized renders, the same rays as the full image's.
    let cameras = [
        Camera {
            intrinsics: crop_intrinsics,
            ..left_camera
        },
        Camera {
            intrinsics: right_intrinsics,
            ..right_camera
        },
    ];
    let rendered_sigma = settings.sigma == SigmaModel::Rendered;
    // Per camera, the first surface's depth and label from the centre rays alone (the
    // renders' own to the bit); when σ̌_z is rendered, also the white single- and multi-path
    // radiance, from one multi-path trace whose first-vertex terms are the single-path image
    // (eq 14 and 15), over only the pixels eq 1–5 read: the part and, around it, the window
    // plus the gradient's neighbour and the right window's interpolation column (r + 2). A
    // constant σ_z needs no shading.
    let mut surfaces: Vec<(Image<f32>, Image<u16>)> = Vec::with_capacity(2);
    let mut white: Vec<(Image<f32>, Image<f32>)> = Vec::with_capacity(2);
    for (c, camera) in cameras.iter().enumerate() {
        let (depth, label) = render_first_surface(scene, camera, None, None);
        if rendered_sigma {
            let multi_settings = RenderSettings {
                transport: LightTransport::MULTI_PATH_DEFAULT,
                samples_per_pixel: settings.samples_per_pixel,
                roi: None,
                seed: seed ^ (c as u64 + 1).wrapping_mul(0xA5A5),
            };
            let needed = dilated(
                &label.map(|l| l == PART_LABEL),
                settings.window_radius_px + 2,
            );
            let (output, single_path) =
                render_with_single_path_where(scene, camera, &projector, &multi_settings, &needed);
            white.push((single_path, output.radiance));
        }
        surfaces.push((depth, label));
    }
    let [(depth_left, label_left), (depth_right, label_right)] =
        <[_; 2]>::try_from(surfaces).map_err(|_| internal("two cameras rendered"))?;
    let render_ms = ms_since(started);

    // Which left pixels are the part, and whether the right camera sees the same point.
    let (w, h) = (crop.width, crop.height);
    let mut cause = vec![PixelCause::NotPart; (w * h) as usize];
    let mut counts = MissingCounts::default();
    for v in 0..h {
        for u in 0..w {
            let i = (v * w + u) as usize;
            let z = depth_left.data()[i];
            if label_left.data()[i] != PART_LABEL || !z.is_finite() {
                continue;
            }
            counts.part_pixels += 1;
            let d = stereo.disparity_from_depth(z as f64);
            let u_right = (u as f64 - d + crops.right_shift_px as f64).round();
            let on_sensor =
                (0..i64::from(stereo.intrinsics.width_px)).contains(&(right_u0 + u_right as i64));
            let seen = u_right >= 0.0
                && on_sensor
                && label_right.get(u_right as u32, v) == Some(PART_LABEL)
                && depth_right
                    .get(u_right as u32, v)
                    .is_some_and(|zr| (zr - z).abs() as f64 <= settings.occlusion_tolerance_m);
            cause[i] = if seen {
                PixelCause::Kept
            } else {
                PixelCause::RightOccluded
            };
        }
    }

    let started = Instant::now();
    let mut images = None;
    let sigma_image = match settings.sigma {
        SigmaModel::Constant { sigma_z_m } => depth_left.map(|z| {
            if z.is_finite() {
                sigma_z_m as f32
            } else {
                f32::NAN
            }
        }),
        SigmaModel::Rendered => {
            let [(single_l, multi_l), (single_r, multi_r)] = white.as_slice() else {
                return Err(internal("white renders of both cameras"));
            };
            // eq 16 on the white images through g.
            for (i, c) in cause.iter_mut().enumerate() {
                if *c != PixelCause::Kept {
                    continue;
                }
                let i_multi = object.camera.intensity(multi_l.data()[i]) as f64;
                let i_single = object.camera.intensity(single_l.data()[i]) as f64;
                if !(i_multi > 0.0 && i_single / i_multi >= settings.tau_intensity_ratio) {
                    *c = PixelCause::Ratio;
                }
            }
            let patterns = shot_patterns(
                &object.rig.projector_intrinsics,
                settings.shots,
                settings.pattern_fill,
                settings.pattern_seed,
            );
            let left = pattern_images(
                object,
                single_l,
                multi_l,
                &depth_left,
                &crop_intrinsics,
                &cameras[0].t_w_c,
                &projector,
                &patterns,
                settings.pattern_fill,
            )?;
            let right = pattern_images(
                object,
                single_r,
                multi_r,
                &depth_right,
                &right_intrinsics,
                &cameras[1].t_w_c,
                &projector,
                &patterns,
                settings.pattern_fill,
            )?;
            if settings.with_maps {
                let dn = |radiance: &Image<f32>| radiance.map(|e| object.camera.intensity(e));
                images = left.first().map(|pattern| PredictionImages {
                    single_path_dn: dn(single_l),
                    multi_path_dn: dn(multi_l),
                    pattern_dn: pattern.clone(),
                });
            }
            depth_sigma_shifted(
                &left,
                &right,
                &DepthMap::new(depth_left.clone()),
                &crop_stereo,
                &object.noise,
                settings.window_radius_px,
                crops.right_shift_px,
            )?
        }
    };
    // eq 17 judges rendered σ̌_z; the constant-σ baseline keeps every visible pixel.
    for (i, c) in cause.iter_mut().enumerate() {
        if rendered_sigma && *c == PixelCause::Kept {
            let s = sigma_image.data()[i] as f64;
            if !(s.is_finite() && s <= settings.tau_sigma_m) {
                *c = PixelCause::Sigma;
            }
        }
    }
    for c in &cause {
        match c {
            PixelCause::Kept => counts.kept += 1,
            PixelCause::Ratio => counts.missing_ratio += 1,
            PixelCause::Sigma => counts.missing_sigma += 1,
            PixelCause::RightOccluded => counts.right_occluded += 1,
            PixelCause::NotPart => {}
        }
    }
    let sigma_ms = ms_since(started);

    let started = Instant::now();
    let mut points: Vec<DepthPoint> = Vec::with_capacity(counts.kept as usize);
    let kept = |u: u32, v: u32| cause[(v * w + u) as usize] == PixelCause::Kept;
    object_points(
        &DepthMap::new(depth_left),
        kept,
        DepthSigma::PerPixel(&sigma_image),
        &crop_intrinsics,
        t_w_c,
        &mut points,
    );
    let information = information_of_points(
        &object.sdf,
        &points,
        &t_w_o.inverse(),
        settings.model_sigma_m,
    );
    let information_ms = ms_since(started);

    let (sigma_z_m, cause) = if settings.with_maps {
        let causes = cause.iter().map(|&c| c as u8).collect();
        (
            Some(sigma_image),
            Some(
                Image::new(w, h, causes)
                    .map_err(|_| PredictionError::Internal("cause map size"))?,
            ),
        )
    } else {
        (None, None)
    };
    Ok(CandidatePrediction {
        information,
        counts,
        not_in_view: counts.part_pixels == 0,
        crop: Some(crop),
        right_crop_u_min_px: Some(right_u0),
        sigma_z_m,
        cause,
        images,
        render_ms,
        sigma_ms,
        information_ms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_calibration::response::{DebevecConfig, ExposureStack, calibrate};
    use glint_camera::setup::{BinSetup, BinSetupSpec};
    use glint_estimation::view::{ViewMeasurement, noise_model_of};
    use glint_geometry::Part;
    use glint_geometry::image::normalised_intensity;
    use glint_geometry::sdf::{SdfConfig, SdfGrid};
    use glint_render::sensor::Sensor;

    /// The camera as a real calibration would find it: Debevec–Malik on an exposure stack of a
    /// log-uniform radiance chart, the scale fixed by one reference radiance read at the
    /// pattern captures' exposure (the BSDF fit's reference surface does this on real data).
    fn calibrated(sensor: &Sensor) -> CalibratedCamera {
        let (w, h) = (256u32, 8u32);
        let chart: Vec<f32> = (0..w * h)
            .map(|i| 0.01 * (4000f32).powf((i % w) as f32 / (w - 1) as f32))
            .collect();
        let chart = Image::new(w, h, chart).unwrap();
        let exposures: Vec<f64> = (0..7).map(|k| 0.25e-3 * 2f64.powi(k)).collect();
        let stack = ExposureStack::read_out(sensor, &chart, &exposures, 3).unwrap();
        let table = calibrate(&stack, &DebevecConfig::default()).unwrap();
        // A reference that reads mid-scale at the sensor's own exposure.
        let reference = 0.3f32;
        let dn = sensor.noiseless_dn(reference);
        let scale = table.ln_exposure(dn).exp() / (reference as f64 * sensor.exposure_s as f64);
        CalibratedCamera::new(table, scale, sensor.exposure_s as f64).unwrap()
    }

    struct Fixture {
        setup: BinSetup,
        object: PredictorObject,
        view: ViewMeasurement,
        t_w_c: Isometry3<f64>,
    }

    fn fixture(part: Part) -> Fixture {
        let mesh = part.mesh();
        let material = glint_camera::materials::ground_truth(part);
        let setup = BinSetup::new(
            &mesh,
            material,
            &BinSetupSpec {
                instances: 1,
                seed: 4,
                width_px: 640,
                height_px: 512,
                samples_per_pixel: 2,
            },
        )
        .unwrap();
        let t_w_c = setup.views(6)[0];
        let camera = setup.camera();
        let rendered = camera.render_shots(&t_w_c, 21);
        let (capture, _) = camera.capture_rendered(&t_w_c, &rendered, 21).unwrap();
        let view = ViewMeasurement {
            t_w_c,
            stereo: setup.rig.stereo,
            depth: capture.depth.clone(),
            left: capture.shot_images(0).into_iter().cloned().collect(),
            right: capture.shot_images(1).into_iter().cloned().collect(),
            noise_shots: camera.noise_shots(&rendered, 21),
            max_dn: setup.config.sensor.max_dn(),
        };
        let noise = noise_model_of(&view).unwrap();
        let sdf = SdfGrid::build(
            &mesh,
            &SdfConfig {
                voxel_size_m: 0.5e-3,
                ..SdfConfig::default()
            },
        )
        .unwrap();
        let object = PredictorObject {
            mesh: Arc::new(mesh),
            sdf: Arc::new(sdf),
            material,
            camera: calibrated(&setup.config.sensor),
            rig: setup.rig,
            noise,
            surroundings: Vec::new(),
        };
        Fixture {
            setup,
            object,
            view,
            t_w_c,
        }
    }

    fn settings() -> PredictionSettings {
        PredictionSettings {
            with_maps: true,
            // τ_σ was tuned for the 1280×1024 camera; at this fixture's 640×512, f and so σ̌_z
            // are twice as large, and these tests are not about the threshold.
            tau_sigma_m: 1e-3,
            ..PredictionSettings::default()
        }
    }

    #[test]
    fn predicted_sigma_matches_the_cameras_own_on_its_pixels() {
        // With the true pose and material, the predictor's σ̌_z and the σ_z that eq 1–5 gives
        // on the camera's real K-shot capture agree where both exist: they share the formula,
        // so what differs is the images — rendered expectations against noisy read-outs of a
        // scene with the bin around the part. A factor of 2 on the median ratio would mean the
        // synthesised patterns' contrast or the response is wrong.
        let f = fixture(Part::Zigzag);
        let t_w_o = f.setup.poses[0];
        let p = predict_candidate(&f.object, &t_w_o, &f.t_w_c, &settings(), 5).unwrap();
        assert!(
            !p.not_in_view && p.counts.part_pixels > 100,
            "{:?}",
            p.counts
        );
        let measured = glint_estimation::depth_sigma::depth_sigma(
            &f.view
                .left
                .iter()
                .map(|s| normalised_intensity(s, f.view.max_dn))
                .collect::<Vec<_>>(),
            &f.view
                .right
                .iter()
                .map(|s| normalised_intensity(s, f.view.max_dn))
                .collect::<Vec<_>>(),
            &f.view.depth,
            &f.view.stereo,
            &f.object.noise,
            1,
        )
        .unwrap();
        let crop = p.crop.unwrap();
        let predicted = p.sigma_z_m.as_ref().unwrap();
        let mut ratios: Vec<f64> = Vec::new();
        for v in 0..crop.height {
            for u in 0..crop.width {
                let s_pred = predicted.get(u, v).unwrap() as f64;
                let s_meas = measured.get(u + crop.u_min, v + crop.v_min).unwrap() as f64;
                if s_pred.is_finite() && s_meas.is_finite() && s_pred > 0.0 && s_meas > 0.0 {
                    ratios.push(s_pred / s_meas);
                }
            }
        }
        assert!(ratios.len() > 100, "{} pixels with both", ratios.len());
        ratios.sort_by(f64::total_cmp);
        let median = ratios[ratios.len() / 2];
        eprintln!(
            "median σ̌/σ {median} over {} pixels, {:?}",
            ratios.len(),
            p.counts
        );
        assert!((0.5..2.0).contains(&median), "median σ̌/σ {median}");
        let c = p.counts;
        assert_eq!(
            c.kept + c.missing_ratio + c.missing_sigma + c.right_occluded,
            c.part_pixels
        );
    }

    #[test]
    fn information_is_seeded_symmetric_and_grows_with_certainty() {
        let f = fixture(Part::Zigzag);
        let t_w_o = f.setup.poses[0];
        let s = settings();
        let a = predict_candidate(&f.object, &t_w_o, &f.t_w_c, &s, 9).unwrap();
        let b = predict_candidate(&f.object, &t_w_o, &f.t_w_c, &s, 9).unwrap();
        assert_eq!(a.information, b.information, "same request, same answer");
        // A scene shared by the candidates of a decision changes nothing.
        let hypothesis = HypothesisScene::build(&f.object, &t_w_o).unwrap();
        for _ in 0..2 {
            let shared = predict_candidate_in(&f.object, &hypothesis, &f.t_w_c, &s, 9).unwrap();
            assert_eq!(shared.information, a.information);
        }
        let info = a.information;
        assert!((info - info.transpose()).amax() <= 1e-9 * info.amax());
        assert!(info.symmetric_eigenvalues().min() >= -1e-9 * info.amax());
        assert!(a.counts.kept > 50, "{:?}", a.counts);
        // Constant σ: information falls as 1/(G²σ² + σ_model²) per point, so from σ 2 mm to
        // 4 mm it drops by between 1× and 4×, close to 4× when G ≈ 1 dominates.
        let constant = |sigma_z_m| {
            let s = PredictionSettings {
                sigma: SigmaModel::Constant { sigma_z_m },
                ..settings()
            };
            predict_candidate(&f.object, &t_w_o, &f.t_w_c, &s, 9).unwrap()
        };
        let (two, four) = (constant(2e-3), constant(4e-3));
        assert_eq!(two.counts.kept, four.counts.kept);
        let ratio = two.information.trace() / four.information.trace();
        assert!(
            (1.0..=4.0 + 1e-9).contains(&ratio) && ratio > 3.0,
            "ratio {ratio}"
        );
        // A camera looking away sees nothing and adds nothing.
        let away =
            f.t_w_c * Isometry3::rotation(nalgebra::Vector3::new(0.0, std::f64::consts::PI, 0.0));
        let p = predict_candidate(&f.object, &t_w_o, &away, &s, 9).unwrap();
        assert!(p.not_in_view);
        assert_eq!(p.information, Matrix6::zeros());
    }

    #[test]
    fn bad_requests_name_their_field() {
        let f = fixture(Part::Zigzag);
        let t_w_o = f.setup.poses[0];
        let mut nan = f.t_w_c;
        nan.translation.vector.x = f64::NAN;
        let err = predict_candidate(&f.object, &t_w_o, &nan, &settings(), 1).unwrap_err();
        assert!(
            matches!(err, PredictionError::Input { field: "t_w_c", .. }),
            "{err}"
        );
        let mut nan_pose = t_w_o;
        nan_pose.translation.vector.z = f64::NAN;
        for err in [
            HypothesisScene::build(&f.object, &nan_pose).err(),
            predict_candidate(&f.object, &nan_pose, &f.t_w_c, &settings(), 1).err(),
        ] {
            assert!(
                matches!(err, Some(PredictionError::Input { field: "t_w_o", .. })),
                "{err:?}"
            );
        }
        let s = PredictionSettings {
            tau_sigma_m: -1.0,
            ..settings()
        };
        let err = predict_candidate(&f.object, &t_w_o, &f.t_w_c, &s, 1).unwrap_err();
        assert!(
            matches!(
                err,
                PredictionError::Input {
                    field: "tau_sigma_m",
                    ..
                }
            ),
            "{err}"
        );
    }
}
