//! `glint eval thresholds`: how well the render workers predict the pixels a view loses
//! (eq 16–17), over a grid of τ_I and τ_σ (`glint_eval::thresholds`). Run it on tuning seeds
//! to choose the thresholds, then with the chosen pair on evaluation seeds.

use std::path::PathBuf;

use anyhow::Context;
use glint_eval::thresholds::{ThresholdStudy, grid_markdown, run};
use glint_geometry::Part;
use glint_geometry::io::write_file_atomically;

#[derive(clap::Args)]
pub struct ThresholdsArgs {
    #[arg(long, default_value = "zigzag", value_parser = crate::mesh_cmd::parse_part)]
    pub part: Part,
    /// Bins, comma separated: tuning seeds to choose τ (default), evaluation seeds to judge.
    #[arg(long, default_value = "11,12,13", value_delimiter = ',')]
    pub seeds: Vec<u64>,
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub views: u32,
    #[command(flatten)]
    pub bin: super::BinArgs,
    /// τ_I values (eq 16), comma separated.
    #[arg(long, default_value = "0,0.2,0.35,0.5,0.65,0.8", value_delimiter = ',',
          value_parser = crate::calibrate_cmd::parse_unit_interval::<f64>)]
    pub tau_i: Vec<f64>,
    /// τ_σ values (eq 17), mm, comma separated.
    #[arg(long, default_value = "0.25,0.5,1,2,4,1000", value_delimiter = ',')]
    pub tau_sigma_mm: Vec<f64>,
    /// Capture depth within this of the true surface counts as usable, mm.
    #[arg(long, default_value_t = 1.0)]
    pub good_depth_mm: f64,
    #[command(flatten)]
    pub calibration: crate::calibration_args::CalibrationArgs,
    /// Render the bin with the part.
    #[arg(long)]
    pub predict_bin: bool,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run_cmd(args: &ThresholdsArgs) -> anyhow::Result<()> {
    let finite = |v: &f64| v.is_finite() && *v >= 0.0;
    anyhow::ensure!(
        args.tau_sigma_mm.iter().all(|t| finite(t) && *t > 0.0),
        "--tau-sigma-mm: positive values"
    );
    anyhow::ensure!(
        finite(&args.good_depth_mm) && args.good_depth_mm > 0.0,
        "--good-depth-mm: a positive number"
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let calibration = args.calibration.load(args.part)?;
    let study = ThresholdStudy {
        part: args.part,
        seeds: args.seeds.clone(),
        views: args.views as usize,
        instances: args.bin.instances,
        width_px: args.bin.resolution.0,
        height_px: args.bin.resolution.1,
        samples_per_pixel: args.bin.spp,
        min_visible_px: 100,
        good_depth_m: args.good_depth_mm * 1e-3,
        tau_intensity_ratios: args.tau_i.clone(),
        tau_sigmas_m: args.tau_sigma_mm.iter().map(|t| t * 1e-3).collect(),
        with_bin: args.predict_bin,
    };
    let started = std::time::Instant::now();
    let bar = glint_eval::progress::bar((study.seeds.len() * study.views) as u64, "views");
    let grid = run(&study, &calibration, || bar.inc(1))?;
    bar.finish_and_clear();
    let table = grid_markdown(&grid);
    println!(
        "Missing-pixel prediction on the {}: bins {:?}, {} views each, instances with ≥ 100 \
         visible px, true pose, calibrated material; usable = capture depth within {} mm of \
         the true surface.\n\n{table}\n{:.0} s.",
        args.part.display_name(),
        study.seeds,
        study.views,
        args.good_depth_mm,
        started.elapsed().as_secs_f64()
    );
    write_file_atomically(&args.out.join("thresholds.md"), table.as_bytes())?;
    Ok(())
}
