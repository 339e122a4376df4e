//! Renders a calibration scene with the mock camera's renderer and sensor: one part lying in
//! the bin (dropped, seeded), a white-pattern exposure stack of it from one view, and the
//! scene file the BSDF fit reads. Ground truth goes to `gt/` (evaluation only):
//!
//! ```text
//! DIR/calib_scene.json            part, labelled pose, views, resolution, reference material
//! DIR/exposure_stack/stack.json   + dt_NNN.png (the calibration's input layout)
//! DIR/gt/gt_sensor.json           the sensor, with its response
//! DIR/gt/gt_material.json         the part's principled parameters
//! ```
//!
//! Until `glint capture --exposure-stack` lands this is how to get such files:
//! `cargo run --release -p glint-calibration --example render_calibration_scene -- DIR
//!  [PART] [EXPOSURES_MS] [SEED]`, e.g. `… -- /tmp/gear gear 0.25,0.5,1,2,4,8 1`.

use glint_calibration::response::ExposureStack;
use glint_calibration::scene_file::{CalibrationScene, PoseJson, SCENE_FORMAT, params_to_map};
use glint_camera::bin::{BinSpec, bin_scene, drop_parts};
use glint_camera::capture::{CaptureConfig, MockSliCamera};
use glint_camera::{materials, views};
use glint_geometry::parts::Part;
use glint_render::projector::Pattern;
use glint_render::rig::SliRig;
use nalgebra::Point3;

/// Views look at the part from this distance, metres, within this cap half-angle, degrees.
const VIEW_DISTANCE_M: f64 = 0.4;
const VIEW_CAP_DEG: f64 = 40.0;
/// Samples per pixel of the multi-path white render.
const SAMPLES_PER_PIXEL: u32 = 32;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = std::path::PathBuf::from(
        args.first()
            .ok_or("usage: DIR [PART] [EXPOSURES_MS] [SEED]")?,
    );
    let part: Part = args.get(1).map_or("gear", |s| s.as_str()).parse()?;
    let exposures_s: Vec<f64> = args
        .get(2)
        .map_or("0.25,0.5,1,2,4,8", |s| s.as_str())
        .split(',')
        .map(|s| s.trim().parse::<f64>().map(|ms| ms * 1e-3))
        .collect::<Result<_, _>>()?;
    let seed: u64 = args.get(3).map_or(Ok(1), |s| s.parse())?;
    let stack_dir = out.join("exposure_stack");
    let gt_dir = out.join("gt");
    std::fs::create_dir_all(&stack_dir)?;
    std::fs::create_dir_all(&gt_dir)?;

    let (w, h) = (1280, 1024);
    let rig = SliRig::ensenso_n35().resized(w, h)?;
    let bin = BinSpec::default();
    let mesh = part.mesh();
    let t_w_o = drop_parts(&mesh, 1, &bin, seed)?[0];
    let truth = materials::ground_truth(part);
    let scene = bin_scene(&mesh, &[t_w_o], truth, &bin)?;
    let camera = MockSliCamera {
        rig,
        scene: &scene,
        config: CaptureConfig {
            // A real camera integrates every light path: render the white images well
            // converged, so Monte Carlo noise of the simulator does not pose as the target.
            samples_per_pixel: SAMPLES_PER_PIXEL,
            ..CaptureConfig::for_rig(&rig)?
        },
    };
    let centre = Point3::from(t_w_o.translation.vector);
    let views = views::spherical_cap(
        2,
        VIEW_DISTANCE_M,
        VIEW_CAP_DEG,
        centre,
        rig.stereo.baseline_m,
    );
    let [left, _] = camera.render_pair(&views[0], Pattern::White, seed);
    let sensor = &camera.config.sensor;
    let stack = ExposureStack::read_out(
        sensor,
        &left.radiance,
        &exposures_s,
        seed.wrapping_mul(1000),
    )?;
    stack.save(&stack_dir, "white", "left")?;

    CalibrationScene {
        format: SCENE_FORMAT.to_owned(),
        part: part.name().to_owned(),
        t_w_o: PoseJson::from_isometry(&t_w_o),
        t_w_c: PoseJson::from_isometry(&views[0]),
        held_out_t_w_c: PoseJson::from_isometry(&views[1]),
        resolution: [w, h],
        reference_material: params_to_map(&materials::bin()),
    }
    .save(&out.join("calib_scene.json"))?;
    let write = |name: &str, bytes: Vec<u8>| {
        glint_geometry::io::write_file_atomically(&gt_dir.join(name), &bytes)
    };
    write("gt_sensor.json", serde_json::to_vec_pretty(sensor)?)?;
    write(
        "gt_material.json",
        serde_json::to_vec_pretty(&params_to_map(&truth))?,
    )?;
    println!(
        "wrote {} exposures of one {} ({}×{} px) to {}",
        stack.images().len(),
        part,
        w,
        h,
        out.display()
    );
    Ok(())
}
