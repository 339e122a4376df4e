//! `glint calibrate`: the photometric calibration of §IV-A (camera response by Debevec–Malik),
//! and its evaluation against the mock camera's hidden ground truth.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glint_calibration::response::{
    DebevecConfig, ExposureStack, ResponseTable, calibrate, response_png,
};
use glint_geometry::io::write_file_atomically;
use glint_render::sensor::ResponseCurve;

#[derive(clap::Subcommand)]
pub enum CalibrateCommand {
    /// Camera response g and g⁻¹ from an exposure stack (Debevec–Malik).
    Response(ResponseArgs),
    /// Evaluation only: a recovered response against a ground-truth sensor file.
    EvalResponse(EvalResponseArgs),
}

#[derive(clap::Args)]
pub struct ResponseArgs {
    /// Directory with stack.json and its images.
    #[arg(long)]
    pub stack: PathBuf,
    /// Output JSON (g⁻¹ per DN level and g over ln exposure).
    #[arg(long)]
    pub out: PathBuf,
    /// Optional PNG plot of g (DN over ln exposure).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Smoothness weight λ.
    #[arg(long, default_value_t = 10.0)]
    pub lambda: f64,
    /// Number of sample pixels.
    #[arg(long, default_value_t = 70)]
    pub samples: usize,
}

#[derive(clap::Args)]
pub struct EvalResponseArgs {
    /// A response written by `glint calibrate response`.
    #[arg(long)]
    pub response: PathBuf,
    /// Ground-truth sensor JSON (a `Sensor`, or an object with a `response` or `sensor` field).
    #[arg(long)]
    pub gt_sensor: PathBuf,
    /// Well-exposed range compared, as fractions of full scale.
    #[arg(long, default_value_t = 0.1)]
    pub from: f64,
    #[arg(long, default_value_t = 0.9)]
    pub to: f64,
    /// Optional PNG: recovered and true g together.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

pub fn run(command: CalibrateCommand) -> anyhow::Result<()> {
    match command {
        CalibrateCommand::Response(args) => response(&args),
        CalibrateCommand::EvalResponse(args) => eval_response(&args),
    }
}

fn response(args: &ResponseArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let stack = ExposureStack::load(&args.stack)?;
    let config = DebevecConfig {
        lambda: args.lambda,
        samples: args.samples,
    };
    let table = calibrate(&stack, &config)?;
    table.save(&args.out)?;
    if let Some(plot) = &args.plot {
        write_file_atomically(plot, &response_png(&table, None)?)?;
    }
    let (w, h) = stack.size();
    let inner = &table.inverse.ln_exposure[1..table.inverse.ln_exposure.len() - 1];
    let decreasing = inner.windows(2).filter(|p| p[1] < p[0]).count();
    println!(
        "response: {} exposures of {w}×{h} px, {} bits, {} samples, λ = {} → {}",
        stack.images().len(),
        stack.bit_depth(),
        table.solve.samples,
        table.solve.lambda,
        args.out.display()
    );
    println!(
        "  ln X over DN 1 … {}: {:.3} … {:.3} (dynamic range {:.1} stops), {} decreasing steps, rms residual {:.3}, {:.2} s",
        table.max_dn - 1,
        inner[0],
        inner[inner.len() - 1],
        (inner[inner.len() - 1] - inner[0]) / std::f64::consts::LN_2,
        decreasing,
        table.solve.rms_residual,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The true response in a ground-truth sensor file.
fn read_gt_response(path: &Path) -> anyhow::Result<ResponseCurve> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let found = value
        .get("response")
        .or_else(|| value.get("sensor").and_then(|s| s.get("response")))
        .with_context(|| {
            format!(
                "{}: no `response` (or `sensor.response`) field",
                path.display()
            )
        })?;
    serde_json::from_value(found.clone())
        .with_context(|| format!("{}: `response` is not a response curve", path.display()))
}

fn eval_response(args: &EvalResponseArgs) -> anyhow::Result<()> {
    if !(0.0..1.0).contains(&args.from) || !(args.from..=1.0).contains(&args.to) {
        anyhow::bail!(
            "--from {} / --to {} must satisfy 0 ≤ from < to ≤ 1",
            args.from,
            args.to
        );
    }
    let table = ResponseTable::load(&args.response)?;
    let truth = read_gt_response(&args.gt_sensor)?;
    let cmp = table.compare_with(&truth, (args.from, args.to));
    println!(
        "response vs ground truth {truth:?} over {:.0} % … {:.0} % of full scale ({} levels): \
         max |Δ ln g⁻¹| = {:.4}, rms = {:.4} (offset {:.3} removed)",
        args.from * 100.0,
        args.to * 100.0,
        cmp.levels,
        cmp.max_abs_ln_error,
        cmp.rms_ln_error,
        cmp.ln_offset
    );
    if let Some(plot) = &args.plot {
        let m = table.max_dn as f64;
        let reference: Vec<(f64, f64)> = (1..table.max_dn)
            .map(|dn| {
                let x = truth.invert((dn as f64 / m) as f32) as f64;
                (x.ln() + cmp.ln_offset, dn as f64)
            })
            .collect();
        write_file_atomically(
            plot,
            &response_png(&table, Some(("ground truth", &reference)))?,
        )?;
    }
    Ok(())
}
