//! The mock camera's gRPC server: `glint.v1.CameraService` (the camera as known hardware: its
//! rig, the views it can take, captures and exposure stacks) and `glint.v1.MockCameraService`
//! (the simulator's scene set-up and, for evaluation only, its ground truth). Handlers decode
//! and validate, run the library on the blocking pool, encode.
//!
//! The server holds one scene at a time ([`MockScene`]), replaced by `SetUpScene`; a capture
//! already running keeps the scene it started on. Until a scene is set up every call but
//! `SetUpScene` answers FAILED_PRECONDITION.
//!
//! A capture streams a [`v1::CaptureHeader`] and then the arrays' chunks (≤ 1 MiB each, so a
//! client with gRPC's default 4 MiB receive limit gets a full 1280×1024 capture): the K left
//! pattern images ([`left_array_name`]), the K right ones ([`right_array_name`]), the depth
//! ([`DEPTH_ARRAY`]) and, when asked, the noise shots ([`NOISE_ARRAYS`]).
//!
//! Errors: bad input → INVALID_ARGUMENT naming the request's field (`t_w_c.rotation`,
//! `part.builtin`, `instances`, …); no scene yet → FAILED_PRECONDITION; anything else →
//! INTERNAL.

use std::pin::Pin;
use std::sync::{Arc, RwLock};
use std::time::Instant;

use glint_geometry::image::Image;
use glint_geometry::io::LoadedMesh;
use glint_geometry::{Part, TriMesh};
use glint_proto::ConversionError;
use glint_proto::chunks::{CHUNK_BYTES, OutgoingArray};
use glint_proto::v1;
use glint_proto::v1::camera_service_server::{CameraService, CameraServiceServer};
use glint_proto::v1::mock_camera_service_server::{MockCameraService, MockCameraServiceServer};
use glint_render::bsdf::PrincipledParams;
use nalgebra::{Isometry3, Point3};
use tokio_stream::Stream;
use tonic::{Request, Response, Status};

use crate::bin::{BinError, BinSpec};
use crate::capture::{CaptureError, StereoCapture};
use crate::materials;
use crate::setup::{BinSetup, BinSetupSpec, SetupError, VIEW_CAP_DEG, VIEW_DISTANCE_M};
use crate::views::spherical_cap;

/// The camera service's name, as health reports it.
pub const CAMERA_SERVICE_NAME: &str = "glint.v1.CameraService";
/// The mock-only service's name (scene set-up, ground truth), as health reports it.
pub const MOCK_CAMERA_SERVICE_NAME: &str = "glint.v1.MockCameraService";
/// Every service this server hosts.
pub const SERVICE_NAMES: [&str; 2] = [CAMERA_SERVICE_NAME, MOCK_CAMERA_SERVICE_NAME];

/// Most instances a scene may hold.
pub const MAX_INSTANCES: u32 = 40;
/// Image size limits, px: at K = 8 shots a capture streams 40 bytes per pixel (16 pattern
/// images, depth, 2 noise shots), which keeps the largest within the 256 MiB a stream may
/// declare. This is the smallest width and height a scene may ask for.
pub const MIN_IMAGE_SIDE_PX: u32 = 32;
/// Largest image width a scene may ask for, px (see [`MIN_IMAGE_SIDE_PX`]).
pub const MAX_WIDTH_PX: u32 = 2560;
/// Largest image height a scene may ask for, px (see [`MIN_IMAGE_SIDE_PX`]).
pub const MAX_HEIGHT_PX: u32 = 2048;
/// Samples per pixel when a request gives 0.
pub const DEFAULT_SAMPLES_PER_PIXEL: u32 = 4;
/// Most samples per pixel a request may ask for.
pub const MAX_SAMPLES_PER_PIXEL: u32 = 1024;
/// Most views one `ListCandidateViews` returns.
pub const MAX_CANDIDATE_VIEWS: u32 = 1000;
/// Farthest candidate views, metres from their target.
pub const MAX_VIEW_DISTANCE_M: f64 = 10.0;
/// Widest cap of candidate views, degrees.
pub const MAX_CAP_HALF_ANGLE_DEG: f64 = 89.0;
/// Most exposure times in one stack.
pub const MAX_EXPOSURES: usize = 64;

/// The name of left pattern image `k` (0-based, projection order) in a capture stream.
pub fn left_array_name(k: usize) -> String {
    format!("left_{k:03}")
}

/// The name of right pattern image `k` in a capture stream.
pub fn right_array_name(k: usize) -> String {
    format!("right_{k:03}")
}

/// The name of exposure `k` of an exposure-stack stream.
pub fn exposure_array_name(k: usize) -> String {
    format!("exposure_{k:03}")
}

/// The depth map of a capture stream (left camera, float32 metres, NaN where missing).
pub const DEPTH_ARRAY: &str = "depth";
/// The two noise shots of a capture stream, when asked.
pub const NOISE_ARRAYS: [&str; 2] = ["noise_a", "noise_b"];

/// The frame names of the poses this server sends.
const WORLD: &str = "world";

/// A validated `SetUpSceneRequest`.
#[derive(Clone, Debug)]
pub struct SceneRequest {
    /// The part's mesh, metres, object frame.
    pub mesh: TriMesh,
    /// The built-in part's name or the mesh file's.
    pub name: String,
    /// The part's true material.
    pub material: PrincipledParams<f32>,
    /// Instances, drop seed, resolution and samples per pixel of the set-up.
    pub spec: BinSetupSpec,
}

fn required<'a, T>(value: &'a Option<T>, field: &str) -> Result<&'a T, ConversionError> {
    value
        .as_ref()
        .ok_or_else(|| ConversionError::missing(field))
}

/// A pose field of a request: required, finite, a unit quaternion.
fn pose_field(pose: &Option<v1::Pose>, field: &str) -> Result<Isometry3<f64>, ConversionError> {
    Isometry3::try_from(required(pose, field)?).map_err(|e| e.within(field))
}

/// The widest a user's part may be, metres along any axis: the bin's narrower inner side
/// (a bigger part cannot be dropped in, and its collision grid would be needlessly large).
fn max_part_extent_m(bin: &BinSpec) -> f64 {
    bin.inner_size_m[0].min(bin.inner_size_m[1])
}

/// Decodes and validates a scene request: the part (built-in by name, or a mesh file parsed
/// into metres), instances, material (default [`materials::ground_truth`] of the part, the
/// Tube Fitting's for a user's mesh), image size and samples per pixel (0s as the proto
/// says).
pub fn scene_request(msg: &v1::SetUpSceneRequest) -> Result<SceneRequest, ConversionError> {
    let part = required(&msg.part, "part")?
        .part
        .as_ref()
        .ok_or_else(|| ConversionError::new("part", "set either builtin or mesh"))?;
    let (mesh, name, default_material) = match part {
        v1::part_spec::Part::Builtin(name) => {
            let part: Part = name
                .parse()
                .map_err(|e: String| ConversionError::new("part.builtin", e))?;
            (
                part.mesh(),
                part.name().to_owned(),
                materials::ground_truth(part),
            )
        }
        v1::part_spec::Part::Mesh(file) => {
            let loaded = LoadedMesh::try_from(file).map_err(|e| e.within("part.mesh"))?;
            let limit = max_part_extent_m(&BinSpec::default());
            let extent = loaded
                .mesh
                .aabb()
                .map_or(0.0, |(min, max)| f64::from((max - min).max()));
            if extent.is_nan() || extent > limit {
                return Err(ConversionError::new(
                    "part.mesh",
                    format!(
                        "the part is {extent:.3} m across; the bin takes parts up to {limit} m (is `unit` right?)"
                    ),
                ));
            }
            let name = if file.name.is_empty() {
                "mesh".to_owned()
            } else {
                file.name.clone()
            };
            (
                loaded.mesh,
                name,
                materials::ground_truth(Part::TubeFitting),
            )
        }
    };
    if !(1..=MAX_INSTANCES).contains(&msg.instances) {
        return Err(ConversionError::new(
            "instances",
            format!("is {}; it must be 1 to {MAX_INSTANCES}", msg.instances),
        ));
    }
    let material = match &msg.material {
        Some(m) => PrincipledParams::try_from(m).map_err(|e| e.within("material"))?,
        None => default_material,
    };
    let (width_px, height_px) = match (msg.width_px, msg.height_px) {
        (0, 0) => {
            let k = glint_render::rig::SliRig::ensenso_n35().stereo.intrinsics;
            (k.width_px, k.height_px)
        }
        (0, _) => {
            return Err(ConversionError::new(
                "width_px",
                "is 0 but height_px is set: give both or neither (1280x1024)",
            ));
        }
        (_, 0) => {
            return Err(ConversionError::new(
                "height_px",
                "is 0 but width_px is set: give both or neither (1280x1024)",
            ));
        }
        (w, h) => (w, h),
    };
    for (field, value, max) in [
        ("width_px", width_px, MAX_WIDTH_PX),
        ("height_px", height_px, MAX_HEIGHT_PX),
    ] {
        if !(MIN_IMAGE_SIDE_PX..=max).contains(&value) {
            return Err(ConversionError::new(
                field,
                format!("is {value}; it must be {MIN_IMAGE_SIDE_PX} to {max}"),
            ));
        }
    }
    let samples_per_pixel = match msg.samples_per_pixel {
        0 => DEFAULT_SAMPLES_PER_PIXEL,
        n if n <= MAX_SAMPLES_PER_PIXEL => n,
        n => {
            return Err(ConversionError::new(
                "samples_per_pixel",
                format!("is {n}; it must be 1 to {MAX_SAMPLES_PER_PIXEL}"),
            ));
        }
    };
    Ok(SceneRequest {
        mesh,
        name,
        material,
        spec: BinSetupSpec {
            instances: msg.instances,
            seed: msg.seed,
            width_px,
            height_px,
            samples_per_pixel,
        },
    })
}

/// The mock's scene: the bin set-up and what the server says about its part.
pub struct MockScene {
    /// The rig, bin, dropped parts, render scene and capture settings.
    pub setup: BinSetup,
    /// The built-in part's name or the mesh file's, as `SetUpScene` answers it.
    pub name: String,
    /// [`TriMesh::content_sha256_hex`] of the part's mesh (metres): its identity in sessions.
    pub mesh_sha256_hex: String,
    /// The part's true material: ground truth, served only by `GetGroundTruth`, for
    /// evaluation only.
    pub material: PrincipledParams<f32>,
}

fn setup_status(e: SetupError) -> Status {
    let invalid =
        |field: &str, e: &dyn std::fmt::Display| Status::invalid_argument(format!("{field}: {e}"));
    match e {
        SetupError::Rig(e) => invalid("width_px", &e),
        SetupError::Matcher(e) => invalid("width_px", &e),
        SetupError::Drop(e @ BinError::Crowded { .. }) => invalid("instances", &e),
        SetupError::Drop(e @ BinError::Sdf(_)) => invalid("part.mesh", &e),
        SetupError::Scene(e) => Status::internal(format!("building the scene: {e}")),
    }
}

impl MockScene {
    /// Drops the request's part into the bin (the slow part: for the blocking pool).
    pub fn new(request: SceneRequest) -> Result<Self, Status> {
        let setup =
            BinSetup::new(&request.mesh, request.material, &request.spec).map_err(setup_status)?;
        Ok(Self {
            setup,
            name: request.name,
            mesh_sha256_hex: request.mesh.content_sha256_hex(),
            material: request.material,
        })
    }

    /// What `SetUpScene` answers for this scene.
    pub fn response(&self) -> v1::SetUpSceneResponse {
        v1::SetUpSceneResponse {
            mesh: Some(v1::MeshRef {
                name: self.name.clone(),
                ..v1::MeshRef::new(
                    self.mesh_sha256_hex.clone(),
                    glint_geometry::LengthUnit::Metre,
                )
            }),
            instances: self.setup.poses.len() as u32,
        }
    }
}

/// The camera as known hardware (`GetRig`): the rig, sensor full scale and exposure, shots per
/// capture, the matcher's window and the patterns' fill.
pub fn rig_message(setup: &BinSetup) -> v1::GetRigResponse {
    let (rig, config) = (&setup.rig, &setup.config);
    v1::GetRigResponse {
        stereo: Some((&rig.stereo).into()),
        projector: Some((&rig.projector_intrinsics).into()),
        max_dn: u32::from(config.sensor.max_dn()),
        exposure_s: f64::from(config.sensor.exposure_s),
        projector_intensity_w_per_sr: f64::from(rig.projector_intensity_w_per_sr),
        t_left_projector: Some(v1::Pose::with_frames(
            &rig.t_left_projector,
            "left_camera",
            "projector",
        )),
        shots_per_capture: config.shots.max(1),
        window_radius_px: config.matcher.window_radius_px,
        pattern_fill: config.pattern_fill,
    }
}

/// Checks that the optical axis of `t_w_c` hits `bin`.
pub fn check_aim(
    bin: &BinSpec,
    t_w_c: &Isometry3<f64>,
    field: &str,
) -> Result<(), ConversionError> {
    match bin.optical_axis_entry_m(t_w_c) {
        Some(_) => Ok(()),
        None => {
            let (min, max) = bin.bounds();
            Err(ConversionError::new(
                field,
                format!(
                    "the camera's optical axis (its +z) misses the bin (world box x {:.3}..{:.3}, y {:.3}..{:.3}, z {:.3}..{:.3} m): point the camera at the bin",
                    min.x, max.x, min.y, max.y, min.z, max.z
                ),
            ))
        }
    }
}

/// The views a `ListCandidateViewsRequest` asks for on `bin`, for a rig of `baseline_m`:
/// validated, 0s as the proto says (the defaults give [`BinSetup::views`]), and every view
/// aimed at the bin.
pub fn candidate_views(
    msg: &v1::ListCandidateViewsRequest,
    bin: &BinSpec,
    baseline_m: f64,
) -> Result<Vec<Isometry3<f64>>, ConversionError> {
    if !(1..=MAX_CANDIDATE_VIEWS).contains(&msg.count) {
        return Err(ConversionError::new(
            "count",
            format!("is {}; it must be 1 to {MAX_CANDIDATE_VIEWS}", msg.count),
        ));
    }
    let distance_m = if msg.distance_m == 0.0 {
        VIEW_DISTANCE_M
    } else if msg.distance_m.is_finite()
        && msg.distance_m > 0.0
        && msg.distance_m <= MAX_VIEW_DISTANCE_M
    {
        msg.distance_m
    } else {
        return Err(ConversionError::new(
            "distance_m",
            format!(
                "{} must be finite, positive and at most {MAX_VIEW_DISTANCE_M} m",
                msg.distance_m
            ),
        ));
    };
    let cap_deg = if msg.cap_half_angle_deg == 0.0 {
        VIEW_CAP_DEG
    } else if msg.cap_half_angle_deg > 0.0 && msg.cap_half_angle_deg <= MAX_CAP_HALF_ANGLE_DEG {
        msg.cap_half_angle_deg
    } else {
        return Err(ConversionError::new(
            "cap_half_angle_deg",
            format!(
                "{} must be in (0, {MAX_CAP_HALF_ANGLE_DEG}] degrees (0: {VIEW_CAP_DEG})",
                msg.cap_half_angle_deg
            ),
        ));
    };
    let target = match &msg.target_w_m {
        None => bin.centre(),
        Some(v) => {
            for (axis, value) in [("x", v.x), ("y", v.y), ("z", v.z)] {
                if !value.is_finite() {
                    return Err(ConversionError::new(
                        format!("target_w_m.{axis}"),
                        format!("{value} is not finite"),
                    ));
                }
            }
            Point3::new(v.x, v.y, v.z)
        }
    };
    let views = spherical_cap(msg.count as usize, distance_m, cap_deg, target, baseline_m);
    for (i, t_w_c) in views.iter().enumerate() {
        check_aim(bin, t_w_c, "target_w_m").map_err(|e| {
            ConversionError::new(
                e.field,
                format!(
                    "view {i} looking at it: {}; aim at a point of the bin",
                    e.message
                ),
            )
        })?;
    }
    Ok(views)
}

/// An image of digital numbers as its message, camera-response encoded.
fn dn_image(image: &Image<u16>) -> v1::Image {
    let mut msg = v1::Image::from(image);
    msg.set_pixel_space(v1::PixelSpace::CameraResponse);
    msg
}

/// The arrays of a capture stream, in the order the proto documents: the K left pattern
/// images, the K right ones, the depth, and the noise shots when given.
pub fn capture_arrays(
    capture: &StereoCapture,
    noise_shots: Option<&[Image<u16>; 2]>,
) -> Vec<OutgoingArray> {
    let mut arrays = Vec::with_capacity(2 * capture.shots() + 3);
    for (side, name) in [
        (0, left_array_name as fn(usize) -> String),
        (1, right_array_name),
    ] {
        for (k, image) in capture.shot_images(side).into_iter().enumerate() {
            arrays.push(OutgoingArray::image(&name(k), dn_image(image)));
        }
    }
    arrays.push(OutgoingArray::depth(
        DEPTH_ARRAY,
        v1::DepthMap::from(&capture.depth),
    ));
    if let Some(shots) = noise_shots {
        for (name, image) in NOISE_ARRAYS.iter().zip(shots) {
            arrays.push(OutgoingArray::image(name, dn_image(image)));
        }
    }
    arrays
}

/// A capture stream.
pub type CaptureStream = Pin<Box<dyn Stream<Item = Result<v1::CaptureChunk, Status>> + Send>>;

/// `header` (its `arrays` filled from `arrays`), then the arrays' chunks in the order of
/// [`glint_proto::chunks::chunks`], each copied out only when the transport asks for it.
pub fn capture_stream(mut header: v1::CaptureHeader, arrays: Vec<OutgoingArray>) -> CaptureStream {
    use v1::capture_chunk::Part;
    header.arrays = arrays.iter().map(|a| a.header.clone()).collect();
    let pieces: Vec<(usize, usize)> = arrays
        .iter()
        .enumerate()
        .flat_map(|(i, a)| (0..a.bytes.len()).step_by(CHUNK_BYTES).map(move |o| (i, o)))
        .collect();
    let first = std::iter::once(Ok(v1::CaptureChunk {
        part: Some(Part::Header(header)),
    }));
    let rest = pieces.into_iter().map(move |(i, offset)| {
        let bytes = &arrays[i].bytes;
        let end = (offset + CHUNK_BYTES).min(bytes.len());
        Ok(v1::CaptureChunk {
            part: Some(Part::Chunk(v1::BytesChunk {
                array: i as u32,
                offset: offset as u64,
                data: bytes[offset..end].to_vec(),
            })),
        })
    });
    Box::pin(tokio_stream::iter(first.chain(rest)))
}

fn capture_status(e: CaptureError) -> Status {
    match e {
        CaptureError::Exposures { problem } => {
            Status::invalid_argument(format!("exposures_s: {problem}"))
        }
        other => Status::internal(format!("capture: {other}")),
    }
}

/// Checks an exposure list as the proto states it: 2 to [`MAX_EXPOSURES`] finite, positive,
/// strictly increasing seconds.
pub fn check_exposures(exposures_s: &[f64]) -> Result<(), ConversionError> {
    let bad = |message: String| ConversionError::new("exposures_s", message);
    if !(2..=MAX_EXPOSURES).contains(&exposures_s.len()) {
        return Err(bad(format!(
            "has {} times; a stack needs 2 to {MAX_EXPOSURES}",
            exposures_s.len()
        )));
    }
    if let Some(i) = exposures_s
        .iter()
        .position(|x| !(x.is_finite() && *x > 0.0))
    {
        return Err(bad(format!(
            "value {i} is {} s; times must be finite and positive",
            exposures_s[i]
        )));
    }
    if let Some(i) = exposures_s.windows(2).position(|p| p[1] <= p[0]) {
        return Err(bad(format!(
            "value {} ({} s) does not exceed the one before ({} s): times must be strictly increasing",
            i + 1,
            exposures_s[i + 1],
            exposures_s[i]
        )));
    }
    Ok(())
}

/// The mock camera's server: one scene at a time, shared by both services.
#[derive(Clone, Default)]
pub struct Camera {
    scene: Arc<RwLock<Option<Arc<MockScene>>>>,
}

impl Camera {
    /// A camera without a scene: only `SetUpScene` works until one is set up.
    pub fn new() -> Self {
        Self::default()
    }

    /// Replaces the scene by the one `msg` describes: validates, builds (slow: call it off the
    /// async runtime) and answers as `SetUpScene` does. `glint serve camera --part …` starts
    /// the server through this too.
    pub fn set_up(&self, msg: &v1::SetUpSceneRequest) -> Result<v1::SetUpSceneResponse, Status> {
        let scene = MockScene::new(scene_request(msg)?)?;
        let response = scene.response();
        *self
            .scene
            .write()
            .map_err(|_| Status::internal("the scene's lock was poisoned"))? =
            Some(Arc::new(scene));
        Ok(response)
    }

    /// The current scene, or FAILED_PRECONDITION asking for one.
    pub fn scene(&self) -> Result<Arc<MockScene>, Status> {
        self.scene
            .read()
            .map_err(|_| Status::internal("the scene's lock was poisoned"))?
            .clone()
            .ok_or_else(|| {
                Status::failed_precondition(
                    "the mock camera has no scene: call MockCameraService.SetUpScene first (or start the server with one: glint serve camera --part NAME)",
                )
            })
    }

    /// Both services, to add to a server's routes.
    pub fn into_routes(self) -> tonic::service::Routes {
        tonic::service::Routes::new(CameraServiceServer::new(self.clone()))
            .add_service(MockCameraServiceServer::new(self))
    }
}

#[tonic::async_trait]
impl CameraService for Camera {
    async fn get_rig(
        &self,
        _request: Request<v1::GetRigRequest>,
    ) -> Result<Response<v1::GetRigResponse>, Status> {
        Ok(Response::new(rig_message(&self.scene()?.setup)))
    }

    async fn list_candidate_views(
        &self,
        request: Request<v1::ListCandidateViewsRequest>,
    ) -> Result<Response<v1::ListCandidateViewsResponse>, Status> {
        let scene = self.scene()?;
        let setup = &scene.setup;
        let views = candidate_views(request.get_ref(), &setup.bin, setup.rig.stereo.baseline_m)?;
        Ok(Response::new(v1::ListCandidateViewsResponse {
            t_w_c: views
                .iter()
                .map(|t| v1::Pose::with_frames(t, WORLD, "camera"))
                .collect(),
        }))
    }

    type CaptureStream = CaptureStream;

    async fn capture(
        &self,
        request: Request<v1::CaptureRequest>,
    ) -> Result<Response<Self::CaptureStream>, Status> {
        let msg = request.into_inner();
        let t_w_c = pose_field(&msg.t_w_c, "t_w_c")?;
        let scene = self.scene()?;
        check_aim(&scene.setup.bin, &t_w_c, "t_w_c")?;
        let (seed, noise_shots) = (msg.seed, msg.noise_shots);
        let started = Instant::now();
        let (arrays, max_dn) = glint_server::blocking(move || {
            let camera = scene.setup.camera();
            let (capture, noise, _truth) =
                camera.capture_with_noise_shots(&t_w_c, seed, noise_shots)?;
            Ok::<_, CaptureError>((
                capture_arrays(&capture, noise.as_ref()),
                camera.config.sensor.max_dn(),
            ))
        })
        .await?
        .map_err(capture_status)?;
        let header = v1::CaptureHeader {
            t_w_c: Some(v1::Pose::with_frames(&t_w_c, WORLD, "camera")),
            arrays: Vec::new(),
            exposures_s: Vec::new(),
            max_dn: u32::from(max_dn),
            capture_ms: started.elapsed().as_secs_f64() * 1e3,
        };
        Ok(Response::new(capture_stream(header, arrays)))
    }

    type CaptureExposureStackStream = CaptureStream;

    async fn capture_exposure_stack(
        &self,
        request: Request<v1::CaptureExposureStackRequest>,
    ) -> Result<Response<Self::CaptureExposureStackStream>, Status> {
        let msg = request.into_inner();
        let t_w_c = pose_field(&msg.t_w_c, "t_w_c")?;
        check_exposures(&msg.exposures_s)?;
        let scene = self.scene()?;
        check_aim(&scene.setup.bin, &t_w_c, "t_w_c")?;
        let started = Instant::now();
        let seed = msg.seed;
        let (arrays, exposures_s, max_dn) = glint_server::blocking(move || {
            let camera = scene.setup.camera();
            let (stack, _truth) = camera.capture_exposure_stack(&t_w_c, &msg.exposures_s, seed)?;
            let arrays: Vec<OutgoingArray> = stack
                .left
                .iter()
                .enumerate()
                .map(|(k, image)| OutgoingArray::image(&exposure_array_name(k), dn_image(image)))
                .collect();
            Ok::<_, CaptureError>((arrays, stack.exposures_s, camera.config.sensor.max_dn()))
        })
        .await?
        .map_err(capture_status)?;
        let header = v1::CaptureHeader {
            t_w_c: Some(v1::Pose::with_frames(&t_w_c, WORLD, "camera")),
            arrays: Vec::new(),
            exposures_s,
            max_dn: u32::from(max_dn),
            capture_ms: started.elapsed().as_secs_f64() * 1e3,
        };
        Ok(Response::new(capture_stream(header, arrays)))
    }
}

#[tonic::async_trait]
impl MockCameraService for Camera {
    async fn set_up_scene(
        &self,
        request: Request<v1::SetUpSceneRequest>,
    ) -> Result<Response<v1::SetUpSceneResponse>, Status> {
        let camera = self.clone();
        let msg = request.into_inner();
        let response = glint_server::blocking(move || camera.set_up(&msg)).await??;
        Ok(Response::new(response))
    }

    /// EVALUATION ONLY: the instances' poses and the part's true material. Estimators and
    /// predictors never call it.
    async fn get_ground_truth(
        &self,
        request: Request<v1::GetGroundTruthRequest>,
    ) -> Result<Response<v1::GetGroundTruthResponse>, Status> {
        let scene = self.scene()?;
        let visibility = match &request.get_ref().visibility_from_t_w_c {
            None => Vec::new(),
            Some(pose) => {
                let t_w_c =
                    Isometry3::try_from(pose).map_err(|e| e.within("visibility_from_t_w_c"))?;
                let scene = scene.clone();
                glint_server::blocking(move || {
                    scene
                        .setup
                        .instance_visibility(&t_w_c)
                        .iter()
                        .map(|v| v1::InstanceVisibility {
                            px_count_all: v.px_count_all as u32,
                            px_count_visib: v.px_count_visib as u32,
                            visib_fract: v.visib_fract,
                        })
                        .collect()
                })
                .await?
            }
        };
        Ok(Response::new(v1::GetGroundTruthResponse {
            visibility,
            t_w_o: scene
                .setup
                .poses
                .iter()
                .map(|t| v1::Pose::with_frames(t, WORLD, "object"))
                .collect(),
            material: Some(v1::PrincipledMaterial::from(&scene.material)),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_geometry::LengthUnit;
    use glint_geometry::io::{PlyEncoding, write_ply_to_vec};

    fn builtin(name: &str) -> v1::SetUpSceneRequest {
        v1::SetUpSceneRequest {
            part: Some(v1::PartSpec {
                part: Some(v1::part_spec::Part::Builtin(name.into())),
            }),
            instances: 2,
            material: None,
            seed: 1,
            width_px: 0,
            height_px: 0,
            samples_per_pixel: 0,
        }
    }

    fn field(result: Result<SceneRequest, ConversionError>) -> ConversionError {
        result.expect_err("the request is invalid")
    }

    #[test]
    fn scene_requests_take_defaults_and_name_bad_fields() {
        let ok = scene_request(&builtin("gear")).unwrap();
        assert_eq!(ok.name, "gear");
        assert_eq!(ok.material, materials::ground_truth(Part::Gear));
        assert_eq!(
            (
                ok.spec.width_px,
                ok.spec.height_px,
                ok.spec.samples_per_pixel
            ),
            (1280, 1024, 4)
        );
        assert_eq!(
            ok.mesh.content_sha256_hex(),
            Part::Gear.mesh().content_sha256_hex()
        );

        let e = field(scene_request(&builtin("sprocket")));
        assert_eq!(e.field, "part.builtin");
        for part in Part::ALL {
            assert!(e.message.contains(part.name()), "{e}");
        }
        let e = field(scene_request(&v1::SetUpSceneRequest {
            part: None,
            ..builtin("gear")
        }));
        assert_eq!(e.field, "part");
        for instances in [0, MAX_INSTANCES + 1] {
            let e = field(scene_request(&v1::SetUpSceneRequest {
                instances,
                ..builtin("gear")
            }));
            assert_eq!(e.field, "instances", "{e}");
        }
        let e = field(scene_request(&v1::SetUpSceneRequest {
            material: Some(v1::PrincipledMaterial {
                roughness: f64::NAN,
                ..Default::default()
            }),
            ..builtin("gear")
        }));
        assert_eq!(e.field, "material.roughness");
        let e = field(scene_request(&v1::SetUpSceneRequest {
            width_px: 320,
            ..builtin("gear")
        }));
        assert_eq!(e.field, "height_px");
        let e = field(scene_request(&v1::SetUpSceneRequest {
            width_px: 16,
            height_px: 256,
            ..builtin("gear")
        }));
        assert_eq!(e.field, "width_px");
        let e = field(scene_request(&v1::SetUpSceneRequest {
            samples_per_pixel: MAX_SAMPLES_PER_PIXEL + 1,
            ..builtin("gear")
        }));
        assert_eq!(e.field, "samples_per_pixel");
    }

    #[test]
    fn a_users_mesh_is_read_in_its_unit_and_sized_against_the_bin() {
        let mesh = Part::Zigzag.mesh();
        let file = |unit: v1::LengthUnit| v1::SetUpSceneRequest {
            part: Some(v1::PartSpec {
                part: Some(v1::part_spec::Part::Mesh(v1::MeshFile {
                    data: write_ply_to_vec(&mesh, LengthUnit::Millimetre, PlyEncoding::Ascii),
                    format: "ply".into(),
                    unit: unit as i32,
                    name: "bracket".into(),
                })),
            }),
            ..builtin("gear")
        };
        let ok = scene_request(&file(v1::LengthUnit::Millimetre)).unwrap();
        assert_eq!(ok.name, "bracket");
        assert_eq!(ok.material, materials::ground_truth(Part::TubeFitting));
        // Millimetre coordinates read as metres: a part a thousand times too big.
        let e = field(scene_request(&file(v1::LengthUnit::Metre)));
        assert_eq!(e.field, "part.mesh", "{e}");
        let e = field(scene_request(&file(v1::LengthUnit::Unspecified)));
        assert_eq!(e.field, "part.mesh.unit", "{e}");
    }

    #[test]
    fn candidate_views_default_to_the_set_ups_and_name_bad_fields() {
        let bin = BinSpec::default();
        let baseline_m = 0.1;
        let request = v1::ListCandidateViewsRequest {
            count: 12,
            distance_m: 0.0,
            cap_half_angle_deg: 0.0,
            target_w_m: None,
        };
        assert_eq!(
            candidate_views(&request, &bin, baseline_m).unwrap(),
            spherical_cap(12, VIEW_DISTANCE_M, VIEW_CAP_DEG, bin.centre(), baseline_m)
        );
        let bad = |r: v1::ListCandidateViewsRequest| {
            candidate_views(&r, &bin, baseline_m).unwrap_err().field
        };
        assert_eq!(
            bad(v1::ListCandidateViewsRequest {
                count: 0,
                ..request
            }),
            "count"
        );
        assert_eq!(
            bad(v1::ListCandidateViewsRequest {
                distance_m: -1.0,
                ..request
            }),
            "distance_m"
        );
        assert_eq!(
            bad(v1::ListCandidateViewsRequest {
                cap_half_angle_deg: 90.0,
                ..request
            }),
            "cap_half_angle_deg"
        );
        let target = |x: f64| v1::ListCandidateViewsRequest {
            target_w_m: Some(v1::Vector3 { x, y: 0.0, z: 0.0 }),
            ..request
        };
        assert_eq!(bad(target(f64::NAN)), "target_w_m.x");
        // A target a metre beside the bin: the views look past it.
        assert_eq!(bad(target(1.0)), "target_w_m");
    }

    #[test]
    fn exposures_must_be_strictly_increasing() {
        assert!(check_exposures(&[1e-3, 2e-3]).is_ok());
        for bad in [
            &[1e-3][..],
            &[2e-3, 1e-3],
            &[1e-3, 1e-3],
            &[0.0, 1e-3],
            &[1e-3, f64::NAN],
        ] {
            assert_eq!(
                check_exposures(bad).unwrap_err().field,
                "exposures_s",
                "{bad:?}"
            );
        }
    }

    #[test]
    fn the_stream_sends_the_header_then_the_same_chunks_as_chunks() {
        use tokio_stream::StreamExt;
        let image = Image::new(1280, 1024, (0..1280 * 1024).map(|i| i as u16).collect()).unwrap();
        let arrays = vec![
            OutgoingArray::image("left_000", dn_image(&image)),
            OutgoingArray::image("right_000", dn_image(&image)),
        ];
        let expected: Vec<v1::BytesChunk> = glint_proto::chunks::chunks(&arrays).collect();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        let sent: Vec<v1::CaptureChunk> = runtime.block_on(
            capture_stream(v1::CaptureHeader::default(), arrays.clone())
                .map(|m| m.unwrap())
                .collect(),
        );
        let Some(v1::capture_chunk::Part::Header(header)) = &sent[0].part else {
            panic!("the header first")
        };
        assert_eq!(header.arrays.len(), 2);
        assert_eq!(header.arrays[1], arrays[1].header);
        let chunks: Vec<v1::BytesChunk> = sent[1..]
            .iter()
            .map(|m| match &m.part {
                Some(v1::capture_chunk::Part::Chunk(c)) => c.clone(),
                _ => panic!("only chunks after the header"),
            })
            .collect();
        assert_eq!(chunks, expected);
    }
}
