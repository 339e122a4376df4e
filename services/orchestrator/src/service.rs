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
use glint_geometry::{Part, TriMesh};
use nalgebra::Isometry3;

use crate::session::{
    CONST_SIGMA_Z_M, Cell, Masking, Session, SessionConfig, SessionState, Stages, StepRecord,
    ViewPolicy,
};
use crate::stages::{
    CameraStage, EstimationStage, PartCalibration, PredictionObject, PredictionStage,
    SessionObject, StageError, calibrate_noise,
};

/// The part of a session.
#[derive(Clone, Debug)]
pub enum PartSource {
    /// One of Glint's parts.
    Builtin(Part),
    /// A user's mesh, metres.
    Mesh { name: String, mesh: TriMesh },
}

/// What a client starts a session with.
#[derive(Clone, Debug)]
pub struct SessionRequest {
    pub part: PartSource,
    /// The detector's pose, object → world.
    pub initial_t_w_o: Isometry3<f64>,
    /// Candidate left-camera poses (camera → world): `Ok` the client's list, `Err(n)` the
    /// camera's own `n` views.
    pub candidates: Result<Vec<Isometry3<f64>>, usize>,
    pub first_view: usize,
    pub policy: ViewPolicy,
    pub max_views: usize,
    pub entropy_threshold_nats: Option<f64>,
    pub seed: u64,
    /// The part's calibration; `None`: the one Glint ships for a built-in part, if any.
    pub calibration: Option<PartCalibration>,
}

/// A session as the store keeps it: its state machine and what it runs on.
#[derive(Clone, Debug)]
pub struct StoredSession {
    pub session: Session,
    pub object: SessionObject,
    /// The render workers' object (entropy policies only).
    pub prediction: Option<PredictionObject>,
}

/// Where sessions live. In memory today ([`MemoryStore`]); a persistent store implements the
/// same trait.
pub trait SessionStore: Send + Sync {
    /// Adds a new session.
    fn insert(&self, session: StoredSession) -> Result<(), StageError>;
    /// A session with its captures.
    fn get(&self, id: &str) -> Result<Option<StoredSession>, StageError>;
    /// A session's state alone (no copy of its captures), `None` for an unknown id.
    fn state(&self, id: &str) -> Result<Option<SessionState>, StageError>;
    /// Every session without its captures, oldest first.
    fn list(&self) -> Result<Vec<Session>, StageError>;
    /// Records a completed step (and the state it leaves the session in).
    fn record_step(&self, id: &str, step: &StepRecord) -> Result<(), StageError>;
    /// Replaces a session after a run (its steps, captures and final state).
    fn update(&self, session: &Session) -> Result<(), StageError>;
}

/// Sessions in memory, lost when the process ends.
#[derive(Default)]
pub struct MemoryStore {
    sessions: Mutex<(Vec<String>, HashMap<String, StoredSession>)>,
}

fn poisoned<T>(_: T) -> StageError {
    StageError::Internal("the session store's lock was poisoned".into())
}

impl SessionStore for MemoryStore {
    fn insert(&self, session: StoredSession) -> Result<(), StageError> {
        let mut guard = self.sessions.lock().map_err(poisoned)?;
        let (order, map) = &mut *guard;
        order.push(session.session.id.clone());
        map.insert(session.session.id.clone(), session);
        Ok(())
    }

    fn get(&self, id: &str) -> Result<Option<StoredSession>, StageError> {
        Ok(self.sessions.lock().map_err(poisoned)?.1.get(id).cloned())
    }

    fn state(&self, id: &str) -> Result<Option<SessionState>, StageError> {
        Ok(self
            .sessions
            .lock()
            .map_err(poisoned)?
            .1
            .get(id)
            .map(|s| s.session.state))
    }

    fn list(&self) -> Result<Vec<Session>, StageError> {
        let guard = self.sessions.lock().map_err(poisoned)?;
        let (order, map) = &*guard;
        Ok(order
            .iter()
            .filter_map(|id| map.get(id))
            .map(|s| Session {
                views: Vec::new(),
                ..s.session.clone()
            })
            .collect())
    }

    fn record_step(&self, id: &str, step: &StepRecord) -> Result<(), StageError> {
        let mut guard = self.sessions.lock().map_err(poisoned)?;
        let stored = guard
            .1
            .get_mut(id)
            .ok_or_else(|| StageError::NotFound(format!("session {id:?}")))?;
        stored.session.state = SessionState::Running;
        stored.session.steps.push(step.clone());
        Ok(())
    }

    fn update(&self, session: &Session) -> Result<(), StageError> {
        let mut guard = self.sessions.lock().map_err(poisoned)?;
        let stored = guard
            .1
            .get_mut(&session.id)
            .ok_or_else(|| StageError::NotFound(format!("session {:?}", session.id)))?;
        stored.session = session.clone();
        Ok(())
    }
}

/// The orchestrator: its stages, what it knows of the cell, and its sessions.
pub struct Orchestrator {
    pub camera: Arc<dyn CameraStage>,
    pub estimation: Arc<dyn EstimationStage>,
    pub prediction: Arc<dyn PredictionStage>,
    pub cell: Cell,
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
    pub fn new(
        camera: Arc<dyn CameraStage>,
        estimation: Arc<dyn EstimationStage>,
        prediction: Arc<dyn PredictionStage>,
        cell: Cell,
        store: Arc<dyn SessionStore>,
    ) -> Self {
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
            next_id: AtomicU64::new(1),
        }
    }

    /// Runs at most `n` sessions at once (at least 1).
    pub fn with_max_running(mut self, n: usize) -> Self {
        self.max_running = n.max(1);
        self
    }

    /// Session `id`'s state, without copying its captures.
    pub fn state(&self, id: &str) -> Result<SessionState, StageError> {
        self.store
            .state(id)?
            .ok_or_else(|| StageError::NotFound(format!("session_id: no session {id:?}")))
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
        let (name, mesh) = match request.part {
            PartSource::Builtin(part) => (part.name().to_owned(), part.mesh()),
            PartSource::Mesh { name, mesh } => (name, mesh),
        };
        let object = SessionObject {
            mesh_sha256_hex: mesh.content_sha256_hex(),
            name,
            mesh: Arc::new(mesh),
        };
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
        let config = SessionConfig {
            initial_t_w_o: request.initial_t_w_o,
            candidates,
            first_view: request.first_view,
            policy: request.policy,
            max_views: request.max_views,
            entropy_threshold_nats: request.entropy_threshold_nats,
            seed: request.seed,
            refine: self.masking.refine_settings(&info, Some(&self.cell)),
            const_sigma_z_m: CONST_SIGMA_Z_M,
        };
        crate::session::validate(&config)?;
        let prediction = if config.policy.prediction(CONST_SIGMA_Z_M).is_some() {
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
                        .ok_or_else(|| {
                            StageError::FailedPrecondition(format!(
                                "policy {} renders the part, and Glint ships no calibration for \
                                 the {}: send its material, response and radiometric_scale \
                                 (glint calibrate bsdf, glint calibrate response)",
                                config.policy.name(),
                                part.display_name()
                            ))
                        })?
                        .map_err(|e| StageError::Internal(e.to_string()))?;
                    PartCalibration::from_files(&shipped)?
                }
            };
            let noise = self.noise_model(&config.candidates[config.first_view])?;
            Some(PredictionObject::calibrated(
                object.clone(),
                &calibration,
                &info,
                noise,
                self.cell.surroundings.clone(),
            )?)
        } else {
            None
        };
        let id = format!("s{:06}", self.next_id.fetch_add(1, Ordering::Relaxed));
        let session = Session::new(id.clone(), config)?;
        self.store.insert(StoredSession {
            session,
            object,
            prediction,
        })?;
        self.cancelled
            .lock()
            .map_err(poisoned)?
            .insert(id.clone(), Arc::new(AtomicBool::new(false)));
        tracing::info!(session = %id, "session created");
        Ok(id)
    }

    /// The part a session refines, by name.
    pub fn part_name(&self, id: &str) -> Option<String> {
        self.store.get(id).ok().flatten().map(|s| s.object.name)
    }

    /// A session with its captures and the render workers' object, for readers in the same
    /// process (the demo's report).
    pub fn stored(&self, id: &str) -> Result<StoredSession, StageError> {
        self.store
            .get(id)?
            .ok_or_else(|| StageError::NotFound(format!("session_id: no session {id:?}")))
    }

    /// A session without its captures.
    pub fn get(&self, id: &str) -> Result<Session, StageError> {
        let stored = self
            .store
            .get(id)?
            .ok_or_else(|| StageError::NotFound(format!("session_id: no session {id:?}")))?;
        Ok(Session {
            views: Vec::new(),
            ..stored.session
        })
    }

    pub fn list(&self) -> Result<Vec<Session>, StageError> {
        self.store.list()
    }

    /// Asks a session to stop at its next stage boundary; a session not running yet ends at
    /// once.
    pub fn cancel(&self, id: &str) -> Result<Session, StageError> {
        let stored = self
            .store
            .get(id)?
            .ok_or_else(|| StageError::NotFound(format!("session_id: no session {id:?}")))?;
        if let Some(flag) = self.cancelled.lock().map_err(poisoned)?.get(id) {
            flag.store(true, Ordering::Relaxed);
        }
        if stored.session.state == SessionState::Created {
            let mut session = stored.session;
            session.state = SessionState::Cancelled;
            self.store.update(&session)?;
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
        let stored = match self.store.get(id) {
            Ok(Some(stored)) => stored,
            Ok(None) => {
                self.release(id);
                return Err(StageError::NotFound(format!(
                    "session_id: no session {id:?}"
                )));
            }
            Err(e) => {
                self.release(id);
                return Err(e);
            }
        };
        if stored.session.state.is_final() {
            self.release(id);
            for step in &stored.session.steps {
                on_step(step);
            }
            return self.get(id);
        }
        let flag = self
            .cancelled
            .lock()
            .map_err(poisoned)?
            .get(id)
            .cloned()
            .unwrap_or_default();
        let StoredSession {
            mut session,
            object,
            prediction,
        } = stored;
        let stages = Stages {
            camera: self.camera.as_ref(),
            estimation: self.estimation.as_ref(),
            prediction: prediction.as_ref().map(|p| (self.prediction.as_ref(), p)),
        };
        let store = self.store.clone();
        let result = crate::session::run(
            &mut session,
            &object,
            &stages,
            |step| {
                if let Err(e) = store.record_step(id, step) {
                    tracing::error!(session = %id, "recording step {}: {e}", step.step);
                }
                on_step(step);
            },
            || flag.load(Ordering::Relaxed),
        );
        self.release(id);
        self.store.update(&session)?;
        match result {
            Ok(()) | Err(StageError::Cancelled) => {}
            Err(e) => tracing::warn!(session = %id, "session failed: {e}"),
        }
        self.get(id)
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
            Arc::new(MemoryStore::default()),
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
