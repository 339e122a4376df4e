//! The estimation stage over gRPC (`glint.v1.EstimationService`): the same refinement, plan and
//! entropy as [`crate::local::LocalEstimation`], run by a server.
//!
//! `refine` streams every view (its depth and, for σ from pattern images, its shots and noise
//! shots) in chunks of at most 1 MiB, so a server with gRPC's default 4 MiB receive limit
//! takes it; when the server does not know the object's mesh (NOT_FOUND) it registers it and
//! sends the refinement once more. Every call carries the endpoint's deadline. Blocking: see
//! [`crate::remote`].

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

use glint_estimation::nbv::check_symmetric;
use glint_estimation::server::{mesh_file, refine_chunks, refinement_from_message};
use glint_estimation::view::ViewMeasurement;
use glint_proto::v1;
use glint_proto::v1::estimation_service_client::EstimationServiceClient;
use nalgebra::{Isometry3, Matrix6};
use tokio::runtime::Handle;
use tonic::Code;

use super::{AuthChannel, Endpoint, request, stage_error, when_admitted};
use crate::local::plan_error;
use crate::stages::{
    CapturedView, EstimationStage, RefineSettings, Refinement, SessionObject, StageError, ViewPlan,
};

/// The estimator behind a gRPC endpoint.
pub struct RemoteEstimation {
    /// The runtime the calls run on (never block on it from one of its own tasks).
    pub handle: Handle,
    /// The estimation server's address, deadline and security.
    pub endpoint: Endpoint,
    client: EstimationServiceClient<AuthChannel>,
    /// The service's key of each session object's mesh, once registered (the service keys a
    /// mesh by its content hash, which is the session's hash unless a caller computed that
    /// differently).
    keys: Mutex<HashMap<String, String>>,
}

impl RemoteEstimation {
    /// A client of `endpoint` on `handle`'s runtime; connects on the first call.
    pub fn new(handle: Handle, endpoint: Endpoint) -> Result<Self, StageError> {
        // The lazy channel's worker is spawned on the runtime.
        let channel = {
            let _entered = handle.enter();
            endpoint.channel()?
        };
        Ok(Self {
            handle,
            endpoint,
            client: EstimationServiceClient::new(channel),
            keys: Mutex::new(HashMap::new()),
        })
    }

    fn key_of(&self, object: &SessionObject) -> Result<String, StageError> {
        Ok(self
            .keys
            .lock()
            .map_err(|_| StageError::Internal("the mesh keys' lock was poisoned".into()))?
            .get(&object.mesh_sha256_hex)
            .cloned()
            .unwrap_or_else(|| object.mesh_sha256_hex.clone()))
    }

    /// Registers `object`'s mesh; returns the service's key for it.
    fn register(&self, object: &SessionObject) -> Result<String, StageError> {
        let mut client = self.client.clone();
        let file = mesh_file(&object.mesh, &object.name);
        let key = self
            .handle
            .block_on(client.register_mesh(request(file, self.endpoint.deadline)))
            .map_err(|s| stage_error(&s))?
            .into_inner()
            .sha256_hex;
        self.keys
            .lock()
            .map_err(|_| StageError::Internal("the mesh keys' lock was poisoned".into()))?
            .insert(object.mesh_sha256_hex.clone(), key.clone());
        Ok(key)
    }

    fn refine_once(
        &self,
        key: &str,
        views: &[&ViewMeasurement],
        t_w_o: &Isometry3<f64>,
        settings: &RefineSettings,
    ) -> Result<v1::RefineResponse, tonic::Status> {
        let chunks = refine_chunks(key, t_w_o, settings, views);
        let mut client = self.client.clone();
        let stream = tokio_stream::iter(chunks);
        self.handle
            .block_on(client.refine(request(stream, self.endpoint.deadline)))
            .map(tonic::Response::into_inner)
    }
}

/// The planner's checks of a matrix the wire cannot carry (it holds upper triangles): an
/// asymmetric one is refused here as the in-process planner refuses it.
fn symmetric(m: &Matrix6<f64>, which: &str) -> Result<v1::SymmetricMatrix6, StageError> {
    check_symmetric(m, which).map_err(plan_error)?;
    Ok(m.into())
}

impl EstimationStage for RemoteEstimation {
    fn refine(
        &self,
        object: &SessionObject,
        views: &[&CapturedView],
        t_w_o: &Isometry3<f64>,
        settings: &RefineSettings,
    ) -> Result<Refinement, StageError> {
        let started = Instant::now();
        let views: Vec<&ViewMeasurement> = views.iter().map(|v| &v.measurement).collect();
        let response = when_admitted(self.endpoint.deadline, || {
            match self.refine_once(&self.key_of(object)?, &views, t_w_o, settings) {
                Err(status) if status.code() == Code::NotFound => {
                    let key = self.register(object)?;
                    self.refine_once(&key, &views, t_w_o, settings)
                }
                other => other,
            }
            .map_err(|s| stage_error(&s))
        })?;
        let mut refinement = refinement_from_message(&response)
            .map_err(|e| StageError::Internal(format!("the estimation service's answer: {e}")))?;
        if refinement.view_points.len() != views.len() {
            return Err(StageError::Internal(format!(
                "the estimation service counted points of {} views, not {}",
                refinement.view_points.len(),
                views.len()
            )));
        }
        // The session's time: the service's refinement and the views' transfer.
        refinement.refine_ms = started.elapsed().as_secs_f64() * 1e3;
        Ok(refinement)
    }

    fn plan(
        &self,
        collected: &Matrix6<f64>,
        candidates: &[Matrix6<f64>],
        taken: &[usize],
    ) -> Result<ViewPlan, StageError> {
        let message = v1::PlanNextViewRequest {
            collected: Some(symmetric(collected, "collected")?),
            candidates: candidates
                .iter()
                .enumerate()
                .map(|(i, m)| symmetric(m, &format!("candidates[{i}]")))
                .collect::<Result<_, _>>()?,
            taken: taken
                .iter()
                .map(|&i| {
                    u32::try_from(i)
                        .map_err(|_| StageError::invalid("taken", format!("{i} is too large")))
                })
                .collect::<Result<_, _>>()?,
        };
        let response = when_admitted(self.endpoint.deadline, || {
            let mut client = self.client.clone();
            self.handle
                .block_on(client.plan_next_view(request(message.clone(), self.endpoint.deadline)))
                .map_err(|s| stage_error(&s))
        })?
        .into_inner();
        let chosen = response.chosen as usize;
        if response.entropies_nats.len() != candidates.len() || chosen >= candidates.len() {
            return Err(StageError::Internal(format!(
                "the estimation service chose {chosen} and gave {} entropies for {} candidates",
                response.entropies_nats.len(),
                candidates.len()
            )));
        }
        Ok(ViewPlan {
            chosen,
            // NaN is the wire's "taken".
            entropies_nats: response
                .entropies_nats
                .iter()
                .map(|h| (!h.is_nan()).then_some(*h))
                .collect(),
        })
    }

    fn entropy_nats(&self, information: &Matrix6<f64>) -> Result<f64, StageError> {
        let message = v1::PoseEntropyRequest {
            information: Some(symmetric(information, "information")?),
        };
        Ok(when_admitted(self.endpoint.deadline, || {
            let mut client = self.client.clone();
            self.handle
                .block_on(client.pose_entropy(request(message.clone(), self.endpoint.deadline)))
                .map_err(|s| stage_error(&s))
        })?
        .into_inner()
        .entropy_nats)
    }
}
