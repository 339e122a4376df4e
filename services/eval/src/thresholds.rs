//! How well the render workers predict which depth pixels a view will lose (eq 16–17), and
//! the thresholds τ_I and τ_σ chosen by it: on each bin and view, the predictor — given the
//! true pose and the calibrated material, so that only its missing-pixel model is judged — is
//! compared pixel by pixel with the mock camera's real capture on the visible pixels of every
//! instance. A pixel is *usable* in the capture when it has depth within `good_depth_m` of the
//! true surface (wrong depth is as lost as missing depth); *predicted usable* when the worker
//! keeps it. The score is the balanced accuracy ½(TPR + TNR) of "usable", so a threshold that
//! keeps everything (or nothing) scores ½.

use std::fmt::Write as _;

use glint_camera::setup::{BinSetup, BinSetupSpec};
use glint_geometry::Part;
use glint_orchestrator::local::SdfCache;
use glint_orchestrator::stages::SessionObject;
use glint_uncertainty::predict::PixelCause;
use glint_uncertainty::{PredictionSettings, predict_candidate};

use crate::active::{Calibration, prediction_object_for};
use glint_orchestrator::local::MockCamera;

/// What to measure.
#[derive(Clone, Debug)]
pub struct ThresholdStudy {
    /// The part dropped into every bin.
    pub part: Part,
    /// One bin per seed (the seed of its drop).
    pub seeds: Vec<u64>,
    /// Views per bin, on the cap above it; each is captured and predicted.
    pub views: usize,
    /// Parts per bin.
    pub instances: u32,
    /// Width of the mock camera's images, px.
    pub width_px: u32,
    /// Height of the mock camera's images, px.
    pub height_px: u32,
    /// Samples per pixel of the mock camera's renders.
    pub samples_per_pixel: u32,
    /// Instances with fewer visible pixels are skipped.
    pub min_visible_px: u64,
    /// Capture depth within this of the true surface is usable, metres.
    pub good_depth_m: f64,
    /// The τ_I tried (eq 16): missing where `I_single / I_multi` is below it.
    pub tau_intensity_ratios: Vec<f64>,
    /// The τ_σ tried (eq 17), metres: missing where σ̌_z is above it.
    pub tau_sigmas_m: Vec<f64>,
    /// Render the bin with the part.
    pub with_bin: bool,
}

/// Pixel counts of one threshold pair, summed over everything measured.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Confusion {
    /// τ_I of eq 16.
    pub tau_intensity_ratio: f64,
    /// τ_σ of eq 17, metres.
    pub tau_sigma_m: f64,
    /// Usable in the capture and kept by the prediction.
    pub true_usable: u64,
    /// Lost in the capture but kept by the prediction.
    pub false_usable: u64,
    /// Lost in the capture and dropped by the prediction.
    pub true_missing: u64,
    /// Usable in the capture but dropped by the prediction.
    pub false_missing: u64,
}

impl Confusion {
    /// ½ (TPR + TNR) of "usable".
    pub fn balanced_accuracy(&self) -> f64 {
        let usable = (self.true_usable + self.false_missing) as f64;
        let missing = (self.true_missing + self.false_usable) as f64;
        let tpr = if usable > 0.0 {
            self.true_usable as f64 / usable
        } else {
            1.0
        };
        let tnr = if missing > 0.0 {
            self.true_missing as f64 / missing
        } else {
            1.0
        };
        0.5 * (tpr + tnr)
    }

    /// Share of the pixels the capture had usable, and the prediction kept.
    pub fn rates(&self) -> (f64, f64) {
        let all = (self.true_usable + self.false_usable + self.true_missing + self.false_missing)
            .max(1) as f64;
        (
            (self.true_usable + self.false_missing) as f64 / all,
            (self.true_usable + self.false_usable) as f64 / all,
        )
    }
}

/// Runs the study: one [`Confusion`] per (τ_I, τ_σ), in the order of the grid (τ_I outer).
pub fn run(
    study: &ThresholdStudy,
    calibration: &Calibration,
    mut on_view: impl FnMut(),
) -> anyhow::Result<Vec<Confusion>> {
    anyhow::ensure!(!study.seeds.is_empty(), "seeds: at least one");
    anyhow::ensure!(
        !study.tau_intensity_ratios.is_empty() && !study.tau_sigmas_m.is_empty(),
        "thresholds: at least one of each"
    );
    let mesh = study.part.mesh();
    let object = SessionObject::new(study.part.name(), mesh);
    let sdf = SdfCache::with_config(glint_uncertainty::predict::prediction_grid_config())
        .grid(&object)
        .map_err(anyhow::Error::msg)?;
    let mut grid: Vec<Confusion> = study
        .tau_intensity_ratios
        .iter()
        .flat_map(|&ti| {
            study.tau_sigmas_m.iter().map(move |&ts| Confusion {
                tau_intensity_ratio: ti,
                tau_sigma_m: ts,
                ..Confusion::default()
            })
        })
        .collect();
    for &seed in &study.seeds {
        let setup = BinSetup::new(
            &object.mesh,
            glint_camera::materials::ground_truth(study.part),
            &BinSetupSpec {
                instances: study.instances,
                seed,
                width_px: study.width_px,
                height_px: study.height_px,
                samples_per_pixel: study.samples_per_pixel,
            },
        )?;
        let mock = MockCamera { setup };
        let setup = &mock.setup;
        let camera = setup.camera();
        let views = setup.views(study.views);
        let calibrated =
            prediction_object_for(&mock, &views[0], &object, calibration, study.with_bin)?;
        let predictor = calibrated.predictor(sdf.clone());
        for (k, t_w_c) in views.iter().enumerate() {
            let view_seed = glint_camera::setup::capture_seed(seed, k);
            let rendered = camera.render_shots(t_w_c, view_seed);
            let (capture, _) = camera.capture_rendered(t_w_c, &rendered, view_seed)?;
            let truth = &rendered.truth;
            for vis in setup.instance_visibility(t_w_c) {
                if vis.px_count_visib < study.min_visible_px {
                    continue;
                }
                let t_w_o = setup.poses[(vis.label - 1) as usize];
                for ti_index in 0..study.tau_intensity_ratios.len() {
                    let settings = PredictionSettings {
                        tau_intensity_ratio: study.tau_intensity_ratios[ti_index],
                        // σ judged below, for every τ_σ at once.
                        tau_sigma_m: 1.0,
                        samples_per_pixel: 2,
                        shots: setup.config.shots,
                        window_radius_px: setup.config.matcher.window_radius_px,
                        with_maps: true,
                        ..PredictionSettings::default()
                    };
                    let p = predict_candidate(&predictor, &t_w_o, t_w_c, &settings, view_seed)?;
                    let (Some(crop), Some(cause), Some(sigma)) = (p.crop, &p.cause, &p.sigma_z_m)
                    else {
                        continue;
                    };
                    for v in 0..crop.height {
                        for u in 0..crop.width {
                            let (fu, fv) = (u + crop.u_min, v + crop.v_min);
                            if truth.label.get(fu, fv) != Some(vis.label) {
                                continue; // judged on the instance's visible pixels only
                            }
                            let z_true = truth.depth_m.get(fu, fv).unwrap_or(f32::NAN);
                            let usable = capture
                                .depth
                                .get(fu, fv)
                                .is_some_and(|z| ((z - z_true).abs() as f64) <= study.good_depth_m);
                            let c = cause.get(u, v).unwrap_or(PixelCause::NotPart as u8);
                            let s = sigma.get(u, v).unwrap_or(f32::NAN) as f64;
                            for ts_index in 0..study.tau_sigmas_m.len() {
                                let kept = c == PixelCause::Kept as u8
                                    && s.is_finite()
                                    && s <= study.tau_sigmas_m[ts_index];
                                let cell =
                                    &mut grid[ti_index * study.tau_sigmas_m.len() + ts_index];
                                match (usable, kept) {
                                    (true, true) => cell.true_usable += 1,
                                    (true, false) => cell.false_missing += 1,
                                    (false, false) => cell.true_missing += 1,
                                    (false, true) => cell.false_usable += 1,
                                }
                            }
                        }
                    }
                }
            }
            on_view();
        }
    }
    Ok(grid)
}

/// The grid as a table, best first.
pub fn grid_markdown(grid: &[Confusion]) -> String {
    let mut sorted = grid.to_vec();
    sorted.sort_by(|a, b| b.balanced_accuracy().total_cmp(&a.balanced_accuracy()));
    let mut out = String::from(
        "| τ_I | τ_σ (mm) | balanced accuracy | usable in capture | kept by prediction |\n|---:|---:|---:|---:|---:|\n",
    );
    for c in &sorted {
        let (usable, kept) = c.rates();
        let _ = writeln!(
            out,
            "| {:.2} | {:.2} | {:.3} | {:.1} % | {:.1} % |",
            c.tau_intensity_ratio,
            c.tau_sigma_m * 1e3,
            c.balanced_accuracy(),
            100.0 * usable,
            100.0 * kept
        );
    }
    out
}
