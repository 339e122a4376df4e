//! The estimation stage's gRPC server (`glint.v1.EstimationService`): decode and validate the
//! request, run the library on the blocking pool, encode. The refinement is
//! [`crate::multiview::refine_views`], the one the in-process stage runs.
//!
//! - `RegisterMesh` parses a mesh file into metres, builds its SDF grid with the refiner's voxel
//!   and keeps both in a bounded registry under the mesh's content hash
//!   (`TriMesh::content_sha256_hex`); the oldest is evicted beyond [`REGISTRY_CAPACITY`].
//! - `Refine` reads the client stream (header, then per view its header and arrays: see
//!   [`ARRAY_DEPTH`] and the other array names) into [`ViewMeasurement`]s and refines.
//! - `PlanNextView` and `PoseEntropy` run [`plan_next_view`] and [`pose_entropy_nats`] under the
//!   service's [`PosePrior`].
//!
//! Errors: bad input → INVALID_ARGUMENT naming the field (`header.mask_margin_m`,
//! `views[1].t_w_c.rotation`, `candidates[2].upper`); an unknown mesh → NOT_FOUND naming its
//! hash; views that give too few points → FAILED_PRECONDITION.
//!
//! The encoders a client needs ([`mesh_file`], [`refine_chunks`], [`refinement_from_message`])
//! live here too, so both sides agree on the array names.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use glint_geometry::camera::StereoRig;
use glint_geometry::image::{DepthMap, Image};
use glint_geometry::io::{LoadedMesh, PlyEncoding, write_ply_to_vec};
use glint_geometry::sdf::{SdfConfig, SdfGrid};
use glint_geometry::{LengthUnit, TriMesh};
use glint_proto::ConversionError;
use glint_proto::chunks::{ArrayAssembler, AssembledArray, OutgoingArray, chunks};
use glint_proto::v1;
use glint_proto::v1::estimation_service_server::{EstimationService, EstimationServiceServer};
use nalgebra::{Isometry3, Matrix6, Unit, Vector3};
use tokio_stream::StreamExt;
use tonic::{Request, Response, Status, Streaming};

use crate::correlated_error::CorrelatedDepthError;
use crate::multiview::{MultiviewError, RefineSettings, RefineSigma, Refinement, refine_views};
use crate::nbv::{NbvError, PosePrior, plan_next_view, pose_entropy_nats};
use crate::pose_error_model::PoseErrorModel;
use crate::refine::{SdfRefineConfig, refine_grid_config};
use crate::view::{BackgroundPlane, ViewMeasurement};

/// The service's name, as health reports it.
pub const SERVICE_NAME: &str = "glint.v1.EstimationService";

/// Meshes a service keeps; registering one more evicts the oldest.
pub const REGISTRY_CAPACITY: usize = 64;

/// Views one refinement may carry.
pub const MAX_VIEWS: u32 = 64;

/// Candidates one plan may weigh.
pub const MAX_CANDIDATES: usize = 1000;

/// The most array bytes one `Refine` stream may declare over all its views: 2 GiB, e.g. 16
/// full-resolution (1280×1024) views of 16 pattern shots each. More is refused before it is
/// received.
pub const MAX_REFINE_BYTES: u64 = 2 << 30;

/// A view's depth map (DepthMap, the left camera's), required.
pub const ARRAY_DEPTH: &str = "depth";
/// The two read-outs of one static shot for the noise model (σ_I), with pattern-image σ.
pub const ARRAY_NOISE: [&str; 2] = ["noise_a", "noise_b"];
/// Prefix of pattern shot `k`'s left image: `left_000`, `left_001`, ... (see
/// [`shot_array_name`]).
pub const ARRAY_LEFT_PREFIX: &str = "left_";
/// Prefix of pattern shot `k`'s right image: `right_000`, `right_001`, ...
pub const ARRAY_RIGHT_PREFIX: &str = "right_";

/// The name of the left (`camera` 0) or right (1) image of pattern shot `k`.
pub fn shot_array_name(camera: usize, k: usize) -> String {
    let prefix = if camera == 0 {
        ARRAY_LEFT_PREFIX
    } else {
        ARRAY_RIGHT_PREFIX
    };
    format!("{prefix}{k:03}")
}

/// A registered mesh and its SDF grid.
#[derive(Debug)]
pub struct RegisteredMesh {
    /// Metres, object frame.
    pub mesh: Arc<TriMesh>,
    /// The mesh's SDF grid (object frame, metres), built with the service's [`SdfConfig`].
    pub grid: Arc<SdfGrid>,
}

/// Meshes by content hash, oldest first.
#[derive(Debug)]
struct Registry {
    capacity: usize,
    order: VecDeque<String>,
    meshes: HashMap<String, Arc<RegisteredMesh>>,
}

impl Registry {
    fn get(&self, key: &str) -> Option<Arc<RegisteredMesh>> {
        self.meshes.get(key).cloned()
    }

    fn insert(&mut self, key: String, mesh: Arc<RegisteredMesh>) {
        if self.meshes.insert(key.clone(), mesh).is_some() {
            self.order.retain(|k| *k != key);
        }
        self.order.push_back(key);
        while self.order.len() > self.capacity {
            if let Some(oldest) = self.order.pop_front() {
                self.meshes.remove(&oldest);
            }
        }
    }
}

/// The estimation service: its mesh registry, the refiner's configuration and the planner's
/// prior (the in-process stage's defaults unless changed).
#[derive(Clone, Debug)]
pub struct Estimation {
    registry: Arc<Mutex<Registry>>,
    /// The refiner's configuration for `Refine`.
    pub refine: SdfRefineConfig,
    /// The pose prior of `PlanNextView`, `PoseEntropy` and the entropy `Refine` reports.
    pub prior: PosePrior,
    /// The SDF grids of registered meshes: the refiner's voxel.
    pub sdf: SdfConfig,
}

impl Default for Estimation {
    fn default() -> Self {
        Self::with_capacity(REGISTRY_CAPACITY)
    }
}

impl Estimation {
    /// A service keeping at most `capacity` meshes (at least 1).
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            registry: Arc::new(Mutex::new(Registry {
                capacity: capacity.max(1),
                order: VecDeque::new(),
                meshes: HashMap::new(),
            })),
            refine: SdfRefineConfig::default(),
            prior: PosePrior::default(),
            sdf: refine_grid_config(),
        }
    }

    /// The tonic service to add to a server's routes.
    pub fn into_service(self) -> EstimationServiceServer<Self> {
        EstimationServiceServer::new(self)
    }

    fn registry(&self) -> Result<std::sync::MutexGuard<'_, Registry>, Status> {
        self.registry
            .lock()
            .map_err(|_| Status::internal("the mesh registry's lock was poisoned"))
    }

    fn mesh(&self, key: &str) -> Result<Arc<RegisteredMesh>, Status> {
        self.registry()?.get(key).ok_or_else(|| {
            Status::not_found(format!(
                "header.mesh.sha256_hex: mesh {key:?} is not registered on this service; call \
                 RegisterMesh and send the request again"
            ))
        })
    }
}

fn required<'a, T>(value: &'a Option<T>, field: &str) -> Result<&'a T, ConversionError> {
    value
        .as_ref()
        .ok_or_else(|| ConversionError::missing(field))
}

// ---------------------------------------------------------------------------------------------
// Encoding (the client's side)

/// A mesh (metres) as the file `RegisterMesh` takes: binary PLY in metres, exact for its f32
/// vertices, so the service's copy has the same content hash.
pub fn mesh_file(mesh: &TriMesh, name: &str) -> v1::MeshFile {
    v1::MeshFile {
        data: write_ply_to_vec(mesh, LengthUnit::Metre, PlyEncoding::BinaryLittleEndian),
        format: "ply".into(),
        unit: v1::LengthUnit::Metre as i32,
        name: name.into(),
    }
}

/// The header of a refinement of `views` views of the mesh keyed `mesh_sha256_hex` from the
/// hypothesis `t_w_o` (object → world).
pub fn refine_header(
    mesh_sha256_hex: &str,
    t_w_o: &Isometry3<f64>,
    settings: &RefineSettings,
    views: usize,
) -> v1::RefineHeader {
    let (sigma_source, constant_sigma_z_m) = match settings.sigma {
        RefineSigma::PatternImages => (v1::SigmaSource::PatternImages, 0.0),
        RefineSigma::Constant { sigma_z_m } => (v1::SigmaSource::Constant, sigma_z_m),
    };
    v1::RefineHeader {
        mesh: Some(v1::MeshRef {
            sha256_hex: mesh_sha256_hex.into(),
            unit: v1::LengthUnit::Metre as i32,
            uri: String::new(),
            name: String::new(),
        }),
        initial_t_w_o: Some(v1::Pose::with_frames(t_w_o, "world", "object")),
        sigma_source: sigma_source as i32,
        constant_sigma_z_m,
        erode_px: settings.erode_px,
        window_radius_px: settings.window_radius_px,
        views: views.min(u32::MAX as usize) as u32,
        mask_margin_m: settings.mask_margin_m,
        final_mask_margin_m: settings.final_mask_margin_m,
        align_depth: settings.align_depth,
        error_model: settings.error_model.as_ref().map(error_model_message),
        background: settings.background.map(|b| v1::BackgroundPlane {
            normal_w: Some(v1::Vector3 {
                x: b.normal_w.x,
                y: b.normal_w.y,
                z: b.normal_w.z,
            }),
            offset_m: b.offset_m,
            clearance_m: b.clearance_m,
        }),
    }
}

/// A pose error model as its message.
pub fn error_model_message(model: &PoseErrorModel) -> v1::PoseErrorModel {
    v1::PoseErrorModel {
        cell_m: model.depth_error.cell_m,
        bias_sigma_m: model.depth_error.bias_sigma_m,
        view_bias_covariance_v: Some((&model.view_bias.covariance_v).into()),
    }
}

/// A pose error model message as the model, validated; `field` (`error_model`) prefixes the
/// field named in errors (`error_model.cell_m`).
pub fn error_model_from_message(
    m: &v1::PoseErrorModel,
    field: &str,
) -> Result<PoseErrorModel, ConversionError> {
    let covariance_v = Matrix6::try_from(required(
        &m.view_bias_covariance_v,
        &format!("{field}.view_bias_covariance_v"),
    )?)
    .map_err(|e| e.within(&format!("{field}.view_bias_covariance_v")))?;
    let model = PoseErrorModel {
        depth_error: CorrelatedDepthError {
            cell_m: m.cell_m,
            bias_sigma_m: m.bias_sigma_m,
        },
        view_bias: crate::view_bias::ViewPoseBias { covariance_v },
    };
    model
        .validate()
        .map_err(|e| ConversionError::new(format!("{field}.{}", e.field), e.message))?;
    Ok(model)
}

/// A view's header and arrays: its depth (missing depth as NaN: infinite or negative values,
/// which the library treats as missing too, would be rejected on the wire) and, when `sigma`
/// is from pattern images, its shots and noise shots.
pub fn view_arrays(
    view: &ViewMeasurement,
    sigma: &RefineSigma,
) -> (v1::ViewHeader, Vec<OutgoingArray>) {
    let depth = DepthMap::new(view.depth.depth_m.map(|z| {
        if z.is_finite() && z >= 0.0 {
            z
        } else {
            f32::NAN
        }
    }));
    let mut arrays = vec![OutgoingArray::depth(ARRAY_DEPTH, (&depth).into())];
    if *sigma == RefineSigma::PatternImages {
        for (camera, shots) in [&view.left, &view.right].into_iter().enumerate() {
            for (k, shot) in shots.iter().enumerate() {
                arrays.push(OutgoingArray::image(
                    &shot_array_name(camera, k),
                    encoded(shot),
                ));
            }
        }
        if let Some(noise) = &view.noise_shots {
            for (name, shot) in ARRAY_NOISE.iter().zip(noise) {
                arrays.push(OutgoingArray::image(name, encoded(shot)));
            }
        }
    }
    let header = v1::ViewHeader {
        t_w_c: Some(v1::Pose::with_frames(&view.t_w_c, "world", "camera")),
        stereo: Some((&view.stereo).into()),
        arrays: arrays.iter().map(|a| a.header.clone()).collect(),
        max_dn: u32::from(view.max_dn),
    };
    (header, arrays)
}

/// A read-out as a MONO16 image of response-encoded digital numbers.
fn encoded(shot: &Image<u16>) -> v1::Image {
    v1::Image {
        pixel_space: v1::PixelSpace::CameraResponse as i32,
        ..shot.into()
    }
}

/// A whole `Refine` stream: the header, then each view's header and chunks (≤ 1 MiB each).
pub fn refine_chunks(
    mesh_sha256_hex: &str,
    t_w_o: &Isometry3<f64>,
    settings: &RefineSettings,
    views: &[&ViewMeasurement],
) -> Vec<v1::RefineChunk> {
    use v1::refine_chunk::Part;
    let mut out = vec![v1::RefineChunk {
        part: Some(Part::Header(refine_header(
            mesh_sha256_hex,
            t_w_o,
            settings,
            views.len(),
        ))),
    }];
    for view in views {
        let (header, arrays) = view_arrays(view, &settings.sigma);
        out.push(v1::RefineChunk {
            part: Some(Part::View(header)),
        });
        out.extend(chunks(&arrays).map(|c| v1::RefineChunk {
            part: Some(Part::Chunk(c)),
        }));
    }
    out
}

/// A refinement as its response, with its entropy under the service's prior.
pub fn refinement_to_message(r: &Refinement, entropy_nats: f64) -> v1::RefineResponse {
    let points: usize = r.view_points.iter().sum();
    let count = |n: usize| n.min(u32::MAX as usize) as u32;
    v1::RefineResponse {
        t_w_o: Some(v1::Pose::with_frames(&r.t_w_o, "world", "object")),
        covariance: r.covariance.as_ref().map(Into::into),
        information: Some((&r.information).into()),
        pixel_information: Some((&r.pixel_information).into()),
        entropy_nats,
        stats: Some(v1::RefineStats {
            iterations: count(r.iterations),
            points: count(points),
            inliers: count(r.inliers),
            status: r.status.clone(),
            final_cost: r.final_cost,
            refine_ms: r.refine_ms,
            view_points: r.view_points.iter().map(|&n| count(n)).collect(),
        }),
    }
}

/// A response as the refinement it encodes (the inverse of [`refinement_to_message`]; the
/// matrices come back symmetrised, as the wire holds upper triangles).
pub fn refinement_from_message(m: &v1::RefineResponse) -> Result<Refinement, ConversionError> {
    let t_w_o = Isometry3::try_from(required(&m.t_w_o, "t_w_o")?).map_err(|e| e.within("t_w_o"))?;
    let information = Matrix6::try_from(required(&m.information, "information")?)
        .map_err(|e| e.within("information"))?;
    let covariance = m
        .covariance
        .as_ref()
        .map(|c| Matrix6::try_from(c).map_err(|e| e.within("covariance")))
        .transpose()?;
    let pixel_information = m
        .pixel_information
        .as_ref()
        .map(|c| Matrix6::try_from(c).map_err(|e| e.within("pixel_information")))
        .transpose()?
        .unwrap_or(information);
    let stats = required(&m.stats, "stats")?;
    Ok(Refinement {
        t_w_o,
        information,
        covariance,
        pixel_information,
        view_points: stats.view_points.iter().map(|&n| n as usize).collect(),
        inliers: stats.inliers as usize,
        iterations: stats.iterations as usize,
        status: stats.status.clone(),
        final_cost: stats.final_cost,
        refine_ms: stats.refine_ms,
    })
}

// ---------------------------------------------------------------------------------------------
// Decoding (the service's side)

/// What a refinement's header says.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedHeader {
    /// The registered mesh's key: its content hash, 64 lowercase hexadecimal characters.
    pub mesh_sha256_hex: String,
    /// The hypothesis, object → world.
    pub t_w_o: Isometry3<f64>,
    /// How to mask and weigh the views, validated.
    pub settings: RefineSettings,
    /// Views the stream carries, 1 to [`MAX_VIEWS`].
    pub views: u32,
}

/// The header's settings, validated; errors name the header's field (`mask_margin_m`, ...).
pub fn decode_header(h: &v1::RefineHeader) -> Result<DecodedHeader, ConversionError> {
    let mesh = required(&h.mesh, "mesh")?;
    let hash = &mesh.sha256_hex;
    if hash.len() != 64 || !hash.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')) {
        return Err(ConversionError::new(
            "mesh.sha256_hex",
            format!("{hash:?} is not 64 lowercase hexadecimal characters (RegisterMesh's key)"),
        ));
    }
    let t_w_o = Isometry3::try_from(required(&h.initial_t_w_o, "initial_t_w_o")?)
        .map_err(|e| e.within("initial_t_w_o"))?;
    let sigma = match v1::SigmaSource::try_from(h.sigma_source) {
        Ok(v1::SigmaSource::PatternImages) => RefineSigma::PatternImages,
        Ok(v1::SigmaSource::Constant) => RefineSigma::Constant {
            sigma_z_m: h.constant_sigma_z_m,
        },
        Ok(v1::SigmaSource::Unspecified) => {
            return Err(ConversionError::new(
                "sigma_source",
                "must be set (SIGMA_SOURCE_UNSPECIFIED)",
            ));
        }
        Err(_) => {
            return Err(ConversionError::new(
                "sigma_source",
                format!("unknown enum value {}", h.sigma_source),
            ));
        }
    };
    let background = h
        .background
        .as_ref()
        .map(|b| {
            let n = required(&b.normal_w, "background.normal_w")?;
            Ok::<_, ConversionError>(BackgroundPlane {
                // Checked to be a finite unit vector by the settings' validation; not
                // renormalised, so the client's plane is used as it is.
                normal_w: Unit::new_unchecked(Vector3::new(n.x, n.y, n.z)),
                offset_m: b.offset_m,
                clearance_m: b.clearance_m,
            })
        })
        .transpose()?;
    let settings = RefineSettings {
        mask_margin_m: h.mask_margin_m,
        final_mask_margin_m: h.final_mask_margin_m,
        background,
        erode_px: h.erode_px,
        window_radius_px: h.window_radius_px,
        sigma,
        align_depth: h.align_depth,
        error_model: h
            .error_model
            .as_ref()
            .map(|m| error_model_from_message(m, "error_model"))
            .transpose()?,
    };
    settings.validate().map_err(|e| match e {
        MultiviewError::Input { field, message } => ConversionError::new(field, message),
        other => ConversionError::new("", other.to_string()),
    })?;
    if !(1..=MAX_VIEWS).contains(&h.views) {
        return Err(ConversionError::new(
            "views",
            format!("is {}; send 1 to {MAX_VIEWS} views", h.views),
        ));
    }
    Ok(DecodedHeader {
        mesh_sha256_hex: hash.clone(),
        t_w_o,
        settings,
        views: h.views,
    })
}

/// What a view's header says, before its arrays arrive.
struct OpenView {
    t_w_c: Isometry3<f64>,
    stereo: StereoRig,
    max_dn: u32,
    assembler: ArrayAssembler,
}

fn open_view(h: v1::ViewHeader) -> Result<OpenView, ConversionError> {
    let t_w_c = Isometry3::try_from(required(&h.t_w_c, "t_w_c")?).map_err(|e| e.within("t_w_c"))?;
    let stereo =
        StereoRig::try_from(required(&h.stereo, "stereo")?).map_err(|e| e.within("stereo"))?;
    if h.max_dn > u32::from(u16::MAX) {
        return Err(ConversionError::new(
            "max_dn",
            format!("is {}; at most {}", h.max_dn, u16::MAX),
        ));
    }
    let assembler = ArrayAssembler::new(h.arrays, "arrays")?;
    Ok(OpenView {
        t_w_c,
        stereo,
        max_dn: h.max_dn,
        assembler,
    })
}

/// What an array name stands for.
#[derive(Clone, Copy, Debug, PartialEq)]
enum ArrayRole {
    Depth,
    Shot { camera: usize, k: usize },
    Noise(usize),
}

fn role_of(name: &str) -> Option<ArrayRole> {
    if name == ARRAY_DEPTH {
        return Some(ArrayRole::Depth);
    }
    if let Some(i) = ARRAY_NOISE.iter().position(|n| *n == name) {
        return Some(ArrayRole::Noise(i));
    }
    for (camera, prefix) in [ARRAY_LEFT_PREFIX, ARRAY_RIGHT_PREFIX]
        .into_iter()
        .enumerate()
    {
        if let Some(digits) = name.strip_prefix(prefix)
            && digits.len() == 3
            && digits.bytes().all(|b| b.is_ascii_digit())
        {
            return digits.parse().ok().map(|k| ArrayRole::Shot { camera, k });
        }
    }
    None
}

/// An image array as digital numbers (MONO8 or MONO16).
fn read_out(array: AssembledArray) -> Result<Image<u16>, ConversionError> {
    match array {
        AssembledArray::Image(msg) if msg.encoding == v1::ImageEncoding::Mono8 as i32 => {
            Ok(Image::<u8>::try_from(msg)?.map(u16::from))
        }
        AssembledArray::Image(msg) => Image::<u16>::try_from(msg),
        AssembledArray::Depth(_) => Err(ConversionError::new(
            "layout",
            "is a depth map; pattern and noise shots are images",
        )),
    }
}

/// A view's arrays as its measurement; errors name the field within the view (`arrays[2]`).
fn close_view(open: OpenView, sigma: &RefineSigma) -> Result<ViewMeasurement, ConversionError> {
    let intrinsics = open.stereo.intrinsics;
    let (w, h) = (intrinsics.width_px, intrinsics.height_px);
    let mut depth = None;
    let mut shots: [Vec<Option<Image<u16>>>; 2] = [Vec::new(), Vec::new()];
    let mut noise: [Option<Image<u16>>; 2] = [None, None];
    for (j, (name, array)) in open.assembler.finish()?.into_iter().enumerate() {
        let at = format!("arrays[{j}]");
        let size = match &array {
            AssembledArray::Image(m) => (m.width_px, m.height_px),
            AssembledArray::Depth(m) => (m.width_px, m.height_px),
        };
        if size != (w, h) {
            return Err(ConversionError::new(
                at,
                format!(
                    "{name:?} is {}×{} px but the rig's camera is {w}×{h} px",
                    size.0, size.1
                ),
            ));
        }
        let role = role_of(&name).ok_or_else(|| {
            ConversionError::new(
                format!("{at}.name"),
                format!(
                    "{name:?} is not an array of a view: \"depth\", \"left_000\"…, \
                     \"right_000\"…, \"noise_a\", \"noise_b\""
                ),
            )
        })?;
        match role {
            ArrayRole::Depth => match array {
                AssembledArray::Depth(m) => {
                    depth = Some(DepthMap::try_from(m).map_err(|e| e.within(&at))?);
                }
                AssembledArray::Image(_) => {
                    return Err(ConversionError::new(
                        format!("{at}.layout"),
                        "\"depth\" must be a depth map",
                    ));
                }
            },
            ArrayRole::Shot { camera, k } => {
                let image = read_out(array).map_err(|e| e.within(&at))?;
                let list = &mut shots[camera];
                if list.len() <= k {
                    list.resize(k + 1, None);
                }
                list[k] = Some(image);
            }
            ArrayRole::Noise(i) => noise[i] = Some(read_out(array).map_err(|e| e.within(&at))?),
        }
    }
    let depth = depth.ok_or_else(|| ConversionError::new("arrays", "has no \"depth\" array"))?;
    let [left, right] = shots;
    let complete = |list: Vec<Option<Image<u16>>>, camera: usize| {
        let k = list.len();
        list.into_iter()
            .enumerate()
            .map(|(i, s)| {
                s.ok_or_else(|| {
                    ConversionError::new(
                        "arrays",
                        format!(
                            "has shots up to {:?} but no {:?}",
                            shot_array_name(camera, k - 1),
                            shot_array_name(camera, i)
                        ),
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()
    };
    let (left, right) = (complete(left, 0)?, complete(right, 1)?);
    if left.len() != right.len() {
        return Err(ConversionError::new(
            "arrays",
            format!(
                "has {} left and {} right pattern shots; send as many of each",
                left.len(),
                right.len()
            ),
        ));
    }
    let noise_shots = match noise {
        [Some(a), Some(b)] => Some([a, b]),
        [None, None] => None,
        _ => {
            return Err(ConversionError::new(
                "arrays",
                "has one of \"noise_a\" and \"noise_b\"; send both or neither",
            ));
        }
    };
    if *sigma == RefineSigma::PatternImages {
        if left.is_empty() {
            return Err(ConversionError::new(
                "arrays",
                "has no pattern shots; σ from pattern images needs \"left_000\"… and \
                 \"right_000\"…",
            ));
        }
        if noise_shots.is_none() {
            return Err(ConversionError::new(
                "arrays",
                "has no \"noise_a\" and \"noise_b\"; σ from pattern images fits the sensor's \
                 noise from them",
            ));
        }
        if open.max_dn == 0 {
            return Err(ConversionError::new(
                "max_dn",
                "is 0; σ from pattern images needs the read-out's full scale (1 to 65535)",
            ));
        }
    }
    Ok(ViewMeasurement {
        t_w_c: open.t_w_c,
        stereo: open.stereo,
        depth,
        left,
        right,
        noise_shots,
        max_dn: open.max_dn as u16,
    })
}

fn invalid(field: &str, message: &str) -> Status {
    Status::invalid_argument(format!("{field}: {message}"))
}

/// Reads the stream's first message, the header.
async fn read_header(stream: &mut Streaming<v1::RefineChunk>) -> Result<DecodedHeader, Status> {
    use v1::refine_chunk::Part;
    match stream.next().await {
        Some(Ok(v1::RefineChunk {
            part: Some(Part::Header(h)),
        })) => Ok(decode_header(&h).map_err(|e| e.within("header"))?),
        Some(Ok(_)) => Err(invalid(
            "header",
            "the stream must start with a RefineHeader",
        )),
        Some(Err(status)) => Err(status),
        None => Err(invalid("header", "the stream is empty")),
    }
}

/// Reads the views that follow the header.
async fn read_views(
    stream: &mut Streaming<v1::RefineChunk>,
    header: &DecodedHeader,
) -> Result<Vec<ViewMeasurement>, Status> {
    use v1::refine_chunk::Part;
    let expected = header.views as usize;
    let mut views = Vec::with_capacity(expected);
    let mut open: Option<OpenView> = None;
    let mut declared = 0u64;
    let close = |open: OpenView, i: usize| {
        close_view(open, &header.settings.sigma).map_err(|e| e.within(&format!("views[{i}]")))
    };
    while let Some(message) = stream.next().await {
        match message?.part {
            Some(Part::View(h)) => {
                if let Some(previous) = open.take() {
                    views.push(close(previous, views.len())?);
                }
                let i = views.len();
                if i >= expected {
                    return Err(invalid(
                        "header.views",
                        &format!("is {expected}, but more views follow"),
                    ));
                }
                declared = h
                    .arrays
                    .iter()
                    .fold(declared, |sum, a| sum.saturating_add(a.size_bytes));
                if declared > MAX_REFINE_BYTES {
                    return Err(invalid(
                        &format!("views[{i}].arrays"),
                        &format!("the stream's arrays exceed {MAX_REFINE_BYTES} bytes"),
                    ));
                }
                open = Some(open_view(h).map_err(|e| e.within(&format!("views[{i}]")))?);
            }
            Some(Part::Chunk(chunk)) => match open.as_mut() {
                Some(view) => view
                    .assembler
                    .push(chunk)
                    .map_err(|e| e.within(&format!("views[{}]", views.len())))?,
                None => return Err(invalid("chunk", "arrives before any ViewHeader")),
            },
            Some(Part::Header(_)) => {
                return Err(invalid("header", "only one header, first"));
            }
            None => return Err(invalid("part", "a RefineChunk must hold a part")),
        }
    }
    if let Some(last) = open.take() {
        views.push(close(last, views.len())?);
    }
    if views.len() != expected {
        return Err(invalid(
            "header.views",
            &format!("is {expected}, but the stream held {} views", views.len()),
        ));
    }
    Ok(views)
}

/// A refinement's error as a status; a library field outside the views is the header's.
fn refine_status(e: MultiviewError) -> Status {
    match e {
        MultiviewError::Input { field, message } => {
            let field = if field.starts_with("views") {
                field
            } else if field == "t_w_o" {
                "header.initial_t_w_o".into()
            } else {
                format!("header.{field}")
            };
            invalid(&field, &message)
        }
        other => Status::failed_precondition(other.to_string()),
    }
}

/// A planner's error as a status naming the matrix or list at fault.
fn plan_status(e: NbvError) -> Status {
    let field = match &e {
        NbvError::NotSymmetric { which } | NbvError::NotPositive { which } => which.clone(),
        NbvError::TakenOutOfRange { .. } | NbvError::AllTaken => "taken".into(),
        NbvError::NoCandidates | NbvError::NoViewTaken => "candidates".into(),
        NbvError::BadPrior => return Status::internal(e.to_string()),
    };
    invalid(&field, &e.to_string())
}

/// A required 6×6 symmetric matrix (its upper triangle on the wire); `field` names it in errors.
pub fn matrix(
    m: &Option<v1::SymmetricMatrix6>,
    field: &str,
) -> Result<Matrix6<f64>, ConversionError> {
    Matrix6::try_from(required(m, field)?).map_err(|e| e.within(field))
}

/// The planner's input from a PlanNextView request: the information collected, each
/// candidate's, and the candidates taken.
pub type PlanInput = (Matrix6<f64>, Vec<Matrix6<f64>>, Vec<usize>);

/// A PlanNextView request as the planner's input. Rejections name the field.
pub fn plan_request(request: &v1::PlanNextViewRequest) -> Result<PlanInput, Status> {
    let collected = matrix(&request.collected, "collected")?;
    let n = request.candidates.len();
    if n == 0 {
        return Err(invalid(
            "candidates",
            "is empty; send at least one candidate",
        ));
    }
    if n > MAX_CANDIDATES {
        return Err(invalid(
            "candidates",
            &format!("has {n} matrices; at most {MAX_CANDIDATES}"),
        ));
    }
    let candidates = request
        .candidates
        .iter()
        .enumerate()
        .map(|(i, m)| Matrix6::try_from(m).map_err(|e| e.within(&format!("candidates[{i}]"))))
        .collect::<Result<Vec<_>, _>>()?;
    let taken = request.taken.iter().map(|&i| i as usize).collect();
    Ok((collected, candidates, taken))
}

#[tonic::async_trait]
impl EstimationService for Estimation {
    async fn register_mesh(
        &self,
        request: Request<v1::MeshFile>,
    ) -> Result<Response<v1::MeshRef>, Status> {
        let file = request.into_inner();
        let name = file.name.clone();
        let loaded = glint_server::blocking(move || LoadedMesh::try_from(&file)).await??;
        let key = loaded.mesh.content_sha256_hex();
        if self.registry()?.get(&key).is_none() {
            let sdf = self.sdf;
            let mesh = loaded.mesh;
            let grid =
                glint_server::blocking(move || SdfGrid::build(&mesh, &sdf).map(|g| (mesh, g)))
                    .await?
                    .map_err(|e| invalid("data", &format!("SDF grid: {e}")))?;
            let (mesh, grid) = grid;
            self.registry()?.insert(
                key.clone(),
                Arc::new(RegisteredMesh {
                    mesh: Arc::new(mesh),
                    grid: Arc::new(grid),
                }),
            );
            tracing::info!("registered mesh {key} ({name:?})");
        }
        Ok(Response::new(v1::MeshRef {
            sha256_hex: key,
            unit: v1::LengthUnit::Metre as i32,
            uri: String::new(),
            name,
        }))
    }

    async fn refine(
        &self,
        request: Request<Streaming<v1::RefineChunk>>,
    ) -> Result<Response<v1::RefineResponse>, Status> {
        let mut stream = request.into_inner();
        let header = read_header(&mut stream).await?;
        // Before the views arrive: an unknown mesh fails fast.
        let mesh = self.mesh(&header.mesh_sha256_hex)?;
        let views = read_views(&mut stream, &header).await?;
        let (config, prior) = (self.refine, self.prior);
        let response = glint_server::blocking(move || {
            let views: Vec<&ViewMeasurement> = views.iter().collect();
            let refinement = refine_views(
                &mesh.mesh,
                &mesh.grid,
                &views,
                &header.t_w_o,
                &header.settings,
                &config,
            )
            .map_err(refine_status)?;
            let entropy = pose_entropy_nats(&refinement.information, &prior)
                .map_err(|e| Status::internal(format!("the refinement's entropy: {e}")))?;
            Ok::<_, Status>(refinement_to_message(&refinement, entropy))
        })
        .await??;
        Ok(Response::new(response))
    }

    async fn plan_next_view(
        &self,
        request: Request<v1::PlanNextViewRequest>,
    ) -> Result<Response<v1::PlanNextViewResponse>, Status> {
        let (collected, candidates, taken) = plan_request(&request.into_inner())?;
        let prior = self.prior;
        let plan =
            glint_server::blocking(move || plan_next_view(&collected, &candidates, &taken, &prior))
                .await?
                .map_err(plan_status)?;
        Ok(Response::new(v1::PlanNextViewResponse {
            chosen: plan.chosen as u32,
            entropies_nats: plan
                .entropies_nats
                .iter()
                .map(|h| h.unwrap_or(f64::NAN))
                .collect(),
        }))
    }

    async fn pose_entropy(
        &self,
        request: Request<v1::PoseEntropyRequest>,
    ) -> Result<Response<v1::PoseEntropyResponse>, Status> {
        let information = matrix(&request.into_inner().information, "information")?;
        let entropy_nats = pose_entropy_nats(&information, &self.prior).map_err(plan_status)?;
        Ok(Response::new(v1::PoseEntropyResponse {
            entropy_nats,
            prior_sigma_translation_m: self.prior.sigma_translation_m,
            prior_sigma_rotation_rad: self.prior.sigma_rotation_rad,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_names_round_trip() {
        assert_eq!(shot_array_name(0, 7), "left_007");
        assert_eq!(
            role_of("right_012"),
            Some(ArrayRole::Shot { camera: 1, k: 12 })
        );
        assert_eq!(role_of("depth"), Some(ArrayRole::Depth));
        assert_eq!(role_of("noise_b"), Some(ArrayRole::Noise(1)));
        for bad in ["left_7", "left_0007", "left_x01", "mask", ""] {
            assert_eq!(role_of(bad), None, "{bad}");
        }
    }

    #[test]
    fn headers_round_trip_and_name_bad_fields() {
        let settings = RefineSettings {
            mask_margin_m: 10e-3,
            final_mask_margin_m: Some(3e-3),
            background: Some(BackgroundPlane {
                normal_w: Unit::new_normalize(Vector3::new(0.1, 0.0, 1.0)),
                offset_m: 0.02,
                clearance_m: 2e-3,
            }),
            erode_px: 3,
            window_radius_px: 3,
            align_depth: true,
            sigma: RefineSigma::PatternImages,
            error_model: Some(PoseErrorModel {
                depth_error: CorrelatedDepthError {
                    cell_m: 2e-3,
                    bias_sigma_m: 0.5e-3,
                },
                view_bias: crate::view_bias::ViewPoseBias {
                    covariance_v: Matrix6::from_fn(|i, j| {
                        if i == j {
                            1e-6
                        } else {
                            1e-8 / (1 + i + j) as f64
                        }
                    }),
                },
            }),
        };
        let t_w_o = Isometry3::translation(0.1, -0.2, 0.5);
        let hash = "ab".repeat(32);
        let header = refine_header(&hash, &t_w_o, &settings, 2);
        let decoded = decode_header(&header).unwrap();
        assert_eq!(decoded.settings, settings);
        assert_eq!(decoded.mesh_sha256_hex, hash);
        assert_eq!(decoded.views, 2);
        let field = |h: v1::RefineHeader| decode_header(&h).unwrap_err().field;
        let mut h = header.clone();
        h.mask_margin_m = -1.0;
        assert_eq!(field(h), "mask_margin_m");
        let mut h = header.clone();
        h.views = 0;
        assert_eq!(field(h), "views");
        let mut h = header.clone();
        h.sigma_source = 0;
        assert_eq!(field(h), "sigma_source");
        let mut h = header.clone();
        if let Some(m) = h.error_model.as_mut() {
            m.bias_sigma_m = f64::NAN;
        }
        assert_eq!(field(h), "error_model.bias_sigma_m");
        let mut h = header.clone();
        if let Some(m) = h.error_model.as_mut() {
            m.view_bias_covariance_v = None;
        }
        assert_eq!(field(h), "error_model.view_bias_covariance_v");
        let mut h = header.clone();
        h.mesh = Some(v1::MeshRef::new("ABC", LengthUnit::Metre));
        assert_eq!(field(h), "mesh.sha256_hex");
        let mut h = header;
        if let Some(b) = h.background.as_mut() {
            b.normal_w = Some(v1::Vector3 {
                x: 0.0,
                y: 0.0,
                z: 3.0,
            });
        }
        assert_eq!(field(h), "background.normal_w");
    }

    #[test]
    fn the_registry_evicts_the_oldest() {
        let mesh = glint_geometry::Part::Zigzag.mesh();
        let entry = Arc::new(RegisteredMesh {
            grid: Arc::new(SdfGrid::build(&mesh, &SdfConfig::default()).unwrap()),
            mesh: Arc::new(mesh),
        });
        let mut r = Registry {
            capacity: 2,
            order: VecDeque::new(),
            meshes: HashMap::new(),
        };
        r.insert("a".into(), entry.clone());
        r.insert("b".into(), entry.clone());
        r.insert("a".into(), entry.clone());
        r.insert("c".into(), entry);
        assert!(r.get("b").is_none());
        assert_eq!(r.order, ["a", "c"]);
    }
}
