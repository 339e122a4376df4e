//! The paper's Fig. 3 check (`glint eval uncertainty`): over repeated captures of a static bin
//! (one render, fresh sensor noise each time), does the σ_z predicted from one capture's
//! pattern images (eq 1–5, over all K shots) track the measured per-pixel spread of the matched
//! depth? Evaluation only: part pixels are chosen with the ground-truth labels.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use glint_camera::capture::{CaptureConfig, CaptureTruth, StereoCapture};
use glint_camera::materials;
use glint_camera::setup::{BinSetup, BinSetupSpec};
use glint_estimation::depth_sigma::{NoiseModel, depth_sigma};
use glint_geometry::Part;
use glint_geometry::image::normalised_intensity;
use glint_geometry::io::write_file_atomically;
use glint_plot::{FONT, padded_range, png};
use plotters::prelude::*;

use crate::metrics::{pearson, spearman};

/// The settings of one Fig. 3 run.
#[derive(Clone, Debug)]
pub struct DepthUncertaintyExperiment {
    /// The part in the bin, in its ground-truth material.
    pub part: Part,
    /// The bin, the drop's seed, the resolution and the samples per pixel.
    pub spec: BinSetupSpec,
    /// Patterns per capture, K; the camera's window for K
    /// ([`glint_camera::capture::default_window_radius_px`]).
    pub shots: u32,
    /// Captures of the static scene (≥ 3).
    pub repeats: u32,
}

/// Predicted σ_z against the measured spread, per part pixel matched in every capture.
#[derive(Clone, Debug)]
pub struct DepthUncertaintyResult {
    /// σ_z predicted from the first capture (eq 1–5), metres.
    pub predicted_m: Vec<f64>,
    /// Standard deviation of the matched depth over the captures, metres.
    pub measured_m: Vec<f64>,
    /// Pearson r of predicted and measured.
    pub pearson: f64,
    /// Spearman ρ of predicted and measured.
    pub spearman: f64,
    /// Pearson r of their logarithms.
    pub pearson_of_logs: f64,
    /// Median of measured / predicted.
    pub median_ratio: f64,
    /// The matching window radius the camera used, px.
    pub window_radius_px: u32,
}

/// Runs the experiment: one render of the bin's first view, `repeats` read-outs and matches,
/// the noise model fitted to two more read-outs (as a user measures it), σ_z from the first
/// capture. Fails when fewer than 100 part pixels have depth in every capture.
pub fn run(experiment: &DepthUncertaintyExperiment) -> anyhow::Result<DepthUncertaintyResult> {
    anyhow::ensure!(experiment.repeats >= 3, "repeats: at least 3 captures");
    let mut setup = BinSetup::new(
        &experiment.part.mesh(),
        materials::ground_truth(experiment.part),
        &experiment.spec,
    )?;
    setup.config = CaptureConfig {
        samples_per_pixel: experiment.spec.samples_per_pixel,
        ..CaptureConfig::for_rig_and_shots(&setup.rig, experiment.shots)?
    };
    let (rig, camera) = (setup.rig, setup.camera());
    let t_w_c = setup
        .views(1)
        .first()
        .copied()
        .context("the bin has no capture view")?;
    let renders = camera.render_shots(&t_w_c, experiment.spec.seed);
    let sensor = &camera.config.sensor;
    let max_dn = sensor.max_dn();
    let first_radiance = renders.left.first().context("a capture without shots")?;
    let shot = |s: u64| normalised_intensity(&sensor.read_out(first_radiance, s), max_dn);
    let noise = NoiseModel::fit_from_pair(&shot(0xA1), &shot(0xB2), max_dn)?;

    let bar = crate::progress::bar(experiment.repeats as u64, "captures");
    let mut captures: Vec<StereoCapture> = Vec::new();
    let mut truths: Vec<CaptureTruth> = Vec::new();
    for r in 0..experiment.repeats {
        let (capture, truth) =
            camera.capture_rendered(&t_w_c, &renders, experiment.spec.seed ^ (1000 + r as u64))?;
        captures.push(capture);
        truths.push(truth);
        bar.inc(1);
    }
    bar.finish_and_clear();
    // σ_z predicted from the first capture alone, as the refiner would.
    let first = &captures[0];
    let normalised = |side: usize| -> Vec<_> {
        first
            .shot_images(side)
            .into_iter()
            .map(|dn| normalised_intensity(dn, max_dn))
            .collect()
    };
    let window_radius_px = camera.config.matcher.window_radius_px;
    let predicted = depth_sigma(
        &normalised(0),
        &normalised(1),
        &first.depth,
        &rig.stereo,
        &noise,
        window_radius_px,
    )?;
    let (w, h) = (first.depth.depth_m.width(), first.depth.depth_m.height());
    let (mut predicted_m, mut measured_m) = (Vec::new(), Vec::new());
    let mut depths = Vec::with_capacity(captures.len());
    for v in 0..h {
        for u in 0..w {
            let label = truths[0].label.get(u, v).unwrap_or(0);
            if label == 0 || label as u32 > experiment.spec.instances {
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
            predicted_m.push(sigma as f64);
            measured_m.push(var.sqrt());
        }
    }
    anyhow::ensure!(
        predicted_m.len() >= 100,
        "only {} part pixels had depth in all {} captures; use more instances or another seed",
        predicted_m.len(),
        experiment.repeats
    );
    let logs = |v: &[f64]| v.iter().map(|a| a.max(1e-9).ln()).collect::<Vec<_>>();
    let mut ratios: Vec<f64> = measured_m
        .iter()
        .zip(&predicted_m)
        .map(|(m, p)| m / p)
        .collect();
    ratios.sort_by(f64::total_cmp);
    Ok(DepthUncertaintyResult {
        pearson: pearson(&predicted_m, &measured_m),
        spearman: spearman(&predicted_m, &measured_m),
        pearson_of_logs: pearson(&logs(&predicted_m), &logs(&measured_m)),
        median_ratio: ratios[ratios.len() / 2],
        predicted_m,
        measured_m,
        window_radius_px,
    })
}

impl DepthUncertaintyResult {
    /// The report's table row: pixels, Pearson r, Spearman ρ, Pearson r of logs, median ratio.
    pub fn table_row(&self, label: &str) -> String {
        format!(
            "| {label} | {} | {:.3} | {:.3} | {:.3} | {:.3} |",
            self.predicted_m.len(),
            self.pearson,
            self.spearman,
            self.pearson_of_logs,
            self.median_ratio
        )
    }

    /// Writes `scatter.csv` (mm), `scatter.png` and `report.md` to `dir`; returns the report.
    pub fn write(
        &self,
        experiment: &DepthUncertaintyExperiment,
        dir: &Path,
    ) -> anyhow::Result<String> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let mut csv = String::from("predicted_sigma_z_mm,measured_std_mm\n");
        for (p, m) in self.predicted_m.iter().zip(&self.measured_m) {
            writeln!(csv, "{:.5},{:.5}", p * 1e3, m * 1e3)?;
        }
        let side = 2 * self.window_radius_px + 1;
        let report = format!(
            "# Depth uncertainty (eq 1–5) against measured depth spread\n\n\
             {} × {} in the bin, {}×{} px, {} spp, {} shot(s) per capture matched over {side}×{side} windows; {} \
             captures of one static view (one render, fresh sensor noise per shot). Predicted σ_z from the first \
             capture's pattern images (all shots) and a noise model fitted to two extra shots; measured: per-pixel \
             standard deviation of the matched depth over the captures, on part pixels matched in every capture.\n\n\
             | camera | pixels | Pearson r | Spearman ρ | Pearson r of logs | median measured/predicted |\n\
             |---|---:|---:|---:|---:|---:|\n{}\n\n\
             Scatter: `scatter.png`; data: `scatter.csv` (mm).\n",
            experiment.part.display_name(),
            experiment.spec.instances,
            experiment.spec.width_px,
            experiment.spec.height_px,
            experiment.spec.samples_per_pixel,
            experiment.shots,
            experiment.repeats,
            self.table_row(&format!("{} × {side}×{side}", experiment.shots)),
        );
        let scatter = scatter_png(&self.predicted_m, &self.measured_m)?;
        for (name, bytes) in [
            ("scatter.csv", csv.as_bytes()),
            ("report.md", report.as_bytes()),
            ("scatter.png", &scatter),
        ] {
            let path = dir.join(name);
            write_file_atomically(&path, bytes)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        Ok(report)
    }
}

/// Predicted against measured σ_z, mm, log-log, with the identity line.
pub fn scatter_png(predicted_m: &[f64], measured_m: &[f64]) -> anyhow::Result<Vec<u8>> {
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
