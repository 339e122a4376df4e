//! The render worker's gRPC server (`glint.v1.UncertaintyService`): decode and validate the
//! request, run [`crate::predict_candidate_in`] on the blocking pool, encode.
//!
//! - `RegisterObject` builds a [`PredictorObject`] (mesh, its SDF grid with the refiner's voxel,
//!   the fitted material, the calibrated camera, rig, noise and surroundings) and keeps it in a
//!   bounded in-memory registry under the SHA-256 of the request's canonical encoding
//!   ([`object_key`]); the oldest object is evicted beyond [`REGISTRY_CAPACITY`].
//! - `PredictCandidates` predicts every candidate of the request, one after another (each
//!   render is parallel inside), candidate `i` seeded by `candidate_seed(seed, index_i)`.
//!
//! Errors: bad input → INVALID_ARGUMENT naming the request's field; an unknown object →
//! NOT_FOUND naming its hash (the caller registers it and re-sends); anything else → INTERNAL.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use glint_calibration::server::response_from_message;
use glint_estimation::depth_sigma::NoiseModel;
use glint_geometry::TriMesh;
use glint_geometry::camera::{PinholeIntrinsics, StereoRig};
use glint_geometry::image::Image;
use glint_geometry::io::LoadedMesh;
use glint_geometry::sdf::{SdfConfig, SdfGrid};
use glint_proto::ConversionError;
use glint_proto::v1;
use glint_proto::v1::uncertainty_service_server::{UncertaintyService, UncertaintyServiceServer};
use glint_render::bsdf::PrincipledParams;
use glint_render::rig::SliRig;
use nalgebra::Isometry3;
use prost::Message;
use tonic::{Request, Response, Status};

use crate::{
    CalibratedCamera, HypothesisScene, KnownSurface, PredictionError, PredictionSettings,
    PredictorObject, SigmaModel, candidate_seed, predict_candidate_in,
};

/// The service's name, as health reports it.
pub const SERVICE_NAME: &str = "glint.v1.UncertaintyService";

/// Objects a worker keeps; registering one more evicts the oldest.
pub const REGISTRY_CAPACITY: usize = 64;

/// Candidates one request may carry.
pub const MAX_CANDIDATES: usize = 1000;

/// Known surfaces one object may carry.
pub const MAX_SURROUNDINGS: usize = 16;

/// A registered object and what of the camera the predictions need beyond it.
#[derive(Clone, Debug)]
pub struct RegisteredObject {
    /// What the predictions render: mesh, SDF grid, material, calibrated camera, rig, noise and
    /// surroundings.
    pub object: PredictorObject,
    /// Pattern shots per capture (K).
    pub shots: u32,
    /// Fraction of lit projector pixels in the patterns.
    pub pattern_fill: f64,
}

/// Objects by key, oldest first.
#[derive(Debug)]
struct Registry {
    capacity: usize,
    order: VecDeque<String>,
    objects: HashMap<String, Arc<RegisteredObject>>,
}

impl Registry {
    fn get(&self, key: &str) -> Option<Arc<RegisteredObject>> {
        self.objects.get(key).cloned()
    }

    fn insert(&mut self, key: String, object: Arc<RegisteredObject>) {
        if self.objects.insert(key.clone(), object).is_some() {
            self.order.retain(|k| *k != key);
        }
        self.order.push_back(key);
        while self.order.len() > self.capacity {
            if let Some(oldest) = self.order.pop_front() {
                self.objects.remove(&oldest);
            }
        }
    }
}

/// The render worker: its registry and the settings a request's zeros stand for.
#[derive(Clone, Debug)]
pub struct Uncertainty {
    registry: Arc<Mutex<Registry>>,
    /// What a request's 0 settings mean (`PredictionSettings::default()`); the object's camera
    /// overrides shots and pattern fill.
    pub defaults: PredictionSettings,
    /// The SDF grids of registered meshes: the refiner's voxel, so predicted information
    /// weighs as refined.
    pub sdf: SdfConfig,
}

impl Default for Uncertainty {
    fn default() -> Self {
        Self::with_capacity(REGISTRY_CAPACITY)
    }
}

impl Uncertainty {
    /// A worker keeping at most `capacity` objects (at least 1).
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            registry: Arc::new(Mutex::new(Registry {
                capacity: capacity.max(1),
                order: VecDeque::new(),
                objects: HashMap::new(),
            })),
            defaults: PredictionSettings::default(),
            sdf: crate::predict::prediction_grid_config(),
        }
    }

    /// The tonic service to add to a server's routes.
    pub fn into_service(self) -> UncertaintyServiceServer<Self> {
        UncertaintyServiceServer::new(self)
    }

    fn registry(&self) -> Result<std::sync::MutexGuard<'_, Registry>, Status> {
        self.registry
            .lock()
            .map_err(|_| Status::internal("the object registry's lock was poisoned"))
    }
}

/// The object's key: SHA-256 (lowercase hex) of the request re-encoded (protobuf binary,
/// fields in number order, unknown fields dropped) with every mesh's `name` and every pose's
/// frame names cleared, so only what changes a prediction is hashed.
pub fn object_key(request: &v1::RegisterObjectRequest) -> String {
    let mut canonical = request.clone();
    if let Some(mesh) = canonical.mesh.as_mut() {
        mesh.name.clear();
    }
    if let Some(pose) = canonical
        .rig
        .as_mut()
        .and_then(|rig| rig.t_left_projector.as_mut())
    {
        pose.parent_frame.clear();
        pose.child_frame.clear();
    }
    for surface in &mut canonical.surroundings {
        if let Some(mesh) = surface.mesh.as_mut() {
            mesh.name.clear();
        }
        if let Some(pose) = surface.t_w_s.as_mut() {
            pose.parent_frame.clear();
            pose.child_frame.clear();
        }
    }
    glint_geometry::sha256_hex(&canonical.encode_to_vec())
}

fn required<'a, T>(value: &'a Option<T>, field: &str) -> Result<&'a T, ConversionError> {
    value
        .as_ref()
        .ok_or_else(|| ConversionError::missing(field))
}

fn positive(field: &str, value: f64, unit: &str) -> Result<f64, ConversionError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(ConversionError::new(
            field,
            format!("{value} must be finite and positive{unit}"),
        ))
    }
}

/// A mesh file in metres; `field` names it in errors.
fn mesh_of(file: &Option<v1::MeshFile>, field: &str) -> Result<TriMesh, ConversionError> {
    let file = required(file, field)?;
    let loaded = LoadedMesh::try_from(file).map_err(|e| e.within(field))?;
    Ok(loaded.mesh)
}

/// The rig: the stereo pair and the projector at `t_left_projector` (absent: at the rig's
/// midpoint, looking along the left camera's +z).
pub fn rig_from_message(rig: &v1::GetRigResponse) -> Result<SliRig, ConversionError> {
    let stereo =
        StereoRig::try_from(required(&rig.stereo, "stereo")?).map_err(|e| e.within("stereo"))?;
    let projector = PinholeIntrinsics::try_from(required(&rig.projector, "projector")?)
        .map_err(|e| e.within("projector"))?;
    let intensity = if rig.projector_intensity_w_per_sr == 0.0 {
        1.0
    } else {
        positive(
            "projector_intensity_w_per_sr",
            rig.projector_intensity_w_per_sr,
            " (W/sr)",
        )?
    };
    let t_left_projector = match &rig.t_left_projector {
        Some(pose) => Isometry3::try_from(pose).map_err(|e| e.within("t_left_projector"))?,
        None => Isometry3::translation(stereo.baseline_m / 2.0, 0.0, 0.0),
    };
    Ok(SliRig {
        stereo,
        t_left_projector,
        projector_intrinsics: projector,
        projector_intensity_w_per_sr: intensity as f32,
    })
}

/// A rig as its message (`max_dn` and `exposure_s` are the camera's, not the rig's; the
/// capture settings `shots_per_capture`, `window_radius_px` and `pattern_fill` are left 0, as a
/// registration carries its own).
pub fn rig_to_message(rig: &SliRig, max_dn: u32, exposure_s: f64) -> v1::GetRigResponse {
    v1::GetRigResponse {
        stereo: Some((&rig.stereo).into()),
        projector: Some((&rig.projector_intrinsics).into()),
        max_dn,
        exposure_s,
        projector_intensity_w_per_sr: f64::from(rig.projector_intensity_w_per_sr),
        t_left_projector: Some(v1::Pose::with_frames(
            &rig.t_left_projector,
            "left_camera",
            "projector",
        )),
        shots_per_capture: 0,
        window_radius_px: 0,
        pattern_fill: 0.0,
    }
}

/// The sensor's noise model: 1 to 1024 finite, non-negative variances and a positive floor.
pub fn noise_from_message(m: &v1::SensorNoiseModel) -> Result<NoiseModel, ConversionError> {
    let n = m.variance_by_bin.len();
    if !(1..=1024).contains(&n) {
        return Err(ConversionError::new(
            "variance_by_bin",
            format!("has {n} values; it needs 1 to 1024"),
        ));
    }
    if let Some(i) = m
        .variance_by_bin
        .iter()
        .position(|v| !(v.is_finite() && *v >= 0.0))
    {
        return Err(ConversionError::new(
            "variance_by_bin",
            format!(
                "value {i} is {}; variances must be finite and non-negative ((full scale)²)",
                m.variance_by_bin[i]
            ),
        ));
    }
    Ok(NoiseModel {
        variance_by_bin: m.variance_by_bin.clone(),
        floor_variance: positive("floor_variance", m.floor_variance, " ((full scale)²)")?,
    })
}

/// A noise model as its message.
pub fn noise_to_message(noise: &NoiseModel) -> v1::SensorNoiseModel {
    v1::SensorNoiseModel {
        variance_by_bin: noise.variance_by_bin.clone(),
        floor_variance: noise.floor_variance,
    }
}

/// What a caller knows of an object to register it: a [`PredictorObject`] but for the SDF
/// grid, which the worker builds.
#[derive(Clone, Copy, Debug)]
pub struct ObjectDescription<'a> {
    /// The part's name (logs only; not part of the key).
    pub name: &'a str,
    /// The part's mesh, metres, object frame.
    pub mesh: &'a TriMesh,
    /// The fitted material (`glint calibrate bsdf`).
    pub material: &'a PrincipledParams<f32>,
    /// The calibrated response and radiometric scale.
    pub camera: &'a CalibratedCamera,
    /// The camera rig and its projector.
    pub rig: &'a SliRig,
    /// The sensor's intensity noise σ_I².
    pub noise: &'a NoiseModel,
    /// Known static surfaces rendered with the part; empty: the part alone.
    pub surroundings: &'a [KnownSurface],
    /// Pattern shots per capture (K).
    pub shots: u32,
    /// Fraction of lit projector pixels in the patterns.
    pub pattern_fill: f64,
}

/// The registration of `object` (the inverse of [`decode_object`]): meshes as binary PLY in
/// metres.
pub fn object_to_message(object: &ObjectDescription<'_>) -> v1::RegisterObjectRequest {
    let mesh_file = |mesh: &TriMesh, name: &str| v1::MeshFile {
        data: glint_geometry::io::write_ply_to_vec(
            mesh,
            glint_geometry::LengthUnit::Metre,
            glint_geometry::io::PlyEncoding::BinaryLittleEndian,
        ),
        format: "ply".into(),
        unit: v1::LengthUnit::Metre as i32,
        name: name.into(),
    };
    let camera = &object.camera;
    v1::RegisterObjectRequest {
        mesh: Some(mesh_file(object.mesh, object.name)),
        material: Some(v1::PrincipledMaterial::from(object.material)),
        response: Some(glint_calibration::server::response_to_message(
            &camera.response,
        )),
        rig: Some(rig_to_message(
            object.rig,
            u32::from(camera.response.max_dn),
            camera.exposure_s,
        )),
        radiometric_scale: camera.radiometric_scale,
        pattern_exposure_s: camera.exposure_s,
        noise: Some(noise_to_message(object.noise)),
        shots_per_capture: object.shots,
        pattern_fill: object.pattern_fill,
        surroundings: object
            .surroundings
            .iter()
            .map(|s| v1::KnownSurface {
                mesh: Some(mesh_file(&s.mesh, "surrounding")),
                t_w_s: Some((&s.t_w_s).into()),
                material: Some(v1::PrincipledMaterial::from(&s.material)),
            })
            .collect(),
    }
}

/// Decodes and validates a registration and builds its object (meshes, SDF grid): the slow
/// part, for the blocking pool.
pub fn decode_object(
    request: &v1::RegisterObjectRequest,
    sdf: &SdfConfig,
) -> Result<RegisteredObject, ConversionError> {
    let mesh = mesh_of(&request.mesh, "mesh")?;
    let material = PrincipledParams::try_from(required(&request.material, "material")?)
        .map_err(|e| e.within("material"))?;
    let response = response_from_message(required(&request.response, "response")?)
        .map_err(|e| e.within("response"))?;
    let rig_msg = required(&request.rig, "rig")?;
    let rig = rig_from_message(rig_msg).map_err(|e| e.within("rig"))?;
    let radiometric_scale = positive(
        "radiometric_scale",
        request.radiometric_scale,
        " (relative radiance-map units per W·sr⁻¹·m⁻²)",
    )?;
    let exposure_s = if request.pattern_exposure_s == 0.0 {
        positive(
            "rig.exposure_s",
            rig_msg.exposure_s,
            " seconds (pattern_exposure_s is 0)",
        )?
    } else {
        positive("pattern_exposure_s", request.pattern_exposure_s, " seconds")?
    };
    let camera = CalibratedCamera::new(response, radiometric_scale, exposure_s)
        .map_err(|e| ConversionError::new("radiometric_scale", e.to_string()))?;
    let noise =
        noise_from_message(required(&request.noise, "noise")?).map_err(|e| e.within("noise"))?;
    if !(1..=64).contains(&request.shots_per_capture) {
        return Err(ConversionError::new(
            "shots_per_capture",
            format!("is {}; it must be 1 to 64", request.shots_per_capture),
        ));
    }
    let pattern_fill = request.pattern_fill;
    if !(pattern_fill > 0.0 && pattern_fill <= 1.0) {
        return Err(ConversionError::new(
            "pattern_fill",
            format!("{pattern_fill} must be in (0, 1]"),
        ));
    }
    if request.surroundings.len() > MAX_SURROUNDINGS {
        return Err(ConversionError::new(
            "surroundings",
            format!(
                "has {} surfaces; at most {MAX_SURROUNDINGS}",
                request.surroundings.len()
            ),
        ));
    }
    let surroundings = request
        .surroundings
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let field = format!("surroundings[{i}]");
            let inner = || -> Result<KnownSurface, ConversionError> {
                Ok(KnownSurface {
                    mesh: Arc::new(mesh_of(&s.mesh, "mesh")?),
                    t_w_s: Isometry3::try_from(required(&s.t_w_s, "t_w_s")?)
                        .map_err(|e| e.within("t_w_s"))?,
                    material: PrincipledParams::try_from(required(&s.material, "material")?)
                        .map_err(|e| e.within("material"))?,
                })
            };
            inner().map_err(|e| e.within(&field))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let grid = SdfGrid::build(&mesh, sdf)
        .map_err(|e| ConversionError::new("mesh", format!("SDF grid: {e}")))?;
    Ok(RegisteredObject {
        object: PredictorObject {
            mesh: Arc::new(mesh),
            sdf: Arc::new(grid),
            material,
            camera,
            rig,
            noise,
            surroundings,
        },
        shots: request.shots_per_capture,
        pattern_fill,
    })
}

/// The prediction settings of a request for `object`: its zeros are `defaults`, the object's
/// camera sets shots and pattern fill.
pub fn settings_of(
    msg: Option<&v1::PredictionSettings>,
    with_maps: bool,
    object: &RegisteredObject,
    defaults: &PredictionSettings,
) -> PredictionSettings {
    let msg = msg.cloned().unwrap_or_default();
    let or = |v: f64, default: f64| if v == 0.0 { default } else { v };
    let or_u = |v: u32, default: u32| if v == 0 { default } else { v };
    PredictionSettings {
        sigma: if msg.constant_sigma_z_m == 0.0 {
            SigmaModel::Rendered
        } else {
            SigmaModel::Constant {
                sigma_z_m: msg.constant_sigma_z_m,
            }
        },
        tau_intensity_ratio: or(msg.tau_intensity_ratio, defaults.tau_intensity_ratio),
        tau_sigma_m: or(msg.tau_sigma_z_m, defaults.tau_sigma_m),
        samples_per_pixel: or_u(msg.samples_per_pixel, defaults.samples_per_pixel),
        window_radius_px: or_u(msg.window_radius_px, defaults.window_radius_px),
        shots: object.shots,
        pattern_fill: object.pattern_fill,
        with_maps,
        ..*defaults
    }
}

/// The request field a library input error is about.
fn request_field(field: &str, candidate: usize) -> String {
    match field {
        "t_w_c" => format!("candidates_t_w_c[{candidate}]"),
        "t_w_o" => "t_w_o".into(),
        "tau_sigma_m" => "settings.tau_sigma_z_m".into(),
        "sigma_z_m" => "settings.constant_sigma_z_m".into(),
        "tau_intensity_ratio" | "samples_per_pixel" | "window_radius_px" => {
            format!("settings.{field}")
        }
        // Validated at registration; named as the object's fields.
        "shots" => "shots_per_capture".into(),
        other => other.into(),
    }
}

fn status_of(e: PredictionError, candidate: usize) -> Status {
    match e {
        PredictionError::Input { field, message } => {
            Status::invalid_argument(format!("{}: {message}", request_field(field, candidate)))
        }
        other => Status::internal(other.to_string()),
    }
}

/// A σ̌_z map as a FLOAT32 image (NaN where missing, so a receiver reads the bytes rather than
/// `Image::<f32>::try_from`, which rejects NaN).
fn sigma_map_message(map: &Image<f32>) -> v1::Image {
    v1::Image {
        width_px: map.width(),
        height_px: map.height(),
        encoding: v1::ImageEncoding::Float32Le as i32,
        pixel_space: v1::PixelSpace::Unspecified as i32,
        data: map.data().iter().flat_map(|s| s.to_le_bytes()).collect(),
    }
}

/// The cause of each σ̌_z map pixel ([`crate::PixelCause`] as `u8`) as a MONO8 image.
fn cause_map_message(cause: &Image<u8>) -> v1::Image {
    v1::Image {
        width_px: cause.width(),
        height_px: cause.height(),
        encoding: v1::ImageEncoding::Mono8 as i32,
        pixel_space: v1::PixelSpace::Unspecified as i32,
        data: cause.data().to_vec(),
    }
}

/// The poses of a prediction request, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct CandidatePoses {
    /// The hypothesis, object → world.
    pub t_w_o: Isometry3<f64>,
    /// `(index, left camera → world)` per candidate, in the request's order.
    pub candidates: Vec<(u32, Isometry3<f64>)>,
}

/// Decodes a prediction request's poses and candidate indices.
pub fn decode_poses(
    request: &v1::PredictCandidatesRequest,
) -> Result<CandidatePoses, ConversionError> {
    let t_w_o =
        Isometry3::try_from(required(&request.t_w_o, "t_w_o")?).map_err(|e| e.within("t_w_o"))?;
    let n = request.candidates_t_w_c.len();
    if n == 0 {
        return Err(ConversionError::new(
            "candidates_t_w_c",
            "is empty; send at least one candidate pose",
        ));
    }
    if n > MAX_CANDIDATES {
        return Err(ConversionError::new(
            "candidates_t_w_c",
            format!("has {n} poses; at most {MAX_CANDIDATES} per request"),
        ));
    }
    let indices: Vec<u32> = if request.candidate_indices.is_empty() {
        (0..n as u32).collect()
    } else if request.candidate_indices.len() == n {
        request.candidate_indices.clone()
    } else {
        return Err(ConversionError::new(
            "candidate_indices",
            format!(
                "has {} values for {n} candidates; send one per candidate or none",
                request.candidate_indices.len()
            ),
        ));
    };
    let candidates = request
        .candidates_t_w_c
        .iter()
        .zip(indices)
        .enumerate()
        .map(|(i, (pose, index))| {
            Isometry3::try_from(pose)
                .map(|t| (index, t))
                .map_err(|e| e.within(&format!("candidates_t_w_c[{i}]")))
        })
        .collect::<Result<_, _>>()?;
    Ok(CandidatePoses { t_w_o, candidates })
}

#[tonic::async_trait]
impl UncertaintyService for Uncertainty {
    async fn register_object(
        &self,
        request: Request<v1::RegisterObjectRequest>,
    ) -> Result<Response<v1::RegisterObjectResponse>, Status> {
        let request = request.into_inner();
        let key = object_key(&request);
        if self.registry()?.get(&key).is_none() {
            let sdf = self.sdf;
            let object = glint_server::blocking(move || decode_object(&request, &sdf)).await??;
            self.registry()?.insert(key.clone(), Arc::new(object));
            tracing::info!("registered object {key}");
        }
        Ok(Response::new(v1::RegisterObjectResponse {
            object_sha256_hex: key,
        }))
    }

    async fn predict_candidates(
        &self,
        request: Request<v1::PredictCandidatesRequest>,
    ) -> Result<Response<v1::PredictCandidatesResponse>, Status> {
        let request = request.into_inner();
        let key = &request.object_sha256_hex;
        let object = self.registry()?.get(key).ok_or_else(|| {
            Status::not_found(format!(
                "object_sha256_hex: object {key:?} is not registered on this worker; call \
                 RegisterObject and send the request again"
            ))
        })?;
        let CandidatePoses { t_w_o, candidates } = decode_poses(&request)?;
        let settings = settings_of(
            request.settings.as_ref(),
            request.with_sigma_maps,
            &object,
            &self.defaults,
        );
        let seed = request.seed;
        let predictions = glint_server::blocking(move || {
            // One scene for the request's hypothesis, shared by its candidates.
            let hypothesis =
                HypothesisScene::build(&object.object, &t_w_o).map_err(|e| status_of(e, 0))?;
            candidates
                .iter()
                .enumerate()
                .map(|(i, (index, t_w_c))| {
                    let started = Instant::now();
                    let p = predict_candidate_in(
                        &object.object,
                        &hypothesis,
                        t_w_c,
                        &settings,
                        candidate_seed(seed, *index),
                    )
                    .map_err(|e| status_of(e, i))?;
                    let (sigma_z_m, missing_cause, roi_u0_px, roi_v0_px) =
                        match (&p.sigma_z_m, &p.cause, p.crop) {
                            (Some(map), Some(cause), Some(crop)) => (
                                Some(sigma_map_message(map)),
                                Some(cause_map_message(cause)),
                                crop.u_min,
                                crop.v_min,
                            ),
                            _ => (None, None, 0, 0),
                        };
                    Ok(v1::CandidatePrediction {
                        candidate_index: *index,
                        information: Some((&p.information).into()),
                        roi_pixels: p.crop.map_or(0, |c| c.width * c.height),
                        part_pixels: p.counts.part_pixels,
                        predicted_points: p.counts.kept,
                        missing_ratio: p.counts.missing_ratio,
                        missing_sigma: p.counts.missing_sigma,
                        not_in_view: p.not_in_view,
                        sigma_z_m,
                        roi_u0_px,
                        roi_v0_px,
                        predict_ms: started.elapsed().as_secs_f64() * 1e3,
                        missing_right_occluded: p.counts.right_occluded,
                        missing_cause,
                    })
                })
                .collect::<Result<Vec<_>, Status>>()
        })
        .await??;
        Ok(Response::new(v1::PredictCandidatesResponse { predictions }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_registry_evicts_the_oldest() {
        let object = Arc::new(RegisteredObject {
            object: PredictorObject {
                mesh: Arc::new(glint_geometry::Part::Zigzag.mesh()),
                sdf: Arc::new(
                    SdfGrid::build(&glint_geometry::Part::Zigzag.mesh(), &SdfConfig::default())
                        .unwrap(),
                ),
                material: PrincipledParams::from_array([0.5; 10]),
                camera: CalibratedCamera::new(
                    glint_calibration::response::ResponseTable::load(
                        &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                            .join("../../assets/calibration/zigzag/response.json"),
                    )
                    .unwrap(),
                    1.0,
                    1e-3,
                )
                .unwrap(),
                rig: SliRig::ensenso_n35(),
                noise: NoiseModel::constant(1e-5),
                surroundings: Vec::new(),
            },
            shots: 8,
            pattern_fill: 0.5,
        });
        let mut r = Registry {
            capacity: 2,
            order: VecDeque::new(),
            objects: HashMap::new(),
        };
        r.insert("a".into(), object.clone());
        r.insert("b".into(), object.clone());
        r.insert("a".into(), object.clone()); // refreshed: now the newest
        r.insert("c".into(), object);
        assert!(r.get("b").is_none());
        assert!(r.get("a").is_some() && r.get("c").is_some());
        assert_eq!(r.order, ["a", "c"]);
    }

    #[test]
    fn messages_round_trip_and_name_bad_fields() {
        let rig = SliRig::ensenso_n35().resized(320, 256).unwrap();
        let back = rig_from_message(&rig_to_message(&rig, 4095, 1e-3)).unwrap();
        assert_eq!(back, rig);

        let m = PrincipledParams::from_array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]);
        assert_eq!(
            PrincipledParams::try_from(v1::PrincipledMaterial::from(&m)).unwrap(),
            m
        );
        let bad = v1::PrincipledMaterial {
            roughness: f64::NAN,
            ..v1::PrincipledMaterial::from(&m)
        };
        assert_eq!(
            PrincipledParams::try_from(&bad).unwrap_err().field,
            "roughness"
        );

        let noise = NoiseModel::constant(1e-5);
        assert_eq!(
            noise_from_message(&noise_to_message(&noise)).unwrap(),
            noise
        );
        let bad = v1::SensorNoiseModel {
            floor_variance: 0.0,
            ..noise_to_message(&noise)
        };
        assert_eq!(
            noise_from_message(&bad).unwrap_err().field,
            "floor_variance"
        );
        let bad = v1::SensorNoiseModel {
            variance_by_bin: vec![],
            ..noise_to_message(&noise)
        };
        assert_eq!(
            noise_from_message(&bad).unwrap_err().field,
            "variance_by_bin"
        );
    }
}
