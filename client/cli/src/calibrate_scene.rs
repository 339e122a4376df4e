//! The calibration scene of `glint calibrate bsdf` and `eval-bsdf`: a capture written by
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

use anyhow::{Context, bail};
use glint_camera::dataset::bop::{BopSceneReader, read_model};
use glint_camera::dataset::reference_file::read_reference_surface_json;
use glint_camera::dataset::rig_file::read_rig_json;
use glint_render::bsdf::PrincipledParams;
use glint_render::rig::SliRig;
use glint_render::scene::Scene;
use nalgebra::Isometry3;

/// One view of the capture.
#[derive(Clone, Debug)]
pub struct CaptureView {
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
    pub obj_id: u32,
    /// Part instances are scene indices `0 .. part_instances.len()`; the bin comes last.
    pub scene: Scene,
    pub part_instances: Vec<u32>,
    pub bin_instance: u32,
    /// The bin's known material (the radiometric reference).
    pub reference: PrincipledParams<f32>,
    pub rig: SliRig,
    pub views: Vec<CaptureView>,
}

impl CalibrationScene {
    /// The view with image id `im_id`.
    pub fn view(&self, im_id: u32) -> anyhow::Result<&CaptureView> {
        self.views
            .iter()
            .find(|v| v.im_id == im_id)
            .with_context(|| {
                format!(
                    "{}: no view {im_id}; the capture has views {:?}",
                    self.scene_dir.display(),
                    self.views.iter().map(|v| v.im_id).collect::<Vec<_>>()
                )
            })
    }
}

/// The BOP scene folder `dir` names: `dir` itself if it has `scene_gt.json`, else
/// `dir/test/000001` (where `glint capture` writes its one scene).
pub fn scene_dir_of(dir: &Path) -> anyhow::Result<PathBuf> {
    let nested = dir.join("test").join("000001");
    for candidate in [dir.to_path_buf(), nested.clone()] {
        if candidate.join("scene_gt.json").is_file() {
            return Ok(candidate);
        }
    }
    bail!(
        "{}: not a capture: neither {} nor {} exists (write one with `glint capture --exposure-stack`)",
        dir.display(),
        dir.join("scene_gt.json").display(),
        nested.join("scene_gt.json").display()
    )
}

/// Reads the capture at `dir` (see the module doc).
pub fn load(dir: &Path) -> anyhow::Result<CalibrationScene> {
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
            bail!(
                "{}: image {im_id} has no camera pose (cam_R_w2c, cam_t_w2c)",
                layout.scene_camera_json().display()
            );
        };
        let c = camera.intrinsics;
        if (c.fx_px - k.fx_px).abs() > 1e-6 * k.fx_px || (c.cx_px - k.cx_px).abs() > 1e-3 {
            bail!(
                "{}: image {im_id}'s cam_K (fx {}, cx {}) disagrees with {} (fx {}, cx {})",
                layout.scene_camera_json().display(),
                c.fx_px,
                c.cx_px,
                layout.rig_json().display(),
                k.fx_px,
                k.cx_px
            );
        }
        let t_w_c = t_c_w.inverse();
        for gt in reader.gt(im_id).unwrap_or(&[]) {
            if !obj_ids.contains(&gt.obj_id) {
                obj_ids.push(gt.obj_id);
            }
            let t_w_o = t_w_c * gt.t_c_o;
            if !t_w_os.iter().any(|p| crate::eval::same_pose(p, &t_w_o)) {
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
        [] => bail!(
            "{}: no labelled part in any view",
            layout.scene_gt_json().display()
        ),
        many => bail!(
            "{}: objects {many:?}; a calibration scene holds copies of one part",
            layout.scene_gt_json().display()
        ),
    };
    let models_dir = reader
        .models_dir()
        .with_context(|| format!("{}: no models folder above it", scene_dir.display()))?;
    let mesh = read_model(&models_dir, obj_id)?.mesh;
    let parts = t_w_os.len() as u32;
    // The part's material is a placeholder: the fit and the evaluation shade it with their own.
    let scene = glint_camera::bin::bin_scene_with_bin_material(
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
