//! The paper's Fig. 9 on mock-camera data, measured as the paper measures it (`glint eval
//! nbv`): every view policy chooses every view it uses — the first one included — among the
//! same candidates on the spherical cap, from the same initial pose hypotheses (a detector's,
//! drawn at a detection view), with the same refiner on the same segmented depth.
//!
//! - **NBV** (ours) and **NBV with constant σ_z** choose by the least predicted pose entropy
//!   (eq 20–23): the render workers' prediction of each open candidate (eq 14–17, 21–22; the
//!   constant-σ baseline uses visibility and Jacobians only) from the current estimate, with
//!   the part's *fitted* material and *calibrated* response — never the simulator's;
//! - **Random** uniformly among the open candidates, averaged over several draws;
//! - **Max-Distance** the candidate furthest from the detection view and every view taken;
//! - beyond the paper, **NBV under the error model** (`nbv_error_model`): NBV as a session
//!   under the part's measured error model plans — each candidate capped by its view bias,
//!   added to the information that survives the correlated depth error and the bias of the
//!   views taken. It refines as NBV does (the pose does not depend on the model) and shares
//!   NBV's predictions while their views agree.
//!
//! The loop is the paper's: capture the chosen view, refine on all views so far (from the
//! previous estimate; the first from the hypothesis moved along the detection view's ray onto
//! the first view's depth — the detector errs most along its own ray, and the cell knows where
//! it looked from), choose again. The part's pixels in a
//! view are its visible mask, eroded by the matching window — the stand-in for the paper's
//! instance segmentation network, as in Table I. The mock camera captures a view when a policy
//! first picks it; the capture is shared by every trial and policy of the scene.
//!
//! Evaluation code: the truth places the detector's guess, the segmentation and the scores;
//! the predictions and refinements never see it.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use glint_camera::setup::capture_seed;
use glint_estimation::depth_alignment::{DepthAlignmentConfig, align_depth_along};
use glint_estimation::nbv::{
    PosePrior, max_distance_view, plan_next_view, pose_entropy_nats, random_view,
};
use glint_estimation::points::DepthPoint;
use glint_estimation::pose_error_model::PoseErrorModel;
use glint_estimation::refine::{RefineStatus, SdfRefineConfig, refine_grid_config, refine_sdf};
use glint_estimation::view::{SigmaSource, points_in_mask, view_sigma};
use glint_geometry::Part;
use glint_geometry::io::write_file_atomically;
use glint_geometry::pose_deviation::{CorrectThreshold, PoseDeviation, pose_deviation};
use glint_geometry::sdf::SdfGrid;
use glint_orchestrator::local::{LocalPrediction, MockCamera};
use glint_orchestrator::session::{CONST_SIGMA_Z_M, ViewPolicy};
use glint_orchestrator::stages::{
    CameraStage, PredictionObject, PredictionRequest, PredictionStage,
};
use glint_render::integrator::render_labels;
use nalgebra::{Isometry3, Matrix6};
use rand::SeedableRng;
use rayon::prelude::*;

use crate::active::prediction_object_for;
use crate::initial_pose::InitialPoseNoise;
use crate::metrics::paired_sign_flip_p;
use crate::scenes::{CalibratedObject, MockCameraSpec, bin_seed, mock_bin, names_in_order};

/// The settings of one Fig. 9 run (`glint eval nbv`'s flags).
#[derive(Clone, Debug)]
pub struct NbvExperiment {
    /// The parts, each with its calibration.
    pub objects: Vec<CalibratedObject>,
    /// Bins per part.
    pub scenes: u32,
    /// Detection views per bin: trials start from a detector's guess at each of these
    /// candidates (spread evenly over the candidate list), for every instance at least
    /// `min_visib_fract` visible there.
    pub detection_views: u32,
    /// Views each policy takes per trial.
    pub max_views: usize,
    /// Candidate views on the cap above each bin (the detection views among them).
    pub candidates: usize,
    /// Parts per bin.
    pub instances: u32,
    /// Base seed: bin `s` has seed `seed·10⁴ + 8000 + s` (apart from Table I's evaluation and
    /// tuning bins); it also seeds the detector's guesses and the random draws.
    pub seed: u64,
    /// The mock camera.
    pub camera: MockCameraSpec,
    /// The policies compared.
    pub policies: Vec<ViewPolicy>,
    /// Draws of the Random policy per trial (its rates are their mean).
    pub random_draws: u32,
    /// An instance is a trial from a detection view where at least this share of it is
    /// visible (Table I's 0.8).
    pub min_visib_fract: f64,
    /// The render workers render the bin with the part (beyond the paper).
    pub predict_with_bin: bool,
    /// Beyond the paper: each part's measured error model, in `objects`' order, to run NBV
    /// under it as well (column [`NBV_ERROR_MODEL`]); empty: not run.
    pub error_models: Vec<PoseErrorModel>,
    /// Output directory.
    pub out: PathBuf,
}

/// The column of NBV planned under the part's error model.
pub const NBV_ERROR_MODEL: &str = "nbv_error_model";

impl NbvExperiment {
    /// The policies' columns in the output files, NBV under the error model last.
    pub fn columns(&self) -> Vec<&'static str> {
        let mut columns: Vec<&'static str> =
            self.policies.iter().map(|p| policy_column(*p)).collect();
        if !self.error_models.is_empty() {
            columns.push(NBV_ERROR_MODEL);
        }
        columns
    }
}

/// The policy's name in the output files (`nbv`, `nbv_const_sigma`, `random`, `max_distance`).
pub fn policy_column(policy: ViewPolicy) -> &'static str {
    match policy {
        ViewPolicy::Nbv => "nbv",
        ViewPolicy::NbvConstSigma => "nbv_const_sigma",
        ViewPolicy::Random => "random",
        ViewPolicy::MaxDistance => "max_distance",
    }
}

/// One refinement problem: an instance of a bin and a detector's guess of its pose.
#[derive(Clone, Debug)]
struct Trial {
    /// [`part_key`] of the part's name.
    part_key: u64,
    scene: u32,
    detection_view: usize,
    /// The detection view's left camera → world.
    detection_t_w_c: Isometry3<f64>,
    /// Index of the instance among the bin's poses.
    instance: usize,
    gt_t_w_o: Isometry3<f64>,
    initial_t_w_o: Isometry3<f64>,
}

/// One policy's run on one trial.
#[derive(Clone, Debug)]
struct Run {
    trial: usize,
    policy: ViewPolicy,
    /// NBV planning under the part's error model ([`NBV_ERROR_MODEL`]).
    under_model: bool,
    /// Which draw of the Random policy (0 for the others).
    draw: u32,
    views: Vec<usize>,
    t_w_o: Isometry3<f64>,
    information: Matrix6<f64>,
    /// The entropy the policy predicted for the view it chose last (entropy policies).
    predicted_entropy_nats: Option<f64>,
    predict_ms: f64,
}

impl Run {
    /// The error model this run plans under: the part's `model` if it is the NBV run under
    /// it, none otherwise.
    fn planning_model<'a>(&self, model: Option<&'a PoseErrorModel>) -> Option<&'a PoseErrorModel> {
        model.filter(|_| self.under_model)
    }

    fn column(&self) -> &'static str {
        if self.under_model {
            NBV_ERROR_MODEL
        } else {
            policy_column(self.policy)
        }
    }

    /// What its next decision needs predicted, if anything: its trial, views so far (its
    /// estimate follows from them) and σ source. Runs with the same key read one prediction:
    /// NBV and NBV under the error model while their views agree (their estimates then agree
    /// to rounding; the request's seed is the same, draw 0).
    fn prediction_key(&self) -> Option<(usize, Vec<usize>, &'static str)> {
        self.policy
            .prediction(CONST_SIGMA_Z_M)
            .map(|_| (self.trial, self.views.clone(), policy_column(self.policy)))
    }
}

/// A run's seed for its decisions and predictions.
fn run_seed(seed: u64, run: &Run, trial: &Trial) -> u64 {
    seed ^ (trial_key(trial) << 8) ^ u64::from(run.draw).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// One run's view of its predicted candidates: each candidate's information (zeros where
/// taken) and the time the prediction took.
type Predicted = (Vec<Matrix6<f64>>, f64);

/// One step of one run: the pose after `views` views.
#[derive(Clone, Debug, PartialEq)]
pub struct StepRow {
    /// The part's name.
    pub part: String,
    /// The bin's index among the part's bins.
    pub scene: u32,
    /// The candidate the detector looked from.
    pub detection_view: usize,
    /// The instance's index among the bin's parts.
    pub instance: usize,
    /// The policy ([`policy_column`]).
    pub policy: &'static str,
    /// Which draw of the Random policy (0 for the others).
    pub draw: u32,
    /// Views taken so far.
    pub views: usize,
    /// The candidate taken at this step.
    pub view: usize,
    /// Points of the instance in this view.
    pub view_points: usize,
    /// The pose's error against the truth (symmetry-aware).
    pub deviation: PoseDeviation,
    /// Pose entropy after the step (eq 18's information with the prior), nats.
    pub entropy_nats: f64,
    /// The entropy the policy predicted for this view (entropy policies), nats.
    pub predicted_entropy_nats: Option<f64>,
    /// The refinement's outcome (`converged`, `max_iterations`, `diverged`, `no points`, or
    /// the error).
    pub status: String,
    /// Time the decision for this view spent predicting candidates, ms.
    pub predict_ms: f64,
    /// The initial pose's error against the truth.
    pub initial_deviation: PoseDeviation,
}

impl StepRow {
    fn correct(&self, threshold: &CorrectThreshold) -> bool {
        self.deviation.is_correct(threshold)
    }
}

/// A captured view as the trials use it: each instance's segmented depth points with σ_z.
struct ViewCapture {
    /// Per instance (index into the bin's poses), its points (world frame, eq 1–7).
    points: Vec<Vec<DepthPoint>>,
}

/// Captures candidate `view` of `camera` and segments it: σ_z from the pattern images
/// (eq 1–5), each instance's visible mask eroded by `erode_px` (the stand-in segmentation).
fn capture_view(
    camera: &MockCamera,
    t_w_c: &Isometry3<f64>,
    seed: u64,
    window_radius_px: u32,
) -> anyhow::Result<ViewCapture> {
    let view = camera
        .capture(t_w_c, seed)
        .map_err(|e| anyhow::anyhow!("capture: {e}"))?
        .measurement;
    let sigma = view_sigma(
        &view,
        &SigmaSource::PatternImages {
            window_radius_px,
            noise: None,
        },
    )?;
    let setup = &camera.setup;
    let [left, _] = setup.rig.cameras(t_w_c);
    // Each instance's visible mask (what `instance_visibility` calls `mask_visib`), without
    // the amodal renders it would add per instance.
    let visible_labels = render_labels(&setup.scene, &left, None, None);
    let points = (1..=setup.poses.len() as u16)
        .map(|label| {
            let mask = visible_labels.map(|l| l == label);
            Ok(points_in_mask(&view, &mask, &sigma, window_radius_px)?.points)
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(ViewCapture { points })
}

/// The candidates the trials' detectors look from: `count` spread evenly over `candidates`.
fn detection_views(count: u32, candidates: usize) -> Vec<usize> {
    let count = (count as usize).clamp(1, candidates);
    (0..count).map(|i| i * candidates / count).collect()
}

/// The prediction an entropy policy's run reads: every open candidate from its estimate.
fn predict(
    run: &Run,
    trial: &Trial,
    candidates: &[Isometry3<f64>],
    prediction: &(LocalPrediction, PredictionObject),
    seed: u64,
) -> anyhow::Result<Predicted> {
    let sigma = run
        .policy
        .prediction(CONST_SIGMA_Z_M)
        .context("a policy without a prediction")?;
    let (workers, object) = prediction;
    let request = PredictionRequest {
        t_w_o: run.t_w_o,
        candidates: candidates
            .iter()
            .enumerate()
            .filter(|(i, _)| !run.views.contains(i))
            .map(|(i, t)| (i as u32, *t))
            .collect(),
        sigma,
        seed: run_seed(seed, run, trial),
        with_maps: false,
    };
    let started = Instant::now();
    let predicted = workers
        .predict(object, &request)
        .map_err(|e| anyhow::anyhow!("predicting: {e}"))?;
    let predict_ms = started.elapsed().as_secs_f64() * 1e3;
    let mut informations = vec![Matrix6::zeros(); candidates.len()];
    for p in &predicted {
        if let Some(slot) = informations.get_mut(p.index as usize) {
            *slot = p.information;
        }
    }
    Ok((informations, predict_ms))
}

/// The decision of one run: its next view, the entropy predicted for it and the time spent
/// predicting. Entropy policies read `predicted` (their [`Run::prediction_key`]'s); under
/// `model` each candidate is capped by its view bias, as a session under the model plans.
fn choose(
    run: &Run,
    trial: &Trial,
    candidates: &[Isometry3<f64>],
    predicted: Option<&Predicted>,
    model: Option<&PoseErrorModel>,
    prior: &PosePrior,
    seed: u64,
) -> anyhow::Result<(usize, Option<f64>, f64)> {
    let step = run.views.len();
    let Some((informations, predict_ms)) = predicted else {
        let view = match run.policy {
            ViewPolicy::Random => random_view(
                candidates.len(),
                &run.views,
                run_seed(seed, run, trial),
                step,
            )?,
            ViewPolicy::MaxDistance => {
                // Furthest from the detection view and every view taken.
                let mut from = run.views.clone();
                from.push(trial.detection_view);
                max_distance_view(candidates, &from)?
            }
            other => anyhow::bail!("{} reads a prediction", policy_column(other)),
        };
        return Ok((view, None, 0.0));
    };
    let capped: Vec<Matrix6<f64>>;
    let informations = match run.planning_model(model) {
        Some(model) => {
            capped = informations
                .iter()
                .zip(candidates)
                .map(|(f, t_w_c)| model.predicted_candidate_information(f, &run.t_w_o, t_w_c))
                .collect();
            &capped
        }
        None => informations,
    };
    let plan = plan_next_view(&run.information, informations, &run.views, prior)?;
    let h = plan.entropies_nats.get(plan.chosen).copied().flatten();
    Ok((plan.chosen, h, *predict_ms))
}

/// A number naming a part by its name, so that a trial's seeds do not depend on which other
/// parts the run has (`--parts gear` draws the Gear's trials of `--parts all`): a shipped
/// part's place in [`Part::ALL`] (its place in `--parts all`, the published runs' key), any
/// other mesh its name's 64-bit FNV-1a.
fn part_key(name: &str) -> u64 {
    match Part::ALL.iter().position(|p| p.name() == name) {
        Some(index) => index as u64,
        None => name.bytes().fold(0xCBF2_9CE4_8422_2325, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01B3)
        }),
    }
}

/// A number naming a trial (its part, bin, detection view and instance) for seeds.
fn trial_key(trial: &Trial) -> u64 {
    trial.part_key.rotate_left(40)
        ^ (u64::from(trial.scene) << 24
            | (trial.detection_view as u64) << 12
            | trial.instance as u64)
}

/// The refinement after a run's newest view: all its views' points of the trial's instance,
/// from the previous estimate (the first from the hypothesis aligned along the first view's
/// rays onto its depth). Returns the status; a run whose views hold no points keeps its pose.
/// A run under the error model keeps the information under `model` (the views' cameras from
/// `candidates`), any other eq 18's.
fn refine_run(
    run: &mut Run,
    trial: &Trial,
    captures: &HashMap<usize, ViewCapture>,
    candidates: &[Isometry3<f64>],
    model: Option<&PoseErrorModel>,
    grid: &SdfGrid,
    config: &SdfRefineConfig,
) -> String {
    let of = |v: &usize| {
        captures
            .get(v)
            .and_then(|c| c.points.get(trial.instance))
            .map_or(&[][..], |p| p.as_slice())
    };
    let points: Vec<DepthPoint> = run
        .views
        .iter()
        .flat_map(|v| of(v).iter().copied())
        .collect();
    if points.is_empty() {
        return "no points".into();
    }
    let mut t_o_w = run.t_w_o.inverse();
    if run.views.len() == 1 {
        // The detector errs along its own viewing ray, whichever view the depth comes from.
        let ray_w = run.t_w_o.translation.vector - trial.detection_t_w_c.translation.vector;
        t_o_w = align_depth_along(
            grid,
            &points,
            &t_o_w,
            &ray_w,
            &DepthAlignmentConfig::default(),
        )
        .map_or(t_o_w, |a| a.t_o_w);
    }
    match refine_sdf(grid, &points, &t_o_w, config) {
        Ok(r) if r.status != RefineStatus::Diverged => {
            run.t_w_o = r.t_o_w.inverse();
            run.information = match run.planning_model(model) {
                Some(model) => model.refined_information(
                    grid,
                    run.views.iter().map(|v| (of(v), candidates[*v])),
                    &r.t_o_w,
                    config,
                ),
                None => r.information,
            };
            format!("{:?}", r.status).to_lowercase()
        }
        Ok(_) => "diverged".into(),
        Err(e) => format!("error: {e}"),
    }
}

/// Runs the experiment; `on_scene` is told after each bin (part name, bin, its trials, every
/// step so far — so a caller can write what is done before a long run ends). Returns every
/// step of every run.
pub fn run(
    spec: &NbvExperiment,
    mut on_scene: impl FnMut(&str, u32, usize, &[StepRow]) -> anyhow::Result<()>,
) -> anyhow::Result<Vec<StepRow>> {
    anyhow::ensure!(!spec.objects.is_empty(), "parts: at least one");
    anyhow::ensure!(!spec.policies.is_empty(), "policies: at least one");
    anyhow::ensure!(spec.scenes >= 1, "scenes: at least one bin");
    anyhow::ensure!(
        (1..=spec.candidates).contains(&spec.max_views),
        "max_views: 1 to the {} candidates",
        spec.candidates
    );
    anyhow::ensure!(spec.random_draws >= 1, "random_draws: at least one");
    anyhow::ensure!(
        spec.error_models.is_empty() || spec.error_models.len() == spec.objects.len(),
        "error_models: one per part ({} parts, {} models)",
        spec.objects.len(),
        spec.error_models.len()
    );
    for (model, part) in spec.error_models.iter().zip(&spec.objects) {
        model.validate().map_err(|e| {
            anyhow::anyhow!(
                "error_models ({}): {}: {}",
                part.object.name,
                e.field,
                e.message
            )
        })?;
    }
    spec.camera
        .rig_and_config()
        .context("the camera's settings")?;
    let refine_config = SdfRefineConfig::default();
    let prior = PosePrior::default();
    let noise = InitialPoseNoise::default();
    let mut rows = Vec::new();
    for (part_index, part) in spec.objects.iter().enumerate() {
        let object = &part.object;
        let model = spec.error_models.get(part_index);
        let grid = SdfGrid::build(&object.mesh, &refine_grid_config())
            .with_context(|| format!("SDF of {}", object.name))?;
        let session_object = object.session_object();
        for s in 0..spec.scenes {
            let scene_seed = bin_seed(spec.seed, 8000, s);
            let (camera, candidates) = mock_bin(
                object,
                spec.instances,
                scene_seed,
                spec.candidates,
                &spec.camera,
            )
            .with_context(|| format!("{} bin {s}", object.name))?;
            let prediction = (
                LocalPrediction::default(),
                prediction_object_for(
                    &camera,
                    &candidates[0],
                    &session_object,
                    &part.calibration,
                    spec.predict_with_bin,
                )?,
            );
            // Trials: every instance visible enough from each detection view, its pose guessed
            // there by the stand-in detector.
            let setup = &camera.setup;
            let mut trials = Vec::new();
            for d in detection_views(spec.detection_views, candidates.len()) {
                let t_c_w = candidates[d].inverse();
                for (instance, v) in setup.instance_visibility(&candidates[d]).iter().enumerate() {
                    if v.visib_fract < spec.min_visib_fract {
                        continue;
                    }
                    let gt_t_w_o = setup.poses[instance];
                    let mut trial = Trial {
                        part_key: part_key(&object.name),
                        scene: s,
                        detection_view: d,
                        detection_t_w_c: candidates[d],
                        instance,
                        gt_t_w_o,
                        initial_t_w_o: gt_t_w_o,
                    };
                    let mut rng =
                        rand_pcg::Pcg64::seed_from_u64(spec.seed ^ trial_key(&trial) ^ 0xF19);
                    let t_c_o = noise.draw(&(t_c_w * gt_t_w_o), &object.symmetry, &mut rng);
                    trial.initial_t_w_o = candidates[d] * t_c_o;
                    trials.push(trial);
                }
            }
            let mut runs: Vec<Run> = Vec::new();
            for (t, trial) in trials.iter().enumerate() {
                let under_model = model.map(|_| (ViewPolicy::Nbv, true));
                let plans = spec.policies.iter().map(|p| (*p, false)).chain(under_model);
                for (policy, under_model) in plans {
                    let draws = if policy == ViewPolicy::Random {
                        spec.random_draws
                    } else {
                        1
                    };
                    for draw in 0..draws {
                        runs.push(Run {
                            trial: t,
                            policy,
                            under_model,
                            draw,
                            views: Vec::new(),
                            t_w_o: trial.initial_t_w_o,
                            information: Matrix6::zeros(),
                            predicted_entropy_nats: None,
                            predict_ms: 0.0,
                        });
                    }
                }
            }
            let mut captures: HashMap<usize, ViewCapture> = HashMap::new();
            for _step in 0..spec.max_views {
                // 1. The predictions the entropy policies read, once per key (the renders are
                //    parallel inside too); then every run chooses its next view.
                let mut keys: HashMap<(usize, Vec<usize>, &'static str), usize> = HashMap::new();
                let mut first_of_key = Vec::new();
                for (i, r) in runs.iter().enumerate() {
                    if let Some(key) = r.prediction_key() {
                        keys.entry(key).or_insert_with(|| {
                            first_of_key.push(i);
                            first_of_key.len() - 1
                        });
                    }
                }
                let predicted: Vec<Predicted> = first_of_key
                    .par_iter()
                    .map(|&i| {
                        let r = &runs[i];
                        predict(r, &trials[r.trial], &candidates, &prediction, spec.seed)
                    })
                    .collect::<anyhow::Result<_>>()?;
                let choices: Vec<(usize, Option<f64>, f64)> = runs
                    .par_iter()
                    .map(|r| {
                        let read = r
                            .prediction_key()
                            .and_then(|k| keys.get(&k))
                            .map(|&k| &predicted[k]);
                        choose(
                            r,
                            &trials[r.trial],
                            &candidates,
                            read,
                            model,
                            &prior,
                            spec.seed,
                        )
                    })
                    .collect::<anyhow::Result<_>>()?;
                // 2. The views no run has seen yet are captured, once each.
                let mut needed: Vec<usize> = choices.iter().map(|c| c.0).collect();
                needed.sort_unstable();
                needed.dedup();
                for v in needed {
                    if let std::collections::hash_map::Entry::Vacant(e) = captures.entry(v) {
                        e.insert(capture_view(
                            &camera,
                            &candidates[v],
                            capture_seed(scene_seed, v),
                            spec.camera.window_radius_px,
                        )?);
                    }
                }
                // 3. Every run refines on its views so far.
                let statuses: Vec<String> = runs
                    .par_iter_mut()
                    .zip(&choices)
                    .map(|(r, &(view, h, ms))| {
                        r.views.push(view);
                        r.predicted_entropy_nats = h;
                        r.predict_ms = ms;
                        refine_run(
                            r,
                            &trials[r.trial],
                            &captures,
                            &candidates,
                            model,
                            &grid,
                            &refine_config,
                        )
                    })
                    .collect();
                for (r, status) in runs.iter().zip(statuses) {
                    let trial = &trials[r.trial];
                    let deviation = |t_w_o: &Isometry3<f64>| -> PoseDeviation {
                        pose_deviation(t_w_o, &trial.gt_t_w_o, &object.symmetry)
                    };
                    let (d, d0) = (deviation(&r.t_w_o), deviation(&trial.initial_t_w_o));
                    let view = r.views.last().copied().unwrap_or_default();
                    rows.push(StepRow {
                        part: object.name.clone(),
                        scene: s,
                        detection_view: trial.detection_view,
                        instance: trial.instance,
                        policy: r.column(),
                        draw: r.draw,
                        views: r.views.len(),
                        view,
                        view_points: captures
                            .get(&view)
                            .and_then(|c| c.points.get(trial.instance))
                            .map_or(0, Vec::len),
                        deviation: d,
                        entropy_nats: pose_entropy_nats(&r.information, &prior)?,
                        predicted_entropy_nats: r.predicted_entropy_nats,
                        status,
                        predict_ms: r.predict_ms,
                        initial_deviation: d0,
                    });
                }
            }
            on_scene(&object.name, s, trials.len(), &rows)?;
        }
    }
    Ok(rows)
}

/// One cell of the results: a part (or `all`), a policy and a view count.
#[derive(Clone, Debug, PartialEq)]
pub struct RateRow {
    /// The part's name, or `all`.
    pub part: String,
    /// The policy ([`policy_column`]).
    pub policy: &'static str,
    /// Views taken.
    pub views: usize,
    /// Trials.
    pub n: usize,
    /// Share of trials within 5 mm/5° (Random: the mean over its draws).
    pub rate_5mm5deg: f64,
    /// Share of trials within 2 mm/2°.
    pub rate_2mm2deg: f64,
}

/// Per trial (part, bin, detection view, instance) and view count, each policy's success at
/// `threshold`, Random's averaged over its draws.
type TrialKey = (String, u32, usize, usize, usize);

fn successes(
    rows: &[StepRow],
    threshold: &CorrectThreshold,
) -> HashMap<(&'static str, TrialKey), f64> {
    let mut sums: HashMap<(&'static str, TrialKey), (f64, usize)> = HashMap::new();
    for r in rows {
        let key = (
            r.policy,
            (
                r.part.clone(),
                r.scene,
                r.detection_view,
                r.instance,
                r.views,
            ),
        );
        let e = sums.entry(key).or_default();
        e.0 += f64::from(u8::from(r.correct(threshold)));
        e.1 += 1;
    }
    sums.into_iter()
        .map(|(k, (s, n))| (k, s / n as f64))
        .collect()
}

/// The rates per part (and `all`), policy and view count.
pub fn rates(rows: &[StepRow], columns: &[&'static str], max_views: usize) -> Vec<RateRow> {
    let five = successes(rows, &CorrectThreshold::MM5_DEG5);
    let two = successes(rows, &CorrectThreshold::MM2_DEG2);
    let mut parts = names_in_order(rows.iter().map(|r| r.part.as_str()));
    parts.push("all");
    let mut out = Vec::new();
    for part in &parts {
        for &name in columns {
            for views in 1..=max_views {
                let keep = |k: &(&'static str, TrialKey)| {
                    k.0 == name && k.1.4 == views && (*part == "all" || k.1.0 == *part)
                };
                let hits: Vec<f64> = five.iter().filter(|(k, _)| keep(k)).map(|e| *e.1).collect();
                let hits2: Vec<f64> = two.iter().filter(|(k, _)| keep(k)).map(|e| *e.1).collect();
                if hits.is_empty() {
                    continue;
                }
                let n = hits.len();
                out.push(RateRow {
                    part: part.to_string(),
                    policy: name,
                    views,
                    n,
                    rate_5mm5deg: hits.iter().sum::<f64>() / n as f64,
                    rate_2mm2deg: hits2.iter().sum::<f64>() / n as f64,
                });
            }
        }
    }
    out
}

/// A planner (NBV, or NBV under the error model) against another policy on the same trials
/// at one view count and threshold.
#[derive(Clone, Debug, PartialEq)]
pub struct PairedRow {
    /// The part's name, or `all`.
    pub part: String,
    /// The planner: [`ViewPolicy::Nbv`]'s column or [`NBV_ERROR_MODEL`].
    pub policy: &'static str,
    /// The policy the planner is compared with.
    pub other: &'static str,
    /// Views taken.
    pub views: usize,
    /// `5mm5deg` or `2mm2deg`.
    pub threshold: &'static str,
    /// Trials both policies ran.
    pub n: usize,
    /// The planner's rate minus the other's, percentage points.
    pub margin_points: f64,
    /// Two-sided p of the paired sign-flip test on the per-trial differences.
    pub p: f64,
}

/// Each planner run (NBV, then NBV under the error model) against every other policy, per
/// part and `all`, view count and threshold; a pair of planners is compared once.
pub fn paired(rows: &[StepRow], columns: &[&'static str], max_views: usize) -> Vec<PairedRow> {
    let mut out = Vec::new();
    let planners: Vec<&'static str> = [policy_column(ViewPolicy::Nbv), NBV_ERROR_MODEL]
        .into_iter()
        .filter(|c| columns.contains(c))
        .collect();
    let mut parts = names_in_order(rows.iter().map(|r| r.part.as_str()));
    parts.push("all");
    for (threshold_name, threshold) in [
        ("5mm5deg", CorrectThreshold::MM5_DEG5),
        ("2mm2deg", CorrectThreshold::MM2_DEG2),
    ] {
        let s = successes(rows, &threshold);
        for (rank, &policy) in planners.iter().enumerate() {
            for part in &parts {
                for &other in columns
                    .iter()
                    .filter(|c| **c != policy && !planners[..rank].contains(c))
                {
                    for views in 1..=max_views {
                        let mut d: Vec<f64> = s
                            .iter()
                            .filter(|((p, k), _)| {
                                *p == policy && k.4 == views && (*part == "all" || k.0 == *part)
                            })
                            .filter_map(|((_, k), &hit)| Some(hit - s.get(&(other, k.clone()))?))
                            .collect();
                        if d.is_empty() {
                            continue;
                        }
                        // The map's order is arbitrary; the test's resampling is seeded, so sort.
                        d.sort_by(f64::total_cmp);
                        out.push(PairedRow {
                            part: part.to_string(),
                            policy,
                            other,
                            views,
                            threshold: threshold_name,
                            n: d.len(),
                            margin_points: 100.0 * d.iter().sum::<f64>() / d.len() as f64,
                            p: paired_sign_flip_p(&d, 20_000, 0xF169),
                        });
                    }
                }
            }
        }
    }
    out
}

/// `results.csv`: `part,policy,views,n,rate_5mm5deg,rate_2mm2deg`.
pub fn results_csv(rates: &[RateRow]) -> String {
    let mut out = String::from("part,policy,views,n,rate_5mm5deg,rate_2mm2deg\n");
    for r in rates {
        let _ = writeln!(
            out,
            "{},{},{},{},{:.4},{:.4}",
            r.part, r.policy, r.views, r.n, r.rate_5mm5deg, r.rate_2mm2deg
        );
    }
    out
}

/// `trials.csv`: one row per trial, policy, draw and step.
pub fn trials_csv(rows: &[StepRow]) -> String {
    let mut out = String::from(
        "part,scene,detection_view,instance,policy,draw,views,view,view_points,err_mm,err_deg,\
         entropy_nats,predicted_entropy_nats,status,predict_ms,initial_err_mm,initial_err_deg\n",
    );
    for r in rows {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{:.4},{:.4},{:.4},{},{},{:.1},{:.4},{:.4}",
            r.part,
            r.scene,
            r.detection_view,
            r.instance,
            r.policy,
            r.draw,
            r.views,
            r.view,
            r.view_points,
            r.deviation.translation_mm(),
            r.deviation.rotation_deg(),
            r.entropy_nats,
            r.predicted_entropy_nats
                .map_or(String::new(), |h| format!("{h:.4}")),
            r.status.replace(',', ";"),
            r.predict_ms,
            r.initial_deviation.translation_mm(),
            r.initial_deviation.rotation_deg()
        );
    }
    out
}

/// `table.md`: the rates at 5 mm/5° and 2 mm/2° per part and view count, one column per
/// policy, and the planners' paired margins on `all`.
pub fn table_markdown(
    rates: &[RateRow],
    paired: &[PairedRow],
    columns: &[&'static str],
    max_views: usize,
) -> String {
    let mut out = String::new();
    let parts = names_in_order(rates.iter().map(|r| r.part.as_str()));
    let _ = writeln!(
        out,
        "Rates within 5 mm/5° · 2 mm/2° (%), n trials per cell (Random: the mean of its draws).\n"
    );
    let _ = write!(out, "| part | views | n |");
    for c in columns {
        let _ = write!(out, " {c} |");
    }
    let _ = writeln!(out);
    let _ = write!(out, "|---|---:|---:|");
    for _ in columns {
        let _ = write!(out, "---:|");
    }
    let _ = writeln!(out);
    for part in &parts {
        for views in 1..=max_views {
            let cells: Vec<Option<&RateRow>> = columns
                .iter()
                .map(|c| {
                    rates
                        .iter()
                        .find(|r| r.part == *part && r.views == views && r.policy == *c)
                })
                .collect();
            let Some(n) = cells.iter().flatten().map(|r| r.n).next() else {
                continue;
            };
            let _ = write!(out, "| {part} | {views} | {n} |");
            for c in &cells {
                match c {
                    Some(r) => {
                        let _ = write!(
                            out,
                            " {:.1} · {:.1} |",
                            100.0 * r.rate_5mm5deg,
                            100.0 * r.rate_2mm2deg
                        );
                    }
                    None => {
                        let _ = write!(out, " – |");
                    }
                }
            }
            let _ = writeln!(out);
        }
    }
    if !paired.is_empty() {
        let _ = writeln!(
            out,
            "\nEach planner minus each other policy on `all`, percentage points, with the \
             two-sided p of a paired sign-flip test over the trials (20 000 resamples).\n\n\
             | policy | other | views | threshold | n | margin | p |\n\
             |---|---|---:|---|---:|---:|---:|"
        );
        for p in paired.iter().filter(|p| p.part == "all") {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {:+.1} | {:.4} |",
                p.policy, p.other, p.views, p.threshold, p.n, p.margin_points, p.p
            );
        }
    }
    out
}

/// `fig9.png`: per part and `all`, the rate within 5 mm/5° (solid) and 2 mm/2° (dashed)
/// against views, one colour per policy.
pub fn fig9_png(
    rates: &[RateRow],
    columns: &[&'static str],
    max_views: usize,
) -> anyhow::Result<Vec<u8>> {
    use plotters::prelude::*;
    let parts = names_in_order(rates.iter().map(|r| r.part.as_str()));
    let colours = [BLUE, RGBColor(230, 180, 0), RED, GREEN, MAGENTA, CYAN];
    let panel_columns = 3usize;
    let rows_n = parts.len().div_ceil(panel_columns).max(1);
    Ok(glint_plot::png(
        (360 * panel_columns) as u32,
        (300 * rows_n) as u32,
        |root| {
            let areas = root.split_evenly((rows_n, panel_columns));
            for (area, part) in areas.iter().zip(&parts) {
                let mut chart = ChartBuilder::on(area)
                    .caption(*part, (glint_plot::FONT, 18))
                    .margin(8)
                    .x_label_area_size(28)
                    .y_label_area_size(40)
                    .build_cartesian_2d(0.8..max_views as f64 + 0.2, 0.0..100.0)?;
                chart
                    .configure_mesh()
                    .x_desc("views")
                    .y_desc("% correct")
                    .draw()?;
                for (&name, colour) in columns.iter().zip(colours.iter().cycle()) {
                    let series = |f: &dyn Fn(&RateRow) -> f64| -> Vec<(f64, f64)> {
                        rates
                            .iter()
                            .filter(|r| r.part == *part && r.policy == name)
                            .map(|r| (r.views as f64, 100.0 * f(r)))
                            .collect()
                    };
                    let c = *colour;
                    chart
                        .draw_series(LineSeries::new(
                            series(&|r| r.rate_5mm5deg),
                            c.stroke_width(2),
                        ))?
                        .label(name)
                        .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], c));
                    chart.draw_series(DashedLineSeries::new(
                        series(&|r| r.rate_2mm2deg),
                        5,
                        4,
                        c.stroke_width(1),
                    ))?;
                }
                if *part == "all" {
                    chart
                        .configure_series_labels()
                        .position(SeriesLabelPosition::LowerRight)
                        .border_style(BLACK)
                        .draw()?;
                }
            }
            Ok(())
        },
    )?)
}

/// Writes `results.csv`, `trials.csv`, `paired.csv`, `table.md`, `fig9.png` and `index.html`
/// to `spec.out`; returns the table.
pub fn write_outputs(spec: &NbvExperiment, rows: &[StepRow]) -> anyhow::Result<String> {
    let out = &spec.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let columns = spec.columns();
    let rates = rates(rows, &columns, spec.max_views);
    let paired = paired(rows, &columns, spec.max_views);
    let table = table_markdown(&rates, &paired, &columns, spec.max_views);
    let mut paired_csv = String::from("part,policy,other,views,threshold,n,margin_points,p\n");
    for p in &paired {
        let _ = writeln!(
            paired_csv,
            "{},{},{},{},{},{},{:.2},{:.5}",
            p.part, p.policy, p.other, p.views, p.threshold, p.n, p.margin_points, p.p
        );
    }
    write_file_atomically(&out.join("results.csv"), results_csv(&rates).as_bytes())?;
    write_file_atomically(&out.join("trials.csv"), trials_csv(rows).as_bytes())?;
    write_file_atomically(&out.join("paired.csv"), paired_csv.as_bytes())?;
    write_file_atomically(&out.join("table.md"), table.as_bytes())?;
    write_file_atomically(
        &out.join("fig9.png"),
        &fig9_png(&rates, &columns, spec.max_views)?,
    )?;
    let html = format!(
        "<!doctype html><html><head><meta charset=utf-8><title>Glint: Fig. 9</title></head>\
         <body style=\"font-family:sans-serif;margin:2em\"><h1>Next-best-view policies (Fig. 9)</h1>\
         <p>{} bins per part, {} candidates, {} views, {}. Files: \
         <a href=results.csv>results.csv</a>, <a href=trials.csv>trials.csv</a>, \
         <a href=paired.csv>paired.csv</a>.</p><img src=fig9.png><pre>{table}</pre></body></html>",
        spec.scenes, spec.candidates, spec.max_views, spec.camera
    );
    write_file_atomically(&out.join("index.html"), html.as_bytes())?;
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(policy: &'static str, draw: u32, instance: usize, views: usize, err: f64) -> StepRow {
        StepRow {
            part: "gear".into(),
            scene: 0,
            detection_view: 0,
            instance,
            policy,
            draw,
            views,
            view: 0,
            view_points: 10,
            deviation: PoseDeviation {
                translation_m: err * 1e-3,
                rotation_rad: err.to_radians(),
            },
            entropy_nats: 0.0,
            predicted_entropy_nats: None,
            status: "converged".into(),
            predict_ms: 0.0,
            initial_deviation: PoseDeviation {
                translation_m: 10e-3,
                rotation_rad: 10f64.to_radians(),
            },
        }
    }

    #[test]
    fn random_rates_are_the_mean_of_their_draws_and_every_part_adds_to_all() {
        // Two trials; NBV right on both at 5/5; Random right on trial 0 in one draw of two.
        let rows = vec![
            row("nbv", 0, 0, 1, 1.0),
            row("nbv", 0, 1, 1, 3.0),
            row("random", 0, 0, 1, 1.0),
            row("random", 1, 0, 1, 9.0),
            row("random", 0, 1, 1, 9.0),
            row("random", 1, 1, 1, 9.0),
        ];
        let policies = ["nbv", "random"];
        let r = rates(&rows, &policies, 1);
        let find = |part: &str, policy: &str| {
            r.iter()
                .find(|x| x.part == part && x.policy == policy)
                .unwrap()
                .clone()
        };
        let nbv = find("gear", "nbv");
        assert_eq!((nbv.n, nbv.rate_5mm5deg, nbv.rate_2mm2deg), (2, 1.0, 0.5));
        let random = find("all", "random");
        assert_eq!((random.n, random.rate_5mm5deg), (2, 0.25));
        let p = paired(&rows, &policies, 1);
        let at5 = p
            .iter()
            .find(|x| x.part == "all" && x.threshold == "5mm5deg")
            .unwrap();
        assert_eq!(at5.n, 2);
        assert!((at5.margin_points - 75.0).abs() < 1e-9);
    }

    #[test]
    fn each_planner_meets_each_other_policy_and_the_two_planners_meet_once() {
        // NBV right on both trials, the model's run on trial 0, Random on neither.
        let rows = vec![
            row("nbv", 0, 0, 1, 1.0),
            row("nbv", 0, 1, 1, 1.0),
            row(NBV_ERROR_MODEL, 0, 0, 1, 1.0),
            row(NBV_ERROR_MODEL, 0, 1, 1, 9.0),
            row("random", 0, 0, 1, 9.0),
            row("random", 0, 1, 1, 9.0),
        ];
        let p = paired(&rows, &["nbv", "random", NBV_ERROR_MODEL], 1);
        let margin = |policy: &str, other: &str| {
            let found: Vec<_> = p
                .iter()
                .filter(|x| {
                    x.part == "all"
                        && x.threshold == "5mm5deg"
                        && x.policy == policy
                        && x.other == other
                })
                .collect();
            assert!(found.len() <= 1, "{policy} against {other} twice");
            found.first().map(|x| x.margin_points)
        };
        // Hit differences per trial: 1 and 1 (NBV − Random), 1 and 0 (model − Random), 0 and 1.
        assert_eq!(margin("nbv", "random"), Some(100.0));
        assert_eq!(margin("nbv", NBV_ERROR_MODEL), Some(50.0));
        assert_eq!(margin(NBV_ERROR_MODEL, "random"), Some(50.0));
        assert_eq!(margin(NBV_ERROR_MODEL, "nbv"), None);
        assert_eq!(margin("random", "nbv"), None);
    }

    #[test]
    fn detection_views_spread_over_the_candidates() {
        assert_eq!(detection_views(4, 60), [0, 15, 30, 45]);
        assert_eq!(detection_views(0, 60), [0]);
        assert_eq!(detection_views(9, 3), [0, 1, 2]);
    }

    #[test]
    fn a_part_keys_its_trials_by_name_not_by_its_place_in_the_run() {
        // The published `--parts all` runs keyed a part by its place in Part::ALL.
        for (index, part) in Part::ALL.iter().enumerate() {
            assert_eq!(part_key(part.name()), index as u64);
        }
        let custom = part_key("bracket");
        assert!(custom >= Part::ALL.len() as u64);
        assert_ne!(custom, part_key("bracket2"));
    }
}
