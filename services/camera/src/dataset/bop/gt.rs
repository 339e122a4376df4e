//! Ground truth: `scene_gt.json` (poses) and `scene_gt_info.json` (boxes, pixel counts).

use glint_geometry::image::{DepthMap, Image};
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::dataset::error::DatasetError;
use crate::dataset::json::JsonNode;
use crate::dataset::transforms::{isometry_from_rotation_and_mm, rotation_and_mm_from_isometry};

/// Why GT info could not be computed from an instance's masks.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GtInfoError {
    /// The two masks (and the depth map, when given) must have one size.
    #[error(
        "masks and depth must have the same size: full mask {full_px:?} px, visible mask {visible_px:?} px, depth {depth_px:?} px"
    )]
    SizeMismatch {
        /// Full mask's `(width, height)`, px.
        full_px: (u32, u32),
        /// Visible mask's `(width, height)`, px.
        visible_px: (u32, u32),
        /// Depth map's `(width, height)`, px, when one was given.
        depth_px: Option<(u32, u32)>,
    },
}

/// One annotated object instance in one image.
#[derive(Clone, Debug, PartialEq)]
pub struct BopGt {
    /// The model, `models/obj_XXXXXX.ply`.
    pub obj_id: u32,
    /// Object → camera, metres (BOP's `cam_R_m2c`, `cam_t_m2c`): `p_c = t_c_o · p_o`.
    pub t_c_o: Isometry3<f64>,
}

/// One instance's entry of `scene_gt.json`, exactly as in the file (row-major, mm).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneGtEntry {
    /// The model, `models/obj_XXXXXX.ply`.
    pub obj_id: u32,
    /// Object → camera rotation, row-major.
    #[serde(rename = "cam_R_m2c")]
    pub cam_r_m2c: [f64; 9],
    /// Object → camera translation, mm.
    #[serde(rename = "cam_t_m2c")]
    pub cam_t_m2c: [f64; 3],
}

impl SceneGtEntry {
    /// The file entry of `gt`: metres to millimetres, rotation to row-major.
    pub fn from_gt(gt: &BopGt) -> Self {
        let (cam_r_m2c, cam_t_m2c) = rotation_and_mm_from_isometry(&gt.t_c_o);
        Self {
            obj_id: gt.obj_id,
            cam_r_m2c,
            cam_t_m2c,
        }
    }
}

impl BopGt {
    /// Parses one instance of `scene_gt.json`; errors name the key.
    pub(crate) fn parse(instance: &JsonNode<'_>) -> Result<Self, DatasetError> {
        let obj_id = instance.field("obj_id")?.integer::<u32>()?;
        let r_node = instance.field("cam_R_m2c")?;
        let r = r_node.f64_array::<9>()?;
        let t_mm = instance.field("cam_t_m2c")?.f64_array::<3>()?;
        let t_c_o = isometry_from_rotation_and_mm(&r, &t_mm).map_err(|p| r_node.error(p))?;
        Ok(Self { obj_id, t_c_o })
    }
}

/// A pixel rectangle: top-left corner `(x, y)` (column, row of its first pixel) and size.
/// BOP's `bbox_obj` may reach beyond the image, so the corner may be negative.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelBox {
    /// Column of the first pixel, px.
    pub x: i64,
    /// Row of the first pixel, px.
    pub y: i64,
    /// Width, px (≥ 0).
    pub width: i64,
    /// Height, px (≥ 0).
    pub height: i64,
}

impl PixelBox {
    /// BOP's `[x, y, w, h]`, or `[-1, -1, -1, -1]` for "no box".
    fn to_bop(bbox: Option<PixelBox>) -> [i64; 4] {
        match bbox {
            Some(b) => [b.x, b.y, b.width, b.height],
            None => [-1; 4],
        }
    }

    fn parse(node: &JsonNode<'_>) -> Result<Option<Self>, DatasetError> {
        let items = node.items()?;
        if items.len() != 4 {
            return Err(node.error(format!(
                "expected [x, y, width, height], found an array of {}",
                items.len()
            )));
        }
        let mut v = [0i64; 4];
        for (slot, item) in v.iter_mut().zip(&items) {
            *slot = item.integer()?;
        }
        if v == [-1; 4] {
            return Ok(None);
        }
        if v[2] < 0 || v[3] < 0 {
            return Err(node.error(format!(
                "box {v:?} has a negative size ([-1, -1, -1, -1] is the only \"no box\")"
            )));
        }
        Ok(Some(Self {
            x: v[0],
            y: v[1],
            width: v[2],
            height: v[3],
        }))
    }
}

/// What `scene_gt_info.json` says about one instance.
#[derive(Clone, Debug, PartialEq)]
pub struct BopGtInfo {
    /// Box of the whole silhouette; `None` when the object projects outside the image.
    pub bbox_obj: Option<PixelBox>,
    /// Box of the visible part; `None` when nothing is visible.
    pub bbox_visib: Option<PixelBox>,
    /// Pixels of the whole silhouette (inside the image).
    pub px_count_all: u64,
    /// Pixels of the whole silhouette with a depth measurement.
    pub px_count_valid: u64,
    /// Pixels of the visible part.
    pub px_count_visib: u64,
    /// `px_count_visib / px_count_all`, 0 when the silhouette is empty.
    pub visib_fract: f64,
}

/// One instance's entry of `scene_gt_info.json`, exactly as in the file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GtInfoEntry {
    /// `[x, y, w, h]` px, `[-1, -1, -1, -1]` for none.
    pub bbox_obj: [i64; 4],
    /// `[x, y, w, h]` px of the visible part, `[-1, -1, -1, -1]` for none.
    pub bbox_visib: [i64; 4],
    /// [`BopGtInfo::px_count_all`].
    pub px_count_all: u64,
    /// [`BopGtInfo::px_count_valid`].
    pub px_count_valid: u64,
    /// [`BopGtInfo::px_count_visib`].
    pub px_count_visib: u64,
    /// [`BopGtInfo::visib_fract`], in [0, 1].
    pub visib_fract: f64,
}

impl GtInfoEntry {
    /// The file entry of `info` (`None` boxes become `[-1, -1, -1, -1]`).
    pub fn from_info(info: &BopGtInfo) -> Self {
        Self {
            bbox_obj: PixelBox::to_bop(info.bbox_obj),
            bbox_visib: PixelBox::to_bop(info.bbox_visib),
            px_count_all: info.px_count_all,
            px_count_valid: info.px_count_valid,
            px_count_visib: info.px_count_visib,
            visib_fract: info.visib_fract,
        }
    }
}

impl BopGtInfo {
    /// Parses one instance of `scene_gt_info.json`; errors name the key.
    pub(crate) fn parse(instance: &JsonNode<'_>) -> Result<Self, DatasetError> {
        let count = |key: &str| instance.field(key)?.integer::<u64>();
        let visib_node = instance.field("visib_fract")?;
        let visib_fract = visib_node.f64()?;
        if !(0.0..=1.0).contains(&visib_fract) {
            return Err(visib_node.error(format!("{visib_fract} is not a fraction in [0, 1]")));
        }
        Ok(Self {
            bbox_obj: PixelBox::parse(&instance.field("bbox_obj")?)?,
            bbox_visib: PixelBox::parse(&instance.field("bbox_visib")?)?,
            px_count_all: count("px_count_all")?,
            px_count_valid: count("px_count_valid")?,
            px_count_visib: count("px_count_visib")?,
            visib_fract,
        })
    }

    /// The info BOP's `calc_gt_info` computes, from an instance's two masks (non-zero = in)
    /// and the depth map (valid = finite and positive). Unlike BOP's script, which renders the
    /// silhouette into a larger canvas, `bbox_obj` is clipped to the image.
    pub fn from_masks(
        full: &Image<u8>,
        visible: &Image<u8>,
        depth: Option<&DepthMap>,
    ) -> Result<Self, GtInfoError> {
        let size = (full.width(), full.height());
        let visible_size = (visible.width(), visible.height());
        let depth_size = depth.map(|d| (d.depth_m.width(), d.depth_m.height()));
        if visible_size != size || depth_size.is_some_and(|d| d != size) {
            return Err(GtInfoError::SizeMismatch {
                full_px: size,
                visible_px: visible_size,
                depth_px: depth_size,
            });
        }
        let mut obj = BoxAccumulator::default();
        let mut visib = BoxAccumulator::default();
        let mut px_count_valid = 0;
        for v in 0..size.1 {
            for u in 0..size.0 {
                if full.get(u, v) != Some(0) {
                    obj.add(u, v);
                    if depth.is_some_and(|d| d.get(u, v).is_some()) {
                        px_count_valid += 1;
                    }
                }
                if visible.get(u, v) != Some(0) {
                    visib.add(u, v);
                }
            }
        }
        Ok(Self {
            bbox_obj: obj.bbox(),
            bbox_visib: visib.bbox(),
            px_count_all: obj.count,
            px_count_valid,
            px_count_visib: visib.count,
            visib_fract: if obj.count > 0 {
                visib.count as f64 / obj.count as f64
            } else {
                0.0
            },
        })
    }
}

#[derive(Default)]
struct BoxAccumulator {
    count: u64,
    min: (u32, u32),
    max: (u32, u32),
}

impl BoxAccumulator {
    fn add(&mut self, u: u32, v: u32) {
        if self.count == 0 {
            self.min = (u, v);
            self.max = (u, v);
        } else {
            self.min = (self.min.0.min(u), self.min.1.min(v));
            self.max = (self.max.0.max(u), self.max.1.max(v));
        }
        self.count += 1;
    }

    fn bbox(&self) -> Option<PixelBox> {
        (self.count > 0).then(|| PixelBox {
            x: self.min.0 as i64,
            y: self.min.1 as i64,
            width: (self.max.0 - self.min.0 + 1) as i64,
            height: (self.max.1 - self.min.1 + 1) as i64,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn info_from_masks_counts_and_boxes() {
        // 4×3; the silhouette covers columns 1..=3 of rows 0..=1, the visible part column 3.
        let full = Image::new(4, 3, vec![0, 255, 255, 255, 0, 255, 255, 255, 0, 0, 0, 0]).unwrap();
        let visible = Image::new(4, 3, vec![0, 0, 0, 255, 0, 0, 0, 255, 0, 0, 0, 0]).unwrap();
        let mut z = vec![0.5f32; 12];
        z[1] = f32::NAN;
        let depth = DepthMap::new(Image::new(4, 3, z).unwrap());
        let info = BopGtInfo::from_masks(&full, &visible, Some(&depth)).unwrap();
        assert_eq!(
            info.bbox_obj,
            Some(PixelBox {
                x: 1,
                y: 0,
                width: 3,
                height: 2
            })
        );
        assert_eq!(
            info.bbox_visib,
            Some(PixelBox {
                x: 3,
                y: 0,
                width: 1,
                height: 2
            })
        );
        assert_eq!(
            (info.px_count_all, info.px_count_valid, info.px_count_visib),
            (6, 5, 2)
        );
        assert!((info.visib_fract - 1.0 / 3.0).abs() < 1e-15);

        let empty = Image::filled(4, 3, 0u8).unwrap();
        let info = BopGtInfo::from_masks(&empty, &empty, None).unwrap();
        assert_eq!((info.bbox_obj, info.visib_fract), (None, 0.0));
        assert_eq!(GtInfoEntry::from_info(&info).bbox_visib, [-1; 4]);
        assert!(BopGtInfo::from_masks(&full, &Image::filled(2, 2, 0).unwrap(), None).is_err());
    }
}
