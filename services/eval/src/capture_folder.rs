//! A mock capture folder as `glint capture` writes it: a BOP dataset of one bin (models in mm,
//! scene `test/000001/`) with the files Glint's calibration reads beside it, and the
//! white-pattern exposure stacks a calibration is run on (`glint capture --exposure-stack`, the
//! demo's first calibration).
//!
//! Ground truth written here (`glint/gt_*.json`, `gt_left_radiance.exr`, the BOP poses and
//! masks) is for evaluating a calibration, and for the BSDF fit's known calibration pose; no
//! estimator or predictor reads it.

use std::path::Path;

use anyhow::Context;
use glint_calibration::material_file::GroundTruthMaterials;
use glint_camera::dataset::bop::{BopCamera, BopSceneWriter, write_dataset_camera, write_models};
use glint_camera::dataset::reference_file::{ReferenceSurface, write_reference_surface_json};
use glint_camera::dataset::rig_file::{write_gt_sensor_json, write_rig_json};
use glint_camera::dataset::write_exposure_stack;
use glint_camera::materials;
use glint_camera::record::write_bop_annotations;
use glint_camera::setup::{BinSetup, capture_seed};
use glint_geometry::io::write_file_atomically;
use glint_geometry::parts::Part;
use nalgebra::Isometry3;

/// The BOP object id a mock capture gives its part.
pub const PART_OBJ_ID: u32 = 1;

/// Fraction of full scale below which an exposure-stack pixel counts as under-exposed.
pub const UNDER_EXPOSED_FRACTION: f64 = 0.02;

/// Starts a capture folder at `out` for `setup`, a bin of `part`: `models/` (mm), the BOP
/// scene `test/000001/` with the ground-truth materials, `glint/rig.json` (the rig as known
/// hardware), `glint/reference_surface.json` (the bin and its known reflectance, the BSDF fit's
/// radiometric reference), `glint/gt_sensor.json` (evaluation only) and `camera.json`. The
/// returned writer takes the views; `finish` it.
pub fn start_capture_folder(
    out: &Path,
    part: Part,
    setup: &BinSetup,
) -> anyhow::Result<BopSceneWriter> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write_models(
        &out.join("models"),
        &[(PART_OBJ_ID, &part.mesh(), &part.symmetry())],
    )?;
    let mut bop = BopSceneWriter::create(
        out.join("test").join("000001"),
        BopSceneWriter::DEFAULT_DEPTH_SCALE_MM,
    )?;
    bop.set_gt_materials(serde_json::to_value(GroundTruthMaterials::new(
        part.name(),
        materials::ground_truth(part),
        materials::bin(),
    ))?);
    let layout = bop.layout().clone();
    std::fs::create_dir_all(layout.glint_dir())
        .with_context(|| format!("creating {}", layout.glint_dir().display()))?;
    write_rig_json(&layout.rig_json(), &setup.rig)?;
    write_reference_surface_json(
        &layout.reference_surface_json(),
        &ReferenceSurface {
            bin: setup.bin,
            material: materials::bin(),
        },
    )?;
    write_gt_sensor_json(&layout.gt_sensor_json(), &setup.config.sensor)?;
    write_dataset_camera(
        &out.join("camera.json"),
        &BopCamera {
            intrinsics: setup.rig.stereo.intrinsics,
            depth_scale_mm: Some(bop.depth_scale_mm()),
            t_c_w: None,
        },
    )?;
    Ok(bop)
}

/// What [`record_exposure_stacks`] recorded.
pub struct ExposureStacksRecorded {
    /// `report.md`: per view and exposure, the part pixels' under-exposed and saturated shares.
    pub report: String,
}

/// A calibration capture: per view of `views` (left camera → world), a white-pattern exposure
/// stack of the left camera (`exposures_s`, seconds) in `glint/exposure_stack/XXXXXX/` with the
/// left radiance beside it (evaluation only) and the view's BOP camera, poses and masks; the
/// capture folder `out` is started here and finished, `report.md` last. `scene_seed` seeds the
/// captures' noise as every capture of the bin does ([`capture_seed`]); `on_view` runs after
/// each view.
pub fn record_exposure_stacks(
    out: &Path,
    part: Part,
    setup: &BinSetup,
    scene_seed: u64,
    views: &[Isometry3<f64>],
    exposures_s: &[f64],
    mut on_view: impl FnMut(),
) -> anyhow::Result<ExposureStacksRecorded> {
    let mut bop = start_capture_folder(out, part, setup)?;
    let camera = setup.camera();
    let max_dn = camera.config.sensor.max_dn();
    let under_dn = (UNDER_EXPOSED_FRACTION * max_dn as f64).ceil() as u16;
    let ms: Vec<String> = exposures_s.iter().map(|t| format!("{}", t * 1e3)).collect();
    let k = &setup.rig.stereo.intrinsics;
    let mut report = format!(
        "# glint capture --exposure-stack: {} × {}, {} views, seed {scene_seed}, {}×{} px, {} spp multi-path, white pattern\n\n\
         Exposure times (ms): {}. Per view and exposure, over the pixels where a part is visible: the share \
         under-exposed (below {:.0} % of full scale, DN < {under_dn}) and saturated (DN = {max_dn}).\n\n\
         | view | exposure (ms) | part pixels | under-exposed | saturated |\n|---:|---:|---:|---:|---:|\n",
        part.display_name(),
        setup.poses.len(),
        views.len(),
        k.width_px,
        k.height_px,
        setup.config.samples_per_pixel,
        ms.join(", "),
        UNDER_EXPOSED_FRACTION * 100.0,
    );
    for (index, t_w_c) in views.iter().enumerate() {
        let (stack, truth) =
            camera.capture_exposure_stack(t_w_c, exposures_s, capture_seed(scene_seed, index))?;
        let dir = bop.layout().exposure_stack_dir(index as u32);
        write_exposure_stack(&dir, &stack)?;
        glint_render::exr_io::write_exr(
            &dir.join("gt_left_radiance.exr"),
            &[("gt_left_radiance", &truth.left_radiance)],
        )?;
        let seen = write_bop_annotations(
            &mut bop,
            index as u32,
            t_w_c,
            &camera,
            &setup.poses,
            PART_OBJ_ID,
            None,
        )?;
        let on_part: Vec<usize> = (0..truth.left_radiance.data().len())
            .filter(|&i| seen.iter().any(|v| v.mask_visib.data()[i] != 0))
            .collect();
        let share = |count: usize| count as f64 / on_part.len().max(1) as f64;
        for (image, dt) in stack.left.iter().zip(&stack.exposures_s) {
            let dn = |i: &usize| image.data()[*i];
            let under = on_part.iter().filter(|i| dn(i) < under_dn).count();
            let saturated = on_part.iter().filter(|i| dn(i) >= max_dn).count();
            report += &format!(
                "| {index} | {} | {} | {:.3} | {:.3} |\n",
                dt * 1e3,
                on_part.len(),
                share(under),
                share(saturated)
            );
        }
        on_view();
    }
    report += "\nFiles: `test/000001/glint/exposure_stack/XXXXXX/stack.json` with `dt_NNN.png` (the sensor's digital numbers), \
               `gt_left_radiance.exr` beside it and `glint/gt_sensor.json` (ground truth, evaluation only), `glint/rig.json` (the rig as known hardware), \
               `glint/reference_surface.json` (the bin and its known reflectance, the BSDF fit's radiometric reference), \
               and the BOP files of each view (scene_camera, scene_gt, scene_gt_info, mask, mask_visib).\n";
    bop.finish()?;
    let path = out.join("report.md");
    write_file_atomically(&path, report.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(ExposureStacksRecorded { report })
}
