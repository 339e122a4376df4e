//! `glint eval uncertainty`: the paper's Fig. 3 check. Over repeated captures of a static bin
//! (same radiance, fresh sensor noise each shot), does the σ_z predicted from one capture's
//! pattern images (eq 1–5) track the measured per-pixel spread of the matched depth?

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use glint_camera::capture::{CaptureTruth, StereoCapture};
use glint_camera::materials;
use glint_camera::setup::BinSetup;
use glint_estimation::depth_sigma::{NoiseModel, depth_sigma};
use glint_geometry::Part;
use glint_geometry::image::normalised_intensity;
use glint_geometry::io::write_file_atomically;
use glint_plot::{FONT, padded_range, png};
use plotters::prelude::*;

#[derive(clap::Args)]
pub struct UncertaintyArgs {
    #[arg(long, default_value = "gear", value_parser = crate::mesh_cmd::parse_part)]
    pub part: Part,
    #[command(flatten)]
    pub bin: crate::capture_cmd::BinArgs,
    /// Captures of the static scene.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(3..=1000))]
    pub repeats: u32,
    #[arg(long)]
    pub out: PathBuf,
}

/// Per-pixel statistics over the repeats.
struct PixelSpread {
    predicted_m: f64,
    measured_m: f64,
}

/// Pearson correlation of two equally long samples.
fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    sxy / (sxx * syy).sqrt()
}

/// Spearman rank correlation (ties broken by order; the data are continuous).
fn spearman(x: &[f64], y: &[f64]) -> f64 {
    let rank = |v: &[f64]| {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
        let mut r = vec![0.0; v.len()];
        for (k, &i) in idx.iter().enumerate() {
            r[i] = k as f64;
        }
        r
    };
    pearson(&rank(x), &rank(y))
}

pub fn run(args: &UncertaintyArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let setup = BinSetup::new(
        &args.part.mesh(),
        materials::ground_truth(args.part),
        &args.bin.spec(),
    )?;
    let (rig, camera) = (setup.rig, setup.camera());
    let t_w_c = setup.views(1)[0];
    let renders = camera.render_shots(&t_w_c, args.bin.seed);
    let sensor = &camera.config.sensor;
    let max_dn = sensor.max_dn();

    // The noise model from two extra shots, as a user would measure it.
    let shot = |s: u64| normalised_intensity(&sensor.read_out(&renders.left[0], s), max_dn);
    let noise = NoiseModel::fit_from_pair(&shot(0xA1), &shot(0xB2), max_dn)?;

    let bar = glint_eval::progress::bar(args.repeats as u64, "captures");
    let mut captures: Vec<StereoCapture> = Vec::new();
    let mut truths: Vec<CaptureTruth> = Vec::new();
    for r in 0..args.repeats {
        let (capture, truth) =
            camera.capture_rendered(&t_w_c, &renders, args.bin.seed ^ (1000 + r as u64))?;
        captures.push(capture);
        truths.push(truth);
        bar.inc(1);
    }
    bar.finish_and_clear();
    // σ_z predicted from the first capture alone, as the refiner would.
    let first = &captures[0];
    let predicted = depth_sigma(
        &first
            .shot_images(0)
            .into_iter()
            .map(|dn| normalised_intensity(dn, max_dn))
            .collect::<Vec<_>>(),
        &first
            .shot_images(1)
            .into_iter()
            .map(|dn| normalised_intensity(dn, max_dn))
            .collect::<Vec<_>>(),
        &first.depth,
        &rig.stereo,
        &noise,
        camera.config.matcher.window_radius_px,
    )?;
    let (w, h) = (first.depth.depth_m.width(), first.depth.depth_m.height());
    let mut spreads = Vec::new();
    let mut depths = Vec::with_capacity(captures.len());
    for v in 0..h {
        for u in 0..w {
            let label = truths[0].label.get(u, v).unwrap_or(0);
            if label == 0 || label as u32 > args.bin.instances {
                continue; // parts only
            }
            let Some(sigma) = predicted.get(u, v).filter(|s| s.is_finite()) else {
                continue;
            };
            depths.clear();
            depths.extend(
                captures
                    .iter()
                    .filter_map(|c| c.depth.get(u, v))
                    .map(f64::from),
            );
            // Pixels matched in every repeat: a spread over fewer shots mixes in drop-outs.
            if depths.len() < captures.len() {
                continue;
            }
            let mean = depths.iter().sum::<f64>() / depths.len() as f64;
            let var =
                depths.iter().map(|z| (z - mean).powi(2)).sum::<f64>() / (depths.len() - 1) as f64;
            spreads.push(PixelSpread {
                predicted_m: sigma as f64,
                measured_m: var.sqrt(),
            });
        }
    }
    anyhow::ensure!(
        spreads.len() >= 100,
        "only {} part pixels had depth in all {} captures; use more instances or another seed",
        spreads.len(),
        args.repeats
    );
    let x: Vec<f64> = spreads.iter().map(|s| s.predicted_m).collect();
    let y: Vec<f64> = spreads.iter().map(|s| s.measured_m).collect();
    let r_pearson = pearson(&x, &y);
    let r_spearman = spearman(&x, &y);
    let logs = |v: &[f64]| v.iter().map(|a| a.max(1e-9).ln()).collect::<Vec<_>>();
    let r_log = pearson(&logs(&x), &logs(&y));
    let mut ratios: Vec<f64> = spreads
        .iter()
        .map(|s| s.measured_m / s.predicted_m)
        .collect();
    ratios.sort_by(f64::total_cmp);
    let median_ratio = ratios[ratios.len() / 2];

    let mut csv = String::from("predicted_sigma_z_mm,measured_std_mm\n");
    for s in &spreads {
        writeln!(csv, "{:.5},{:.5}", s.predicted_m * 1e3, s.measured_m * 1e3)?;
    }
    let report = format!(
        "# Depth uncertainty (eq 1–5) against measured depth spread\n\n\
         {} × {} in the bin, {}×{} px, {} spp; {} captures of one static view (one render, fresh sensor noise per shot). \
         Predicted σ_z from the first capture's pattern images and a noise model fitted to two extra shots; measured: \
         per-pixel standard deviation of the matched depth over the captures, on part pixels matched in every capture.\n\n\
         | pixels | Pearson r | Spearman ρ | Pearson r of logs | median measured/predicted |\n|---:|---:|---:|---:|---:|\n\
         | {} | {r_pearson:.3} | {r_spearman:.3} | {r_log:.3} | {median_ratio:.3} |\n\n\
         Scatter: `scatter.png`; data: `scatter.csv` (mm).\n",
        args.part.display_name(),
        args.bin.instances,
        args.bin.resolution.0,
        args.bin.resolution.1,
        args.bin.spp,
        args.repeats,
        spreads.len()
    );
    let scatter = scatter_png(&x, &y)?;
    for (name, bytes) in [
        ("scatter.csv", csv.as_bytes()),
        ("report.md", report.as_bytes()),
        ("scatter.png", &scatter),
    ] {
        let path = args.out.join(name);
        write_file_atomically(&path, bytes)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    println!("{report}\nwrote {}", args.out.display());
    Ok(())
}

/// Predicted against measured σ_z, mm, log-log, with the identity line.
fn scatter_png(predicted_m: &[f64], measured_m: &[f64]) -> anyhow::Result<Vec<u8>> {
    let to_log_mm = |v: f64| (v * 1e3).max(1e-4).log10();
    let xs: Vec<f64> = predicted_m.iter().map(|&v| to_log_mm(v)).collect();
    let ys: Vec<f64> = measured_m.iter().map(|&v| to_log_mm(v)).collect();
    let (lo_x, hi_x) = padded_range(xs.iter().copied(), 0.05);
    let (lo_y, hi_y) = padded_range(ys.iter().copied(), 0.05);
    let (lo, hi) = (lo_x.min(lo_y), hi_x.max(hi_y));
    Ok(png(800, 700, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption("depth σ_z: predicted (eq 1-5) vs measured", (FONT, 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(lo..hi, lo..hi)?;
        chart
            .configure_mesh()
            .x_desc("log10 predicted σ_z (mm)")
            .y_desc("log10 measured std (mm)")
            .label_style((FONT, 14))
            .draw()?;
        chart.draw_series(
            xs.iter()
                .zip(&ys)
                .map(|(&x, &y)| Circle::new((x, y), 1, BLUE.mix(0.25).filled())),
        )?;
        chart.draw_series(LineSeries::new([(lo, lo), (hi, hi)], &RED))?;
        Ok(())
    })?)
}
