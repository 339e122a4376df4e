//! The BOP scene format (Hodaň et al.; `docs/bop_datasets_format.md` of the BOP toolkit),
//! read and written.
//!
//! A dataset is `models/obj_XXXXXX.ply` (mm) with `models/models_info.json`, an optional
//! `camera.json`, and split directories (`test/`, `val/`, `train_pbr/`, ...) of scenes
//! `<split>/XXXXXX/`:
//!
//! | file | holds |
//! |---|---|
//! | `scene_camera.json` | per image: `cam_K` (row-major, px), `depth_scale` (mm per depth unit), optional `cam_R_w2c`, `cam_t_w2c` (mm) |
//! | `scene_gt.json` | per image, a list of `obj_id`, `cam_R_m2c`, `cam_t_m2c` (mm) |
//! | `scene_gt_info.json` | per image and instance: `bbox_obj`, `bbox_visib` (x, y, w, h px), pixel counts, `visib_fract` |
//! | `depth/XXXXXX.png` | 16-bit depth; `z_mm = value × depth_scale`, 0 = missing |
//! | `gray/` or `rgb/XXXXXX.png` | the image |
//! | `mask/`, `mask_visib/XXXXXX_YYYYYY.png` | 8-bit 0/255 silhouette and its visible part, YYYYYY = index into the image's GT list |
//!
//! Multi-sensor datasets (XYZ-IBD) suffix every one of these with the sensor:
//! `scene_camera_xyz.json`, `gray_xyz/`, `mask_visib_xyz/`, ... ([`BopSceneLayout::for_sensor`]).
//!
//! Glint's captures add `glint/pattern_left/XXXXXX.png`, `glint/pattern_right/XXXXXX.png`
//! (8- or 16-bit structured-light images; a multi-shot capture's later shots beside them as
//! `XXXXXX_01.png`, `XXXXXX_02.png`, ...), `glint/gt_materials.json` (free-form, from the
//! caller), and for calibration `glint/exposure_stack/XXXXXX/`, `glint/rig.json` and
//! `glint/gt_sensor.json`. BOP tools ignore the `glint/` directory.
//!
//! **Pixel convention.** BOP's `cam_K` is OpenCV's: pixel centres at integer coordinates.
//! Glint puts pixel `(u, v)`'s centre at `(u + 0.5, v + 0.5)`, so
//! `cx_glint = cx_bop + 0.5` (and the same for `cy`) on reading, and the reverse on writing.

mod camera;
mod gt;
mod models;
mod reader;
mod writer;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

pub use camera::{BopCamera, SceneCameraEntry, read_dataset_camera, write_dataset_camera};
pub use gt::{BopGt, BopGtInfo, GtInfoEntry, GtInfoError, PixelBox, SceneGtEntry};
pub use models::{
    ContinuousSymmetry, EXACT_DIAMETER_MAX_VERTICES, ModelBox, ModelInfo, ModelSymmetry,
    mesh_diameter_m, model_path, read_model, read_models_info, write_models,
};
pub use reader::BopSceneReader;
pub use writer::BopSceneWriter;

use super::StereoSide;

/// The same pose up to BOP's file rounding (millimetres with ~6 digits, rotations as 9
/// rounded numbers): within 0.1 mm and 0.01 rad. Identifies one instance across the views of
/// a static scene.
pub fn same_pose(a: &nalgebra::Isometry3<f64>, b: &nalgebra::Isometry3<f64>) -> bool {
    (a.translation.vector - b.translation.vector).norm() < 1e-4
        && (a.rotation.inverse() * b.rotation).angle() < 1e-2
}

/// Which of BOP's two masks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MaskKind {
    /// `mask/`: the whole silhouette, occluded parts included.
    Full,
    /// `mask_visib/`: the visible part of the silhouette.
    Visible,
}

/// Where the files of one BOP scene are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BopSceneLayout {
    scene_dir: PathBuf,
    /// `"_xyz"` for sensor `xyz`, `""` for a classic single-sensor scene.
    suffix: String,
}

impl BopSceneLayout {
    /// A classic scene: `scene_camera.json`, `depth/`, ...
    pub fn new(scene_dir: impl Into<PathBuf>) -> Self {
        Self {
            scene_dir: scene_dir.into(),
            suffix: String::new(),
        }
    }

    /// A multi-sensor scene's files for one sensor: `scene_camera_<sensor>.json`,
    /// `depth_<sensor>/`, `gray_<sensor>/`, ... (XYZ-IBD, ITODD-MV).
    pub fn for_sensor(scene_dir: impl Into<PathBuf>, sensor: &str) -> Self {
        Self {
            scene_dir: scene_dir.into(),
            suffix: format!("_{sensor}"),
        }
    }

    /// The scene directory, `<split>/XXXXXX/`.
    pub fn scene_dir(&self) -> &Path {
        &self.scene_dir
    }

    fn json(&self, stem: &str) -> PathBuf {
        self.scene_dir.join(format!("{stem}{}.json", self.suffix))
    }

    fn dir(&self, name: &str) -> PathBuf {
        self.scene_dir.join(format!("{name}{}", self.suffix))
    }

    /// `scene_camera.json`: per-image intrinsics, depth scale and camera pose.
    pub fn scene_camera_json(&self) -> PathBuf {
        self.json("scene_camera")
    }
    /// `scene_gt.json`: per-image ground-truth object poses, evaluation only.
    pub fn scene_gt_json(&self) -> PathBuf {
        self.json("scene_gt")
    }
    /// `scene_gt_info.json`: per-instance boxes and visibility, evaluation only.
    pub fn scene_gt_info_json(&self) -> PathBuf {
        self.json("scene_gt_info")
    }
    /// `depth/`: 16-bit depth PNGs.
    pub fn depth_dir(&self) -> PathBuf {
        self.dir("depth")
    }
    /// `gray/`: grey-level images.
    pub fn gray_dir(&self) -> PathBuf {
        self.dir("gray")
    }
    /// `rgb/`: colour images.
    pub fn rgb_dir(&self) -> PathBuf {
        self.dir("rgb")
    }
    /// `mask/` or `mask_visib/`: ground-truth silhouettes, evaluation only.
    pub fn mask_dir(&self, kind: MaskKind) -> PathBuf {
        match kind {
            MaskKind::Full => self.dir("mask"),
            MaskKind::Visible => self.dir("mask_visib"),
        }
    }

    /// `depth/XXXXXX.png`.
    pub fn depth_png(&self, im_id: u32) -> PathBuf {
        self.depth_dir().join(image_file_name(im_id, "png"))
    }
    /// `gray/XXXXXX.png`.
    pub fn gray_png(&self, im_id: u32) -> PathBuf {
        self.gray_dir().join(image_file_name(im_id, "png"))
    }
    /// `mask/XXXXXX_YYYYYY.png` or `mask_visib/...`, YYYYYY = the GT index.
    pub fn mask_png(&self, im_id: u32, gt_index: usize, kind: MaskKind) -> PathBuf {
        self.mask_dir(kind)
            .join(format!("{im_id:06}_{gt_index:06}.png"))
    }

    /// `glint/`: Glint's own files, which BOP tools ignore.
    pub fn glint_dir(&self) -> PathBuf {
        self.scene_dir.join("glint")
    }
    /// `glint/pattern_left/` or `glint/pattern_right/`.
    pub fn pattern_dir(&self, side: StereoSide) -> PathBuf {
        self.glint_dir().join(format!("pattern_{}", side.name()))
    }
    /// `glint/pattern_left/XXXXXX.png`.
    pub fn pattern_png(&self, im_id: u32, side: StereoSide) -> PathBuf {
        self.pattern_dir(side).join(image_file_name(im_id, "png"))
    }
    /// Shot `shot` of a multi-shot capture: shot 0 is [`Self::pattern_png`], later ones
    /// `glint/pattern_left/XXXXXX_KK.png` (KK = 01, 02, ...).
    pub fn pattern_shot_png(&self, im_id: u32, side: StereoSide, shot: usize) -> PathBuf {
        if shot == 0 {
            self.pattern_png(im_id, side)
        } else {
            self.pattern_dir(side)
                .join(format!("{im_id:06}_{shot:02}.png"))
        }
    }
    /// `glint/gt_materials.json`.
    pub fn gt_materials_json(&self) -> PathBuf {
        self.glint_dir().join("gt_materials.json")
    }
    /// `glint/exposure_stack/XXXXXX/`: image `im_id`'s white-pattern exposure stack
    /// ([`crate::dataset::exposure_stack`]).
    pub fn exposure_stack_dir(&self, im_id: u32) -> PathBuf {
        self.glint_dir()
            .join("exposure_stack")
            .join(format!("{im_id:06}"))
    }
    /// `glint/rig.json`: the SLI rig as calibration-known hardware
    /// ([`crate::dataset::rig_file`]).
    pub fn rig_json(&self) -> PathBuf {
        self.glint_dir().join("rig.json")
    }
    /// `glint/reference_surface.json`: the bin and its known reflectance, the radiometric
    /// reference of the BSDF calibration ([`crate::dataset::reference_file`]).
    pub fn reference_surface_json(&self) -> PathBuf {
        self.glint_dir().join("reference_surface.json")
    }
    /// `glint/gt_sensor.json`: the simulator's sensor, for evaluation only.
    pub fn gt_sensor_json(&self) -> PathBuf {
        self.glint_dir().join("gt_sensor.json")
    }
}

/// `XXXXXX.<extension>`: the image id, zero-padded to six digits.
fn image_file_name(im_id: u32, extension: &str) -> String {
    format!("{im_id:06}.{extension}")
}
