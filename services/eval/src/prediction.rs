//! Is the prediction right? For every candidate view of a bin, the render workers' prediction
//! (eq 14–17 → the 6×6 Fisher information of eq 21–22) against what the mock camera then
//! captures from that view:
//!
//! - **IoU of the missing masks** over the instance's visible pixels: predicted missing is
//!   any pixel the worker drops (ratio test, σ test, not seen by the right camera); captured
//!   missing is a pixel with no depth or depth further than `good_depth_m` from the true
//!   surface (wrong depth is as lost as none). Both empty counts as agreement, 1;
//! - **Spearman ρ of σ̌_z against the capture's σ_z** (eq 1–5 on the captured pattern images,
//!   the refiner's σ) on the pixels both keep;
//! - **log-det ratio** `ln |F_pred + P| − ln |F_capt + P|` (nats), with `F_capt` the
//!   information of the captured points (the instance's visible mask eroded by the window,
//!   as Fig. 9 segments) and `P` the planner's prior — 0 when the prediction has the
//!   capture's information; twice the entropy the prediction gets wrong;
//! - **ranks**: each candidate's rank by predicted and by captured entropy (1 = most
//!   informative); the captured ("oracle") rank of the predicted best view says what
//!   planning on predictions loses.
//!
//! Both sides are judged at the true pose, so that the rendering model alone is measured
//! (Fig. 9 measures it from the detector's pose); the predictor still knows only the
//! calibrated material and response — or, as the evaluation-only control
//! `true_materials`, the simulator's true material, to show what calibration error costs.
//! The instances judged in each bin are the most visible from the first candidate; each has
//! its own ranking of the candidates.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use glint_calibration::material_file::MaterialFile;
use glint_camera::setup::capture_seed;
use glint_estimation::nbv::{PosePrior, pose_entropy_nats};
use glint_estimation::refine::information_of_points;
use glint_estimation::view::{SigmaSource, ViewSigma, points_in_mask, view_sigma};
use glint_geometry::image::Image;
use glint_geometry::io::write_file_atomically;
use glint_geometry::sdf::SdfGrid;
use glint_uncertainty::predict::{PredictionImages, prediction_grid_config};
use glint_uncertainty::{
    HypothesisScene, PixelCause, PredictionSettings, candidate_seed, predict_candidate_in,
};
use rayon::prelude::*;

use crate::active::{MISSING_RGB, prediction_object_for};
use crate::metrics::{mean, median, spearman};
use crate::scenes::{CalibratedObject, MockCameraSpec, bin_seed, mock_bin, names_in_order};

/// The settings of one study (`glint eval prediction`'s flags).
#[derive(Clone, Debug)]
pub struct PredictionExperiment {
    /// The parts, each with its calibration.
    pub objects: Vec<CalibratedObject>,
    /// Bins per part: bin `s` has seed `seed·10⁴ + 9000 + s` (apart from Fig. 9's and the
    /// threshold tuning's bins).
    pub scenes: u32,
    /// Candidate views on the cap above each bin; every one is predicted and captured.
    pub candidates: usize,
    /// Parts per bin.
    pub instances: u32,
    /// Instances judged per bin: the most visible from the first candidate, among those at
    /// least `min_visib_fract` visible there.
    pub judged_instances: usize,
    /// See `judged_instances`.
    pub min_visib_fract: f64,
    /// Base seed.
    pub seed: u64,
    /// The mock camera.
    pub camera: MockCameraSpec,
    /// Evaluation-only control: predict with the simulator's true material instead of the
    /// fitted one (the response and radiometric scale stay the calibrated ones).
    pub true_materials: bool,
    /// The render workers render the bin with the part (beyond the paper).
    pub predict_with_bin: bool,
    /// Captured depth within this of the true surface is usable, metres.
    pub good_depth_m: f64,
    /// Output directory.
    pub out: PathBuf,
}

impl PredictionExperiment {
    /// Which materials the predictor knows, for reports.
    pub fn materials_label(&self) -> &'static str {
        if self.true_materials {
            "true (evaluation-only control)"
        } else {
            "fitted"
        }
    }
}

/// One candidate's comparison (a row of `prediction.csv`).
#[derive(Clone, Debug, PartialEq)]
pub struct CandidateRow {
    /// The part's name.
    pub part: String,
    /// The bin.
    pub scene: u32,
    /// The candidate's index.
    pub view: usize,
    /// The judged instance (index into the bin's parts).
    pub instance: usize,
    /// The judged instance's visible pixels in the capture's truth.
    pub visible_px: usize,
    /// IoU of the predicted and captured missing masks (NaN when fewer than
    /// [`MIN_JUDGED_PX`] pixels are visible).
    pub iou_missing: f64,
    /// Spearman ρ of σ̌_z against the captured σ_z on the pixels both keep (NaN under
    /// [`MIN_JUDGED_PX`] of them).
    pub spearman_sigma: f64,
    /// `ln |F_pred + P| − ln |F_capt + P|`, nats.
    pub logdet_ratio: f64,
    /// Rank by predicted entropy, 1 = lowest.
    pub predicted_rank: usize,
    /// Rank by the captured points' entropy, 1 = lowest.
    pub oracle_rank: usize,
    /// Entropy of the prior plus the predicted information, nats (eq 20).
    pub predicted_entropy_nats: f64,
    /// Entropy of the prior plus the captured information, nats.
    pub captured_entropy_nats: f64,
}

/// Fewer visible (or commonly kept) pixels than this leave the IoU (or ρ) unjudged.
pub const MIN_JUDGED_PX: usize = 50;

/// The pixel-level comparison of one candidate.
struct PixelScores {
    visible_px: usize,
    iou_missing: f64,
    spearman_sigma: f64,
}

/// Compares the prediction's crop maps with the capture on the pixels the truth gives to
/// `label`. `sigma_captured` is the capture's σ_z (full image), `usable(u, v)` whether the
/// capture's depth there is within tolerance of the truth.
fn pixel_scores(
    crop: &glint_geometry::image::PixelRect,
    cause: &Image<u8>,
    sigma_predicted: &Image<f32>,
    sigma_captured: &Image<f32>,
    on_instance: impl Fn(u32, u32) -> bool,
    usable: impl Fn(u32, u32) -> bool,
) -> PixelScores {
    let (mut visible, mut both_missing, mut either_missing) = (0usize, 0usize, 0usize);
    let (mut predicted, mut captured) = (Vec::new(), Vec::new());
    for v in 0..crop.height {
        for u in 0..crop.width {
            let (fu, fv) = (u + crop.u_min, v + crop.v_min);
            if !on_instance(fu, fv) {
                continue;
            }
            visible += 1;
            let predicted_missing = cause.get(u, v) != Some(PixelCause::Kept as u8);
            let captured_missing = !usable(fu, fv);
            both_missing += usize::from(predicted_missing && captured_missing);
            either_missing += usize::from(predicted_missing || captured_missing);
            if !predicted_missing && !captured_missing {
                let (p, c) = (
                    sigma_predicted.get(u, v).unwrap_or(f32::NAN),
                    sigma_captured.get(fu, fv).unwrap_or(f32::NAN),
                );
                if p.is_finite() && c.is_finite() {
                    predicted.push(f64::from(p));
                    captured.push(f64::from(c));
                }
            }
        }
    }
    PixelScores {
        visible_px: visible,
        iou_missing: if visible < MIN_JUDGED_PX {
            f64::NAN
        } else if either_missing == 0 {
            1.0
        } else {
            both_missing as f64 / either_missing as f64
        },
        spearman_sigma: if predicted.len() < MIN_JUDGED_PX {
            f64::NAN
        } else {
            spearman(&predicted, &captured)
        },
    }
}

/// Ranks 1..n of `values`, lowest first (ties by index).
fn ranks(values: &[f64]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let mut rank = vec![0; values.len()];
    for (r, &i) in order.iter().enumerate() {
        rank[i] = r + 1;
    }
    rank
}

/// The Fig. 8 panels of one view: what the study keeps of a prediction to draw it.
pub struct Fig8View {
    /// The part's name.
    pub part: String,
    /// The candidate drawn.
    pub view: usize,
    /// The prediction's images (left camera, DN).
    pub images: PredictionImages,
    /// σ̌_z over the crop, metres.
    pub sigma_z_m: Image<f32>,
    /// [`PixelCause`] over the crop.
    pub cause: Image<u8>,
    /// The σ̌_z at the top of the colour ramp (τ_σ), metres.
    pub scale_max_m: f64,
}

/// Runs the study; `on_scene` is told after each bin. Returns every candidate's row and, per
/// part, the Fig. 8 panels of the first bin's predicted best view.
pub fn run(
    spec: &PredictionExperiment,
    mut on_scene: impl FnMut(&str, u32),
) -> anyhow::Result<(Vec<CandidateRow>, Vec<Fig8View>)> {
    anyhow::ensure!(!spec.objects.is_empty(), "parts: at least one");
    anyhow::ensure!(spec.scenes >= 1, "scenes: at least one bin");
    anyhow::ensure!(spec.candidates >= 2, "candidates: at least two to rank");
    anyhow::ensure!(
        spec.good_depth_m.is_finite() && spec.good_depth_m > 0.0,
        "good_depth: a positive distance"
    );
    spec.camera
        .rig_and_config()
        .context("the camera's settings")?;
    let prior = PosePrior::default();
    let mut rows = Vec::new();
    let mut fig8 = Vec::new();
    for part in &spec.objects {
        let object = &part.object;
        let session_object = object.session_object();
        let grid = std::sync::Arc::new(
            SdfGrid::build(&object.mesh, &prediction_grid_config())
                .with_context(|| format!("SDF of {}", object.name))?,
        );
        let mut calibration = part.calibration.clone();
        if spec.true_materials {
            calibration.material =
                MaterialFile::new(&object.material, calibration.material.provenance.clone());
        }
        for s in 0..spec.scenes {
            let scene_seed = bin_seed(spec.seed, 9000, s);
            let (camera, candidates) = mock_bin(
                object,
                spec.instances,
                scene_seed,
                spec.candidates,
                &spec.camera,
            )
            .with_context(|| format!("{} bin {s}", object.name))?;
            let setup = &camera.setup;
            // The judged instances: the most visible from the first candidate, enough of
            // each in view (the same captures serve them all).
            let mut judged: Vec<_> = setup
                .instance_visibility(&candidates[0])
                .into_iter()
                .filter(|v| v.visib_fract >= spec.min_visib_fract)
                .collect();
            judged.sort_by_key(|v| std::cmp::Reverse(v.px_count_visib));
            judged.truncate(spec.judged_instances);
            if judged.is_empty() {
                on_scene(&object.name, s);
                continue;
            }
            let predictor = prediction_object_for(
                &camera,
                &candidates[0],
                &session_object,
                &calibration,
                spec.predict_with_bin,
            )?;
            let settings = PredictionSettings {
                shots: predictor.shots,
                pattern_fill: predictor.pattern_fill,
                window_radius_px: predictor.window_radius_px,
                with_maps: true,
                ..PredictionSettings::default()
            };
            let predictor = predictor.predictor(grid.clone());
            // predictions[j][k]: judged instance j from candidate k, at its true pose.
            let predictions = judged
                .iter()
                .map(|v| {
                    let gt_t_w_o = setup.poses[usize::from(v.label - 1)];
                    let hypothesis = HypothesisScene::build(&predictor, &gt_t_w_o)
                        .map_err(|e| anyhow::anyhow!("the judged instance's scene: {e}"))?;
                    candidates
                        .par_iter()
                        .enumerate()
                        .map(|(k, t_w_c)| {
                            predict_candidate_in(
                                &predictor,
                                &hypothesis,
                                t_w_c,
                                &settings,
                                candidate_seed(spec.seed, k as u32),
                            )
                            .map_err(|e| anyhow::anyhow!("predicting view {k}: {e}"))
                        })
                        .collect::<anyhow::Result<Vec<_>>>()
                })
                .collect::<anyhow::Result<Vec<_>>>()?;
            let mut scene_rows: Vec<Vec<CandidateRow>> = vec![Vec::new(); judged.len()];
            for (k, t_w_c) in candidates.iter().enumerate() {
                let (captured, truth) = camera
                    .capture_with_truth(t_w_c, capture_seed(scene_seed, k))
                    .map_err(|e| anyhow::anyhow!("capturing view {k}: {e}"))?;
                let view = &captured.measurement;
                let sigma = view_sigma(
                    view,
                    &SigmaSource::PatternImages {
                        window_radius_px: spec.camera.window_radius_px,
                        noise: None,
                    },
                )?;
                let captured_sigma = match &sigma {
                    ViewSigma::PerPixel(image) => image.clone(),
                    ViewSigma::Constant(c) => truth.label.map(|_| *c as f32),
                };
                let usable = |u: u32, v: u32| {
                    let z_true = truth.depth_m.get(u, v).unwrap_or(f32::NAN);
                    view.depth
                        .depth_m
                        .get(u, v)
                        .is_some_and(|z| f64::from((z - z_true).abs()) <= spec.good_depth_m)
                };
                for (j, vis) in judged.iter().enumerate() {
                    let label = vis.label;
                    let gt_t_w_o = setup.poses[usize::from(label - 1)];
                    let predicted = &predictions[j][k];
                    let on_instance = |u: u32, v: u32| truth.label.get(u, v) == Some(label);
                    let mask = truth.label.map(|l| l == label);
                    let points =
                        points_in_mask(view, &mask, &sigma, spec.camera.window_radius_px)?.points;
                    let captured_information = information_of_points(
                        &grid,
                        &points,
                        &gt_t_w_o.inverse(),
                        settings.model_sigma_m,
                    );
                    let h_pred = pose_entropy_nats(&predicted.information, &prior)?;
                    let h_capt = pose_entropy_nats(&captured_information, &prior)?;
                    let scores = match (&predicted.crop, &predicted.cause, &predicted.sigma_z_m) {
                        (Some(crop), Some(cause), Some(sigma_z)) => {
                            pixel_scores(crop, cause, sigma_z, &captured_sigma, on_instance, usable)
                        }
                        _ => PixelScores {
                            visible_px: mask.data().iter().filter(|&&m| m).count(),
                            iou_missing: f64::NAN,
                            spearman_sigma: f64::NAN,
                        },
                    };
                    scene_rows[j].push(CandidateRow {
                        part: object.name.clone(),
                        scene: s,
                        view: k,
                        instance: usize::from(label - 1),
                        visible_px: scores.visible_px,
                        iou_missing: scores.iou_missing,
                        spearman_sigma: scores.spearman_sigma,
                        // Entropy is −½ ln |F + P| plus a constant (eq 20).
                        logdet_ratio: 2.0 * (h_capt - h_pred),
                        predicted_rank: 0,
                        oracle_rank: 0,
                        predicted_entropy_nats: h_pred,
                        captured_entropy_nats: h_capt,
                    });
                }
            }
            for (j, instance_rows) in scene_rows.iter_mut().enumerate() {
                let of =
                    |f: fn(&CandidateRow) -> f64| instance_rows.iter().map(f).collect::<Vec<_>>();
                let predicted_ranks = ranks(&of(|r| r.predicted_entropy_nats));
                let oracle_ranks = ranks(&of(|r| r.captured_entropy_nats));
                for (row, (p, o)) in instance_rows
                    .iter_mut()
                    .zip(predicted_ranks.iter().zip(&oracle_ranks))
                {
                    row.predicted_rank = *p;
                    row.oracle_rank = *o;
                }
                if s == 0 && j == 0 {
                    let best = predicted_ranks.iter().position(|&r| r == 1).unwrap_or(0);
                    let p = &predictions[j][best];
                    if let (Some(images), Some(sigma_z_m), Some(cause)) =
                        (&p.images, &p.sigma_z_m, &p.cause)
                    {
                        fig8.push(Fig8View {
                            part: object.name.clone(),
                            view: best,
                            images: images.clone(),
                            sigma_z_m: sigma_z_m.clone(),
                            cause: cause.clone(),
                            scale_max_m: settings.tau_sigma_m,
                        });
                    }
                }
            }
            rows.extend(scene_rows.into_iter().flatten());
            on_scene(&object.name, s);
        }
    }
    Ok((rows, fig8))
}

/// One line of `summary.csv`: a part, or `all`.
#[derive(Clone, Debug, PartialEq)]
pub struct SummaryRow {
    /// The part's name, or `all`.
    pub part: String,
    /// Candidates compared.
    pub candidates: usize,
    /// Mean IoU of the missing masks over the judged candidates.
    pub mean_iou_missing: f64,
    /// Mean Spearman ρ of σ̌_z against the captured σ_z over the judged candidates.
    pub mean_spearman_sigma: f64,
    /// Median log-det ratio, nats.
    pub median_logdet_ratio: f64,
    /// Mean over rankings (a bin's judged instance) of the predicted best view's oracle rank
    /// (1 is perfect).
    pub best_oracle_rank: f64,
    /// Mean over rankings of Spearman ρ between predicted and captured entropy.
    pub rank_spearman: f64,
}

/// The mean of the finite `values` (unjudged ones are NaN); NaN if there are none.
fn mean_finite(values: impl Iterator<Item = f64>) -> f64 {
    mean(&values.filter(|x| x.is_finite()).collect::<Vec<_>>())
}

/// Per part (in order of appearance) and `all`.
pub fn summary(rows: &[CandidateRow]) -> Vec<SummaryRow> {
    let parts = names_in_order(rows.iter().map(|r| r.part.as_str()));
    let of = |name: &str, rows: Vec<&CandidateRow>| {
        // A ranking is over one instance's candidates in one bin.
        let mut bins: Vec<(&str, u32, usize)> = rows
            .iter()
            .map(|r| (r.part.as_str(), r.scene, r.instance))
            .collect();
        bins.sort_unstable();
        bins.dedup();
        let in_bin = |b: &(&str, u32, usize)| {
            rows.iter()
                .filter(|r| (r.part.as_str(), r.scene, r.instance) == *b)
                .collect::<Vec<_>>()
        };
        SummaryRow {
            part: name.into(),
            candidates: rows.len(),
            mean_iou_missing: mean_finite(rows.iter().map(|r| r.iou_missing)),
            mean_spearman_sigma: mean_finite(rows.iter().map(|r| r.spearman_sigma)),
            median_logdet_ratio: median(rows.iter().map(|r| r.logdet_ratio).collect()),
            best_oracle_rank: mean_finite(bins.iter().filter_map(|b| {
                in_bin(b)
                    .iter()
                    .find(|r| r.predicted_rank == 1)
                    .map(|r| r.oracle_rank as f64)
            })),
            rank_spearman: mean_finite(bins.iter().map(|b| {
                let bin = in_bin(b);
                let p: Vec<f64> = bin.iter().map(|r| r.predicted_entropy_nats).collect();
                let c: Vec<f64> = bin.iter().map(|r| r.captured_entropy_nats).collect();
                spearman(&p, &c)
            })),
        }
    };
    let mut out: Vec<SummaryRow> = parts
        .iter()
        .map(|p| of(p, rows.iter().filter(|r| r.part == *p).collect()))
        .collect();
    out.push(of("all", rows.iter().collect()));
    out
}

/// `prediction.csv`: one row per candidate.
pub fn prediction_csv(rows: &[CandidateRow]) -> String {
    let mut out = String::from(
        "part,scene,view,iou_missing,spearman_sigma,logdet_ratio,predicted_rank,oracle_rank,\
         instance\n",
    );
    for r in rows {
        let _ = writeln!(
            out,
            "{},{},{},{:.4},{:.4},{:.4},{},{},{}",
            r.part,
            r.scene,
            r.view,
            r.iou_missing,
            r.spearman_sigma,
            r.logdet_ratio,
            r.predicted_rank,
            r.oracle_rank,
            r.instance
        );
    }
    out
}

impl SummaryRow {
    /// The row's cells, for `summary.csv` (4 decimals) or for reading (fewer, the log-det
    /// ratio signed).
    fn cells(&self, for_csv: bool) -> [String; 7] {
        let (d, rank_d) = if for_csv { (4, 2) } else { (3, 1) };
        let logdet = if for_csv {
            format!("{:.4}", self.median_logdet_ratio)
        } else {
            format!("{:+.2}", self.median_logdet_ratio)
        };
        [
            self.part.clone(),
            self.candidates.to_string(),
            format!("{:.d$}", self.mean_iou_missing),
            format!("{:.d$}", self.mean_spearman_sigma),
            logdet,
            format!("{:.rank_d$}", self.best_oracle_rank),
            format!("{:.d$}", self.rank_spearman),
        ]
    }
}

/// `summary.csv`.
pub fn summary_csv(summary: &[SummaryRow]) -> String {
    let mut out = String::from(
        "part,candidates,mean_iou_missing,mean_spearman_sigma,median_logdet_ratio,\
         best_oracle_rank,rank_spearman\n",
    );
    for s in summary {
        let _ = writeln!(out, "{}", s.cells(true).join(","));
    }
    out
}

/// The summary as a Markdown table.
pub fn summary_markdown(summary: &[SummaryRow], candidates: usize) -> String {
    let mut out = format!(
        "| part | candidates | IoU missing | ρ(σ̌_z, σ_z) | median log-det ratio (nats) | \
         oracle rank of predicted best (of {candidates}) | ρ(predicted, captured entropy) |\n\
         |---|---:|---:|---:|---:|---:|---:|\n"
    );
    for s in summary {
        let _ = writeln!(out, "| {} |", s.cells(false).join(" | "));
    }
    out
}

/// Fig. 8 for one view: single-path, multi-path, the first synthesised pattern image (grey,
/// 0 to the brightest DN of the three) and σ̌_z (colour ramp to τ_σ, missing pixels by cause
/// in [`MISSING_RGB`]), side by side with 4 px gaps, magnified when the crop is small.
pub fn fig8_png(view: &Fig8View) -> anyhow::Result<Vec<u8>> {
    let (w, h) = (view.sigma_z_m.width(), view.sigma_z_m.height());
    let grey = [
        &view.images.single_path_dn,
        &view.images.multi_path_dn,
        &view.images.pattern_dn,
    ];
    for image in grey {
        anyhow::ensure!(
            (image.width(), image.height()) == (w, h),
            "the prediction's images differ in size"
        );
    }
    let top = grey
        .iter()
        .flat_map(|i| i.data().iter().copied())
        .filter(|v| v.is_finite())
        .fold(1.0f32, f32::max);
    const GAP: u32 = 4;
    // Small crops are magnified (nearest pixel) to at least 240 px high.
    let zoom = (240 / h.max(1)).max(1);
    let (zw, zh) = (w * zoom, h * zoom);
    let width = 4 * zw + 3 * GAP;
    let mut rgb = vec![255u8; (width * zh * 3) as usize];
    for y in 0..zh {
        let v = y / zoom;
        for x in 0..zw {
            let u = x / zoom;
            let mut put = |panel: u32, colour: [u8; 3]| {
                let i = ((y * width + panel * (zw + GAP) + x) * 3) as usize;
                rgb[i..i + 3].copy_from_slice(&colour);
            };
            for (panel, image) in grey.iter().enumerate() {
                let g = (image.get(u, v).unwrap_or(0.0) / top * 255.0).clamp(0.0, 255.0) as u8;
                put(panel as u32, [g, g, g]);
            }
            let c = view.cause.get(u, v).unwrap_or(PixelCause::NotPart as u8);
            let colour = MISSING_RGB
                .iter()
                .find(|(k, _)| *k as u8 == c)
                .map(|(_, rgb)| *rgb)
                .unwrap_or_else(|| {
                    let s = f64::from(view.sigma_z_m.get(u, v).unwrap_or(f32::NAN));
                    glint_plot::ramp_rgb(s / view.scale_max_m)
                });
            put(3, colour);
        }
    }
    Ok(glint_plot::encode_rgb_png(&rgb, width, zh)?)
}

/// Writes `prediction.csv`, `summary.csv`, `summary.md`, `fig8_<part>.png` and `index.html` to
/// `spec.out`; returns the summary table.
pub fn write_outputs(
    spec: &PredictionExperiment,
    rows: &[CandidateRow],
    fig8: &[Fig8View],
) -> anyhow::Result<String> {
    let out = &spec.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let summary = summary(rows);
    let table = summary_markdown(&summary, spec.candidates);
    write_file_atomically(&out.join("prediction.csv"), prediction_csv(rows).as_bytes())?;
    write_file_atomically(&out.join("summary.csv"), summary_csv(&summary).as_bytes())?;
    write_file_atomically(&out.join("summary.md"), table.as_bytes())?;
    let mut figures = String::new();
    for view in fig8 {
        let name = format!("fig8_{}.png", view.part);
        write_file_atomically(&out.join(&name), &fig8_png(view)?)?;
        let _ = write!(
            figures,
            "<h2>{} (view {})</h2><img src={name}>",
            view.part, view.view
        );
    }
    let html = format!(
        "<!doctype html><html><head><meta charset=utf-8><title>Glint: is the prediction right?\
         </title></head><body style=\"font-family:sans-serif;margin:2em\"><h1>Predicted against \
         captured, per candidate</h1><p>{} bins per part, {} candidates, {}, {} materials. \
         Files: <a href=prediction.csv>prediction.csv</a>, <a href=summary.csv>summary.csv</a>.</p><pre>{table}</pre><p>Fig. 8, each part's \
         predicted best view of its first bin: single-path, multi-path, synthesised pattern, \
         σ̌_z (red: ratio test, magenta: σ test, orange: not seen by the right camera).</p>\
         {figures}</body></html>",
        spec.scenes,
        spec.candidates,
        spec.camera,
        spec.materials_label()
    );
    write_file_atomically(&out.join("index.html"), html.as_bytes())?;
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_geometry::image::PixelRect;

    #[test]
    fn missing_masks_are_compared_on_the_instance_only() {
        // A 10×10 crop at (5, 5) of a 20×20 image; the instance covers the crop's left 8
        // columns. Predicted missing: columns 0–1; captured missing: columns 1–2.
        fn image<T: Copy>(w: u32, h: u32, f: impl Fn(u32, u32) -> T) -> Image<T> {
            let data = (0..w * h).map(|i| f(i % w, i / w)).collect();
            Image::new(w, h, data).unwrap()
        }
        let crop = PixelRect::new(5, 5, 10, 10);
        let cause = image(10, 10, |u, _| {
            if u < 2 {
                PixelCause::Ratio as u8
            } else {
                PixelCause::Kept as u8
            }
        });
        // The capture's σ_z is the prediction's doubled, at the crop's offset.
        let sigma_predicted = image(10, 10, |u, v| (u + 10 * v) as f32);
        let sigma_captured = image(20, 20, |u, v| (u + 10 * v) as f32 * 2.0);
        let on = |u: u32, _| (5..13).contains(&u);
        let usable = |u: u32, _| !(6..8).contains(&u);
        let s = pixel_scores(&crop, &cause, &sigma_predicted, &sigma_captured, on, usable);
        assert_eq!(s.visible_px, 80);
        // Both missing: column 1 (10 px); either: columns 0–2 (30 px).
        assert!(
            (s.iou_missing - 10.0 / 30.0).abs() < 1e-12,
            "{}",
            s.iou_missing
        );
        // Kept by both: columns 3–7, σ monotone in each other: ρ = 1.
        assert!((s.spearman_sigma - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ranks_and_the_summary_follow_from_the_rows() {
        assert_eq!(ranks(&[0.3, -1.0, 2.0, 0.0]), vec![3, 1, 4, 2]);
        let row = |view, h_pred: f64, h_capt: f64, p, o| CandidateRow {
            part: "gear".into(),
            scene: 0,
            view,
            instance: 2,
            visible_px: 100,
            iou_missing: 0.5,
            // Unjudged on view 0: the mean is over the judged ones.
            spearman_sigma: if view == 0 { f64::NAN } else { 0.3 },
            logdet_ratio: 2.0 * (h_capt - h_pred),
            predicted_rank: p,
            oracle_rank: o,
            predicted_entropy_nats: h_pred,
            captured_entropy_nats: h_capt,
        };
        // The predicted best (view 1) is second by the capture.
        let rows = vec![row(0, -30.0, -31.0, 2, 1), row(1, -32.0, -30.5, 1, 2)];
        let s = summary(&rows);
        assert_eq!(s.len(), 2);
        // One part: `all` is that part under another name.
        assert_eq!(
            s[1],
            SummaryRow {
                part: "all".into(),
                ..s[0].clone()
            }
        );
        assert_eq!(s[0].best_oracle_rank, 2.0);
        assert_eq!(s[0].mean_spearman_sigma, 0.3);
        assert_eq!(s[0].rank_spearman, -1.0);
        // Median of {−2, 3}: the mean of the middle two.
        assert_eq!(s[0].median_logdet_ratio, 0.5);
    }

    #[test]
    fn the_summary_prints_the_same_numbers_to_csv_and_markdown() {
        let s = SummaryRow {
            part: "gear".into(),
            candidates: 60,
            mean_iou_missing: 0.12346,
            mean_spearman_sigma: -0.5,
            median_logdet_ratio: 0.25,
            best_oracle_rank: 3.2,
            rank_spearman: 0.75,
        };
        let csv = summary_csv(std::slice::from_ref(&s));
        assert_eq!(
            csv.lines().nth(1),
            Some("gear,60,0.1235,-0.5000,0.2500,3.20,0.7500")
        );
        let md = summary_markdown(&[s], 60);
        assert!(md.contains("(of 60)"));
        assert_eq!(
            md.lines().nth(2),
            Some("| gear | 60 | 0.123 | -0.500 | +0.25 | 3.2 | 0.750 |")
        );
    }
}
