//! The paper's Fig. 9 on mock-camera data: active sessions with each view policy — NBV
//! (rendered σ̌_z), NBV with constant σ_z, Random, Max-Distance — from the same detector pose on
//! the same bins, each for a fixed view budget; per number of views, the pose error and the
//! pose entropy. Evaluation code: the truth scores the steps, the sessions never see it.

use std::fmt::Write as _;

use glint_geometry::Part;
use glint_geometry::pose_deviation::CorrectThreshold;
use glint_orchestrator::local::{LocalEstimation, LocalPrediction};
use glint_orchestrator::session::{self, Session, Stages, ViewPolicy};
use glint_orchestrator::stages::PredictionStage;

use glint_estimation::pose_error_model::PoseErrorModel;

use crate::active::{
    ActiveSceneSpec, Calibration, Masking, deviations, prediction_object, session_config, set_up,
};
use crate::metrics::nees;

/// What to compare.
#[derive(Clone, Debug)]
pub struct PolicyComparison {
    /// The part dropped into every bin.
    pub part: Part,
    /// One bin per seed; disjoint from any seed used to choose settings.
    pub seeds: Vec<u64>,
    /// The view policies compared, each run on every bin.
    pub policies: Vec<ViewPolicy>,
    /// Views per session (the first, the detector's, included).
    pub views: usize,
    /// Candidate views on the cap above each bin; at least `views`.
    pub candidates: usize,
    /// Parts per bin.
    pub instances: u32,
    /// Width of the mock camera's images, px.
    pub width_px: u32,
    /// Height of the mock camera's images, px.
    pub height_px: u32,
    /// Samples per pixel of the mock camera's renders.
    pub samples_per_pixel: u32,
    /// How the part's pixels are found in each view.
    pub masking: Masking,
    /// The render workers render the bin with the part (beyond the paper).
    pub predict_with_bin: bool,
    /// The camera's error model on the part the sessions refine and plan under (`None`:
    /// eq 18's independent pixels).
    pub error_model: Option<PoseErrorModel>,
}

/// One step of one session.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StepRow {
    /// Seed of the bin.
    pub seed: u64,
    /// The view policy's name ([`ViewPolicy::name`]).
    pub policy: &'static str,
    /// Views taken after this step (1 = the detector's view only).
    pub views: usize,
    /// Index into the candidates of the view taken at this step.
    pub view: usize,
    /// Part points of all views taken so far.
    pub points: usize,
    /// Translation error of the refined pose against the truth (symmetry-aware), mm.
    pub err_mm: f64,
    /// Rotation error of the refined pose against the truth (symmetry-aware), degrees.
    pub err_deg: f64,
    /// Pose entropy after this step (the planner's prior included), nats.
    pub entropy_nats: f64,
    /// The entropy the planner predicted for this view (entropy policies, after the first).
    pub predicted_entropy_nats: Option<f64>,
    /// NEES of the refined pose against the truth under the session's information (its
    /// error model's), and under eq 18's independent pixels; `nees_dof` degrees of freedom.
    pub nees: f64,
    /// NEES under eq 18's information.
    pub nees_pixels: f64,
    /// Degrees of freedom of the NEES: 6, or 5 for a part with a continuous symmetry.
    pub nees_dof: usize,
    /// Time the step spent in the prediction stage, seconds.
    pub predict_s: f64,
    /// Wall-clock time of the whole step, from the previous step's end (or the session's
    /// start), seconds.
    pub step_s: f64,
}

/// Runs every policy on every seed's bin; `on_session` is told after each session.
pub fn run(
    spec: &PolicyComparison,
    calibration: Option<&Calibration>,
    mut on_session: impl FnMut(&[StepRow]),
) -> anyhow::Result<Vec<StepRow>> {
    anyhow::ensure!(!spec.seeds.is_empty(), "seeds: at least one bin");
    anyhow::ensure!(!spec.policies.is_empty(), "policies: at least one");
    anyhow::ensure!(
        (1..=spec.candidates).contains(&spec.views),
        "views: 1 to the {} candidates",
        spec.candidates
    );
    let needs_prediction = spec.policies.iter().any(|p| p.prediction(1e-3).is_some());
    anyhow::ensure!(
        calibration.is_some() || !needs_prediction,
        "the entropy policies need the part's calibration (material and response)"
    );
    let estimation = LocalEstimation::default();
    let workers = LocalPrediction::default();
    let mut rows = Vec::new();
    for &seed in &spec.seeds {
        let scene = set_up(&ActiveSceneSpec {
            part: spec.part,
            instances: spec.instances,
            seed,
            width_px: spec.width_px,
            height_px: spec.height_px,
            samples_per_pixel: spec.samples_per_pixel,
            candidates: spec.candidates,
        })?;
        let object = match calibration {
            Some(c) if needs_prediction => {
                Some(prediction_object(&scene, c, spec.predict_with_bin)?)
            }
            _ => None,
        };
        for &policy in &spec.policies {
            let config = session_config(
                &scene,
                policy,
                spec.views,
                None,
                seed,
                &spec.masking,
                spec.error_model,
            )?;
            let stages = Stages {
                camera: &scene.camera,
                estimation: &estimation,
                prediction: object
                    .as_ref()
                    .map(|o| (&workers as &dyn PredictionStage, o)),
            };
            let mut session = Session::new(format!("{seed}-{}", policy.name()), config)
                .map_err(anyhow::Error::msg)?;
            let started = std::time::Instant::now();
            let mut step_started = started;
            let mut step_s = Vec::new();
            let result = session::run(
                &mut session,
                &scene.object,
                &stages,
                |_| {
                    step_s.push(step_started.elapsed().as_secs_f64());
                    step_started = std::time::Instant::now();
                },
                || false,
            );
            if let Err(e) = result {
                // A refinement that fails (too few points) ends that session: record it as
                // such rather than dropping the bin from one policy only.
                tracing::warn!(seed, policy = policy.name(), "session failed: {e}");
            }
            let (_, devs) = deviations(&scene, &session.steps);
            let t_o_w_gt = scene.gt_t_w_o.inverse();
            let session_rows: Vec<StepRow> = session
                .steps
                .iter()
                .zip(&devs)
                .zip(&step_s)
                .map(|((s, d), &secs)| {
                    let t_o_w = s.t_w_o.inverse();
                    let (nees_model, nees_dof) =
                        nees(&t_o_w, &t_o_w_gt, &s.information, &scene.symmetry);
                    let (nees_pixels, _) =
                        nees(&t_o_w, &t_o_w_gt, &s.pixel_information, &scene.symmetry);
                    StepRow {
                        seed,
                        policy: policy.name(),
                        views: s.step + 1,
                        view: s.view,
                        points: s.total_points,
                        err_mm: d.translation_mm(),
                        err_deg: d.rotation_deg(),
                        entropy_nats: s.entropy_nats,
                        predicted_entropy_nats: s.predicted_entropy_nats,
                        nees: nees_model,
                        nees_pixels,
                        nees_dof,
                        predict_s: s.times.predict_ms * 1e-3,
                        step_s: secs,
                    }
                })
                .collect();
            on_session(&session_rows);
            rows.extend(session_rows);
        }
    }
    Ok(rows)
}

/// Per policy and number of views: sessions, mean translation/rotation error, the rates
/// within 5 mm/5° and 2 mm/2°, mean entropy, for the entropy policies the mean gap between
/// the entropy predicted for the view and the one reached, and the mean NEES over the poses
/// correct at 5 mm/5° (Table I's local check) under the sessions' information and eq 18's.
pub fn summary_markdown(rows: &[StepRow], policies: &[ViewPolicy], views: usize) -> String {
    let mut out = String::from(
        "| policy | views | sessions | mean err (mm) | mean err (°) | 5mm/5° | 2mm/2° | mean h (nats) | mean h − h_pred (nats) | mean NEES (dof) | mean NEES eq 18 | mean predict (s) |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for policy in policies {
        for k in 1..=views {
            let at: Vec<&StepRow> = rows
                .iter()
                .filter(|r| r.policy == policy.name() && r.views == k)
                .collect();
            if at.is_empty() {
                continue;
            }
            let n = at.len() as f64;
            let mean = |f: &dyn Fn(&StepRow) -> f64| at.iter().map(|r| f(r)).sum::<f64>() / n;
            let within = |r: &StepRow, t: &CorrectThreshold| {
                r.err_mm * 1e-3 < t.translation_m && r.err_deg.to_radians() < t.rotation_rad
            };
            let rate = |t: &CorrectThreshold| {
                100.0 * at.iter().filter(|r| within(r, t)).count() as f64 / n
            };
            let gaps: Vec<f64> = at
                .iter()
                .filter_map(|r| Some(r.entropy_nats - r.predicted_entropy_nats?))
                .collect();
            let gap = if gaps.is_empty() {
                "-".to_string()
            } else {
                format!("{:+.2}", gaps.iter().sum::<f64>() / gaps.len() as f64)
            };
            let correct: Vec<&&StepRow> = at
                .iter()
                .filter(|r| within(r, &CorrectThreshold::MM5_DEG5))
                .collect();
            let mean_nees = |f: &dyn Fn(&StepRow) -> f64| {
                if correct.is_empty() {
                    "-".to_string()
                } else {
                    let m = correct.iter().map(|r| f(r)).sum::<f64>() / correct.len() as f64;
                    format!("{m:.1}")
                }
            };
            let dof = correct.first().map_or(6, |r| r.nees_dof);
            let _ = writeln!(
                out,
                "| {} | {k} | {} | {:.2} | {:.2} | {:.0} % | {:.0} % | {:.2} | {gap} | {} ({dof}) | {} | {:.2} |",
                policy.name(),
                at.len(),
                mean(&|r| r.err_mm),
                mean(&|r| r.err_deg),
                rate(&CorrectThreshold::MM5_DEG5),
                rate(&CorrectThreshold::MM2_DEG2),
                mean(&|r| r.entropy_nats),
                mean_nees(&|r| r.nees),
                mean_nees(&|r| r.nees_pixels),
                mean(&|r| r.predict_s),
            );
        }
    }
    out
}
