//! The calibration scene of the BSDF fit (`glint calibrate bsdf`, `eval-bsdf`, the calibration
//! server): a capture written by
//! `glint capture --exposure-stack … --out DIR`, read as a real set-up would know it:
//!
//! - the BOP scene folder `DIR/test/000001` (`--scene` may name it or `DIR` itself, which must
//!   then hold exactly that scene): per view (`im_id`) the camera pose (`scene_camera.json`,
//!   `cam_R_w2c`/`cam_t_w2c`) and the labelled poses of the parts (`scene_gt.json`; the paper
//!   labels the object pose by hand, "object pose known");
//! - the part's model `DIR/models/obj_XXXXXX.ply` (millimetres), one object id;
//! - `glint/rig.json` (the rig as known hardware) and `glint/reference_surface.json` (the bin
//!   and its known reflectance, the radiometric reference);
//! - `glint/exposure_stack/XXXXXX/` per view.
//!
//! Never read here: `glint/gt_materials.json`, `glint/gt_sensor.json`, `gt_left_radiance.exr`.
//!
//! Every copy of the part has the same material, so all labelled instances (the union over
//! views, identified by their world pose) are fitted together. Parts labelled in no view are
//! missing from the scene; they are out of sight or hidden, and their inter-reflections are
//! lost (a small bias, the only one of this reading).

use std::path::{Path, PathBuf};

use glint_render::bsdf::PrincipledParams;
use glint_render::rig::SliRig;
use glint_render::scene::Scene;
use glint_render::scene::SceneError;
use nalgebra::Isometry3;

use crate::dataset::DatasetError;
use crate::dataset::bop::{BopSceneReader, read_model, same_pose};
use crate::dataset::reference_file::read_reference_surface_json;
use crate::dataset::rig_file::read_rig_json;

/// Why a calibration scene could not be read; each names the file to fix.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationSceneError {
    /// A file of the capture could not be read or parsed; the error names it.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// Neither `dir` nor `dir/test/000001` holds `scene_gt.json`; write a capture with
    /// `glint capture --exposure-stack`.
    #[error(
        "{}: not a capture: neither {} nor {} exists (write one with `glint capture --exposure-stack`)",
        dir.display(),
        dir.join("scene_gt.json").display(),
        dir.join("test").join("000001").join("scene_gt.json").display()
    )]
    NotACapture {
        /// The directory given.
        dir: PathBuf,
    },
    /// A view of `scene_camera.json` lacks `cam_R_w2c`/`cam_t_w2c`; the fit needs every
    /// view's camera pose (`glint capture` writes it).
    #[error("{}: image {im_id} has no camera pose (cam_R_w2c, cam_t_w2c)", path.display())]
    NoCameraPose {
        /// `scene_camera.json`.
        path: PathBuf,
        /// The view without a pose.
        im_id: u32,
    },
    /// A view's `cam_K` disagrees with the rig's left intrinsics (fx relatively by more than
    /// 1e-6, cx by more than 1e-3 px): the scene and `glint/rig.json` are from different
    /// cameras.
    #[error(
        "{}: image {im_id}'s cam_K (fx {fx_px}, cx {cx_px}) disagrees with {} (fx {rig_fx_px}, cx {rig_cx_px})",
        path.display(),
        rig_path.display()
    )]
    IntrinsicsMismatch {
        /// `scene_camera.json`.
        path: PathBuf,
        /// `glint/rig.json`.
        rig_path: PathBuf,
        /// The disagreeing view.
        im_id: u32,
        /// The view's focal length, px.
        fx_px: f64,
        /// The view's principal point x, px (Glint's pixel convention).
        cx_px: f64,
        /// The rig's left-camera focal length, px.
        rig_fx_px: f64,
        /// The rig's left-camera principal point x, px (Glint's pixel convention).
        rig_cx_px: f64,
    },
    /// `scene_gt.json` labels no part in any view: there is nothing to fit.
    #[error("{}: no labelled part in any view", path.display())]
    NoPart {
        /// `scene_gt.json`.
        path: PathBuf,
    },
    /// `scene_gt.json` labels more than one object id; a calibration scene holds copies of one
    /// part.
    #[error("{}: objects {obj_ids:?}; a calibration scene holds copies of one part", path.display())]
    SeveralParts {
        /// `scene_gt.json`.
        path: PathBuf,
        /// The object ids found, in order of first appearance.
        obj_ids: Vec<u32>,
    },
    /// The scene folder has no dataset root two levels up to hold `models/`; pass the capture
    /// directory, not a copied-out scene folder.
    #[error("{}: no models folder above it", scene_dir.display())]
    NoModels {
        /// The BOP scene folder.
        scene_dir: PathBuf,
    },
    /// [`CalibrationScene::view`] was asked for an image id the capture does not have.
    #[error("{}: no view {im_id}; the capture has views {available:?}", scene_dir.display())]
    NoView {
        /// The BOP scene folder.
        scene_dir: PathBuf,
        /// The image id asked for.
        im_id: u32,
        /// The capture's image ids.
        available: Vec<u32>,
    },
    /// The parts and the bin did not form a renderable scene.
    #[error("building the scene: {0}")]
    Scene(#[from] SceneError),
}

/// One view of the capture.
#[derive(Clone, Debug)]
pub struct CaptureView {
    /// BOP image id of the view.
    pub im_id: u32,
    /// Left camera → world.
    pub t_w_c: Isometry3<f64>,
    /// The view's white-pattern exposure stack.
    pub stack_dir: PathBuf,
}

/// A capture as the BSDF fit sees it.
pub struct CalibrationScene {
    /// The BOP scene folder read.
    pub scene_dir: PathBuf,
    /// The part's BOP object id, `models/obj_XXXXXX.ply`.
    pub obj_id: u32,
    /// Part instances are scene indices `0 .. part_instances.len()`; the bin comes last.
    pub scene: Scene,
    /// Scene instance indices of the parts (the union over views of the labelled poses).
    pub part_instances: Vec<u32>,
    /// Scene instance index of the bin.
    pub bin_instance: u32,
    /// The bin's known material (the radiometric reference).
    pub reference: PrincipledParams<f32>,
    /// The rig as calibration-known hardware (`glint/rig.json`).
    pub rig: SliRig,
    /// The views, in ascending image id.
    pub views: Vec<CaptureView>,
}

impl CalibrationScene {
    /// The view with image id `im_id`.
    pub fn view(&self, im_id: u32) -> Result<&CaptureView, CalibrationSceneError> {
        self.views
            .iter()
            .find(|v| v.im_id == im_id)
            .ok_or_else(|| CalibrationSceneError::NoView {
                scene_dir: self.scene_dir.clone(),
                im_id,
                available: self.views.iter().map(|v| v.im_id).collect(),
            })
    }
}

/// The BOP scene folder `dir` names: `dir` itself if it has `scene_gt.json`, else
/// `dir/test/000001` (where `glint capture` writes its one scene).
pub fn scene_dir_of(dir: &Path) -> Result<PathBuf, CalibrationSceneError> {
    let nested = dir.join("test").join("000001");
    [dir.to_path_buf(), nested]
        .into_iter()
        .find(|candidate| candidate.join("scene_gt.json").is_file())
        .ok_or_else(|| CalibrationSceneError::NotACapture {
            dir: dir.to_path_buf(),
        })
}

/// Reads the capture at `dir` (see the module doc).
pub fn load(dir: &Path) -> Result<CalibrationScene, CalibrationSceneError> {
    let scene_dir = scene_dir_of(dir)?;
    let reader = BopSceneReader::open(&scene_dir)?;
    let layout = reader.layout().clone();
    let rig = read_rig_json(&layout.rig_json())?;
    let reference = read_reference_surface_json(&layout.reference_surface_json())?;
    let k = rig.stereo.intrinsics;
    let reader = reader.with_image_size(k.width_px, k.height_px);
    let mut views = Vec::new();
    let mut t_w_os: Vec<Isometry3<f64>> = Vec::new();
    let mut obj_ids = Vec::new();
    for im_id in reader.image_ids() {
        let camera = reader.camera(im_id)?;
        let Some(t_c_w) = camera.t_c_w else {
            return Err(CalibrationSceneError::NoCameraPose {
                path: layout.scene_camera_json(),
                im_id,
            });
        };
        let c = camera.intrinsics;
        if (c.fx_px - k.fx_px).abs() > 1e-6 * k.fx_px || (c.cx_px - k.cx_px).abs() > 1e-3 {
            return Err(CalibrationSceneError::IntrinsicsMismatch {
                path: layout.scene_camera_json(),
                rig_path: layout.rig_json(),
                im_id,
                fx_px: c.fx_px,
                cx_px: c.cx_px,
                rig_fx_px: k.fx_px,
                rig_cx_px: k.cx_px,
            });
        }
        let t_w_c = t_c_w.inverse();
        for gt in reader.gt(im_id).unwrap_or(&[]) {
            if !obj_ids.contains(&gt.obj_id) {
                obj_ids.push(gt.obj_id);
            }
            let t_w_o = t_w_c * gt.t_c_o;
            if !t_w_os.iter().any(|p| same_pose(p, &t_w_o)) {
                t_w_os.push(t_w_o);
            }
        }
        views.push(CaptureView {
            im_id,
            t_w_c,
            stack_dir: layout.exposure_stack_dir(im_id),
        });
    }
    let obj_id = match obj_ids.as_slice() {
        [one] => *one,
        [] => {
            return Err(CalibrationSceneError::NoPart {
                path: layout.scene_gt_json(),
            });
        }
        many => {
            return Err(CalibrationSceneError::SeveralParts {
                path: layout.scene_gt_json(),
                obj_ids: many.to_vec(),
            });
        }
    };
    let Some(models_dir) = reader.models_dir() else {
        return Err(CalibrationSceneError::NoModels { scene_dir });
    };
    let mesh = read_model(&models_dir, obj_id)?.mesh;
    let parts = t_w_os.len() as u32;
    // The part's material is a placeholder: the fit and the evaluation shade it with their own.
    let scene = crate::bin::bin_scene_with_bin_material(
        &mesh,
        &t_w_os,
        reference.material,
        &reference.bin,
        reference.material,
    )?;
    Ok(CalibrationScene {
        scene_dir,
        obj_id,
        scene,
        part_instances: (0..parts).collect(),
        bin_instance: parts,
        reference: reference.material,
        rig,
        views,
    })
}
