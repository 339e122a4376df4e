//! A capture as one file: the bytes a session's capture is kept as in the blob directory.
//!
//! Layout (little-endian): the magic `GLINTCAP`, the format version (u32), the header's
//! length (u32), the header as JSON ([`CaptureHeader`]: pose, rig, image size, shots), then
//! the depth map (f32, metres, NaN where missing), the K left shots, the K right shots and, if
//! the header says so, the two noise read-outs (u16 digital numbers each), row-major.

use glint_estimation::view::ViewMeasurement;
use glint_geometry::camera::StereoRig;
use glint_geometry::image::{DepthMap, Image};
use nalgebra::Isometry3;

use crate::stages::CapturedView;

const MAGIC: &[u8; 8] = b"GLINTCAP";
const VERSION: u32 = 1;

/// What a capture file says of its images.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct CaptureHeader {
    /// Left camera → world.
    t_w_c: Isometry3<f64>,
    stereo: StereoRig,
    max_dn: u16,
    width: u32,
    height: u32,
    /// Pattern shots per camera.
    shots: u32,
    noise_shots: bool,
    capture_ms: f64,
}

/// Why bytes are not a capture file.
#[derive(Debug, thiserror::Error)]
#[error("not a capture file: {0}")]
pub struct CaptureFileError(String);

/// `view` as a capture file's bytes. Fails only for images of unequal sizes.
pub fn to_bytes(view: &CapturedView) -> Result<Vec<u8>, CaptureFileError> {
    let m = &view.measurement;
    let (width, height) = (m.depth.depth_m.width(), m.depth.depth_m.height());
    let u16_images: Vec<&Image<u16>> = m
        .left
        .iter()
        .chain(&m.right)
        .chain(m.noise_shots.iter().flatten())
        .collect();
    if m.left.len() != m.right.len()
        || u16_images
            .iter()
            .any(|i| i.width() != width || i.height() != height)
    {
        return Err(CaptureFileError(
            "the shots and the depth map differ in number or size".into(),
        ));
    }
    let header = serde_json::to_vec(&CaptureHeader {
        t_w_c: m.t_w_c,
        stereo: m.stereo,
        max_dn: m.max_dn,
        width,
        height,
        shots: m.left.len() as u32,
        noise_shots: m.noise_shots.is_some(),
        capture_ms: view.capture_ms,
    })
    .map_err(|e| CaptureFileError(e.to_string()))?;
    let pixels = (width as usize) * (height as usize);
    let mut bytes = Vec::with_capacity(16 + header.len() + pixels * (4 + 2 * u16_images.len()));
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&VERSION.to_le_bytes());
    bytes.extend_from_slice(&(header.len() as u32).to_le_bytes());
    bytes.extend_from_slice(&header);
    for z in m.depth.depth_m.data() {
        bytes.extend_from_slice(&z.to_le_bytes());
    }
    for image in u16_images {
        for dn in image.data() {
            bytes.extend_from_slice(&dn.to_le_bytes());
        }
    }
    Ok(bytes)
}

/// The capture of a capture file's bytes.
pub fn from_bytes(bytes: &[u8]) -> Result<CapturedView, CaptureFileError> {
    let bad = |what: &str| CaptureFileError(what.to_owned());
    if bytes.get(..8) != Some(MAGIC.as_slice()) {
        return Err(bad("no GLINTCAP magic"));
    }
    let word = |at: usize| -> Result<u32, CaptureFileError> {
        let b = bytes
            .get(at..at + 4)
            .ok_or_else(|| bad("truncated header"))?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let version = word(8)?;
    if version != VERSION {
        return Err(CaptureFileError(format!(
            "format version {version}, this build reads {VERSION}"
        )));
    }
    let header_len = word(12)? as usize;
    let header_end = 16usize
        .checked_add(header_len)
        .ok_or_else(|| bad("header length overflows"))?;
    let header: CaptureHeader = serde_json::from_slice(
        bytes
            .get(16..header_end)
            .ok_or_else(|| bad("truncated header"))?,
    )
    .map_err(|e| CaptureFileError(format!("header: {e}")))?;
    let pixels = (header.width as usize) * (header.height as usize);
    if pixels == 0 {
        return Err(bad("the header's image is empty"));
    }
    let u16_count = 2 * header.shots as usize + if header.noise_shots { 2 } else { 0 };
    let expected = header_end + pixels * 4 + pixels * 2 * u16_count;
    if bytes.len() != expected {
        return Err(CaptureFileError(format!(
            "{} bytes where the header's {}×{} px and {} shots need {expected}",
            bytes.len(),
            header.width,
            header.height,
            header.shots
        )));
    }
    let image_error = |e: glint_geometry::image::ImageError| CaptureFileError(e.to_string());
    let depth: Vec<f32> = bytes[header_end..header_end + pixels * 4]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let depth = DepthMap::new(Image::new(header.width, header.height, depth).map_err(image_error)?);
    let mut images = bytes[header_end + pixels * 4..]
        .chunks_exact(pixels * 2)
        .map(|chunk| {
            let data = chunk
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect();
            Image::new(header.width, header.height, data).map_err(image_error)
        })
        .collect::<Result<Vec<_>, _>>()?
        .into_iter();
    let shots = header.shots as usize;
    let left: Vec<Image<u16>> = images.by_ref().take(shots).collect();
    let right: Vec<Image<u16>> = images.by_ref().take(shots).collect();
    let noise_shots = match (images.next(), images.next()) {
        (Some(a), Some(b)) => Some([a, b]),
        _ => None,
    };
    Ok(CapturedView {
        measurement: ViewMeasurement {
            t_w_c: header.t_w_c,
            stereo: header.stereo,
            depth,
            left,
            right,
            noise_shots,
            max_dn: header.max_dn,
        },
        capture_ms: header.capture_ms,
    })
}
