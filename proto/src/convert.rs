//! Conversions between `glint.v1` messages and Glint's core types.
//!
//! Message → core is `TryFrom` (for both `&Message` and `Message`) and validates everything a
//! receiver must not trust: every rejection is a [`ConversionError`] whose `field` names the
//! offending field (dotted for nested messages, e.g. `intrinsics.fx_px`), and which turns into
//! `tonic::Status::invalid_argument` with `?` in a service method.
//! Core → message is infallible `From` (for both `&Core` and `Core`).
//!
//! | message                 | core type                                   |
//! |-------------------------|---------------------------------------------|
//! | `v1::Pose`              | `nalgebra::Isometry3<f64>`                  |
//! | `v1::PinholeIntrinsics` | `glint_geometry::camera::PinholeIntrinsics` |
//! | `v1::StereoRig`         | `glint_geometry::camera::StereoRig`         |
//! | `v1::Image`             | `glint_geometry::image::Image<u8/u16/f32>`  |
//! | `v1::DepthMap`          | `glint_geometry::image::DepthMap`           |
//! | `v1::LengthUnit`        | `glint_geometry::LengthUnit`                |
//! | `v1::MeshFile`          | `glint_geometry::io::LoadedMesh` (one way)  |
//! | `v1::PrincipledMaterial`| `glint_render::bsdf::PrincipledParams<f32>` |
//!
//! What is rejected: missing required sub-messages, NaN or infinite numbers (pose, intrinsics,
//! baseline, float32 image samples, float32 depth other than the NaN "missing" marker),
//! quaternions whose norm is off 1 by more than [`UNIT_QUATERNION_TOLERANCE`], zero-size or
//! out-of-range image sizes, byte buffers of the wrong length, unspecified or unknown enum
//! values, material parameters outside [0, 1], an image encoding other than the requested sample type's (no silent conversion), and
//! a uint16 depth scale that is not positive.

use glint_geometry::LengthUnit;
use glint_geometry::camera::{CameraError, PinholeIntrinsics, StereoRig};
use glint_geometry::image::{DepthMap, Image};
use glint_geometry::io::{LoadedMesh, MeshFormat, read_mesh_from_bytes};
use glint_render::bsdf::PrincipledParams;
use nalgebra::{Isometry3, Matrix6, Quaternion, Translation3, UnitQuaternion};

use crate::v1;

/// A message that does not describe a valid core value.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct ConversionError {
    /// The offending field, dotted for nested messages (`intrinsics.fx_px`).
    pub field: String,
    /// What is wrong with it.
    pub message: String,
}

impl ConversionError {
    pub fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            message: message.into(),
        }
    }

    /// A required sub-message that is absent.
    pub fn missing(field: impl Into<String>) -> Self {
        Self::new(field, "required but missing")
    }

    /// The same error seen from the message that contains this one in field `parent`:
    /// `fx_px` becomes `parent.fx_px`. Server code uses it for nested fields of requests, e.g.
    /// `Isometry3::try_from(pose).map_err(|e| e.within("t_w_c"))`.
    #[must_use]
    pub fn within(mut self, parent: &str) -> Self {
        self.field = if self.field.is_empty() {
            parent.to_owned()
        } else {
            format!("{parent}.{}", self.field)
        };
        self
    }
}

impl From<ConversionError> for tonic::Status {
    fn from(e: ConversionError) -> Self {
        tonic::Status::invalid_argument(e.to_string())
    }
}

/// The by-value conversion of a type whose by-reference one is written out: a message is only
/// read, so taking it by value just forwards. `try WIRE => CORE` for decoding, `CORE => WIRE`
/// for encoding.
macro_rules! by_value {
    (try $wire:ty => $core:ty) => {
        impl TryFrom<$wire> for $core {
            type Error = ConversionError;
            fn try_from(msg: $wire) -> Result<Self, Self::Error> {
                Self::try_from(&msg)
            }
        }
    };
    ($core:ty => $wire:ty) => {
        impl From<$core> for $wire {
            fn from(value: $core) -> Self {
                Self::from(&value)
            }
        }
    };
}

fn finite(field: &str, value: f64) -> Result<f64, ConversionError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ConversionError::new(
            field,
            format!("{value} is not finite"),
        ))
    }
}

/// An enum field's value, rejecting numbers this build does not know.
fn known_enum<E: TryFrom<i32>>(field: &str, value: i32) -> Result<E, ConversionError> {
    E::try_from(value)
        .map_err(|_| ConversionError::new(field, format!("unknown enum value {value}")))
}

// ---------------------------------------------------------------------------------------------
// Pose ↔ Isometry3<f64>

/// How far from 1 a received quaternion's norm may be. Within it the quaternion is renormalised
/// (this only removes rounding); beyond it the pose is rejected, never silently normalised.
pub const UNIT_QUATERNION_TOLERANCE: f64 = 1e-6;

impl TryFrom<&v1::Pose> for Isometry3<f64> {
    type Error = ConversionError;

    /// `t_a_b`; the frame names are not part of the core type (check them before converting).
    fn try_from(pose: &v1::Pose) -> Result<Self, Self::Error> {
        let t = pose
            .translation_m
            .as_ref()
            .ok_or_else(|| ConversionError::missing("translation_m"))?;
        let translation = Translation3::new(
            finite("translation_m.x", t.x)?,
            finite("translation_m.y", t.y)?,
            finite("translation_m.z", t.z)?,
        );
        let q = pose
            .rotation
            .as_ref()
            .ok_or_else(|| ConversionError::missing("rotation"))?;
        let q = Quaternion::new(
            finite("rotation.w", q.w)?,
            finite("rotation.x", q.x)?,
            finite("rotation.y", q.y)?,
            finite("rotation.z", q.z)?,
        );
        let norm = q.norm();
        if (norm - 1.0).abs() > UNIT_QUATERNION_TOLERANCE {
            return Err(ConversionError::new(
                "rotation",
                format!(
                    "quaternion norm is {norm}, not 1 (tolerance {UNIT_QUATERNION_TOLERANCE:e}); send a unit quaternion"
                ),
            ));
        }
        Ok(Isometry3::from_parts(
            translation,
            UnitQuaternion::new_normalize(q),
        ))
    }
}

by_value!(try v1::Pose => Isometry3<f64>);

impl From<&Isometry3<f64>> for v1::Pose {
    /// A pose without frame names; see [`v1::Pose::with_frames`].
    fn from(t: &Isometry3<f64>) -> Self {
        let p = &t.translation.vector;
        let q = t.rotation.quaternion();
        v1::Pose {
            translation_m: Some(v1::Vector3 {
                x: p.x,
                y: p.y,
                z: p.z,
            }),
            rotation: Some(v1::UnitQuaternion {
                w: q.w,
                x: q.i,
                y: q.j,
                z: q.k,
            }),
            parent_frame: String::new(),
            child_frame: String::new(),
        }
    }
}

by_value!(Isometry3<f64> => v1::Pose);

impl v1::Pose {
    /// `t_a_b` with its frame names: `parent_frame` is a, `child_frame` is b.
    pub fn with_frames(t_a_b: &Isometry3<f64>, parent_frame: &str, child_frame: &str) -> Self {
        v1::Pose {
            parent_frame: parent_frame.to_owned(),
            child_frame: child_frame.to_owned(),
            ..Self::from(t_a_b)
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Cameras

fn camera_error(e: CameraError) -> ConversionError {
    match e {
        CameraError::BadSize { width, .. } => {
            let field = if width == 0 || width > 65535 {
                "width_px"
            } else {
                "height_px"
            };
            ConversionError::new(field, e.to_string())
        }
        CameraError::NotPositive { field, value } => {
            ConversionError::new(field, format!("{value} must be finite and positive"))
        }
        CameraError::NotFinite { field, value } => {
            ConversionError::new(field, format!("{value} must be finite"))
        }
    }
}

impl TryFrom<&v1::PinholeIntrinsics> for PinholeIntrinsics {
    type Error = ConversionError;
    fn try_from(k: &v1::PinholeIntrinsics) -> Result<Self, Self::Error> {
        PinholeIntrinsics::new(k.width_px, k.height_px, k.fx_px, k.fy_px, k.cx_px, k.cy_px)
            .map_err(camera_error)
    }
}

by_value!(try v1::PinholeIntrinsics => PinholeIntrinsics);

impl From<&PinholeIntrinsics> for v1::PinholeIntrinsics {
    fn from(k: &PinholeIntrinsics) -> Self {
        v1::PinholeIntrinsics {
            width_px: k.width_px,
            height_px: k.height_px,
            fx_px: k.fx_px,
            fy_px: k.fy_px,
            cx_px: k.cx_px,
            cy_px: k.cy_px,
        }
    }
}

by_value!(PinholeIntrinsics => v1::PinholeIntrinsics);

impl TryFrom<&v1::StereoRig> for StereoRig {
    type Error = ConversionError;
    fn try_from(rig: &v1::StereoRig) -> Result<Self, Self::Error> {
        let k = rig
            .intrinsics
            .as_ref()
            .ok_or_else(|| ConversionError::missing("intrinsics"))?;
        let k = PinholeIntrinsics::try_from(k).map_err(|e| e.within("intrinsics"))?;
        StereoRig::new(k, rig.baseline_m).map_err(camera_error)
    }
}

by_value!(try v1::StereoRig => StereoRig);

impl From<&StereoRig> for v1::StereoRig {
    fn from(rig: &StereoRig) -> Self {
        v1::StereoRig {
            intrinsics: Some((&rig.intrinsics).into()),
            baseline_m: rig.baseline_m,
        }
    }
}

by_value!(StereoRig => v1::StereoRig);

// ---------------------------------------------------------------------------------------------
// Images

/// A pixel sample type with a wire encoding.
trait Sample: Copy + std::fmt::Display {
    const ENCODING: v1::ImageEncoding;
    const BYTES: usize;
    fn from_le(bytes: &[u8]) -> Self;
    fn to_le(self) -> impl IntoIterator<Item = u8>;
    /// Whether a received sample may be used.
    fn is_valid(self) -> bool {
        true
    }
}

impl Sample for u8 {
    const ENCODING: v1::ImageEncoding = v1::ImageEncoding::Mono8;
    const BYTES: usize = 1;
    fn from_le(bytes: &[u8]) -> Self {
        bytes[0]
    }
    fn to_le(self) -> impl IntoIterator<Item = u8> {
        [self]
    }
}

impl Sample for u16 {
    const ENCODING: v1::ImageEncoding = v1::ImageEncoding::Mono16Le;
    const BYTES: usize = 2;
    fn from_le(bytes: &[u8]) -> Self {
        u16::from_le_bytes([bytes[0], bytes[1]])
    }
    fn to_le(self) -> impl IntoIterator<Item = u8> {
        self.to_le_bytes()
    }
}

impl Sample for f32 {
    const ENCODING: v1::ImageEncoding = v1::ImageEncoding::Float32Le;
    const BYTES: usize = 4;
    fn from_le(bytes: &[u8]) -> Self {
        f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]])
    }
    fn to_le(self) -> impl IntoIterator<Item = u8> {
        self.to_le_bytes()
    }
    fn is_valid(self) -> bool {
        self.is_finite()
    }
}

/// Checks a width/height pair and a buffer length; returns the pixel count.
fn check_buffer(
    width_px: u32,
    height_px: u32,
    bytes_per_sample: usize,
    encoding_name: &str,
    actual_bytes: usize,
) -> Result<usize, ConversionError> {
    if width_px == 0 {
        return Err(ConversionError::new(
            "width_px",
            format!("must be non-zero (image is {width_px}×{height_px} px)"),
        ));
    }
    if height_px == 0 {
        return Err(ConversionError::new(
            "height_px",
            format!("must be non-zero (image is {width_px}×{height_px} px)"),
        ));
    }
    let pixels = width_px as usize * height_px as usize;
    let expected = pixels.checked_mul(bytes_per_sample).ok_or_else(|| {
        ConversionError::new(
            "width_px",
            format!("image of {width_px}×{height_px} px is too large"),
        )
    })?;
    if actual_bytes != expected {
        return Err(ConversionError::new(
            "data",
            format!(
                "expected {expected} bytes ({width_px}×{height_px} px × {bytes_per_sample} bytes per sample for \
                 {encoding_name}), got {actual_bytes}"
            ),
        ));
    }
    Ok(pixels)
}

/// Validates an image message's header for sample type `T` and returns the pixel count.
fn check_image_header<T: Sample>(msg: &v1::Image) -> Result<usize, ConversionError> {
    let encoding: v1::ImageEncoding = known_enum("encoding", msg.encoding)?;
    if encoding == v1::ImageEncoding::Unspecified {
        return Err(ConversionError::new(
            "encoding",
            "must be set (IMAGE_ENCODING_UNSPECIFIED)",
        ));
    }
    if encoding != T::ENCODING {
        return Err(ConversionError::new(
            "encoding",
            format!(
                "is {} but a {} image was expected ({})",
                encoding.as_str_name(),
                std::any::type_name::<T>(),
                T::ENCODING.as_str_name()
            ),
        ));
    }
    let _: v1::PixelSpace = known_enum("pixel_space", msg.pixel_space)?;
    check_buffer(
        msg.width_px,
        msg.height_px,
        T::BYTES,
        T::ENCODING.as_str_name(),
        msg.data.len(),
    )
}

/// The first sample that fails `ok`, as "pixel (u, v) is {value}".
fn first_bad_sample<T: Copy + std::fmt::Display>(
    samples: &[T],
    width_px: u32,
    ok: impl Fn(T) -> bool,
) -> Option<String> {
    samples.iter().position(|&s| !ok(s)).map(|i| {
        let (u, v) = (i % width_px as usize, i / width_px as usize);
        format!("pixel ({u}, {v}) is {}", samples[i])
    })
}

fn image_from_message<T: Sample>(msg: &v1::Image) -> Result<Image<T>, ConversionError> {
    check_image_header::<T>(msg)?;
    let samples: Vec<T> = msg.data.chunks_exact(T::BYTES).map(T::from_le).collect();
    if let Some(bad) = first_bad_sample(&samples, msg.width_px, T::is_valid) {
        return Err(ConversionError::new(
            "data",
            format!(
                "{bad}; {} samples must be finite",
                T::ENCODING.as_str_name()
            ),
        ));
    }
    Image::new(msg.width_px, msg.height_px, samples)
        .map_err(|e| ConversionError::new("data", e.to_string()))
}

fn image_to_message<T: Sample>(img: &Image<T>) -> v1::Image {
    v1::Image {
        width_px: img.width(),
        height_px: img.height(),
        encoding: T::ENCODING as i32,
        pixel_space: v1::PixelSpace::Unspecified as i32,
        data: img.data().iter().flat_map(|s| s.to_le()).collect(),
    }
}

macro_rules! image_conversions {
    ($($t:ty),*) => {$(
        impl TryFrom<&v1::Image> for Image<$t> {
            type Error = ConversionError;
            /// Accepts only the matching encoding; `pixel_space` is not checked beyond being a
            /// known value (the core type does not carry it: check it where it matters).
            fn try_from(msg: &v1::Image) -> Result<Self, Self::Error> {
                image_from_message::<$t>(msg)
            }
        }

        impl From<&Image<$t>> for v1::Image {
            /// `pixel_space` is left UNSPECIFIED: set it with `set_pixel_space`.
            fn from(img: &Image<$t>) -> Self {
                image_to_message(img)
            }
        }

        impl From<Image<$t>> for v1::Image {
            fn from(img: Image<$t>) -> Self {
                image_to_message(&img)
            }
        }
    )*};
}

image_conversions!(u8, u16, f32);

impl TryFrom<v1::Image> for Image<u8> {
    type Error = ConversionError;
    /// As for `&v1::Image`, reusing the message's buffer.
    fn try_from(msg: v1::Image) -> Result<Self, Self::Error> {
        check_image_header::<u8>(&msg)?;
        Image::new(msg.width_px, msg.height_px, msg.data)
            .map_err(|e| ConversionError::new("data", e.to_string()))
    }
}

by_value!(try v1::Image => Image<u16>);

by_value!(try v1::Image => Image<f32>);

// ---------------------------------------------------------------------------------------------
// Depth maps

impl TryFrom<&v1::DepthMap> for DepthMap {
    type Error = ConversionError;

    /// Float32 metres are taken as they are (NaN stays NaN, bit for bit); uint16 counts become
    /// `count × depth_scale_mm / 1000` metres, with 0 becoming NaN.
    fn try_from(msg: &v1::DepthMap) -> Result<Self, Self::Error> {
        let encoding: v1::DepthEncoding = known_enum("encoding", msg.encoding)?;
        let depth_m: Vec<f32> = match encoding {
            v1::DepthEncoding::Unspecified => {
                return Err(ConversionError::new(
                    "encoding",
                    "must be set (DEPTH_ENCODING_UNSPECIFIED)",
                ));
            }
            v1::DepthEncoding::Float32LeM => {
                if msg.depth_scale_mm != 0.0 {
                    return Err(ConversionError::new(
                        "depth_scale_mm",
                        format!(
                            "must be 0 for DEPTH_ENCODING_FLOAT32_LE_M (got {}): float32 depth is already in metres",
                            msg.depth_scale_mm
                        ),
                    ));
                }
                check_buffer(
                    msg.width_px,
                    msg.height_px,
                    4,
                    encoding.as_str_name(),
                    msg.data.len(),
                )?;
                let depth: Vec<f32> = msg
                    .data
                    .chunks_exact(4)
                    .map(<f32 as Sample>::from_le)
                    .collect();
                if let Some(bad) = first_bad_sample(&depth, msg.width_px, |z| {
                    z.is_nan() || (z.is_finite() && z >= 0.0)
                }) {
                    return Err(ConversionError::new(
                        "data",
                        format!(
                            "{bad} m; float32 depth must be NaN (missing) or finite and non-negative"
                        ),
                    ));
                }
                depth
            }
            v1::DepthEncoding::Uint16LeScaled => {
                let scale_mm = msg.depth_scale_mm;
                if !(scale_mm.is_finite() && scale_mm > 0.0) {
                    return Err(ConversionError::new(
                        "depth_scale_mm",
                        format!(
                            "{scale_mm} must be finite and positive for DEPTH_ENCODING_UINT16_LE_SCALED"
                        ),
                    ));
                }
                check_buffer(
                    msg.width_px,
                    msg.height_px,
                    2,
                    encoding.as_str_name(),
                    msg.data.len(),
                )?;
                let m_per_count = scale_mm / 1000.0;
                msg.data
                    .chunks_exact(2)
                    .map(|c| match <u16 as Sample>::from_le(c) {
                        0 => f32::NAN,
                        count => (f64::from(count) * m_per_count) as f32,
                    })
                    .collect()
            }
        };
        let image = Image::new(msg.width_px, msg.height_px, depth_m)
            .map_err(|e| ConversionError::new("data", e.to_string()))?;
        Ok(DepthMap::new(image))
    }
}

by_value!(try v1::DepthMap => DepthMap);

impl From<&DepthMap> for v1::DepthMap {
    /// Lossless float32 metres. Infinite or negative depths, which the core type treats as
    /// missing, are sent as they are and rejected by receivers: store NaN for missing depth.
    fn from(depth: &DepthMap) -> Self {
        let img = &depth.depth_m;
        v1::DepthMap {
            width_px: img.width(),
            height_px: img.height(),
            encoding: v1::DepthEncoding::Float32LeM as i32,
            depth_scale_mm: 0.0,
            data: img.data().iter().flat_map(|z| z.to_le_bytes()).collect(),
        }
    }
}

by_value!(DepthMap => v1::DepthMap);

impl v1::DepthMap {
    /// The BOP-style uint16 encoding of `depth` (half the bytes of float32): each valid depth
    /// becomes `round(z_mm / depth_scale_mm)`; missing depth (NaN, infinite, ≤ 0) becomes 0.
    /// Fails if the scale is not finite and positive, or if a valid depth rounds to 0 or
    /// exceeds 65535 counts (`field` is `depth_scale_mm` or `data`).
    pub fn uint16_from_depth(
        depth: &DepthMap,
        depth_scale_mm: f64,
    ) -> Result<Self, ConversionError> {
        if !(depth_scale_mm.is_finite() && depth_scale_mm > 0.0) {
            return Err(ConversionError::new(
                "depth_scale_mm",
                format!("{depth_scale_mm} must be finite and positive"),
            ));
        }
        let img = &depth.depth_m;
        let mut data = Vec::with_capacity(img.data().len() * 2);
        for (i, &z) in img.data().iter().enumerate() {
            let count = if z.is_finite() && z > 0.0 {
                let counts = (f64::from(z) * 1000.0 / depth_scale_mm).round();
                if !(1.0..=65535.0).contains(&counts) {
                    let (u, v) = (i % img.width() as usize, i / img.width() as usize);
                    return Err(ConversionError::new(
                        "data",
                        format!(
                            "pixel ({u}, {v}) depth {z} m is {counts} counts of {depth_scale_mm} mm, outside 1..=65535"
                        ),
                    ));
                }
                counts as u16
            } else {
                0
            };
            data.extend_from_slice(&count.to_le_bytes());
        }
        Ok(v1::DepthMap {
            width_px: img.width(),
            height_px: img.height(),
            encoding: v1::DepthEncoding::Uint16LeScaled as i32,
            depth_scale_mm,
            data,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Meshes

impl TryFrom<v1::LengthUnit> for LengthUnit {
    type Error = ConversionError;
    fn try_from(unit: v1::LengthUnit) -> Result<Self, Self::Error> {
        match unit {
            v1::LengthUnit::Unspecified => Err(ConversionError::new(
                "unit",
                "must be set (LENGTH_UNIT_UNSPECIFIED)",
            )),
            v1::LengthUnit::Millimetre => Ok(LengthUnit::Millimetre),
            v1::LengthUnit::Metre => Ok(LengthUnit::Metre),
        }
    }
}

impl From<LengthUnit> for v1::LengthUnit {
    fn from(unit: LengthUnit) -> Self {
        match unit {
            LengthUnit::Millimetre => v1::LengthUnit::Millimetre,
            LengthUnit::Metre => v1::LengthUnit::Metre,
        }
    }
}

impl v1::MeshRef {
    /// A reference to a mesh file by its SHA-256 (64 lowercase hex characters) and unit.
    pub fn new(sha256_hex: impl Into<String>, unit: LengthUnit) -> Self {
        v1::MeshRef {
            sha256_hex: sha256_hex.into(),
            unit: v1::LengthUnit::from(unit) as i32,
            uri: String::new(),
            name: String::new(),
        }
    }

    /// Checks the hash format and the unit; returns the unit.
    pub fn validate(&self) -> Result<LengthUnit, ConversionError> {
        let hash = &self.sha256_hex;
        if hash.len() != 64 || !hash.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')) {
            return Err(ConversionError::new(
                "sha256_hex",
                format!(
                    "{hash:?} is not 64 lowercase hexadecimal characters (the SHA-256 of the mesh file)"
                ),
            ));
        }
        known_enum::<v1::LengthUnit>("unit", self.unit)?.try_into()
    }
}

impl TryFrom<&v1::MeshFile> for LoadedMesh {
    type Error = ConversionError;

    /// Parses the inline file (PLY, OBJ or STL; an empty `format` is guessed from the bytes)
    /// into metres, validated. A file that does not parse is rejected in `data`, naming where
    /// in the file the problem is.
    fn try_from(file: &v1::MeshFile) -> Result<Self, Self::Error> {
        let format = if file.format.is_empty() {
            MeshFormat::sniff(&file.data).ok_or_else(|| {
                ConversionError::new(
                    "format",
                    "not given, and the data is not recognisably PLY, OBJ or STL",
                )
            })?
        } else {
            MeshFormat::from_extension(&file.format).ok_or_else(|| {
                ConversionError::new(
                    "format",
                    format!("{:?} is not \"ply\", \"obj\" or \"stl\"", file.format),
                )
            })?
        };
        let unit: LengthUnit = known_enum::<v1::LengthUnit>("unit", file.unit)?.try_into()?;
        if file.data.is_empty() {
            return Err(ConversionError::new("data", "is empty"));
        }
        let name = if file.name.is_empty() {
            "the mesh"
        } else {
            file.name.as_str()
        };
        read_mesh_from_bytes(&file.data, format, unit, name).map_err(|e| {
            let mut message = e.to_string();
            let mut source = std::error::Error::source(&e);
            while let Some(cause) = source {
                message.push_str(&format!(": {cause}"));
                source = cause.source();
            }
            ConversionError::new("data", message)
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Information and covariance matrices

/// Entries of a symmetric 6×6 matrix's upper triangle.
const UPPER_6: usize = 21;

impl TryFrom<&v1::SymmetricMatrix6> for Matrix6<f64> {
    type Error = ConversionError;
    fn try_from(m: &v1::SymmetricMatrix6) -> Result<Self, Self::Error> {
        if m.upper.len() != UPPER_6 {
            return Err(ConversionError::new(
                "upper",
                format!(
                    "has {} values; a symmetric 6x6 matrix needs its 21 upper-triangle entries",
                    m.upper.len()
                ),
            ));
        }
        let mut out = Matrix6::zeros();
        let mut values = m.upper.iter();
        for i in 0..6 {
            for j in i..6 {
                let v = finite("upper", *values.next().unwrap_or(&f64::NAN))?;
                out[(i, j)] = v;
                out[(j, i)] = v;
            }
        }
        Ok(out)
    }
}

impl From<&Matrix6<f64>> for v1::SymmetricMatrix6 {
    /// The upper triangle of the symmetric part `(M + Mᵀ)/2`.
    fn from(m: &Matrix6<f64>) -> Self {
        let upper = (0..6)
            .flat_map(|i| (i..6).map(move |j| (i, j)))
            .map(|(i, j)| 0.5 * (m[(i, j)] + m[(j, i)]))
            .collect();
        v1::SymmetricMatrix6 { upper }
    }
}

// ---------------------------------------------------------------------------------------------
// Materials

impl TryFrom<&v1::PrincipledMaterial> for PrincipledParams<f32> {
    type Error = ConversionError;
    /// Every parameter must be finite and in [0, 1]; the error names the first that is not.
    fn try_from(m: &v1::PrincipledMaterial) -> Result<Self, Self::Error> {
        let values = [
            m.base_color,
            m.metallic,
            m.roughness,
            m.specular,
            m.spec_tint,
            m.anisotropic,
            m.sheen,
            m.sheen_tint,
            m.clearcoat,
            m.clearcoat_gloss,
        ];
        // Checked in f64, before the narrowing cast could round a value into range.
        let names = PrincipledParams::<f32>::NAMES;
        if let Some((name, value)) = names
            .iter()
            .zip(values)
            .find(|(_, v)| !(0.0..=1.0).contains(v))
        {
            return Err(ConversionError::new(
                *name,
                format!("{value} must be a finite number in [0, 1]"),
            ));
        }
        Ok(PrincipledParams::from_array(values.map(|v| v as f32)))
    }
}
by_value!(try v1::PrincipledMaterial => PrincipledParams<f32>);

impl From<&PrincipledParams<f32>> for v1::PrincipledMaterial {
    fn from(p: &PrincipledParams<f32>) -> Self {
        v1::PrincipledMaterial {
            base_color: f64::from(p.base_color),
            metallic: f64::from(p.metallic),
            roughness: f64::from(p.roughness),
            specular: f64::from(p.specular),
            spec_tint: f64::from(p.spec_tint),
            anisotropic: f64::from(p.anisotropic),
            sheen: f64::from(p.sheen),
            sheen_tint: f64::from(p.sheen_tint),
            clearcoat: f64::from(p.clearcoat),
            clearcoat_gloss: f64::from(p.clearcoat_gloss),
        }
    }
}
by_value!(PrincipledParams<f32> => v1::PrincipledMaterial);

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn symmetric_matrices_round_trip_and_reject_bad_input() {
        let a = Matrix6::from_fn(|i, j| (i * 6 + j) as f64 * 0.25 - 3.0);
        let sym = 0.5 * (a + a.transpose());
        let msg = v1::SymmetricMatrix6::from(&a);
        assert_eq!(msg.upper.len(), 21);
        assert_eq!(Matrix6::try_from(&msg).unwrap(), sym);
        let short = v1::SymmetricMatrix6 {
            upper: vec![1.0; 20],
        };
        assert_field(Matrix6::try_from(&short), "upper", "21");
        let mut nan = msg.clone();
        nan.upper[7] = f64::NAN;
        assert_field(Matrix6::try_from(&nan), "upper", "finite");
    }

    fn pose_msg() -> v1::Pose {
        let t = Isometry3::new(
            Vector3::new(0.12, -0.034, 0.61),
            Vector3::new(0.3, -1.1, 2.0),
        );
        v1::Pose::with_frames(&t, "world", "camera")
    }

    fn assert_field<T: std::fmt::Debug>(
        result: Result<T, ConversionError>,
        field: &str,
        contains: &str,
    ) {
        let e = result.expect_err("conversion should fail");
        assert_eq!(e.field, field, "{e}");
        assert!(
            e.message.contains(contains),
            "message {:?} lacks {contains:?}",
            e.message
        );
        assert_eq!(e.to_string(), format!("{}: {}", e.field, e.message));
    }

    // --- Pose

    #[test]
    fn pose_round_trips() {
        let t = Isometry3::new(
            Vector3::new(0.12, -0.034, 0.61),
            Vector3::new(0.3, -1.1, 2.0),
        );
        let msg = v1::Pose::with_frames(&t, "world", "camera");
        assert_eq!(
            (msg.parent_frame.as_str(), msg.child_frame.as_str()),
            ("world", "camera")
        );
        let back = Isometry3::try_from(&msg).unwrap();
        assert!((back.translation.vector - t.translation.vector).norm() < 1e-12);
        assert!(back.rotation.angle_to(&t.rotation) < 1e-12);
        assert!((back.to_homogeneous() - t.to_homogeneous()).abs().max() < 1e-12);
        let owned: Isometry3<f64> = v1::Pose::from(t).try_into().unwrap();
        assert!((owned.to_homogeneous() - t.to_homogeneous()).abs().max() < 1e-12);
    }

    #[test]
    fn pose_quaternion_within_tolerance_is_renormalised() {
        let mut msg = pose_msg();
        let q = msg.rotation.as_mut().unwrap();
        q.w *= 1.0 + 5e-7;
        let t = Isometry3::try_from(&msg).unwrap();
        assert!((t.rotation.quaternion().norm() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn pose_rejections_name_the_field() {
        let mut m = pose_msg();
        m.translation_m = None;
        assert_field(Isometry3::try_from(&m), "translation_m", "missing");

        let mut m = pose_msg();
        m.rotation = None;
        assert_field(Isometry3::try_from(&m), "rotation", "missing");

        let mut m = pose_msg();
        m.translation_m.as_mut().unwrap().y = f64::NAN;
        assert_field(Isometry3::try_from(&m), "translation_m.y", "NaN");

        let mut m = pose_msg();
        m.rotation.as_mut().unwrap().z = f64::INFINITY;
        assert_field(Isometry3::try_from(&m), "rotation.z", "not finite");

        let mut m = pose_msg();
        m.rotation = Some(v1::UnitQuaternion {
            w: 1.0,
            x: 0.0,
            y: 0.0,
            z: 0.1,
        });
        let norm = (1.01f64).sqrt();
        assert_field(
            Isometry3::try_from(&m),
            "rotation",
            &format!("norm is {norm}"),
        );

        // An all-zero quaternion (the proto default) is not a rotation either.
        let mut m = pose_msg();
        m.rotation = Some(v1::UnitQuaternion::default());
        assert_field(Isometry3::try_from(&m), "rotation", "norm is 0");
    }

    // --- Cameras

    #[test]
    fn cameras_round_trip() {
        let k = PinholeIntrinsics::new(640, 512, 541.55, 542.0, 320.25, 255.75).unwrap();
        let msg = v1::PinholeIntrinsics::from(&k);
        assert_eq!(PinholeIntrinsics::try_from(&msg).unwrap(), k);
        assert_eq!(PinholeIntrinsics::try_from(msg).unwrap(), k);

        let rig = StereoRig::ensenso_n35();
        let msg = v1::StereoRig::from(rig);
        assert_eq!(StereoRig::try_from(&msg).unwrap(), rig);
        assert_eq!(StereoRig::try_from(msg).unwrap(), rig);
    }

    #[test]
    fn camera_rejections_name_the_field() {
        let good = v1::PinholeIntrinsics::from(PinholeIntrinsics::ensenso_n35());
        let bad = |f: fn(&mut v1::PinholeIntrinsics)| {
            let mut k = good;
            f(&mut k);
            PinholeIntrinsics::try_from(&k)
        };
        assert_field(bad(|k| k.width_px = 0), "width_px", "non-zero");
        assert_field(bad(|k| k.height_px = 70000), "height_px", "65535");
        assert_field(bad(|k| k.fx_px = f64::NAN), "fx_px", "finite and positive");
        assert_field(bad(|k| k.fy_px = -3.0), "fy_px", "finite and positive");
        assert_field(bad(|k| k.cx_px = f64::INFINITY), "cx_px", "finite");
        assert_field(bad(|k| k.cy_px = f64::NEG_INFINITY), "cy_px", "finite");

        let rig = v1::StereoRig::from(StereoRig::ensenso_n35());
        assert_field(
            StereoRig::try_from(&v1::StereoRig {
                intrinsics: None,
                ..rig
            }),
            "intrinsics",
            "missing",
        );
        let mut r = rig;
        r.intrinsics.as_mut().unwrap().fx_px = 0.0;
        assert_field(StereoRig::try_from(&r), "intrinsics.fx_px", "positive");
        assert_field(
            StereoRig::try_from(&v1::StereoRig {
                baseline_m: 0.0,
                ..rig
            }),
            "baseline_m",
            "positive",
        );
        assert_field(
            StereoRig::try_from(&v1::StereoRig {
                baseline_m: f64::NAN,
                ..rig
            }),
            "baseline_m",
            "NaN",
        );
    }

    // --- Images

    #[test]
    fn images_round_trip_bit_exact() {
        let img8 = Image::new(3, 2, vec![0u8, 1, 127, 128, 254, 255]).unwrap();
        let msg = v1::Image::from(&img8);
        assert_eq!(msg.encoding(), v1::ImageEncoding::Mono8);
        assert_eq!(msg.data, img8.data());
        assert_eq!(Image::<u8>::try_from(&msg).unwrap(), img8);
        assert_eq!(Image::<u8>::try_from(msg).unwrap(), img8);

        let img16 = Image::new(2, 3, vec![0u16, 1, 256, 0x1234, 65534, 65535]).unwrap();
        let msg = v1::Image::from(img16.clone());
        assert_eq!(msg.encoding(), v1::ImageEncoding::Mono16Le);
        assert_eq!(&msg.data[6..8], &[0x34, 0x12], "little-endian");
        assert_eq!(Image::<u16>::try_from(&msg).unwrap(), img16);
        assert_eq!(Image::<u16>::try_from(msg).unwrap(), img16);

        let values = vec![
            0.0f32,
            -0.0,
            1.0e-38,
            f32::MIN_POSITIVE / 2.0,
            0.1,
            -123.456,
            f32::MAX,
            1.0 / 3.0,
        ];
        let imgf = Image::new(4, 2, values).unwrap();
        let mut msg = v1::Image::from(&imgf);
        msg.set_pixel_space(v1::PixelSpace::LinearRadiance);
        assert_eq!(msg.encoding(), v1::ImageEncoding::Float32Le);
        assert_eq!(msg.data.len(), 32);
        let back = Image::<f32>::try_from(msg).unwrap();
        let bits = |i: &Image<f32>| i.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back), bits(&imgf));
        assert_eq!((back.width(), back.height()), (4, 2));
    }

    #[test]
    fn image_rejections_name_the_field() {
        let good = v1::Image::from(Image::new(3, 2, vec![1u16; 6]).unwrap());

        let m = v1::Image {
            width_px: 0,
            data: vec![],
            ..good.clone()
        };
        assert_field(Image::<u16>::try_from(&m), "width_px", "non-zero");
        let m = v1::Image {
            height_px: 0,
            data: vec![],
            ..good.clone()
        };
        assert_field(Image::<u16>::try_from(&m), "height_px", "non-zero");

        let m = v1::Image {
            data: vec![0; 11],
            ..good.clone()
        };
        assert_field(Image::<u16>::try_from(&m), "data", "expected 12 bytes");
        assert_field(Image::<u16>::try_from(&m), "data", "got 11");

        assert_field(
            Image::<u8>::try_from(&good),
            "encoding",
            "IMAGE_ENCODING_MONO16_LE",
        );
        assert_field(
            Image::<u8>::try_from(good.clone()),
            "encoding",
            "expected (IMAGE_ENCODING_MONO8)",
        );
        assert_field(
            Image::<f32>::try_from(&good),
            "encoding",
            "IMAGE_ENCODING_FLOAT32_LE",
        );
        let m = v1::Image {
            encoding: 0,
            ..good.clone()
        };
        assert_field(Image::<u16>::try_from(&m), "encoding", "must be set");
        let m = v1::Image {
            encoding: 9,
            ..good.clone()
        };
        assert_field(
            Image::<u16>::try_from(&m),
            "encoding",
            "unknown enum value 9",
        );
        let m = v1::Image {
            pixel_space: 5,
            ..good.clone()
        };
        assert_field(
            Image::<u16>::try_from(&m),
            "pixel_space",
            "unknown enum value 5",
        );

        let mut f = v1::Image::from(Image::new(2, 2, vec![1.0f32; 4]).unwrap());
        f.data[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_field(Image::<f32>::try_from(&f), "data", "pixel (1, 1) is NaN");
        f.data[12..16].copy_from_slice(&f32::INFINITY.to_le_bytes());
        assert_field(Image::<f32>::try_from(f), "data", "pixel (1, 1) is inf");
    }

    // --- Depth

    #[test]
    fn float_depth_round_trips_with_nan() {
        let payload_nan = f32::from_bits(0x7fc0_1234);
        let depth = DepthMap::new(Image::new(3, 1, vec![0.61, f32::NAN, payload_nan]).unwrap());
        let msg = v1::DepthMap::from(&depth);
        assert_eq!(msg.encoding(), v1::DepthEncoding::Float32LeM);
        let back = DepthMap::try_from(msg).unwrap();
        let bits: Vec<u32> = back.depth_m.data().iter().map(|z| z.to_bits()).collect();
        assert_eq!(
            bits,
            vec![0.61f32.to_bits(), f32::NAN.to_bits(), 0x7fc0_1234]
        );
        assert_eq!(back.get(1, 0), None);
    }

    #[test]
    fn uint16_depth_converts_to_metres() {
        // BOP: depth_mm = value × depth_scale; 0 is missing.
        let counts: [u16; 4] = [0, 1000, 6100, 65535];
        let msg = v1::DepthMap {
            width_px: 2,
            height_px: 2,
            encoding: v1::DepthEncoding::Uint16LeScaled as i32,
            depth_scale_mm: 0.1,
            data: counts.iter().flat_map(|c| c.to_le_bytes()).collect(),
        };
        let depth = DepthMap::try_from(&msg).unwrap();
        let z = depth.depth_m.data();
        assert!(z[0].is_nan());
        for (i, &c) in counts.iter().enumerate().skip(1) {
            let expected = (f64::from(c) * 0.1 / 1000.0) as f32;
            assert_eq!(z[i], expected);
        }
        assert_eq!(z[2], 0.61);

        // …and back through the uint16 encoder.
        let again = v1::DepthMap::uint16_from_depth(&depth, 0.1).unwrap();
        assert_eq!(again, msg);
    }

    #[test]
    fn uint16_encoder_rejects_what_it_cannot_represent() {
        let depth = DepthMap::new(Image::new(2, 1, vec![0.5, 7.0]).unwrap());
        assert_field(
            v1::DepthMap::uint16_from_depth(&depth, 0.1),
            "data",
            "pixel (1, 0)",
        );
        assert_field(
            v1::DepthMap::uint16_from_depth(&depth, 0.0),
            "depth_scale_mm",
            "positive",
        );
        let ok = v1::DepthMap::uint16_from_depth(&depth, 1.0).unwrap();
        assert_eq!(
            ok.data,
            [500u16.to_le_bytes(), 7000u16.to_le_bytes()].concat()
        );
    }

    #[test]
    fn depth_rejections_name_the_field() {
        let float = v1::DepthMap::from(DepthMap::new(Image::new(2, 2, vec![0.5f32; 4]).unwrap()));
        let uint16 = v1::DepthMap {
            encoding: v1::DepthEncoding::Uint16LeScaled as i32,
            depth_scale_mm: 1.0,
            data: vec![0; 8],
            ..float.clone()
        };
        assert!(DepthMap::try_from(&uint16).is_ok());

        for scale in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let m = v1::DepthMap {
                depth_scale_mm: scale,
                ..uint16.clone()
            };
            assert_field(
                DepthMap::try_from(&m),
                "depth_scale_mm",
                "finite and positive",
            );
        }
        let m = v1::DepthMap {
            depth_scale_mm: 1.0,
            ..float.clone()
        };
        assert_field(DepthMap::try_from(&m), "depth_scale_mm", "must be 0");
        let m = v1::DepthMap {
            data: vec![0; 7],
            ..uint16.clone()
        };
        assert_field(DepthMap::try_from(&m), "data", "expected 8 bytes");
        let m = v1::DepthMap {
            data: vec![0; 8],
            ..float.clone()
        };
        assert_field(DepthMap::try_from(&m), "data", "expected 16 bytes");
        let m = v1::DepthMap {
            width_px: 0,
            ..float.clone()
        };
        assert_field(DepthMap::try_from(&m), "width_px", "non-zero");
        let m = v1::DepthMap {
            encoding: 0,
            ..float.clone()
        };
        assert_field(DepthMap::try_from(&m), "encoding", "must be set");
        let m = v1::DepthMap {
            encoding: 3,
            ..float.clone()
        };
        assert_field(DepthMap::try_from(&m), "encoding", "unknown");

        let mut m = float.clone();
        m.data[4..8].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
        assert_field(DepthMap::try_from(&m), "data", "pixel (1, 0) is -inf");
        m.data[4..8].copy_from_slice(&(-0.25f32).to_le_bytes());
        assert_field(DepthMap::try_from(&m), "data", "pixel (1, 0) is -0.25");
    }

    // --- Meshes

    #[test]
    fn mesh_ref_validates_hash_and_unit() {
        let hash = "9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08";
        let mesh = v1::MeshRef {
            name: "gear".into(),
            ..v1::MeshRef::new(hash, LengthUnit::Millimetre)
        };
        assert_eq!(mesh.validate().unwrap(), LengthUnit::Millimetre);
        assert_eq!(
            LengthUnit::try_from(v1::LengthUnit::from(LengthUnit::Metre)).unwrap(),
            LengthUnit::Metre
        );

        let m = v1::MeshRef {
            sha256_hex: hash.to_uppercase(),
            ..mesh.clone()
        };
        assert_field(m.validate(), "sha256_hex", "64 lowercase");
        let m = v1::MeshRef {
            sha256_hex: hash[1..].into(),
            ..mesh.clone()
        };
        assert_field(m.validate(), "sha256_hex", "64 lowercase");
        let m = v1::MeshRef {
            unit: 0,
            ..mesh.clone()
        };
        assert_field(m.validate(), "unit", "must be set");
        let m = v1::MeshRef { unit: 7, ..mesh };
        assert_field(m.validate(), "unit", "unknown enum value 7");
    }

    #[test]
    fn mesh_files_parse_and_name_their_problems() {
        use glint_geometry::io::{PlyEncoding, write_ply_to_vec};
        let mesh = glint_geometry::Part::Zigzag.mesh();
        let good = v1::MeshFile {
            data: write_ply_to_vec(
                &mesh,
                LengthUnit::Millimetre,
                PlyEncoding::BinaryLittleEndian,
            ),
            format: "ply".into(),
            unit: v1::LengthUnit::Millimetre as i32,
            name: "zigzag".into(),
        };
        let loaded = LoadedMesh::try_from(&good).unwrap();
        assert_eq!(loaded.mesh.triangles.len(), mesh.triangles.len());
        let sniffed = v1::MeshFile {
            format: String::new(),
            ..good.clone()
        };
        assert_eq!(
            LoadedMesh::try_from(&sniffed).unwrap().mesh.vertices,
            loaded.mesh.vertices
        );

        let m = v1::MeshFile {
            format: "step".into(),
            ..good.clone()
        };
        assert_field(LoadedMesh::try_from(&m), "format", "\"step\"");
        let m = v1::MeshFile {
            unit: 0,
            ..good.clone()
        };
        assert_field(LoadedMesh::try_from(&m), "unit", "must be set");
        let m = v1::MeshFile {
            data: good.data[..good.data.len() / 2].to_vec(),
            ..good.clone()
        };
        assert_field(LoadedMesh::try_from(&m), "data", "zigzag");
        let m = v1::MeshFile {
            data: vec![],
            ..good
        };
        assert_field(LoadedMesh::try_from(&m), "data", "empty");
    }

    // --- Errors

    #[test]
    fn errors_become_invalid_argument() {
        let mut m = pose_msg();
        m.rotation = None;
        let e = Isometry3::try_from(&m).unwrap_err().within("t_w_c");
        assert_eq!(e.field, "t_w_c.rotation");
        let status = tonic::Status::from(e);
        assert_eq!(status.code(), tonic::Code::InvalidArgument);
        assert_eq!(status.message(), "t_w_c.rotation: required but missing");

        // `?` works in a function returning Status.
        fn decode(k: &v1::PinholeIntrinsics) -> Result<PinholeIntrinsics, tonic::Status> {
            Ok(PinholeIntrinsics::try_from(k)?)
        }
        let status = decode(&v1::PinholeIntrinsics::default()).unwrap_err();
        assert_eq!(status.code(), tonic::Code::InvalidArgument);
        assert!(
            status.message().starts_with("width_px: "),
            "{}",
            status.message()
        );
    }
}
