//! `glint eval prediction`: is the prediction right? Every candidate's predicted missing
//! pixels, σ̌_z and Fisher information against the mock camera's capture from that view; the
//! study itself is [`glint_eval::prediction`].

use std::path::PathBuf;

use glint_eval::prediction::{PredictionExperiment, run, write_outputs};

#[derive(clap::Args)]
pub struct PredictionArgs {
    /// Parts: `all` or a comma-separated list of eye-bolt, tube-fitting, chrome-screw, gear,
    /// zigzag.
    #[arg(long, default_value = "all")]
    pub parts: String,
    /// Bins per part (seeds SEED·10⁴ + 9000 + s).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub scenes: u32,
    /// Candidate views per bin; each is predicted and captured.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(2..=256))]
    pub candidates: u32,
    /// Parts per bin.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    /// Instances judged per bin (each ranks the candidates): the most visible from the first
    /// candidate, among those at least --min-visib-fract visible there.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub judged_instances: u32,
    #[arg(long, default_value_t = 0.5, value_parser = crate::calibrate_cmd::parse_unit_interval::<f64>)]
    pub min_visib_fract: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub camera: super::MockCameraArgs,
    /// Evaluation-only control: predict with the simulator's true materials instead of the
    /// fitted ones; the gap to a run without it is what calibration error costs.
    #[arg(long)]
    pub true_materials: bool,
    /// Captured depth within this of the true surface counts as usable, mm.
    #[arg(long, default_value_t = 1.0)]
    pub good_depth_mm: f64,
    #[command(flatten)]
    pub calibration: crate::calibration_args::PartCalibrationArgs,
    /// The render workers render the bin with the part (beyond the paper).
    #[arg(long)]
    pub predict_bin: bool,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run_cmd(args: &PredictionArgs) -> anyhow::Result<()> {
    if !(args.good_depth_mm.is_finite() && args.good_depth_mm > 0.0) {
        anyhow::bail!("--good-depth-mm {}: a positive number", args.good_depth_mm);
    }
    let parts = super::parse_parts(&args.parts)?;
    let objects = glint_eval::scenes::eval_objects(
        &parts,
        None,
        glint_geometry::LengthUnit::Millimetre,
        &glint_geometry::Symmetry::none(),
        false,
    )?;
    let with_calibration = super::calibrated_objects(objects, &parts, &args.calibration, false)?;
    let spec = PredictionExperiment {
        objects: with_calibration,
        scenes: args.scenes,
        candidates: args.candidates as usize,
        instances: args.instances,
        judged_instances: args.judged_instances as usize,
        min_visib_fract: args.min_visib_fract,
        seed: args.seed,
        camera: args.camera.spec(),
        true_materials: args.true_materials,
        predict_with_bin: args.predict_bin,
        good_depth_m: args.good_depth_mm * 1e-3,
        out: args.out.clone(),
    };
    println!(
        "Predicted against captured: {} part(s) × {} bins × {} candidates, {}, {} materials; \
         both judged at the true pose.",
        spec.objects.len(),
        spec.scenes,
        spec.candidates,
        spec.camera,
        spec.materials_label()
    );
    let started = std::time::Instant::now();
    let bar = glint_eval::progress::bar(u64::from(spec.scenes) * spec.objects.len() as u64, "bins");
    let (rows, fig8) = run(&spec, |part, scene| {
        bar.suspend(|| {
            println!(
                "  {part} bin {scene} ({:.0} s so far)",
                started.elapsed().as_secs_f64()
            )
        });
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    let table = write_outputs(&spec, &rows, &fig8)?;
    println!("{table}");
    println!(
        "{:.0} s in all. Report: {}",
        started.elapsed().as_secs_f64(),
        spec.out.join("index.html").display()
    );
    Ok(())
}
