//! Cameras: `scene_camera.json` (per image) and the dataset's `camera.json`.

use std::path::Path;

use glint_geometry::camera::PinholeIntrinsics;
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::dataset::error::DatasetError;
use crate::dataset::json::{JsonNode, read_json_file, write_pretty_json};
use crate::dataset::transforms::{isometry_from_rotation_and_mm, rotation_and_mm_from_isometry};

/// Offset from BOP's (OpenCV's) principal point to Glint's: Glint's pixel centres sit at
/// `+0.5` (see the [module doc](super)).
const GLINT_MINUS_BOP_PX: f64 = 0.5;

/// Largest |skew|, px, and largest deviation of K's last row from `(0, 0, 1)` that still
/// counts as a plain pinhole.
const PINHOLE_K_TOLERANCE: f64 = 1e-6;

/// The camera of one BOP image, in Glint's units and conventions.
#[derive(Clone, Debug, PartialEq)]
pub struct BopCamera {
    /// Pinhole intrinsics, Glint's pixel convention (`cx = cx_bop + 0.5`). The image size is
    /// not in `scene_camera.json`; readers take it from the image files.
    pub intrinsics: PinholeIntrinsics,
    /// Millimetres per unit of the 16-bit depth file (BOP's `depth_scale`); `None` when the
    /// file has none (an image without depth).
    pub depth_scale_mm: Option<f64>,
    /// World → camera, metres (BOP's `cam_R_w2c`, `cam_t_w2c`); `None` when absent.
    pub t_c_w: Option<Isometry3<f64>>,
}

/// One image's entry of `scene_camera.json`, exactly as in the file: OpenCV pixel convention,
/// row-major matrices, millimetres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneCameraEntry {
    /// `[fx, 0, cx, 0, fy, cy, 0, 0, 1]`, px.
    #[serde(rename = "cam_K")]
    pub cam_k: [f64; 9],
    /// Millimetres per depth unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale: Option<f64>,
    /// World → camera rotation, row-major.
    #[serde(rename = "cam_R_w2c", default, skip_serializing_if = "Option::is_none")]
    pub cam_r_w2c: Option<[f64; 9]>,
    /// World → camera translation, mm.
    #[serde(rename = "cam_t_w2c", default, skip_serializing_if = "Option::is_none")]
    pub cam_t_w2c: Option<[f64; 3]>,
}

impl SceneCameraEntry {
    /// The file's entry for `camera`.
    pub fn from_camera(camera: &BopCamera) -> Self {
        let k = &camera.intrinsics;
        let (cam_r_w2c, cam_t_w2c) = match &camera.t_c_w {
            Some(t_c_w) => {
                let (r, t_mm) = rotation_and_mm_from_isometry(t_c_w);
                (Some(r), Some(t_mm))
            }
            None => (None, None),
        };
        Self {
            cam_k: [
                k.fx_px,
                0.0,
                k.cx_px - GLINT_MINUS_BOP_PX,
                0.0,
                k.fy_px,
                k.cy_px - GLINT_MINUS_BOP_PX,
                0.0,
                0.0,
                1.0,
            ],
            depth_scale: camera.depth_scale_mm,
            cam_r_w2c,
            cam_t_w2c,
        }
    }
}

/// A camera read from `scene_camera.json`, checked, still without the image size.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct UnsizedCamera {
    /// Glint's convention.
    fx_px: f64,
    fy_px: f64,
    cx_px: f64,
    cy_px: f64,
    pub(crate) depth_scale_mm: Option<f64>,
    pub(crate) t_c_w: Option<Isometry3<f64>>,
}

impl UnsizedCamera {
    /// Parses and checks one image's entry; errors name the key.
    pub(crate) fn parse(entry: &JsonNode<'_>) -> Result<Self, DatasetError> {
        let k_node = entry.field("cam_K").map_err(|error| {
            if entry.optional_field("cam_model").is_some() {
                entry.error(
                    "has a BOP24 `cam_model` instead of `cam_K`; only pinhole `cam_K` is supported",
                )
            } else {
                error
            }
        })?;
        let k = k_node.f64_array::<9>()?;
        let (fx_px, fy_px) = (k[0], k[4]);
        if !(fx_px > 0.0 && fy_px > 0.0) {
            return Err(k_node.error(format!(
                "focal lengths fx = {fx_px}, fy = {fy_px} px must be positive"
            )));
        }
        let off_pinhole = [k[1], k[3], k[6], k[7], k[8] - 1.0];
        if off_pinhole.iter().any(|x| x.abs() > PINHOLE_K_TOLERANCE) {
            return Err(k_node.error(format!(
                "not a pinhole K [fx, 0, cx, 0, fy, cy, 0, 0, 1]: found {k:?} (skew is not supported)"
            )));
        }
        let depth_scale_mm = parse_depth_scale(entry)?;
        let t_c_w = match (
            entry.optional_field("cam_R_w2c"),
            entry.optional_field("cam_t_w2c"),
        ) {
            (None, None) => None,
            (Some(r_node), Some(t_node)) => {
                let r = r_node.f64_array::<9>()?;
                let t_mm = t_node.f64_array::<3>()?;
                Some(isometry_from_rotation_and_mm(&r, &t_mm).map_err(|p| r_node.error(p))?)
            }
            (Some(_), None) => return Err(entry.missing("cam_t_w2c")),
            (None, Some(_)) => return Err(entry.missing("cam_R_w2c")),
        };
        Ok(Self {
            fx_px,
            fy_px,
            cx_px: k[2] + GLINT_MINUS_BOP_PX,
            cy_px: k[5] + GLINT_MINUS_BOP_PX,
            depth_scale_mm,
            t_c_w,
        })
    }

    /// The camera for images of `width × height` pixels.
    pub(crate) fn with_size(&self, width_px: u32, height_px: u32) -> Result<BopCamera, String> {
        let intrinsics = PinholeIntrinsics::new(
            width_px, height_px, self.fx_px, self.fy_px, self.cx_px, self.cy_px,
        )
        .map_err(|error| error.to_string())?;
        Ok(BopCamera {
            intrinsics,
            depth_scale_mm: self.depth_scale_mm,
            t_c_w: self.t_c_w,
        })
    }
}

/// The dataset-level `camera.json` (`cx`, `cy`, `fx`, `fy`, `width`, `height`,
/// `depth_scale`): the sensor BOP simulates when rendering. Returned with `t_c_w = None`.
pub fn read_dataset_camera(path: &Path) -> Result<BopCamera, DatasetError> {
    let value = read_json_file(path)?;
    let root = JsonNode::root(path, &value);
    let number = |key: &str| root.field(key)?.f64();
    let size = |key: &str| root.field(key)?.integer::<u32>();
    let (width_px, height_px) = (size("width")?, size("height")?);
    let intrinsics = PinholeIntrinsics::new(
        width_px,
        height_px,
        number("fx")?,
        number("fy")?,
        number("cx")? + GLINT_MINUS_BOP_PX,
        number("cy")? + GLINT_MINUS_BOP_PX,
    )
    .map_err(|error| root.error(format!("unusable intrinsics: {error}")))?;
    Ok(BopCamera {
        intrinsics,
        depth_scale_mm: parse_depth_scale(&root)?,
        t_c_w: None,
    })
}

/// The optional `depth_scale` of an object: mm per depth unit, positive.
fn parse_depth_scale(object: &JsonNode<'_>) -> Result<Option<f64>, DatasetError> {
    let Some(node) = object.optional_field("depth_scale") else {
        return Ok(None);
    };
    let scale = node.f64()?;
    if scale <= 0.0 {
        return Err(node.error(format!("depth_scale {scale} mm must be positive")));
    }
    Ok(Some(scale))
}

/// Writes a dataset-level `camera.json` for `camera` (its `t_c_w` is not part of that file).
pub fn write_dataset_camera(path: &Path, camera: &BopCamera) -> Result<(), DatasetError> {
    let k = &camera.intrinsics;
    let mut record = serde_json::json!({
        "cx": k.cx_px - GLINT_MINUS_BOP_PX,
        "cy": k.cy_px - GLINT_MINUS_BOP_PX,
        "fx": k.fx_px,
        "fy": k.fy_px,
        "height": k.height_px,
        "width": k.width_px,
    });
    if let Some(scale) = camera.depth_scale_mm {
        record["depth_scale"] = scale.into();
    }
    write_pretty_json(path, &record)
}
