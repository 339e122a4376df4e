//! The render workers over gRPC: one decision's candidates fanned out across every
//! `UncertaintyService` worker, with failover.
//!
//! - One channel per worker address, at most [`PoolConfig::in_flight_per_worker`] requests in
//!   flight on each, all pulling from one shared queue of candidates, so a fast worker takes
//!   more.
//! - Every call has a deadline ([`PoolConfig::call_deadline`], sent as `grpc-timeout`); a call
//!   that fails as a transport would (UNAVAILABLE, DEADLINE_EXCEEDED, a reset stream...) puts
//!   its candidates back at the front of the queue for another worker, and its worker rests
//!   for [`PoolConfig::retry_after`] before it is tried again. A worker that comes back is used
//!   again.
//! - A worker that lacks the object answers NOT_FOUND: it is registered there and the request
//!   re-sent, so workers stay stateless and replaceable.
//! - Workers come from a static list or from re-resolving a DNS name before every decision
//!   (compose service names, Kubernetes headless Services): every address is a worker.
//!
//! A candidate's prediction depends only on the request (its seed and the candidate's index),
//! so whichever worker answers, the decision is the same.

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use glint_geometry::image::Image;
use glint_proto::v1;
use glint_proto::v1::uncertainty_service_client::UncertaintyServiceClient;
use glint_uncertainty::server::{ObjectDescription, object_key, object_to_message};
use nalgebra::Matrix6;
use tokio::runtime::Handle;
use tonic::Code;

use super::{AuthChannel, ClientSecurity, Endpoint, request, stage_error};
use crate::stages::{
    CandidateInformation, PredictedMaps, PredictionObject, PredictionRequest, PredictionSigma,
    PredictionStage, StageError,
};

/// Where the render workers are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WorkerSource {
    /// Fixed addresses, `host:port` or `http://host:port`.
    Static(Vec<String>),
    /// `host:port` resolved again before every decision: each address it resolves to is a
    /// worker (a compose service scaled to N, a Kubernetes headless Service).
    Dns(String),
}

impl WorkerSource {
    /// A comma-separated list of addresses, or `dns:HOST:PORT`.
    pub fn parse(spec: &str) -> Result<Self, StageError> {
        let spec = spec.trim();
        if let Some(name) = spec.strip_prefix("dns:") {
            if name
                .rsplit_once(':')
                .is_none_or(|(_, p)| p.parse::<u16>().is_err())
            {
                return Err(StageError::invalid(
                    "workers",
                    format!("dns:{name}: give dns:HOST:PORT, e.g. dns:uncertainty:50051"),
                ));
            }
            return Ok(Self::Dns(name.to_owned()));
        }
        let list: Vec<String> = spec
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(str::to_owned)
            .collect();
        if list.is_empty() {
            return Err(StageError::invalid(
                "workers",
                "no worker address; give HOST:PORT[,HOST:PORT...] or dns:HOST:PORT",
            ));
        }
        Ok(Self::Static(list))
    }

    /// The workers as the flag gave them, for messages.
    pub fn describe(&self) -> String {
        match self {
            Self::Static(list) => list.join(","),
            Self::Dns(name) => format!("dns:{name}"),
        }
    }
}

/// How the pool spreads a decision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoolConfig {
    /// Requests in flight per worker (each worker renders in parallel inside too).
    pub in_flight_per_worker: usize,
    /// Candidates per request: 1 balances best; more saves round trips.
    pub candidates_per_request: usize,
    /// Deadline of one PredictCandidates (or RegisterObject) call.
    pub call_deadline: Duration,
    /// Deadline of a whole decision: past it, the decision fails UNAVAILABLE.
    pub decision_deadline: Duration,
    /// A worker whose call failed is not sent more for this long.
    pub retry_after: Duration,
}

impl Default for PoolConfig {
    fn default() -> Self {
        Self {
            in_flight_per_worker: 2,
            candidates_per_request: 1,
            call_deadline: Duration::from_secs(60),
            decision_deadline: Duration::from_secs(600),
            retry_after: Duration::from_millis(500),
        }
    }
}

/// What the pool has done, for benchmarks and tests.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PoolStats {
    /// PredictCandidates calls answered, per worker address.
    pub answered_by: HashMap<String, usize>,
    /// Requests put back on the queue after a worker failed them.
    pub resent: usize,
    /// RegisterObject calls made (a worker lacked the object).
    pub registered: usize,
    /// Answers refused as invalid (wrong candidates, a Fisher information that is not a
    /// finite symmetric positive semi-definite matrix); their candidates were re-sent.
    pub rejected: usize,
    /// Bytes of the answered PredictCandidates requests (protobuf encoded).
    pub request_bytes: usize,
    /// Bytes of their responses (protobuf encoded).
    pub response_bytes: usize,
}

struct Worker {
    uri: String,
    client: UncertaintyServiceClient<AuthChannel>,
    /// Objects this worker is known to hold.
    registered: HashSet<String>,
    /// Not sent anything before this instant.
    resting_until: Option<Instant>,
}

/// The render workers over gRPC.
pub struct RemotePrediction {
    handle: Handle,
    source: WorkerSource,
    /// How decisions are spread over the workers, and their deadlines.
    pub config: PoolConfig,
    /// The token and TLS settings of the calls to workers.
    security: ClientSecurity,
    workers: Mutex<Vec<Worker>>,
    /// Why the last decision lacked workers, for the error a client sees.
    last_problem: Mutex<Option<String>>,
    stats: Mutex<PoolStats>,
}

fn poisoned<T>(_: T) -> StageError {
    StageError::Internal("the worker pool's lock was poisoned".into())
}

/// Whether a failed call should go to another worker: what a dead, restarting or overloaded
/// worker (or the network) answers, as opposed to the request's own fault.
fn is_worker_failure(code: Code) -> bool {
    matches!(
        code,
        Code::Unavailable
            | Code::DeadlineExceeded
            | Code::ResourceExhausted
            | Code::Aborted
            | Code::Unknown
            | Code::Cancelled
    )
}

/// One request's worth of candidates.
type Batch = Vec<(u32, v1::Pose)>;

/// One decision's shared work: the batches to send, the answers, and how many batches are out
/// with workers.
struct DecisionWork {
    queue: Mutex<VecDeque<Batch>>,
    results: Mutex<Vec<v1::CandidatePrediction>>,
    out: AtomicUsize,
}

/// A batch taken from the queue and not yet answered or given back; counted down when dropped
/// (after a give-back has queued it again).
struct BatchOut<'a>(&'a AtomicUsize);

impl Drop for BatchOut<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

enum TaskEnd {
    /// The queue ran dry.
    Done,
    /// This worker failed a call (its batch is back on the queue).
    WorkerFailed,
}

impl RemotePrediction {
    /// A pool of the workers `source` names, called through `handle`'s runtime (which must
    /// outlive it), with neither token nor TLS until [`Self::with_security`]. Nothing is
    /// resolved or connected before the first decision.
    pub fn new(handle: Handle, source: WorkerSource, config: PoolConfig) -> Self {
        Self {
            handle,
            source,
            config,
            security: ClientSecurity::default(),
            workers: Mutex::new(Vec::new()),
            last_problem: Mutex::new(None),
            stats: Mutex::new(PoolStats::default()),
        }
    }

    /// Calls the workers with this token and TLS settings.
    pub fn with_security(mut self, security: ClientSecurity) -> Self {
        self.security = security;
        self
    }

    /// What the pool has done since it was made.
    pub fn stats(&self) -> PoolStats {
        self.stats.lock().map(|s| s.clone()).unwrap_or_default()
    }

    /// The workers' addresses now.
    async fn resolve(&self) -> Result<Vec<String>, StageError> {
        match &self.source {
            WorkerSource::Static(list) => Ok(list.clone()),
            WorkerSource::Dns(name) => {
                let addrs = tokio::net::lookup_host(name.as_str())
                    .await
                    .map_err(|e| StageError::Unavailable(format!("resolving {name}: {e}")))?;
                let mut list: Vec<String> = addrs.map(|a| a.to_string()).collect();
                list.sort();
                list.dedup();
                Ok(list)
            }
        }
    }

    fn endpoint(&self, address: &str) -> Endpoint {
        Endpoint::secured(address, self.config.call_deadline, self.security.clone())
    }

    /// Brings the worker list in line with `addresses` (new ones get a channel; vanished ones
    /// are dropped) and returns the indices of those not resting.
    fn refresh(&self, addresses: &[String]) -> Result<Vec<usize>, StageError> {
        let mut workers = self.workers.lock().map_err(poisoned)?;
        let uris: Vec<String> = addresses.iter().map(|a| self.endpoint(a).uri).collect();
        workers.retain(|w| uris.contains(&w.uri));
        for uri in &uris {
            if !workers.iter().any(|w| &w.uri == uri) {
                let channel = self.endpoint(uri).channel()?;
                workers.push(Worker {
                    uri: uri.clone(),
                    client: UncertaintyServiceClient::new(channel),
                    registered: HashSet::new(),
                    resting_until: None,
                });
            }
        }
        let now = Instant::now();
        Ok(workers
            .iter()
            .enumerate()
            .filter(|(_, w)| w.resting_until.is_none_or(|t| t <= now))
            .map(|(i, _)| i)
            .collect())
    }

    /// When the first resting worker wakes, if any.
    fn next_wake(&self) -> Option<Instant> {
        self.workers
            .lock()
            .ok()?
            .iter()
            .filter_map(|w| w.resting_until)
            .min()
    }

    fn worker(
        &self,
        i: usize,
    ) -> Result<(String, UncertaintyServiceClient<AuthChannel>), StageError> {
        let workers = self.workers.lock().map_err(poisoned)?;
        let w = workers
            .get(i)
            .ok_or_else(|| StageError::Internal(format!("worker {i} vanished")))?;
        Ok((w.uri.clone(), w.client.clone()))
    }

    fn rest(&self, uri: &str) {
        if let Ok(mut workers) = self.workers.lock()
            && let Some(w) = workers.iter_mut().find(|w| w.uri == uri)
        {
            w.resting_until = Some(Instant::now() + self.config.retry_after);
            // A restarted worker has lost its objects.
            w.registered.clear();
        }
    }

    fn is_resting(&self, uri: &str) -> bool {
        self.workers.lock().is_ok_and(|workers| {
            workers
                .iter()
                .any(|w| w.uri == uri && w.resting_until.is_some_and(|t| t > Instant::now()))
        })
    }

    fn count(&self, f: impl FnOnce(&mut PoolStats)) {
        if let Ok(mut s) = self.stats.lock() {
            f(&mut s);
        }
    }

    /// Takes batches from `queue` and sends them to worker `i` until the queue is empty, the
    /// worker fails (its batch goes back) or a request fails on its own (the error).
    async fn drain_into(
        &self,
        i: usize,
        work: &DecisionWork,
        template: &v1::PredictCandidatesRequest,
        registration: &v1::RegisterObjectRequest,
        key: &str,
    ) -> Result<TaskEnd, StageError> {
        let (queue, results, out) = (&work.queue, &work.results, &work.out);
        let (uri, mut client) = self.worker(i)?;
        loop {
            if self.is_resting(&uri) {
                return Ok(TaskEnd::WorkerFailed);
            }
            // Taken under the queue's lock, with the count of batches out, so that an idle
            // task sees either work queued or work that may come back.
            let (popped, batches_out) = {
                let mut q = queue.lock().map_err(poisoned)?;
                let popped = q.pop_front();
                if popped.is_some() {
                    out.fetch_add(1, Ordering::SeqCst);
                }
                (popped, out.load(Ordering::SeqCst))
            };
            let Some(batch) = popped else {
                if batches_out == 0 {
                    return Ok(TaskEnd::Done);
                }
                // Batches out with other workers come back when one fails or passes its
                // deadline: wait for them here, or a worker that is slow every time would
                // take its batch back at each round and never let a sound worker have it.
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            };
            let _out = BatchOut(out);
            let give_back = |batch: Batch| {
                if let Ok(mut q) = queue.lock() {
                    q.push_front(batch);
                }
            };
            let mut message = template.clone();
            message.candidate_indices = batch.iter().map(|(i, _)| *i).collect();
            message.candidates_t_w_c = batch.iter().map(|(_, p)| p.clone()).collect();
            let request_bytes = prost::Message::encoded_len(&message);
            let mut registered_now = false;
            let answer = loop {
                let call = client
                    .predict_candidates(request(message.clone(), self.config.call_deadline))
                    .await;
                match call {
                    Err(status) if status.code() == Code::NotFound && !registered_now => {
                        // The worker lacks the object (new or restarted): register, re-send.
                        registered_now = true;
                        self.count(|s| s.registered += 1);
                        match client
                            .register_object(request(
                                registration.clone(),
                                self.config.call_deadline,
                            ))
                            .await
                        {
                            Ok(r) if r.get_ref().object_sha256_hex == key => {}
                            Ok(r) => {
                                return Err(StageError::Internal(format!(
                                    "worker {uri} registered the object as {} where this \
                                     orchestrator computes {key}: are they the same version?",
                                    r.get_ref().object_sha256_hex
                                )));
                            }
                            Err(status) => break Err(status),
                        }
                    }
                    other => break other,
                }
            };
            match answer {
                Ok(response) => {
                    let response = response.into_inner();
                    if let Err(problem) = check_answer(&batch, &response.predictions) {
                        // Garbage from one worker (a bug, a bad build, bit rot) must not
                        // decide the view: its candidates go to another worker.
                        tracing::warn!(
                            worker = %uri,
                            "worker answered an invalid prediction ({problem}); re-sending its \
                             {} candidate(s) to another worker", batch.len()
                        );
                        give_back(batch);
                        self.count(|s| {
                            s.resent += 1;
                            s.rejected += 1;
                        });
                        self.rest(&uri);
                        return Ok(TaskEnd::WorkerFailed);
                    }
                    self.count(|s| {
                        *s.answered_by.entry(uri.clone()).or_default() += 1;
                        s.request_bytes += request_bytes;
                        s.response_bytes += prost::Message::encoded_len(&response);
                    });
                    results
                        .lock()
                        .map_err(poisoned)?
                        .extend(response.predictions);
                }
                Err(status) if is_worker_failure(status.code()) => {
                    tracing::warn!(
                        worker = %uri, code = ?status.code(),
                        "worker failed a prediction ({}); re-sending its {} candidate(s) to \
                         another worker", status.message(), batch.len()
                    );
                    give_back(batch);
                    self.count(|s| s.resent += 1);
                    self.rest(&uri);
                    return Ok(TaskEnd::WorkerFailed);
                }
                Err(status) => {
                    give_back(batch);
                    return Err(stage_error(&status));
                }
            }
        }
    }

    async fn fan_out(
        &self,
        queue: VecDeque<Batch>,
        template: v1::PredictCandidatesRequest,
        registration: v1::RegisterObjectRequest,
        key: String,
    ) -> Result<Vec<v1::CandidatePrediction>, StageError> {
        let work = DecisionWork {
            queue: Mutex::new(queue),
            results: Mutex::new(Vec::new()),
            out: AtomicUsize::new(0),
        };
        loop {
            // No worker yet (a name that resolves to nothing: a service scaled to zero, a
            // worker not up yet) is waited out like a resting one, within the decision's
            // deadline: the decision goes on when workers appear.
            let addresses = match self.resolve().await {
                Ok(addresses) => addresses,
                Err(e) => {
                    tracing::warn!("no render worker: {e}; waiting for one");
                    if let Ok(mut last) = self.last_problem.lock() {
                        *last = Some(e.to_string());
                    }
                    Vec::new()
                }
            };
            if addresses.is_empty()
                && let Ok(mut last) = self.last_problem.lock()
                && last.is_none()
            {
                *last = Some("the worker list is empty".into());
            }
            let ready = self.refresh(&addresses)?;
            if !ready.is_empty() {
                let tasks = ready.iter().flat_map(|&i| {
                    (0..self.config.in_flight_per_worker.max(1))
                        .map(move |_| i)
                        .map(|i| self.drain_into(i, &work, &template, &registration, &key))
                });
                let ends = futures_util::future::join_all(tasks).await;
                for end in ends {
                    end?;
                }
            }
            if work.queue.lock().map_err(poisoned)?.is_empty() {
                return work.results.into_inner().map_err(poisoned);
            }
            // Every worker failed (or none was ready): wait for the first to wake, re-resolve.
            let wake = self
                .next_wake()
                .unwrap_or_else(|| Instant::now() + self.config.retry_after);
            tokio::time::sleep_until(wake.into()).await;
        }
    }
}

/// Whether a worker's `answer` to `batch` is one to use: exactly the batch's candidates, each
/// with a Fisher information that is finite, symmetric and positive semi-definite (eq 21–22
/// sums outer products, so anything else is garbage).
fn check_answer(batch: &Batch, answer: &[v1::CandidatePrediction]) -> Result<(), String> {
    let mut asked: Vec<u32> = batch.iter().map(|(i, _)| *i).collect();
    let mut got: Vec<u32> = answer.iter().map(|p| p.candidate_index).collect();
    asked.sort_unstable();
    got.sort_unstable();
    if asked != got {
        return Err(format!("asked for candidates {asked:?}, answered {got:?}"));
    }
    for p in answer {
        // Finite and symmetric by the conversion.
        let information = p
            .information
            .as_ref()
            .ok_or_else(|| format!("candidate {}: no information", p.candidate_index))
            .and_then(|m| {
                Matrix6::try_from(m).map_err(|e| format!("candidate {}: {e}", p.candidate_index))
            })?;
        let eigenvalues = information.symmetric_eigenvalues();
        let scale = eigenvalues.amax().max(f64::MIN_POSITIVE);
        if eigenvalues.min() < -1e-9 * scale {
            return Err(format!(
                "candidate {}: information is not positive semi-definite (eigenvalue {:.3e} \
                 of {scale:.3e})",
                p.candidate_index,
                eigenvalues.min()
            ));
        }
    }
    Ok(())
}

/// A worker's σ̌_z map (FLOAT32, NaN where missing, kept) and its cause map (MONO8 of the
/// same size).
fn predicted_maps(
    sigma: &v1::Image,
    cause: Option<&v1::Image>,
    roi_u0_px: u32,
    roi_v0_px: u32,
) -> Result<PredictedMaps, StageError> {
    let bad = |m: &str| StageError::Internal(format!("a worker's {m}"));
    if sigma.encoding != v1::ImageEncoding::Float32Le as i32 {
        return Err(bad("sigma_z_m map is not FLOAT32"));
    }
    let n = sigma.width_px as usize * sigma.height_px as usize;
    if sigma.data.len() != 4 * n {
        return Err(bad("sigma_z_m map is not 4 bytes per pixel"));
    }
    let samples = sigma
        .data
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let sigma_z_m = Image::new(sigma.width_px, sigma.height_px, samples)
        .map_err(|e| bad(&format!("sigma_z_m map: {e}")))?;
    let cause = cause.ok_or_else(|| bad("prediction has a sigma_z_m map but no missing_cause"))?;
    if cause.encoding != v1::ImageEncoding::Mono8 as i32
        || (cause.width_px, cause.height_px) != (sigma.width_px, sigma.height_px)
    {
        return Err(bad(
            "missing_cause map is not MONO8 of the sigma_z_m map's size",
        ));
    }
    let cause = Image::new(cause.width_px, cause.height_px, cause.data.to_vec())
        .map_err(|e| bad(&format!("missing_cause map: {e}")))?;
    Ok(PredictedMaps {
        sigma_z_m,
        cause,
        roi_u0_px,
        roi_v0_px,
    })
}

fn candidate_information(p: v1::CandidatePrediction) -> Result<CandidateInformation, StageError> {
    let information = p
        .information
        .as_ref()
        .ok_or_else(|| StageError::Internal("a worker's prediction has no information".into()))
        .and_then(|m| {
            Matrix6::try_from(m).map_err(|e| StageError::Internal(format!("a worker's {e}")))
        })?;
    let maps = match &p.sigma_z_m {
        Some(sigma) => Some(predicted_maps(
            sigma,
            p.missing_cause.as_ref(),
            p.roi_u0_px,
            p.roi_v0_px,
        )?),
        None => None,
    };
    Ok(CandidateInformation {
        index: p.candidate_index,
        information,
        part_pixels: p.part_pixels,
        predicted_points: p.predicted_points,
        missing_ratio: p.missing_ratio,
        missing_sigma: p.missing_sigma,
        not_in_view: p.not_in_view,
        maps,
        predict_ms: p.predict_ms,
    })
}

impl PredictionStage for RemotePrediction {
    fn predict(
        &self,
        object: &PredictionObject,
        prediction: &PredictionRequest,
    ) -> Result<Vec<CandidateInformation>, StageError> {
        if prediction.candidates.is_empty() {
            return Ok(Vec::new());
        }
        // The worker builds the SDF grid itself; this side only describes the object.
        let registration = object_to_message(&ObjectDescription {
            name: &object.object.name,
            mesh: &object.object.mesh,
            material: &object.material,
            camera: &object.camera,
            rig: &object.rig,
            noise: &object.noise,
            surroundings: &object.surroundings,
            shots: object.shots,
            pattern_fill: object.pattern_fill,
        });
        let key = object_key(&registration);
        let template = v1::PredictCandidatesRequest {
            object_sha256_hex: key.clone(),
            t_w_o: Some((&prediction.t_w_o).into()),
            candidates_t_w_c: Vec::new(),
            candidate_indices: Vec::new(),
            settings: Some(v1::PredictionSettings {
                window_radius_px: object.window_radius_px,
                constant_sigma_z_m: match prediction.sigma {
                    PredictionSigma::Rendered => 0.0,
                    PredictionSigma::Constant { sigma_z_m } => sigma_z_m,
                },
                ..Default::default()
            }),
            seed: prediction.seed,
            with_sigma_maps: prediction.with_maps,
        };
        let per_request = self.config.candidates_per_request.max(1);
        let queue: VecDeque<Batch> = prediction
            .candidates
            .chunks(per_request)
            .map(|chunk| chunk.iter().map(|(i, t)| (*i, t.into())).collect())
            .collect();
        if let Ok(mut last) = self.last_problem.lock() {
            *last = None;
        }
        let deadline = self.config.decision_deadline;
        let answers = self.handle.block_on(async {
            tokio::time::timeout(deadline, self.fan_out(queue, template, registration, key))
                .await
                .map_err(|_| {
                    let why = self
                        .last_problem
                        .lock()
                        .ok()
                        .and_then(|p| p.clone())
                        .map_or_else(String::new, |p| format!(" (last: {p})"));
                    StageError::Unavailable(format!(
                        "the render workers ({}) did not finish the decision within \
                         {deadline:?}{why}",
                        self.source.describe()
                    ))
                })?
        })?;
        let mut out: Vec<CandidateInformation> = answers
            .into_iter()
            .map(candidate_information)
            .collect::<Result<_, _>>()?;
        out.sort_by_key(|c| c.index);
        out.dedup_by_key(|c| c.index);
        Ok(out)
    }
}
