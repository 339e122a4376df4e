//! Where an orchestrator keeps its sessions: [`SessionStore`], with [`MemoryStore`] (lost
//! when the process ends) and [`DiskStore`] (a redb database of session records beside a
//! content-addressed blob directory of captures and meshes, which survives a crash).
//!
//! A session reaches its store as it runs: each capture as soon as it is taken, each step as
//! it completes, its final state at the end. A session interrupted by a crash therefore
//! resumes from its last completed step and refines on the captures it already has.

pub mod blobs;
pub mod capture_file;
mod disk;
mod memory;

pub use disk::{DiskStore, StoreError};
pub use memory::MemoryStore;

use glint_estimation::depth_sigma::NoiseModel;

use crate::session::{Session, SessionState, StepRecord};
use crate::stages::{CapturedView, PartCalibration, SessionObject, StageError};

/// What the render workers' object of a session is built from (entropy policies only): the
/// part's calibration and the sensor's noise as fitted when the session started. The rest —
/// the camera's rig, exposure and shots, the cell's surroundings — is the orchestrator's.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SessionCalibration {
    /// The part's material, response and radiometric scale.
    pub part: PartCalibration,
    /// The sensor's noise σ_I² (eq 2), fitted when the session started.
    pub noise: NoiseModel,
}

/// A session as the store keeps it: its state machine with its captures, its part, and what
/// its predictions need.
#[derive(Clone, Debug)]
pub struct StoredSession {
    /// The session, its captures included.
    pub session: Session,
    /// The part it refines.
    pub object: SessionObject,
    /// What its predictions need; `None` for a policy that predicts nothing.
    pub calibration: Option<SessionCalibration>,
}

/// Where sessions live. Every write is complete or absent: a crash between two calls loses
/// nothing that an earlier call returned `Ok` for.
pub trait SessionStore: Send + Sync {
    /// Adds a new session (no steps, no captures yet: anything else is refused).
    fn insert(&self, session: &StoredSession) -> Result<(), StageError>;
    /// A session with its captures, to run it or to write its report; `None` for an
    /// unknown id.
    fn get(&self, id: &str) -> Result<Option<StoredSession>, StageError>;
    /// A session without its captures (`views` empty).
    fn session(&self, id: &str) -> Result<Option<Session>, StageError>;
    /// Every session without its captures, oldest first.
    fn list(&self) -> Result<Vec<Session>, StageError>;
    /// The name of a session's part.
    fn part_name(&self, id: &str) -> Result<Option<String>, StageError>;
    /// Keeps step `step`'s capture (replacing one kept for that step before).
    fn record_capture(&self, id: &str, step: usize, view: &CapturedView) -> Result<(), StageError>;
    /// Keeps a completed step, which must be the session's next (a step is never kept
    /// twice); the session is then running.
    fn record_step(&self, id: &str, step: &StepRecord) -> Result<(), StageError>;
    /// Sets a session's state and error (after a run, a cancel).
    fn set_state(
        &self,
        id: &str,
        state: SessionState,
        error: Option<&str>,
    ) -> Result<(), StageError>;
}

/// The number in an orchestrator's session id (`s000042` → 42).
pub fn id_number(id: &str) -> Option<u64> {
    id.strip_prefix('s')?.parse().ok()
}

/// The id of session number `n`.
pub fn id_of(n: u64) -> String {
    format!("s{n:06}")
}

/// Appends a completed step to a session's `steps`, which must be its next (a step is kept
/// once, in order); the session is then running.
fn append_step(
    id: &str,
    steps: &mut Vec<StepRecord>,
    state: &mut SessionState,
    step: &StepRecord,
) -> Result<(), StageError> {
    if step.step != steps.len() {
        return Err(StageError::Internal(format!(
            "session {id}: step {} recorded after {} steps; steps are kept once, in order",
            step.step,
            steps.len()
        )));
    }
    *state = SessionState::Running;
    steps.push(step.clone());
    Ok(())
}

/// A session [`SessionStore::insert`] takes: new, without steps or captures (those come
/// through `record_step` and `record_capture`, so that nothing given is silently not kept).
fn check_new(stored: &StoredSession) -> Result<(), StageError> {
    let session = &stored.session;
    if session.steps.is_empty() && session.views.is_empty() {
        Ok(())
    } else {
        Err(StageError::Internal(format!(
            "session {}: insert takes a new session; its {} steps and {} captures go through \
             record_step and record_capture",
            session.id,
            session.steps.len(),
            session.views.len()
        )))
    }
}

/// Puts step `step`'s capture `item` into a session's `captures`: replaces a kept one, or
/// appends the next; a capture beyond the next is an error.
fn place_capture<T>(
    id: &str,
    captures: &mut Vec<T>,
    step: usize,
    item: T,
) -> Result<(), StageError> {
    match step.cmp(&captures.len()) {
        std::cmp::Ordering::Less => captures[step] = item,
        std::cmp::Ordering::Equal => captures.push(item),
        std::cmp::Ordering::Greater => {
            return Err(StageError::Internal(format!(
                "session {id}: the capture of step {step} recorded after {} captures",
                captures.len()
            )));
        }
    }
    Ok(())
}
