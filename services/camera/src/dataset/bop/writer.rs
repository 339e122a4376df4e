//! Writing one BOP scene: images as they come, JSON files at the end.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::{DepthMap, Image};
use nalgebra::Isometry3;

use super::camera::{BopCamera, SceneCameraEntry};
use super::gt::{BopGt, BopGtInfo, GtInfoEntry, SceneGtEntry};
use super::{BopSceneLayout, MaskKind};
use crate::dataset::error::{DatasetError, create_directory};
use crate::dataset::image_files::{depth_to_units, write_png_u8, write_png_u16};
use crate::dataset::json::{write_bop_style_object, write_pretty_json};
use crate::dataset::{PatternImage, StereoSide};

/// Writes one BOP scene directory (`<split>/XXXXXX/`).
///
/// Image files (depth, gray, masks, patterns) are written, each atomically, when their
/// `write_*` method is called. The JSON files (`scene_camera.json`, `scene_gt.json`,
/// `scene_gt_info.json`, `glint/gt_materials.json`) collect what the `set_*` methods give and
/// are written, atomically, by [`BopSceneWriter::finish`]: dropping the writer without it
/// leaves the images without their annotations. Files already in the directory are
/// overwritten when written again.
///
/// Every image of one id must have the same size, and the camera's intrinsics that size.
#[must_use = "the JSON files are only written by `finish`"]
#[derive(Debug)]
pub struct BopSceneWriter {
    layout: BopSceneLayout,
    depth_scale_mm: f64,
    cameras: BTreeMap<u32, SceneCameraEntry>,
    gts: BTreeMap<u32, Vec<SceneGtEntry>>,
    gt_infos: BTreeMap<u32, Vec<GtInfoEntry>>,
    gt_materials: Option<serde_json::Value>,
    /// Size of each image id's files so far, and which file set it.
    image_sizes: BTreeMap<u32, ((u32, u32), PathBuf)>,
    /// Per image, one more than the largest GT index a mask was written for.
    mask_counts: BTreeMap<u32, (usize, PathBuf)>,
}

impl BopSceneWriter {
    /// Depth unit Glint writes by default: 0.1 mm, so 16 bits reach 6.5535 m.
    pub const DEFAULT_DEPTH_SCALE_MM: f64 = 0.1;

    /// A writer for the scene at `scene_dir` (created if missing), writing depth in units of
    /// `depth_scale_mm` millimetres.
    pub fn create(
        scene_dir: impl Into<PathBuf>,
        depth_scale_mm: f64,
    ) -> Result<Self, DatasetError> {
        let layout = BopSceneLayout::new(scene_dir);
        if !(depth_scale_mm.is_finite() && depth_scale_mm > 0.0) {
            return Err(DatasetError::Invalid {
                path: layout.scene_camera_json(),
                problem: format!("depth_scale {depth_scale_mm} mm must be finite and positive"),
            });
        }
        create_directory(layout.scene_dir())?;
        Ok(Self {
            layout,
            depth_scale_mm,
            cameras: BTreeMap::new(),
            gts: BTreeMap::new(),
            gt_infos: BTreeMap::new(),
            gt_materials: None,
            image_sizes: BTreeMap::new(),
            mask_counts: BTreeMap::new(),
        })
    }

    /// Where the scene's files are written.
    pub fn layout(&self) -> &BopSceneLayout {
        &self.layout
    }

    /// Millimetres per unit of the depth files.
    pub fn depth_scale_mm(&self) -> f64 {
        self.depth_scale_mm
    }

    /// Checks that `path`, a file of image `im_id`, has the size of the image's other files.
    fn claim_size(
        &mut self,
        im_id: u32,
        size: (u32, u32),
        path: &Path,
    ) -> Result<(), DatasetError> {
        match self.image_sizes.get(&im_id) {
            Some((known, first)) if *known != size => Err(DatasetError::Invalid {
                path: path.to_owned(),
                problem: format!(
                    "image {im_id} is {}×{} px here but {}×{} px in {}",
                    size.0,
                    size.1,
                    known.0,
                    known.1,
                    first.display()
                ),
            }),
            Some(_) => Ok(()),
            None => {
                self.image_sizes.insert(im_id, (size, path.to_owned()));
                Ok(())
            }
        }
    }

    /// Sets image `im_id`'s camera: `intrinsics` (Glint's pixel convention), the writer's
    /// depth scale, and world → camera `t_c_w` (metres) if given. Written by `finish`.
    pub fn set_camera(
        &mut self,
        im_id: u32,
        intrinsics: &PinholeIntrinsics,
        t_c_w: Option<&Isometry3<f64>>,
    ) -> Result<(), DatasetError> {
        let path = self.layout.scene_camera_json();
        self.claim_size(im_id, (intrinsics.width_px, intrinsics.height_px), &path)?;
        let camera = BopCamera {
            intrinsics: *intrinsics,
            depth_scale_mm: Some(self.depth_scale_mm),
            t_c_w: t_c_w.copied(),
        };
        self.cameras
            .insert(im_id, SceneCameraEntry::from_camera(&camera));
        Ok(())
    }

    /// Writes `depth/XXXXXX.png`: metres → units of the depth scale, NaN (and 0) → 0. A
    /// depth the 16 bits cannot hold is an error naming the pixel, and nothing is written.
    pub fn write_depth(&mut self, im_id: u32, depth: &DepthMap) -> Result<(), DatasetError> {
        let path = self.layout.depth_png(im_id);
        let size = (depth.depth_m.width(), depth.depth_m.height());
        self.claim_size(im_id, size, &path)?;
        let units = depth_to_units(depth, self.depth_scale_mm, &path)?;
        create_directory(&self.layout.depth_dir())?;
        write_png_u16(&path, &units)
    }

    /// Writes `gray/XXXXXX.png`, 8-bit.
    pub fn write_gray(&mut self, im_id: u32, gray: &Image<u8>) -> Result<(), DatasetError> {
        let path = self.layout.gray_png(im_id);
        self.claim_size(im_id, (gray.width(), gray.height()), &path)?;
        create_directory(&self.layout.gray_dir())?;
        write_png_u8(&path, gray)
    }

    /// Writes `glint/pattern_left/XXXXXX.png` or `..._right/...`, at the image's bit depth.
    pub fn write_pattern(
        &mut self,
        im_id: u32,
        side: StereoSide,
        pattern: &PatternImage,
    ) -> Result<(), DatasetError> {
        self.write_pattern_shot(im_id, side, 0, pattern)
    }

    /// Writes shot `shot` of a multi-shot capture's pattern images
    /// ([`BopSceneLayout::pattern_shot_png`]); shot 0 is [`Self::write_pattern`]'s file.
    pub fn write_pattern_shot(
        &mut self,
        im_id: u32,
        side: StereoSide,
        shot: usize,
        pattern: &PatternImage,
    ) -> Result<(), DatasetError> {
        let path = self.layout.pattern_shot_png(im_id, side, shot);
        self.claim_size(im_id, pattern.size(), &path)?;
        create_directory(&self.layout.pattern_dir(side))?;
        match pattern {
            PatternImage::Bits8(image) => write_png_u8(&path, image),
            PatternImage::Bits16(image) => write_png_u16(&path, image),
        }
    }

    /// Writes `mask/XXXXXX_YYYYYY.png` (or `mask_visib/`) for GT instance `gt_index` of
    /// image `im_id`, exactly as given (BOP's masks are 0 and 255).
    pub fn write_mask(
        &mut self,
        im_id: u32,
        gt_index: usize,
        kind: MaskKind,
        mask: &Image<u8>,
    ) -> Result<(), DatasetError> {
        let path = self.layout.mask_png(im_id, gt_index, kind);
        self.claim_size(im_id, (mask.width(), mask.height()), &path)?;
        create_directory(&self.layout.mask_dir(kind))?;
        write_png_u8(&path, mask)?;
        let count = self.mask_counts.entry(im_id).or_insert((0, path.clone()));
        if gt_index + 1 > count.0 {
            *count = (gt_index + 1, path);
        }
        Ok(())
    }

    /// Writes one mask per `(label, gt_index)` pair from a label image: 255 where `labels`
    /// holds `label`, 0 elsewhere. A label rendering shows visible parts, so `kind` is
    /// usually [`MaskKind::Visible`].
    pub fn write_masks_from_labels(
        &mut self,
        im_id: u32,
        kind: MaskKind,
        labels: &Image<u16>,
        gt_index_of_label: &[(u16, usize)],
    ) -> Result<(), DatasetError> {
        for (position, &(_, gt_index)) in gt_index_of_label.iter().enumerate() {
            if gt_index_of_label[..position]
                .iter()
                .any(|&(_, earlier)| earlier == gt_index)
            {
                return Err(DatasetError::Invalid {
                    path: self.layout.mask_png(im_id, gt_index, kind),
                    problem: format!("GT index {gt_index} is given for two labels"),
                });
            }
        }
        for &(label, gt_index) in gt_index_of_label {
            let mask = labels.map(|l| if l == label { 255u8 } else { 0 });
            self.write_mask(im_id, gt_index, kind, &mask)?;
        }
        Ok(())
    }

    /// Sets image `im_id`'s ground truth (GT index = position in `gts`). Written by `finish`.
    pub fn set_gt(&mut self, im_id: u32, gts: &[BopGt]) {
        self.gts
            .insert(im_id, gts.iter().map(SceneGtEntry::from_gt).collect());
    }

    /// Sets image `im_id`'s GT info, one per GT instance, in the same order. Written by
    /// `finish`.
    pub fn set_gt_info(&mut self, im_id: u32, infos: &[BopGtInfo]) {
        self.gt_infos
            .insert(im_id, infos.iter().map(GtInfoEntry::from_info).collect());
    }

    /// Sets the scene's `glint/gt_materials.json` (any JSON the caller likes). Written by
    /// `finish`.
    pub fn set_gt_materials(&mut self, materials: serde_json::Value) {
        self.gt_materials = Some(materials);
    }

    /// Checks that the annotations fit together, then writes the JSON files atomically:
    /// `scene_camera.json` and `scene_gt.json` always, `scene_gt_info.json` if any info was
    /// set, `glint/gt_materials.json` if materials were set. Returns the scene directory.
    pub fn finish(self) -> Result<PathBuf, DatasetError> {
        let layout = &self.layout;
        let gt_path = layout.scene_gt_json();
        for (&im_id, infos) in &self.gt_infos {
            let gt_count = self.gts.get(&im_id).map_or(0, Vec::len);
            if infos.len() != gt_count {
                return Err(DatasetError::Invalid {
                    path: layout.scene_gt_info_json(),
                    problem: format!(
                        "image {im_id} has {} GT infos for {gt_count} GT instances in {}",
                        infos.len(),
                        gt_path.display()
                    ),
                });
            }
        }
        for (&im_id, (mask_count, mask_path)) in &self.mask_counts {
            let gt_count = self.gts.get(&im_id).map_or(0, Vec::len);
            if *mask_count > gt_count {
                return Err(DatasetError::Invalid {
                    path: mask_path.clone(),
                    problem: format!(
                        "a mask for GT index {} of image {im_id}, which has {gt_count} GT \
                         instances in {}",
                        mask_count - 1,
                        gt_path.display()
                    ),
                });
            }
        }
        for &im_id in self.gts.keys().chain(self.image_sizes.keys()) {
            if !self.cameras.contains_key(&im_id) {
                return Err(DatasetError::Invalid {
                    path: layout.scene_camera_json(),
                    problem: format!("image {im_id} has files or GT but no camera (set_camera)"),
                });
            }
        }
        write_bop_style_object(&layout.scene_camera_json(), &self.cameras)?;
        write_bop_style_object(&gt_path, &self.gts)?;
        if !self.gt_infos.is_empty() {
            write_bop_style_object(&layout.scene_gt_info_json(), &self.gt_infos)?;
        }
        if let Some(materials) = &self.gt_materials {
            create_directory(&layout.glint_dir())?;
            write_pretty_json(&layout.gt_materials_json(), materials)?;
        }
        Ok(self.layout.scene_dir().to_owned())
    }
}
