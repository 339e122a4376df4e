//! Sessions on disk: `DIR/sessions.redb`, a redb database with one record per session (its
//! configuration, state, steps, and the names of its mesh and capture blobs), and
//! `DIR/blobs/`, the content-addressed captures and meshes ([`super::blobs`]).
//!
//! Why redb: pure Rust (no C library to build, which keeps CI's cold build short), one file,
//! ACID transactions whose commit is durable when it returns, and a crash between commits
//! leaves the last commit. Each record is stored behind its own SHA-256, so a damaged record
//! is reported at open instead of being served. A capture's blob is written (atomically)
//! before the record that names it, so a record never names a blob that was not complete.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use redb::{Database, ReadableDatabase, ReadableTable, TableDefinition};

use super::blobs::{BlobDir, BlobError};
use super::{
    SessionCalibration, SessionStore, StoredSession, append_step, capture_file, check_new,
    place_capture,
};
use crate::session::{Session, SessionConfig, SessionState, StepRecord};
use crate::stages::{CapturedView, SessionObject, StageError};

const SESSIONS: TableDefinition<&str, &[u8]> = TableDefinition::new("sessions");

/// The record format this build writes and reads.
const FORMAT: u32 = 1;

/// A session as its record keeps it.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
struct SessionRecord {
    format: u32,
    id: String,
    part_name: String,
    /// The mesh's blob: its canonical bytes, named by its content hash.
    mesh_blob: String,
    config: SessionConfig,
    calibration: Option<SessionCalibration>,
    state: SessionState,
    error: Option<String>,
    steps: Vec<StepRecord>,
    /// One capture blob per step captured (a step may be captured and not completed).
    captures: Vec<String>,
}

impl SessionRecord {
    fn session(&self) -> Session {
        Session {
            id: self.id.clone(),
            config: self.config.clone(),
            state: self.state,
            steps: self.steps.clone(),
            views: Vec::new(),
            error: self.error.clone(),
        }
    }
}

/// Why a state directory cannot be used. Each says what to do.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The database cannot be created or read: restore it from a backup, or move the state
    /// directory aside.
    #[error(
        "the session store {path} cannot be opened: {reason}. It is damaged or not a Glint \
         state file: restore it from a backup, or move the state directory aside to start \
         with no sessions"
    )]
    Open {
        /// The database file.
        path: String,
        /// What failed.
        reason: String,
    },
    /// A session's record is damaged (checksum, parse, format, id) or names a missing blob:
    /// restore the state directory from a backup, or move it aside.
    #[error(
        "the session store {path} is damaged: session {id}: {reason}. Nothing was served \
         from it: restore the state directory from a backup, or move it aside to start with no \
         sessions"
    )]
    Record {
        /// The database file.
        path: String,
        /// The session's id.
        id: String,
        /// What is wrong with its record.
        reason: String,
    },
    /// The blob directory cannot be opened or cleaned of a crash's temporary files.
    #[error("the session store's blob directory: {0}")]
    Blobs(#[from] BlobError),
}

/// Sessions kept in a state directory; they survive a crash of the process.
pub struct DiskStore {
    db: Database,
    blobs: BlobDir,
    /// The records as committed, ids oldest first.
    records: Mutex<(Vec<String>, HashMap<String, SessionRecord>)>,
    /// Meshes read back, by content hash.
    meshes: Mutex<HashMap<String, Arc<glint_geometry::TriMesh>>>,
}

/// A record's bytes: its SHA-256 (32 bytes), then its JSON.
fn encode(record: &SessionRecord) -> Result<Vec<u8>, StageError> {
    let json = serde_json::to_vec(record).map_err(|e| {
        StageError::Internal(format!("session {}: encoding its record: {e}", record.id))
    })?;
    use sha2::Digest;
    let mut bytes = sha2::Sha256::digest(&json).to_vec();
    bytes.extend_from_slice(&json);
    Ok(bytes)
}

fn decode(bytes: &[u8]) -> Result<SessionRecord, String> {
    use sha2::Digest;
    let (digest, json) = bytes
        .split_at_checked(32)
        .ok_or_else(|| format!("its record is {} bytes, too short", bytes.len()))?;
    if sha2::Sha256::digest(json).as_slice() != digest {
        return Err("its record fails its checksum".into());
    }
    let record: SessionRecord =
        serde_json::from_slice(json).map_err(|e| format!("its record does not parse: {e}"))?;
    if record.format != FORMAT {
        return Err(format!(
            "its record has format {}, this build reads {FORMAT}",
            record.format
        ));
    }
    Ok(record)
}

fn store_error(e: impl std::fmt::Display) -> StageError {
    StageError::Internal(format!("session store: {e}"))
}

fn blob_error(e: BlobError) -> StageError {
    match e {
        BlobError::Damaged { .. } | BlobError::Missing { .. } => {
            StageError::DataLoss(e.to_string())
        }
        _ => store_error(e),
    }
}

fn poisoned<T>(_: T) -> StageError {
    StageError::Internal("the session store's lock was poisoned".into())
}

impl DiskStore {
    /// The store in `dir` (created if missing). Every record is read and checked, and every
    /// blob it names must exist: a damaged store is an error naming what is damaged, never a
    /// store that serves part of it.
    pub fn open(dir: &Path) -> Result<Self, StoreError> {
        let db_path = dir.join("sessions.redb");
        let open_error = |reason: String| StoreError::Open {
            path: db_path.display().to_string(),
            reason,
        };
        std::fs::create_dir_all(dir).map_err(|e| open_error(e.to_string()))?;
        let blobs = BlobDir::open(&dir.join("blobs"))?;
        // redb asserts on some damaged files (a truncated one, for instance): a panic here is
        // a damaged store, said as such, not a crash.
        let opened = std::panic::catch_unwind(|| -> Result<Database, String> {
            let db = Database::create(&db_path).map_err(|e| e.to_string())?;
            let write = db.begin_write().map_err(|e| e.to_string())?;
            write.open_table(SESSIONS).map_err(|e| e.to_string())?;
            write.commit().map_err(|e| e.to_string())?;
            Ok(db)
        });
        let db = match opened {
            Ok(result) => result.map_err(open_error)?,
            Err(panic) => {
                let what = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_owned()))
                    .unwrap_or_default();
                return Err(open_error(format!("redb failed reading it ({what})")));
            }
        };

        let mut records = HashMap::new();
        {
            let read = db.begin_read().map_err(|e| open_error(e.to_string()))?;
            let table = read
                .open_table(SESSIONS)
                .map_err(|e| open_error(e.to_string()))?;
            for entry in table.iter().map_err(|e| open_error(e.to_string()))? {
                let (key, value) = entry.map_err(|e| open_error(e.to_string()))?;
                let id = key.value().to_owned();
                let damaged = |reason: String| StoreError::Record {
                    path: db_path.display().to_string(),
                    id: id.clone(),
                    reason,
                };
                let record = decode(value.value()).map_err(damaged)?;
                if record.id != id {
                    return Err(damaged(format!("its record names session {}", record.id)));
                }
                for blob in std::iter::once(&record.mesh_blob).chain(&record.captures) {
                    if !blobs.contains(blob) {
                        let path = blobs
                            .path(blob)
                            .map_or_else(|_| blob.clone(), |p: PathBuf| p.display().to_string());
                        return Err(damaged(format!("its blob {path} is missing")));
                    }
                }
                records.insert(id, record);
            }
        }
        let mut order: Vec<String> = records.keys().cloned().collect();
        order.sort_by_key(|id| (super::id_number(id), id.clone()));
        tracing::info!(
            path = %db_path.display(),
            sessions = order.len(),
            "session store opened"
        );
        Ok(Self {
            db,
            blobs,
            records: Mutex::new((order, records)),
            meshes: Mutex::new(HashMap::new()),
        })
    }

    /// Commits `record` and then caches it; under the records' lock, so writes are in order.
    fn commit(
        &self,
        records: &mut HashMap<String, SessionRecord>,
        record: SessionRecord,
    ) -> Result<(), StageError> {
        let bytes = encode(&record)?;
        let write = self.db.begin_write().map_err(store_error)?;
        {
            let mut table = write.open_table(SESSIONS).map_err(store_error)?;
            table
                .insert(record.id.as_str(), bytes.as_slice())
                .map_err(store_error)?;
        }
        write.commit().map_err(store_error)?;
        records.insert(record.id.clone(), record);
        Ok(())
    }

    /// Changes session `id`'s record with `change` and commits it.
    fn change(
        &self,
        id: &str,
        change: impl FnOnce(&mut SessionRecord) -> Result<(), StageError>,
    ) -> Result<(), StageError> {
        let mut guard = self.records.lock().map_err(poisoned)?;
        let mut record = guard
            .1
            .get(id)
            .cloned()
            .ok_or_else(|| StageError::NotFound(format!("session {id:?}")))?;
        change(&mut record)?;
        self.commit(&mut guard.1, record)
    }

    fn mesh(&self, name: &str) -> Result<Arc<glint_geometry::TriMesh>, StageError> {
        if let Some(mesh) = self.meshes.lock().map_err(poisoned)?.get(name) {
            return Ok(mesh.clone());
        }
        let bytes = self.blobs.get(name).map_err(blob_error)?;
        let mesh = glint_geometry::TriMesh::from_canonical_bytes(&bytes).ok_or_else(|| {
            StageError::DataLoss(format!("mesh blob {name} is not a canonical mesh"))
        })?;
        let mesh = Arc::new(mesh);
        self.meshes
            .lock()
            .map_err(poisoned)?
            .insert(name.to_owned(), mesh.clone());
        Ok(mesh)
    }
}

impl SessionStore for DiskStore {
    fn insert(&self, stored: &StoredSession) -> Result<(), StageError> {
        check_new(stored)?;
        let mesh_blob = self
            .blobs
            .put(&stored.object.mesh.canonical_bytes())
            .map_err(store_error)?;
        if mesh_blob != stored.object.mesh_sha256_hex {
            return Err(StageError::Internal(format!(
                "the mesh's blob {mesh_blob} is not its content hash {}",
                stored.object.mesh_sha256_hex
            )));
        }
        let session = &stored.session;
        let record = SessionRecord {
            format: FORMAT,
            id: session.id.clone(),
            part_name: stored.object.name.clone(),
            mesh_blob,
            config: session.config.clone(),
            calibration: stored.calibration.clone(),
            state: session.state,
            error: session.error.clone(),
            steps: Vec::new(),
            captures: Vec::new(),
        };
        let mut guard = self.records.lock().map_err(poisoned)?;
        if guard.1.contains_key(&record.id) {
            return Err(StageError::Internal(format!(
                "session {} exists already",
                record.id
            )));
        }
        let id = record.id.clone();
        self.commit(&mut guard.1, record)?;
        guard.0.push(id);
        Ok(())
    }

    fn get(&self, id: &str) -> Result<Option<StoredSession>, StageError> {
        let Some(record) = self.records.lock().map_err(poisoned)?.1.get(id).cloned() else {
            return Ok(None);
        };
        let mesh = self.mesh(&record.mesh_blob)?;
        let mut session = record.session();
        for (step, blob) in record.captures.iter().enumerate() {
            let bytes = self.blobs.get(blob).map_err(blob_error)?;
            let view = capture_file::from_bytes(&bytes).map_err(|e| {
                StageError::DataLoss(format!("session {id}: capture of step {step}: {e}"))
            })?;
            session.views.push(view);
        }
        Ok(Some(StoredSession {
            session,
            object: SessionObject {
                name: record.part_name.clone(),
                mesh,
                mesh_sha256_hex: record.mesh_blob.clone(),
            },
            calibration: record.calibration,
        }))
    }

    fn session(&self, id: &str) -> Result<Option<Session>, StageError> {
        Ok(self
            .records
            .lock()
            .map_err(poisoned)?
            .1
            .get(id)
            .map(SessionRecord::session))
    }

    fn list(&self) -> Result<Vec<Session>, StageError> {
        let guard = self.records.lock().map_err(poisoned)?;
        let (order, records) = &*guard;
        Ok(order
            .iter()
            .filter_map(|id| records.get(id))
            .map(SessionRecord::session)
            .collect())
    }

    fn part_name(&self, id: &str) -> Result<Option<String>, StageError> {
        Ok(self
            .records
            .lock()
            .map_err(poisoned)?
            .1
            .get(id)
            .map(|r| r.part_name.clone()))
    }

    fn record_capture(&self, id: &str, step: usize, view: &CapturedView) -> Result<(), StageError> {
        // The blob first: once the record names it, it is complete on disk.
        let bytes = capture_file::to_bytes(view).map_err(store_error)?;
        let blob = self.blobs.put(&bytes).map_err(store_error)?;
        self.change(id, |record| {
            place_capture(id, &mut record.captures, step, blob)
        })
    }

    fn record_step(&self, id: &str, step: &StepRecord) -> Result<(), StageError> {
        self.change(id, |record| {
            append_step(id, &mut record.steps, &mut record.state, step)
        })
    }

    fn set_state(
        &self,
        id: &str,
        state: SessionState,
        error: Option<&str>,
    ) -> Result<(), StageError> {
        self.change(id, |record| {
            record.state = state;
            record.error = error.map(str::to_owned);
            Ok(())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::session::{SessionConfig, StageTimes, ViewPolicy};
    use crate::stages::{RefineSettings, RefineSigma};
    use glint_estimation::view::ViewMeasurement;
    use glint_geometry::camera::StereoRig;
    use glint_geometry::image::{DepthMap, Image};
    use nalgebra::{Isometry3, Matrix6, Vector3};

    fn view(seed: u16) -> CapturedView {
        let (w, h) = (5, 3);
        let shot = |k: u16| Image::new(w, h, (0..w * h).map(|i| i as u16 * k + seed).collect());
        let mut depth: Vec<f32> = (0..w * h).map(|i| 0.5 + i as f32 * 1e-3).collect();
        depth[2] = f32::NAN;
        CapturedView {
            measurement: ViewMeasurement {
                t_w_c: Isometry3::translation(0.1, 0.0, 0.5),
                stereo: StereoRig::ensenso_n35(),
                depth: DepthMap::new(Image::new(w, h, depth).unwrap()),
                left: vec![shot(1).unwrap(), shot(2).unwrap()],
                right: vec![shot(3).unwrap(), shot(4).unwrap()],
                noise_shots: Some([shot(5).unwrap(), shot(6).unwrap()]),
                max_dn: 4095,
            },
            capture_ms: 12.5,
        }
    }

    fn stored(id: &str, part_name: &str) -> StoredSession {
        let config = SessionConfig {
            initial_t_w_o: Isometry3::translation(0.0, 0.0, 0.02),
            candidates: vec![Isometry3::identity(), Isometry3::translation(0.1, 0.0, 0.0)],
            first_view: 0,
            policy: ViewPolicy::Random,
            max_views: 2,
            entropy_threshold_nats: Some(-40.0),
            seed: 7,
            refine: RefineSettings {
                mask_margin_m: 0.01,
                final_mask_margin_m: Some(0.003),
                background: None,
                erode_px: 1,
                window_radius_px: 1,
                sigma: RefineSigma::PatternImages,
                align_depth: true,
                // A journal keeps the error model (B as rows, not nalgebra's columns).
                error_model: Some(glint_estimation::pose_error_model::PoseErrorModel {
                    depth_error: glint_estimation::correlated_error::CorrelatedDepthError {
                        cell_m: 2e-3,
                        bias_sigma_m: 0.5e-3,
                    },
                    view_bias: glint_estimation::view_bias::ViewPoseBias {
                        covariance_v: Matrix6::from_fn(|i, j| if i == j { 1e-6 } else { 2e-8 }),
                    },
                }),
            },
            const_sigma_z_m: 5e-4,
        };
        let mesh = glint_geometry::TriMesh::uv_sphere(0.01, 8);
        StoredSession {
            session: Session::new(id.into(), config).unwrap(),
            object: SessionObject::new(part_name, mesh),
            calibration: None,
        }
    }

    fn step(n: usize) -> StepRecord {
        StepRecord {
            step: n,
            view: n,
            t_w_c: Isometry3::translation(0.1 * n as f64, 0.0, 0.0),
            view_points: 100 + n,
            total_points: 200 + n,
            t_w_o: Isometry3::new(Vector3::new(0.0, 1e-3, 0.02), Vector3::new(0.0, 0.1, 0.0)),
            information: Matrix6::identity() * 1e6,
            pixel_information: Matrix6::identity() * 4e6,
            covariance: Some(Matrix6::identity() * 1e-6),
            entropy_nats: -41.25,
            predicted_entropy_nats: None,
            refine_status: "converged".into(),
            candidate_entropies_nats: vec![None, Some(-42.5)],
            next_view: Some(1),
            times: StageTimes {
                capture_ms: 1.0,
                refine_ms: 2.0,
                predict_ms: 3.0,
                plan_ms: 4.0,
            },
        }
    }

    fn same_view(a: &CapturedView, b: &CapturedView) -> bool {
        let (a, b) = (&a.measurement, &b.measurement);
        let bits = |m: &ViewMeasurement| -> Vec<u32> {
            m.depth.depth_m.data().iter().map(|z| z.to_bits()).collect()
        };
        a.t_w_c == b.t_w_c
            && a.stereo == b.stereo
            && bits(a) == bits(b)
            && a.left == b.left
            && a.right == b.right
            && a.noise_shots == b.noise_shots
            && a.max_dn == b.max_dn
    }

    #[test]
    fn a_session_reads_back_after_reopening_and_steps_are_kept_once_in_order() {
        let dir = tempfile::tempdir().unwrap();
        {
            let store = DiskStore::open(dir.path()).unwrap();
            store.insert(&stored("s000001", "zigzag")).unwrap();
            store.insert(&stored("s000002", "gear")).unwrap();
            store.record_capture("s000001", 0, &view(1)).unwrap();
            store.record_step("s000001", &step(0)).unwrap();
            store.record_capture("s000001", 1, &view(2)).unwrap();
            // A step is kept once, in order; a capture not before its predecessors.
            assert!(store.record_step("s000001", &step(0)).is_err());
            assert!(store.record_step("s000001", &step(2)).is_err());
            assert!(store.record_capture("s000001", 3, &view(3)).is_err());
            assert!(matches!(
                store.record_step("s000009", &step(0)),
                Err(StageError::NotFound(_))
            ));
        }
        let store = DiskStore::open(dir.path()).unwrap();
        let ids: Vec<String> = store.list().unwrap().into_iter().map(|s| s.id).collect();
        assert_eq!(ids, ["s000001", "s000002"]);
        let back = store.get("s000001").unwrap().unwrap();
        assert_eq!(back.session.state, SessionState::Running);
        assert_eq!(back.session.steps, vec![step(0)]);
        assert_eq!(
            back.session.config,
            stored("s000001", "zigzag").session.config
        );
        assert_eq!(back.session.views.len(), 2);
        assert!(same_view(&back.session.views[0], &view(1)));
        assert!(same_view(&back.session.views[1], &view(2)));
        assert_eq!(back.session.views[1].capture_ms, 12.5);
        assert_eq!(back.object.name, "zigzag");
        assert_eq!(
            back.object.mesh.content_sha256_hex(),
            back.object.mesh_sha256_hex
        );
        assert_eq!(store.part_name("s000002").unwrap().as_deref(), Some("gear"));
        store
            .set_state("s000001", SessionState::Failed, Some("camera unplugged"))
            .unwrap();
        drop(store);
        let store = DiskStore::open(dir.path()).unwrap();
        let session = store.session("s000001").unwrap().unwrap();
        assert_eq!(session.state, SessionState::Failed);
        assert_eq!(session.error.as_deref(), Some("camera unplugged"));
    }

    #[test]
    fn a_truncated_store_is_refused_with_what_to_do() {
        let dir = tempfile::tempdir().unwrap();
        {
            let store = DiskStore::open(dir.path()).unwrap();
            store.insert(&stored("s000001", "zigzag")).unwrap();
            store.record_step("s000001", &step(0)).unwrap();
        }
        let path = dir.path().join("sessions.redb");
        let len = std::fs::metadata(&path).unwrap().len();
        let file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
        file.set_len(len / 2).unwrap();
        drop(file);
        let message = match DiskStore::open(dir.path()) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("a truncated store opened"),
        };
        assert!(message.contains("sessions.redb"), "{message}");
        assert!(
            message.contains("move the state directory aside"),
            "{message}"
        );
    }

    #[test]
    fn a_damaged_record_or_blob_is_reported_and_never_served() {
        let dir = tempfile::tempdir().unwrap();
        let blob = {
            let store = DiskStore::open(dir.path()).unwrap();
            store.insert(&stored("s000001", "probe-part-name")).unwrap();
            store.record_capture("s000001", 0, &view(1)).unwrap();
            store.get("s000001").unwrap();
            let guard = store.records.lock().unwrap();
            guard.1["s000001"].captures[0].clone()
        };
        let blobs = BlobDir::open(&dir.path().join("blobs")).unwrap();

        // A capture's bytes changed: reading the session is DATA_LOSS naming the blob.
        let path = blobs.path(&blob).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 0x40;
        std::fs::write(&path, &bytes).unwrap();
        let store = DiskStore::open(dir.path()).unwrap();
        match store.get("s000001") {
            Err(StageError::DataLoss(m)) => assert!(m.contains(&blob), "{m}"),
            other => panic!("expected DataLoss, got {other:?}"),
        }
        // Its state without the captures is still served.
        assert!(store.session("s000001").unwrap().is_some());
        drop(store);

        // A capture gone: the store refuses to open, naming the session and the blob.
        std::fs::remove_file(&path).unwrap();
        let message = DiskStore::open(dir.path()).err().unwrap().to_string();
        assert!(
            message.contains("s000001") && message.contains(&blob),
            "{message}"
        );
        std::fs::write(&path, &bytes).unwrap();

        // A record's bytes changed inside the database file: refused, never served.
        let db = dir.path().join("sessions.redb");
        let mut file = std::fs::read(&db).unwrap();
        // Every copy (copy-on-write leaves older pages behind).
        let needle = b"probe-part-name";
        let copies: Vec<usize> = (0..file.len() - needle.len())
            .filter(|&i| &file[i..i + needle.len()] == needle)
            .collect();
        assert!(!copies.is_empty());
        for at in copies {
            file[at] = b'P';
        }
        std::fs::write(&db, &file).unwrap();
        let message = DiskStore::open(dir.path()).err().unwrap().to_string();
        assert!(message.contains("sessions.redb"), "{message}");
    }
}
