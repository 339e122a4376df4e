//! Sessions in memory.

use std::collections::HashMap;
use std::sync::Mutex;

use super::{SessionStore, StoredSession, append_step, check_new, place_capture};
use crate::session::{Session, SessionState, StepRecord};
use crate::stages::{CapturedView, StageError};

/// Sessions in memory, lost when the process ends.
#[derive(Default)]
pub struct MemoryStore {
    /// Ids oldest first, and the sessions.
    sessions: Mutex<(Vec<String>, HashMap<String, StoredSession>)>,
}

fn poisoned<T>(_: T) -> StageError {
    StageError::Internal("the session store's lock was poisoned".into())
}

fn not_found(id: &str) -> StageError {
    StageError::NotFound(format!("session {id:?}"))
}

impl MemoryStore {
    fn with<T>(
        &self,
        id: &str,
        f: impl FnOnce(&mut StoredSession) -> Result<T, StageError>,
    ) -> Result<T, StageError> {
        let mut guard = self.sessions.lock().map_err(poisoned)?;
        f(guard.1.get_mut(id).ok_or_else(|| not_found(id))?)
    }
}

/// `session` without its captures.
pub(super) fn without_views(session: &Session) -> Session {
    Session {
        id: session.id.clone(),
        config: session.config.clone(),
        state: session.state,
        steps: session.steps.clone(),
        views: Vec::new(),
        error: session.error.clone(),
    }
}

impl SessionStore for MemoryStore {
    fn insert(&self, session: &StoredSession) -> Result<(), StageError> {
        check_new(session)?;
        let mut guard = self.sessions.lock().map_err(poisoned)?;
        let (order, map) = &mut *guard;
        let id = session.session.id.clone();
        if map.contains_key(&id) {
            return Err(StageError::Internal(format!("session {id} exists already")));
        }
        order.push(id.clone());
        map.insert(id, session.clone());
        Ok(())
    }

    fn get(&self, id: &str) -> Result<Option<StoredSession>, StageError> {
        Ok(self.sessions.lock().map_err(poisoned)?.1.get(id).cloned())
    }

    fn session(&self, id: &str) -> Result<Option<Session>, StageError> {
        Ok(self
            .sessions
            .lock()
            .map_err(poisoned)?
            .1
            .get(id)
            .map(|s| without_views(&s.session)))
    }

    fn list(&self) -> Result<Vec<Session>, StageError> {
        let guard = self.sessions.lock().map_err(poisoned)?;
        let (order, map) = &*guard;
        Ok(order
            .iter()
            .filter_map(|id| map.get(id))
            .map(|s| without_views(&s.session))
            .collect())
    }

    fn part_name(&self, id: &str) -> Result<Option<String>, StageError> {
        Ok(self
            .sessions
            .lock()
            .map_err(poisoned)?
            .1
            .get(id)
            .map(|s| s.object.name.clone()))
    }

    fn record_capture(&self, id: &str, step: usize, view: &CapturedView) -> Result<(), StageError> {
        self.with(id, |stored| {
            place_capture(id, &mut stored.session.views, step, view.clone())
        })
    }

    fn record_step(&self, id: &str, step: &StepRecord) -> Result<(), StageError> {
        self.with(id, |stored| {
            let session = &mut stored.session;
            append_step(id, &mut session.steps, &mut session.state, step)
        })
    }

    fn set_state(
        &self,
        id: &str,
        state: SessionState,
        error: Option<&str>,
    ) -> Result<(), StageError> {
        self.with(id, |stored| {
            stored.session.state = state;
            stored.session.error = error.map(str::to_owned);
            Ok(())
        })
    }
}
