//! An active pose-refinement session as a state machine (paper §VI): capture the view chosen,
//! refine the pose on every view so far, and — unless the entropy threshold or the view
//! budget ends it — predict every remaining candidate and choose the next view by the
//! session's policy (eq 23 for the entropy policies). Each completed step is one
//! [`StepRecord`]; a session can be resumed after its last completed step.

use std::time::Instant;

use nalgebra::{Isometry3, Matrix6};

use crate::stages::{
    CameraInfo, CameraStage, CapturedView, EstimationStage, PredictionObject, PredictionRequest,
    PredictionSigma, PredictionStage, RefineSettings, RefineSigma, StageError,
};

/// How the next view is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ViewPolicy {
    /// Minimum predicted entropy with rendering-based σ̌_z (the paper's method).
    Nbv,
    /// Minimum predicted entropy with a constant σ_z (visibility and Jacobians only).
    NbvConstSigma,
    /// Uniformly at random among the views not taken (seeded).
    Random,
    /// The view whose camera centre is furthest from every view taken.
    MaxDistance,
}

impl ViewPolicy {
    /// Every policy.
    pub const ALL: [ViewPolicy; 4] = [
        ViewPolicy::Nbv,
        ViewPolicy::NbvConstSigma,
        ViewPolicy::Random,
        ViewPolicy::MaxDistance,
    ];

    /// The policy's name on the command line, in reports and in serde (`nbv`,
    /// `nbv-const-sigma`, `random`, `max-distance`); [`std::str::FromStr`] parses it back.
    pub fn name(self) -> &'static str {
        match self {
            ViewPolicy::Nbv => "nbv",
            ViewPolicy::NbvConstSigma => "nbv-const-sigma",
            ViewPolicy::Random => "random",
            ViewPolicy::MaxDistance => "max-distance",
        }
    }

    /// The prediction this policy needs, if any: `const_sigma_z_m` (metres) is the constant
    /// σ_z of [`ViewPolicy::NbvConstSigma`].
    pub fn prediction(self, const_sigma_z_m: f64) -> Option<PredictionSigma> {
        match self {
            ViewPolicy::Nbv => Some(PredictionSigma::Rendered),
            ViewPolicy::NbvConstSigma => Some(PredictionSigma::Constant {
                sigma_z_m: const_sigma_z_m,
            }),
            ViewPolicy::Random | ViewPolicy::MaxDistance => None,
        }
    }
}

impl std::str::FromStr for ViewPolicy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| {
                format!("unknown policy {s:?}; one of nbv, nbv-const-sigma, random, max-distance")
            })
    }
}

/// Everything a session is started with.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SessionConfig {
    /// The initial pose hypothesis, object → world (the client's detector).
    pub initial_t_w_o: Isometry3<f64>,
    /// Candidate left-camera poses, camera → world.
    pub candidates: Vec<Isometry3<f64>>,
    /// The candidate the first capture is taken from (the detector's view).
    pub first_view: usize,
    /// How the views after the first are chosen.
    pub policy: ViewPolicy,
    /// Views at most, 1 to 64.
    pub max_views: usize,
    /// Stop once the pose entropy is below this, nats; `None`: only the budget stops.
    pub entropy_threshold_nats: Option<f64>,
    /// Seed of the captures' noise, the predictions' renders and the random policy.
    pub seed: u64,
    /// The refinement's settings (masks, known background, σ_z model).
    pub refine: RefineSettings,
    /// σ_z of the constant-σ policy's predictions, metres.
    pub const_sigma_z_m: f64,
}

/// How the part's pixels are found in each view, as the demo, the experiments and the
/// orchestrator's sessions do it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Masking {
    /// The margin around the hypothesis' silhouette in the first pass, metres.
    pub margin_m: f64,
    /// The margin around the first pass's silhouette in the second pass, metres.
    pub final_margin_m: f64,
    /// Points this close to the cell's known floor are dropped, metres.
    pub floor_clearance_m: f64,
    /// Move each refinement's start along the viewing rays onto the depth first
    /// ([`RefineSettings::align_depth`]).
    pub align_depth: bool,
}

impl Default for Masking {
    /// 10 mm (the detector's error), then 3 mm, and 2 mm above the floor; the start aligned
    /// onto the depth.
    fn default() -> Self {
        Self {
            margin_m: 10e-3,
            final_margin_m: 3e-3,
            floor_clearance_m: 2e-3,
            align_depth: true,
        }
    }
}

impl Masking {
    /// The refinement's settings for `camera` in `cell` (its floor dropped when it has one),
    /// σ_z from the pattern images (eq 1–5), no error model (the part's is set beside).
    pub fn refine_settings(&self, camera: &CameraInfo, cell: Option<&Cell>) -> RefineSettings {
        RefineSettings {
            mask_margin_m: self.margin_m,
            final_mask_margin_m: Some(self.final_margin_m),
            background: cell.and_then(|c| c.floor).map(|floor| {
                glint_estimation::view::BackgroundPlane {
                    clearance_m: self.floor_clearance_m,
                    ..floor
                }
            }),
            erode_px: camera.window_radius_px,
            window_radius_px: camera.window_radius_px,
            sigma: RefineSigma::PatternImages,
            align_depth: self.align_depth,
            error_model: None,
        }
    }
}

/// σ_z of the constant-σ policy's predictions: 0.5 mm, about the median σ_z eq 1–5 gives the
/// default camera's depth on the parts at 0.5 m.
pub const CONST_SIGMA_Z_M: f64 = 0.5e-3;

/// What the cell's calibration knows of its static surroundings: surfaces the render workers
/// may render with the part (occluders and inter-reflectors), and the floor plane whose points
/// are not the part.
#[derive(Clone, Debug)]
pub struct Cell {
    /// Known static surfaces (the bin), rendered with the part by the render workers.
    pub surroundings: Vec<glint_uncertainty::KnownSurface>,
    /// The floor, world frame (`clearance_m` is set by [`Masking`]).
    pub floor: Option<glint_estimation::view::BackgroundPlane>,
}

impl Cell {
    /// Glint's standard bin (the mock camera's), its floor at world z = 0, parts above.
    pub fn standard_bin() -> Self {
        Self {
            surroundings: vec![glint_uncertainty::KnownSurface {
                mesh: std::sync::Arc::new(glint_camera::bin::BinSpec::default().mesh()),
                t_w_s: Isometry3::identity(),
                material: glint_camera::materials::bin(),
            }],
            floor: Some(glint_estimation::view::BackgroundPlane {
                normal_w: nalgebra::Vector3::z_axis(),
                offset_m: 0.0,
                clearance_m: 0.0,
            }),
        }
    }

    /// A cell the orchestrator knows nothing of: the part alone, as the paper renders it.
    pub fn unknown() -> Self {
        Self {
            surroundings: Vec::new(),
            floor: None,
        }
    }
}

/// Why a session's configuration is unusable: [`StageError::InvalidArgument`] naming the
/// first field out of range (e.g. a pose not finite, `first_view` not a candidate, not 1 to
/// 64 views, a margin not 0 to 0.1 m).
pub fn validate(config: &SessionConfig) -> Result<(), StageError> {
    let finite = |t: &Isometry3<f64>| {
        t.translation.vector.iter().all(|c| c.is_finite())
            && t.rotation.coords.iter().all(|c| c.is_finite())
    };
    if !finite(&config.initial_t_w_o) {
        return Err(StageError::invalid("initial_t_w_o", "must be finite"));
    }
    if config.candidates.is_empty() {
        return Err(StageError::invalid(
            "candidates_t_w_c",
            "at least one candidate view is needed",
        ));
    }
    if let Some(i) = config.candidates.iter().position(|t| !finite(t)) {
        return Err(StageError::invalid(
            format!("candidates_t_w_c[{i}]"),
            "must be finite",
        ));
    }
    if config.first_view >= config.candidates.len() {
        return Err(StageError::invalid(
            "first_view",
            format!(
                "is {} but there are {} candidates",
                config.first_view,
                config.candidates.len()
            ),
        ));
    }
    if !(1..=64).contains(&config.max_views) {
        return Err(StageError::invalid(
            "max_views",
            format!("is {}; 1 to 64 views", config.max_views),
        ));
    }
    if let Some(h) = config.entropy_threshold_nats
        && !h.is_finite()
    {
        return Err(StageError::invalid(
            "entropy_threshold_nats",
            "must be finite",
        ));
    }
    let margin = config.refine.mask_margin_m;
    if !(margin.is_finite() && (0.0..=0.1).contains(&margin)) {
        return Err(StageError::invalid(
            "refine.mask_margin_m",
            format!("is {margin}; 0 to 0.1 m around the hypothesis' silhouette"),
        ));
    }
    if let Some(m) = config.refine.final_mask_margin_m
        && !(m.is_finite() && (0.0..=0.1).contains(&m))
    {
        return Err(StageError::invalid(
            "refine.final_mask_margin_m",
            format!("is {m}; 0 to 0.1 m around the first pass' silhouette"),
        ));
    }
    if let Some(b) = &config.refine.background
        && !(b.offset_m.is_finite() && b.clearance_m.is_finite() && b.clearance_m >= 0.0)
    {
        return Err(StageError::invalid(
            "refine.background",
            "the plane's offset and clearance must be finite, the clearance ≥ 0",
        ));
    }
    if let Some(model) = &config.refine.error_model {
        model.validate().map_err(|e| {
            StageError::invalid(format!("refine.error_model.{}", e.field), e.message)
        })?;
    }
    if !(config.const_sigma_z_m.is_finite() && config.const_sigma_z_m > 0.0) {
        return Err(StageError::invalid(
            "const_sigma_z_m",
            "must be finite and positive (metres)",
        ));
    }
    Ok(())
}

/// Where a session is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SessionState {
    /// Created and not yet run.
    Created,
    /// Being run (a stored session held as running that no thread runs is shown as
    /// [`SessionState::Interrupted`]).
    Running,
    /// Ended by the entropy threshold.
    Converged,
    /// Ended by the view budget (or no candidate left).
    BudgetSpent,
    /// Ended by a cancel, before or while it ran.
    Cancelled,
    /// Ended by an error; [`Session::error`] says which.
    Failed,
    /// Held as running by the store, but the orchestrator that ran it stopped (a crash, a
    /// restart): running it again resumes it after its last completed step. Only shown,
    /// never stored.
    Interrupted,
}

impl SessionState {
    /// Whether the session has ended (converged, budget spent, cancelled or failed): running
    /// it again does nothing.
    pub fn is_final(self) -> bool {
        matches!(
            self,
            SessionState::Converged
                | SessionState::BudgetSpent
                | SessionState::Cancelled
                | SessionState::Failed
        )
    }
}

/// Time per stage of a step, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageTimes {
    /// The capture, as the camera reports it; 0 when a resumed session already held it.
    pub capture_ms: f64,
    /// The refinement on every view so far.
    pub refine_ms: f64,
    /// Predicting the open candidates; 0 when the policy predicts nothing or the session
    /// ended.
    pub predict_ms: f64,
    /// Choosing the next view; 0 when the session ended.
    pub plan_ms: f64,
}

/// One completed step: a view taken and the pose refined on all views so far.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepRecord {
    /// The step's number, from 0.
    pub step: usize,
    /// Index into the candidates of the view taken.
    pub view: usize,
    /// The view's left-camera pose, camera → world.
    pub t_w_c: Isometry3<f64>,
    /// Part points of this view.
    pub view_points: usize,
    /// Part points of all views so far.
    pub total_points: usize,
    /// The refined pose, object → world.
    pub t_w_o: Isometry3<f64>,
    /// Fisher information of the pose over all views so far, under the refinement's error
    /// model (eq 18 without one), without the planner's prior; zero when the refinement
    /// diverged.
    pub information: Matrix6<f64>,
    /// Eq 18's information of independent pixels, whatever the error model (`information`
    /// itself without one). Absent from older journals: zeros.
    #[serde(default = "Matrix6::zeros")]
    pub pixel_information: Matrix6<f64>,
    /// The pose covariance, `information⁻¹` (eq 18); `None` when singular or diverged.
    pub covariance: Option<Matrix6<f64>>,
    /// Pose entropy after this step (planner's prior included), nats.
    pub entropy_nats: f64,
    /// The entropy predicted for this view when it was chosen (`None`: chosen without one).
    pub predicted_entropy_nats: Option<f64>,
    /// The refinement's end ("converged", ...).
    pub refine_status: String,
    /// Every candidate's predicted entropy for the next view (empty when the session ends
    /// here or the policy predicts nothing); `None` for taken views.
    pub candidate_entropies_nats: Vec<Option<f64>>,
    /// The view chosen next, if the session goes on.
    pub next_view: Option<usize>,
    /// Time each stage of this step took, milliseconds.
    pub times: StageTimes,
}

/// A session: its configuration, its steps and its captures.
#[derive(Clone, Debug)]
pub struct Session {
    /// Its id (an orchestrator's are [`crate::store::id_of`]'s, `s000042`).
    pub id: String,
    /// What it was started with (validated).
    pub config: SessionConfig,
    /// Where it is.
    pub state: SessionState,
    /// Its completed steps, in order.
    pub steps: Vec<StepRecord>,
    /// Its captures, one per step captured (a step may be captured and not completed);
    /// empty when read without captures.
    pub views: Vec<CapturedView>,
    /// Why it failed.
    pub error: Option<String>,
}

impl Session {
    /// A new session (created, no steps), or the [`StageError::InvalidArgument`] of
    /// [`validate`].
    pub fn new(id: String, config: SessionConfig) -> Result<Self, StageError> {
        validate(&config)?;
        Ok(Self {
            id,
            config,
            state: SessionState::Created,
            steps: Vec::new(),
            views: Vec::new(),
            error: None,
        })
    }

    /// The view the next step captures.
    fn next_view(&self) -> usize {
        self.steps
            .last()
            .and_then(|s| s.next_view)
            .unwrap_or(self.config.first_view)
    }

    fn taken(&self) -> Vec<usize> {
        self.steps.iter().map(|s| s.view).collect()
    }
}

/// The stages a session runs on.
pub struct Stages<'a> {
    /// The camera the session captures with.
    pub camera: &'a dyn CameraStage,
    /// The estimator: refinement, entropy and the entropy policies' plan (eq 20, 23).
    pub estimation: &'a dyn EstimationStage,
    /// The render workers with the object they predict for; required by the entropy policies.
    pub prediction: Option<(&'a dyn PredictionStage, &'a PredictionObject)>,
}

impl<'a> Stages<'a> {
    /// The stages of a session whose policy predicts nothing (Random, Max-Distance).
    pub fn without_prediction(
        camera: &'a dyn CameraStage,
        estimation: &'a dyn EstimationStage,
    ) -> Self {
        Self {
            camera,
            estimation,
            prediction: None,
        }
    }
}

/// The noise seed of capture `step` of a session seeded `seed`.
pub fn step_capture_seed(seed: u64, step: usize) -> u64 {
    glint_camera::setup::capture_seed(seed, step)
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// What a session reports as it goes, so that a store keeps it: each capture as soon as it
/// is taken (a resumed session refines on it instead of capturing again) and each completed
/// step. An error stops the session: a step that cannot be kept is not taken.
pub trait Journal {
    /// Step `step`'s capture, before anything is computed from it.
    fn captured(&mut self, step: usize, view: &CapturedView) -> Result<(), StageError>;
    /// A completed step.
    fn completed(&mut self, step: &StepRecord) -> Result<(), StageError>;
}

/// A journal that keeps nothing and shows each completed step to a closure.
pub struct OnStep<F>(pub F);

impl<F: FnMut(&StepRecord)> Journal for OnStep<F> {
    fn captured(&mut self, _: usize, _: &CapturedView) -> Result<(), StageError> {
        Ok(())
    }
    fn completed(&mut self, step: &StepRecord) -> Result<(), StageError> {
        (self.0)(step);
        Ok(())
    }
}

/// Runs `session` from its last completed step to its end; `on_step` sees each step as it
/// completes, `cancelled` is polled between stages.
pub fn run(
    session: &mut Session,
    object: &crate::stages::SessionObject,
    stages: &Stages<'_>,
    on_step: impl FnMut(&StepRecord),
    cancelled: impl Fn() -> bool,
) -> Result<(), StageError> {
    run_journaled(session, object, stages, &mut OnStep(on_step), cancelled)
}

/// [`run`], reporting each capture and step to `journal` as it happens.
pub fn run_journaled(
    session: &mut Session,
    object: &crate::stages::SessionObject,
    stages: &Stages<'_>,
    journal: &mut dyn Journal,
    cancelled: impl Fn() -> bool,
) -> Result<(), StageError> {
    if session.state.is_final() {
        return Ok(());
    }
    session.state = SessionState::Running;
    let result = run_steps(session, object, stages, journal, &cancelled);
    match &result {
        Ok(()) => {}
        Err(StageError::Cancelled) => session.state = SessionState::Cancelled,
        Err(e) => {
            session.state = SessionState::Failed;
            session.error = Some(e.to_string());
        }
    }
    result
}

fn run_steps(
    session: &mut Session,
    object: &crate::stages::SessionObject,
    stages: &Stages<'_>,
    journal: &mut dyn Journal,
    cancelled: &dyn Fn() -> bool,
) -> Result<(), StageError> {
    let config = session.config.clone();
    let check = || {
        if cancelled() {
            Err(StageError::Cancelled)
        } else {
            Ok(())
        }
    };
    while !session.state.is_final() {
        check()?;
        let step = session.steps.len();
        let view = session.next_view();
        let t_w_c = config.candidates[view];
        let predicted_entropy_nats = session
            .steps
            .last()
            .and_then(|s| s.candidate_entropies_nats.get(view).copied().flatten());
        let mut times = StageTimes::default();

        // Capture, unless a resumed session already holds this step's capture.
        if session.views.len() <= step {
            tracing::debug!(session = %session.id, step, view, "capturing");
            let captured = stages
                .camera
                .capture(&t_w_c, step_capture_seed(config.seed, step))?;
            times.capture_ms = captured.capture_ms;
            journal.captured(step, &captured)?;
            session.views.push(captured);
        }
        check()?;

        // Refine on every view so far, from the last estimate (the initial hypothesis first).
        let hypothesis = session
            .steps
            .last()
            .map_or(config.initial_t_w_o, |s| s.t_w_o);
        let views: Vec<&CapturedView> = session.views.iter().take(step + 1).collect();
        let started = Instant::now();
        tracing::debug!(session = %session.id, step, views = views.len(), "refining");
        let refinement = stages
            .estimation
            .refine(object, &views, &hypothesis, &config.refine)?;
        times.refine_ms = ms_since(started);
        let entropy_nats = stages.estimation.entropy_nats(&refinement.information)?;
        check()?;

        let mut taken = session.taken();
        taken.push(view);
        let converged = config
            .entropy_threshold_nats
            .is_some_and(|h| entropy_nats < h);
        let budget_spent =
            taken.len() >= config.max_views || taken.len() >= config.candidates.len();
        let (next_view, candidate_entropies_nats) = if converged || budget_spent {
            (None, Vec::new())
        } else {
            let (next, entropies) = choose_next_view(
                &config,
                stages,
                &refinement.t_w_o,
                &refinement.information,
                &taken,
                step,
                &mut times,
            )?;
            (Some(next), entropies)
        };
        let record = StepRecord {
            step,
            view,
            t_w_c,
            view_points: refinement.view_points.last().copied().unwrap_or(0),
            total_points: refinement.view_points.iter().sum(),
            t_w_o: refinement.t_w_o,
            information: refinement.information,
            pixel_information: refinement.pixel_information,
            covariance: refinement.covariance,
            entropy_nats,
            predicted_entropy_nats,
            refine_status: refinement.status,
            candidate_entropies_nats,
            next_view,
            times,
        };
        tracing::info!(
            session = %session.id, step, view, points = record.total_points,
            entropy_nats, "step done"
        );
        journal.completed(&record)?;
        session.steps.push(record);
        if converged {
            session.state = SessionState::Converged;
        } else if budget_spent {
            session.state = SessionState::BudgetSpent;
        }
    }
    Ok(())
}

/// The next view by the session's policy, and (entropy policies) every candidate's
/// predicted entropy.
fn choose_next_view(
    config: &SessionConfig,
    stages: &Stages<'_>,
    t_w_o: &Isometry3<f64>,
    collected: &Matrix6<f64>,
    taken: &[usize],
    step: usize,
    times: &mut StageTimes,
) -> Result<(usize, Vec<Option<f64>>), StageError> {
    let Some(sigma) = config.policy.prediction(config.const_sigma_z_m) else {
        let started = Instant::now();
        let next = match config.policy {
            ViewPolicy::Random => glint_estimation::nbv::random_view(
                config.candidates.len(),
                taken,
                config.seed,
                step,
            ),
            _ => glint_estimation::nbv::max_distance_view(&config.candidates, taken),
        }
        .map_err(|e| StageError::FailedPrecondition(e.to_string()))?;
        times.plan_ms = ms_since(started);
        return Ok((next, Vec::new()));
    };
    let Some((predictor, object)) = stages.prediction else {
        return Err(StageError::FailedPrecondition(format!(
            "policy {} needs render workers and a calibrated object (material and response)",
            config.policy.name()
        )));
    };
    let open: Vec<(u32, Isometry3<f64>)> = config
        .candidates
        .iter()
        .enumerate()
        .filter(|(i, _)| !taken.contains(i))
        .map(|(i, t)| (i as u32, *t))
        .collect();
    let request = PredictionRequest {
        t_w_o: *t_w_o,
        candidates: open,
        sigma,
        seed: config.seed,
        with_maps: false,
    };
    let started = Instant::now();
    tracing::debug!(candidates = request.candidates.len(), step, "predicting");
    let predictions = predictor.predict(object, &request)?;
    times.predict_ms = ms_since(started);
    // The planner sees every candidate; taken ones are excluded by `taken`. Every open
    // candidate must have been predicted: a silent gap would read as "no information".
    let mut informations = vec![None; config.candidates.len()];
    for p in &predictions {
        let slot = informations.get_mut(p.index as usize).ok_or_else(|| {
            StageError::Internal(format!(
                "a worker answered for candidate {} of {}",
                p.index,
                config.candidates.len()
            ))
        })?;
        *slot = Some(p.information);
    }
    if let Some(missing) = request
        .candidates
        .iter()
        .find(|(i, _)| informations[*i as usize].is_none())
    {
        return Err(StageError::Internal(format!(
            "no prediction came back for candidate {}",
            missing.0
        )));
    }
    // Under the part's error model a candidate adds what its own pose estimate would know,
    // capped by the per-view bias (taken views get zeros and are excluded anyway).
    let informations: Vec<Matrix6<f64>> = informations
        .into_iter()
        .zip(&config.candidates)
        .map(|(f, t_w_c)| match (f, &config.refine.error_model) {
            (Some(f), Some(model)) => model.predicted_candidate_information(&f, t_w_o, t_w_c),
            (f, _) => f.unwrap_or_else(Matrix6::zeros),
        })
        .collect();
    let started = Instant::now();
    let plan = stages.estimation.plan(collected, &informations, taken)?;
    times.plan_ms = ms_since(started);
    Ok((plan.chosen, plan.entropies_nats))
}
