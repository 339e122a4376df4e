//! Renders a white-pattern exposure stack of a bin of parts with the mock camera's renderer and
//! sensor, and writes it in the calibration's input layout (`stack.json` + PNGs) with the
//! sensor's ground truth beside it (`gt_sensor.json`, for evaluation only).
//!
//! Until `glint capture --exposure-stack` lands this is how to get stack files on disk:
//! `cargo run --release -p glint-calibration --example render_exposure_stack -- DIR [PART]
//!  [EXPOSURES_MS] [SEED]`, e.g. `… -- /tmp/stack gear 0.25,0.5,1,2,4,8 1`.

use glint_calibration::response::ExposureStack;
use glint_camera::bin::{BinSpec, bin_scene, drop_parts};
use glint_camera::capture::{CaptureConfig, MockSliCamera};
use glint_camera::{materials, views};
use glint_geometry::parts::Part;
use glint_render::projector::Pattern;
use glint_render::rig::SliRig;
use glint_render::sensor::Sensor;

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
    std::fs::create_dir_all(&out)?;

    let rig = SliRig::ensenso_n35().resized(640, 512)?;
    let bin = BinSpec::default();
    let mesh = part.mesh();
    let poses = drop_parts(&mesh, 6, &bin, seed)?;
    let scene = bin_scene(&mesh, &poses, materials::ground_truth(part), &bin)?;
    let camera = MockSliCamera {
        rig,
        scene: &scene,
        config: CaptureConfig {
            samples_per_pixel: 4,
            ..CaptureConfig::for_rig(&rig)?
        },
    };
    let t_w_c = views::spherical_cap(1, 0.5, 35.0, bin.centre(), rig.stereo.baseline_m)[0];
    let [left, _] = camera.render_pair(&t_w_c, Pattern::White, seed);
    let sensor = &camera.config.sensor;
    let images = exposures_s
        .iter()
        .enumerate()
        .map(|(j, &dt)| {
            Sensor {
                exposure_s: dt as f32,
                ..sensor.clone()
            }
            .read_out(&left.radiance, seed.wrapping_mul(1000) + j as u64)
        })
        .collect();
    let stack = ExposureStack::new(images, exposures_s, sensor.bit_depth)?;
    stack.save(&out, "white", "left")?;
    glint_geometry::io::write_file_atomically(
        &out.join("gt_sensor.json"),
        &serde_json::to_vec_pretty(sensor)?,
    )?;
    println!(
        "wrote {} exposures of {} to {}",
        stack.images().len(),
        part,
        out.display()
    );
    Ok(())
}
