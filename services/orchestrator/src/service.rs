//! The orchestrator as a library: it owns the sessions (behind [`SessionStore`]) and runs them
//! on its stages. The gRPC server (`server`) and the demo call exactly this.
//!
//! A session is started from what a client knows — the part (a built-in one or its mesh), its
//! detector's pose, the candidate views, the policy and budget, and the part's calibration —
//! and run to its end on the orchestrator's camera, estimator and render workers. The sensor's
//! noise (σ_I², eq 2) is calibrated once per orchestrator from two read-outs of one shot.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use glint_estimation::depth_sigma::NoiseModel;
use glint_estimation::pose_error_model::PoseErrorModel;
use glint_geometry::{Part, TriMesh};
use nalgebra::Isometry3;

use crate::session::{
    CONST_SIGMA_Z_M, Cell, Journal, Masking, Session, SessionConfig, SessionState, Stages,
    StepRecord, ViewPolicy,
};
use crate::stages::{
    CameraStage, CapturedView, EstimationStage, PartCalibration, PredictionObject, PredictionStage,
    RefineSettings, SessionObject, StageError, calibrate_noise,
};
use crate::store::{SessionCalibration, SessionStore, StoredSession};

fn poisoned<T>(_: T) -> StageError {
    StageError::Internal("the orchestrator's lock was poisoned".into())
}

/// The part of a session.
#[derive(Clone, Debug)]
pub enum PartSource {
    /// One of Glint's parts.
    Builtin(Part),
    /// A user's mesh, metres.
    Mesh {
        /// Its name for logs and reports; a built-in part's name also selects that part's
        /// shipped calibration when none is sent.
        name: String,
        /// The mesh, metres, in the object's frame.
        mesh: TriMesh,
    },
}

/// What a client starts a session with.
#[derive(Clone, Debug)]
pub struct SessionRequest {
    /// The part to refine.
    pub part: PartSource,
    /// The detector's pose, object → world.
    pub initial_t_w_o: Isometry3<f64>,
    /// Candidate left-camera poses (camera → world): `Ok` the client's list, `Err(n)` the
    /// camera's own `n` views.
    pub candidates: Result<Vec<Isometry3<f64>>, usize>,
    /// Index into the candidates of the first capture (the detector's view).
    pub first_view: usize,
    /// How the views after the first are chosen.
    pub policy: ViewPolicy,
    /// Views at most, 1 to 64.
    pub max_views: usize,
    /// Stop once the pose entropy is below this, nats; `None`: only the budget stops.
    pub entropy_threshold_nats: Option<f64>,
    /// Seed of the captures' noise, the predictions' renders and the random policy.
    pub seed: u64,
    /// The part's calibration; `None`: the one Glint ships for a built-in part, if any.
    pub calibration: Option<PartCalibration>,
    /// The camera's error model on the part; `None`: the one Glint ships for a built-in part,
    /// eq 18's independent pixels for a mesh.
    pub error_model: Option<PoseErrorModel>,
}

/// The orchestrator: its stages, what it knows of the cell, and its sessions.
pub struct Orchestrator {
    /// The camera every session captures with.
    pub camera: Arc<dyn CameraStage>,
    /// The estimator: refinement, entropy and planning.
    pub estimation: Arc<dyn EstimationStage>,
    /// The render workers, used by the entropy policies.
    pub prediction: Arc<dyn PredictionStage>,
    /// What the orchestrator knows of the cell: surroundings and floor.
    pub cell: Cell,
    /// How sessions started from now on find the part's pixels.
    pub masking: Masking,
    store: Arc<dyn SessionStore>,
    /// The sensor's noise, calibrated at the first session that needs it.
    noise: Mutex<Option<NoiseModel>>,
    running: Mutex<HashSet<String>>,
    /// Sessions run at once at most; more are refused as [`StageError::Overloaded`] rather
    /// than queued, so the stages' work and the memory of captures stay bounded.
    max_running: usize,
    cancelled: Mutex<HashMap<String, Arc<AtomicBool>>>,
    next_id: AtomicU64,
}

/// Sessions an orchestrator runs at once unless told otherwise: enough to keep a few render
/// workers busy while another session captures, few enough that each step stays fast.
pub const DEFAULT_MAX_RUNNING: usize = 4;

/// How long a refused session is told to wait before asking again, ms: about one step.
pub const OVERLOADED_RETRY_AFTER_MS: u64 = 1000;

/// Candidate views a session gets from the camera when it names none.
pub const DEFAULT_CANDIDATES: usize = 20;

impl Orchestrator {
    /// An orchestrator over these stages, `cell` and `store`, running at most
    /// [`DEFAULT_MAX_RUNNING`] sessions at once; new ids follow the highest the store holds.
    pub fn new(
        camera: Arc<dyn CameraStage>,
        estimation: Arc<dyn EstimationStage>,
        prediction: Arc<dyn PredictionStage>,
        cell: Cell,
        store: Arc<dyn SessionStore>,
    ) -> Self {
        // A restarted orchestrator numbers on after the sessions its store kept.
        let last = match store.list() {
            Ok(sessions) => sessions
                .iter()
                .filter_map(|s| crate::store::id_number(&s.id))
                .max()
                .unwrap_or(0),
            Err(e) => {
                tracing::error!("listing the stored sessions: {e}");
                0
            }
        };
        Self {
            camera,
            estimation,
            prediction,
            cell,
            masking: Masking::default(),
            store,
            noise: Mutex::new(None),
            running: Mutex::new(HashSet::new()),
            max_running: DEFAULT_MAX_RUNNING,
            cancelled: Mutex::new(HashMap::new()),
            next_id: AtomicU64::new(last + 1),
        }
    }

    /// Runs at most `n` sessions at once (at least 1).
    pub fn with_max_running(mut self, n: usize) -> Self {
        self.max_running = n.max(1);
        self
    }

    /// Session `id`'s state, without copying its captures.
    pub fn state(&self, id: &str) -> Result<SessionState, StageError> {
        Ok(self.get(id)?.state)
    }

    /// Takes a place for session `id` to run in, if it is not running already and a place is
    /// free; [`Self::run_reserved`] then runs it and frees the place.
    pub fn reserve(&self, id: &str) -> Result<(), StageError> {
        let mut running = self.running.lock().map_err(poisoned)?;
        self.admission(&running, id)?;
        running.insert(id.to_owned());
        Ok(())
    }

    fn release(&self, id: &str) {
        if let Ok(mut running) = self.running.lock() {
            running.remove(id);
        }
    }

    fn admission(&self, running: &HashSet<String>, id: &str) -> Result<(), StageError> {
        if running.contains(id) {
            return Err(StageError::FailedPrecondition(format!(
                "session {id} is already running; GetSession shows its progress"
            )));
        }
        if running.len() >= self.max_running {
            return Err(StageError::Overloaded {
                message: format!(
                    "{} sessions are running, the most this orchestrator runs at once \
                     (--max-running-sessions); session {id} can run when one ends",
                    running.len()
                ),
                retry_after_ms: OVERLOADED_RETRY_AFTER_MS,
            });
        }
        Ok(())
    }

    fn noise_model(&self, t_w_c: &Isometry3<f64>) -> Result<NoiseModel, StageError> {
        let mut noise = self.noise.lock().map_err(poisoned)?;
        if let Some(n) = noise.as_ref() {
            return Ok(n.clone());
        }
        let fitted = calibrate_noise(self.camera.as_ref(), t_w_c)?;
        *noise = Some(fitted.clone());
        Ok(fitted)
    }

    /// Creates a session (it does not run yet) and returns its id.
    pub fn start(&self, request: SessionRequest) -> Result<String, StageError> {
        // The shipped error model goes with a built-in part, not with a mesh of its name.
        let builtin = match &request.part {
            PartSource::Builtin(part) => Some(*part),
            PartSource::Mesh { .. } => None,
        };
        let (name, mesh) = match request.part {
            PartSource::Builtin(part) => (part.name().to_owned(), part.mesh()),
            PartSource::Mesh { name, mesh } => (name, mesh),
        };
        let object = SessionObject::new(name, mesh);
        let candidates = match request.candidates {
            Ok(list) => list,
            Err(count) => {
                if !(2..=1000).contains(&count) {
                    return Err(StageError::invalid(
                        "default_candidates",
                        format!("is {count}; 2 to 1000 views"),
                    ));
                }
                self.camera.candidate_views(count)?
            }
        };
        let info = self.camera.info()?;
        let error_model = match request.error_model {
            Some(m) => Some(m),
            None => builtin
                .map(PoseErrorModel::shipped)
                .transpose()
                .map_err(|e| StageError::Internal(format!("the shipped error model: {e}")))?,
        };
        let config = SessionConfig {
            initial_t_w_o: request.initial_t_w_o,
            candidates,
            first_view: request.first_view,
            policy: request.policy,
            max_views: request.max_views,
            entropy_threshold_nats: request.entropy_threshold_nats,
            seed: request.seed,
            refine: RefineSettings {
                error_model,
                ..self.masking.refine_settings(&info, Some(&self.cell))
            },
            const_sigma_z_m: CONST_SIGMA_Z_M,
        };
        crate::session::validate(&config)?;
        let session_calibration = if config.policy.prediction(CONST_SIGMA_Z_M).is_some() {
            let calibration = match request.calibration {
                Some(c) => c,
                None => {
                    let part = Part::ALL
                        .into_iter()
                        .find(|p| p.name() == object.name)
                        .ok_or_else(|| {
                            StageError::FailedPrecondition(format!(
                                "policy {} renders the part: send its calibration (material, \
                                 response, radiometric_scale) for the mesh {:?}",
                                config.policy.name(),
                                object.name
                            ))
                        })?;
                    let shipped = glint_calibration::shipped::Calibration::embedded(part)
                        .map_err(|e| StageError::Internal(e.to_string()))?;
                    PartCalibration::from_files(&shipped)?
                }
            };
            let noise = self.noise_model(&config.candidates[config.first_view])?;
            let calibration = SessionCalibration {
                part: calibration,
                noise,
            };
            // Refused now rather than at the first decision.
            self.prediction_object_with(&object, &calibration, &info)?;
            Some(calibration)
        } else {
            None
        };
        let id = crate::store::id_of(self.next_id.fetch_add(1, Ordering::Relaxed));
        let session = Session::new(id.clone(), config)?;
        self.store.insert(&StoredSession {
            session,
            object,
            calibration: session_calibration,
        })?;
        tracing::info!(session = %id, "session created");
        Ok(id)
    }

    fn prediction_object_with(
        &self,
        object: &SessionObject,
        calibration: &SessionCalibration,
        info: &crate::stages::CameraInfo,
    ) -> Result<PredictionObject, StageError> {
        PredictionObject::calibrated(
            object.clone(),
            &calibration.part,
            info,
            calibration.noise.clone(),
            self.cell.surroundings.clone(),
        )
    }

    /// The render workers' object of a stored session (entropy policies), from its
    /// calibration, the camera's rig and the cell's surroundings.
    pub fn prediction_object(
        &self,
        stored: &StoredSession,
    ) -> Result<Option<PredictionObject>, StageError> {
        stored
            .calibration
            .as_ref()
            .map(|c| self.prediction_object_with(&stored.object, c, &self.camera.info()?))
            .transpose()
    }

    /// Session `id`'s cancel flag, made at first use (a session kept by the store from an
    /// earlier process has none yet).
    fn cancel_flag(&self, id: &str) -> Result<Arc<AtomicBool>, StageError> {
        Ok(self
            .cancelled
            .lock()
            .map_err(poisoned)?
            .entry(id.to_owned())
            .or_default()
            .clone())
    }

    /// `session` as a client sees it: a session the store holds as running that runs in no
    /// thread of this process was interrupted (the orchestrator stopped while it ran).
    fn presented(&self, mut session: Session) -> Result<Session, StageError> {
        if session.state == SessionState::Running
            && !self.running.lock().map_err(poisoned)?.contains(&session.id)
        {
            session.state = SessionState::Interrupted;
        }
        Ok(session)
    }

    /// The part a session refines, by name.
    pub fn part_name(&self, id: &str) -> Option<String> {
        self.store.part_name(id).ok().flatten()
    }

    /// A session with its captures, for readers in the same process (the demo's report).
    pub fn stored(&self, id: &str) -> Result<StoredSession, StageError> {
        self.store
            .get(id)?
            .ok_or_else(|| StageError::NotFound(format!("session_id: no session {id:?}")))
    }

    /// A session without its captures.
    pub fn get(&self, id: &str) -> Result<Session, StageError> {
        let session = self
            .store
            .session(id)?
            .ok_or_else(|| StageError::NotFound(format!("session_id: no session {id:?}")))?;
        self.presented(session)
    }

    /// Every session without its captures, oldest first.
    pub fn list(&self) -> Result<Vec<Session>, StageError> {
        self.store
            .list()?
            .into_iter()
            .map(|s| self.presented(s))
            .collect()
    }

    /// Asks a session to stop at its next stage boundary; a session not running ends at
    /// once.
    pub fn cancel(&self, id: &str) -> Result<Session, StageError> {
        let session = self.get(id)?;
        self.cancel_flag(id)?.store(true, Ordering::Relaxed);
        if matches!(
            session.state,
            SessionState::Created | SessionState::Interrupted
        ) {
            self.store
                .set_state(id, SessionState::Cancelled, session.error.as_deref())?;
        }
        self.get(id)
    }

    /// Runs session `id` to its end (a finished one returns as it is); `on_step` sees each
    /// completed step. Blocks: call it from a blocking thread.
    pub fn run(&self, id: &str, on_step: impl FnMut(&StepRecord)) -> Result<Session, StageError> {
        if self.state(id)?.is_final() {
            return self.run_reserved(id, on_step);
        }
        self.reserve(id)?;
        self.run_reserved(id, on_step)
    }

    /// [`Self::run`] for a session whose place [`Self::reserve`] took (a finished session
    /// needs none); frees the place when it ends.
    pub fn run_reserved(
        &self,
        id: &str,
        mut on_step: impl FnMut(&StepRecord),
    ) -> Result<Session, StageError> {
        let result = self.run_stored(id, &mut on_step);
        self.release(id);
        result
    }

    fn run_stored(
        &self,
        id: &str,
        on_step: &mut dyn FnMut(&StepRecord),
    ) -> Result<Session, StageError> {
        // A finished or resumed session shows its completed steps first; a finished one
        // needs nothing more (its captures stay where they are).
        let kept = self
            .store
            .session(id)?
            .ok_or_else(|| StageError::NotFound(format!("session_id: no session {id:?}")))?;
        for step in &kept.steps {
            on_step(step);
        }
        if kept.state.is_final() {
            return self.presented(kept);
        }
        let stored = self
            .store
            .get(id)?
            .ok_or_else(|| StageError::NotFound(format!("session_id: no session {id:?}")))?;
        let flag = self.cancel_flag(id)?;
        let prediction = self.prediction_object(&stored)?;
        let StoredSession {
            mut session,
            object,
            ..
        } = stored;
        if !session.steps.is_empty() {
            tracing::info!(
                session = %id,
                steps = session.steps.len(),
                captures = session.views.len(),
                "resuming after the last completed step"
            );
        }
        let stages = Stages {
            camera: self.camera.as_ref(),
            estimation: self.estimation.as_ref(),
            prediction: prediction.as_ref().map(|p| (self.prediction.as_ref(), p)),
        };
        let mut journal = StoreJournal {
            store: self.store.as_ref(),
            id,
            on_step,
        };
        let result =
            crate::session::run_journaled(&mut session, &object, &stages, &mut journal, || {
                flag.load(Ordering::Relaxed)
            });
        self.store
            .set_state(id, session.state, session.error.as_deref())?;
        match result {
            Ok(()) | Err(StageError::Cancelled) => {}
            Err(e) => tracing::warn!(session = %id, "session failed: {e}"),
        }
        self.get(id)
    }
}

/// Keeps a running session's captures and steps in the store as they come.
struct StoreJournal<'a> {
    store: &'a dyn SessionStore,
    id: &'a str,
    on_step: &'a mut dyn FnMut(&StepRecord),
}

impl Journal for StoreJournal<'_> {
    fn captured(&mut self, step: usize, view: &CapturedView) -> Result<(), StageError> {
        self.store.record_capture(self.id, step, view)
    }

    fn completed(&mut self, step: &StepRecord) -> Result<(), StageError> {
        self.store.record_step(self.id, step)?;
        (self.on_step)(step);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::local::{LocalEstimation, LocalPrediction};
    use crate::stages::{CameraInfo, CapturedView};

    /// A camera these tests never reach.
    struct NoCamera;

    impl CameraStage for NoCamera {
        fn info(&self) -> Result<CameraInfo, StageError> {
            Err(StageError::Unavailable("no camera".into()))
        }
        fn capture(&self, _: &Isometry3<f64>, _: u64) -> Result<CapturedView, StageError> {
            Err(StageError::Unavailable("no camera".into()))
        }
        fn candidate_views(&self, _: usize) -> Result<Vec<Isometry3<f64>>, StageError> {
            Err(StageError::Unavailable("no camera".into()))
        }
    }

    #[test]
    fn sessions_beyond_the_limit_are_refused_with_a_retry_hint_until_a_place_frees() {
        let orchestrator = Orchestrator::new(
            Arc::new(NoCamera),
            Arc::new(LocalEstimation::default()),
            Arc::new(LocalPrediction::default()),
            Cell::unknown(),
            Arc::new(crate::store::MemoryStore::default()),
        )
        .with_max_running(2);
        orchestrator.reserve("s1").unwrap();
        orchestrator.reserve("s2").unwrap();
        match orchestrator.reserve("s3") {
            Err(StageError::Overloaded {
                message,
                retry_after_ms,
            }) => {
                assert_eq!(retry_after_ms, OVERLOADED_RETRY_AFTER_MS);
                assert!(message.contains("--max-running-sessions"), "{message}");
            }
            other => panic!("expected Overloaded, got {other:?}"),
        }
        assert!(matches!(
            orchestrator.reserve("s1"),
            Err(StageError::FailedPrecondition(_))
        ));
        // A run that ends (here at once: no such session) frees its place.
        assert!(matches!(
            orchestrator.run_reserved("s2", |_| {}),
            Err(StageError::NotFound(_))
        ));
        orchestrator.reserve("s3").unwrap();
    }
}
