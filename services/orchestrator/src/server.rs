//! The orchestrator's gRPC server (`glint.v1.OrchestratorService`): decode and validate,
//! call [`Orchestrator`] on the blocking pool, encode. `RunSession` streams one event per
//! completed step, then the session's final state.
//!
//! Errors: bad input → INVALID_ARGUMENT naming the request's field; an unknown session →
//! NOT_FOUND; a session that cannot run (no calibration for the NBV policy, already running)
//! → FAILED_PRECONDITION; a stage that failed → its status.

use std::sync::Arc;

use glint_geometry::Part;
use glint_geometry::io::LoadedMesh;
use glint_proto::ConversionError;
use glint_proto::v1;
use glint_proto::v1::orchestrator_service_server::{
    OrchestratorService, OrchestratorServiceServer,
};
use glint_render::bsdf::PrincipledParams;
use nalgebra::{Isometry3, Matrix6};
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};

use crate::remote::status_of;
use crate::service::{DEFAULT_CANDIDATES, Orchestrator, PartSource, SessionRequest};
use crate::session::{Session, SessionState, StepRecord, ViewPolicy};
use crate::stages::PartCalibration;

/// The service's name, as health reports it.
pub const SERVICE_NAME: &str = "glint.v1.OrchestratorService";

/// The orchestrator's gRPC face.
#[derive(Clone)]
pub struct OrchestratorServer {
    orchestrator: Arc<Orchestrator>,
}

impl OrchestratorServer {
    /// The gRPC face of `orchestrator`, whose errors it answers with [`status_of`]'s
    /// statuses.
    pub fn new(orchestrator: Arc<Orchestrator>) -> Self {
        Self { orchestrator }
    }

    /// The tonic service to add to a server's routes.
    pub fn into_service(self) -> OrchestratorServiceServer<Self> {
        OrchestratorServiceServer::new(self)
    }
}

fn required<'a, T>(value: &'a Option<T>, field: &str) -> Result<&'a T, ConversionError> {
    value
        .as_ref()
        .ok_or_else(|| ConversionError::missing(field))
}

/// A built-in part's name, or a user's mesh.
pub fn part_of(spec: &v1::PartSpec) -> Result<PartSource, ConversionError> {
    match &spec.part {
        Some(v1::part_spec::Part::Builtin(name)) => Part::ALL
            .into_iter()
            .find(|p| p.name() == name)
            .map(PartSource::Builtin)
            .ok_or_else(|| {
                let names: Vec<&str> = Part::ALL.iter().map(|p| p.name()).collect();
                ConversionError::new(
                    "builtin",
                    format!("unknown part {name:?}; one of {}", names.join(", ")),
                )
            }),
        Some(v1::part_spec::Part::Mesh(file)) => {
            let loaded = LoadedMesh::try_from(file).map_err(|e| e.within("mesh"))?;
            Ok(PartSource::Mesh {
                name: if file.name.is_empty() {
                    "mesh".into()
                } else {
                    file.name.clone()
                },
                mesh: loaded.mesh,
            })
        }
        None => Err(ConversionError::new(
            "part",
            "set builtin (a part's name) or mesh (a mesh file)",
        )),
    }
}

/// A view policy from its enum value.
pub fn policy_of(value: i32) -> Result<ViewPolicy, ConversionError> {
    match v1::ViewPolicy::try_from(value) {
        Ok(v1::ViewPolicy::Nbv) => Ok(ViewPolicy::Nbv),
        Ok(v1::ViewPolicy::NbvConstSigma) => Ok(ViewPolicy::NbvConstSigma),
        Ok(v1::ViewPolicy::Random) => Ok(ViewPolicy::Random),
        Ok(v1::ViewPolicy::MaxDistance) => Ok(ViewPolicy::MaxDistance),
        _ => Err(ConversionError::new(
            "policy",
            format!(
                "{value} is not a policy; VIEW_POLICY_NBV, _NBV_CONST_SIGMA, _RANDOM or _MAX_DISTANCE"
            ),
        )),
    }
}

/// A view policy as its enum value.
pub fn policy_message(policy: ViewPolicy) -> v1::ViewPolicy {
    match policy {
        ViewPolicy::Nbv => v1::ViewPolicy::Nbv,
        ViewPolicy::NbvConstSigma => v1::ViewPolicy::NbvConstSigma,
        ViewPolicy::Random => v1::ViewPolicy::Random,
        ViewPolicy::MaxDistance => v1::ViewPolicy::MaxDistance,
    }
}

/// Decodes and validates a StartSession request.
pub fn session_request(msg: &v1::StartSessionRequest) -> Result<SessionRequest, ConversionError> {
    let part = part_of(required(&msg.part, "part")?).map_err(|e| e.within("part"))?;
    let initial_t_w_o = Isometry3::try_from(required(&msg.initial_t_w_o, "initial_t_w_o")?)
        .map_err(|e| e.within("initial_t_w_o"))?;
    let candidates = if msg.candidates_t_w_c.is_empty() {
        Err(if msg.default_candidates == 0 {
            DEFAULT_CANDIDATES
        } else {
            msg.default_candidates as usize
        })
    } else {
        Ok(msg
            .candidates_t_w_c
            .iter()
            .enumerate()
            .map(|(i, p)| {
                Isometry3::try_from(p).map_err(|e| e.within(&format!("candidates_t_w_c[{i}]")))
            })
            .collect::<Result<Vec<_>, _>>()?)
    };
    let policy = policy_of(msg.policy)?;
    if !(1..=64).contains(&msg.max_views) {
        return Err(ConversionError::new(
            "max_views",
            format!("is {}; 1 to 64 views", msg.max_views),
        ));
    }
    let entropy_threshold_nats = match msg.entropy_threshold_nats {
        0.0 => None,
        h if h.is_finite() => Some(h),
        h => {
            return Err(ConversionError::new(
                "entropy_threshold_nats",
                format!("{h} must be finite (nats; 0 = none)"),
            ));
        }
    };
    let calibration = match (&msg.material, &msg.response, msg.radiometric_scale) {
        (None, None, 0.0) => None,
        (Some(material), Some(response), scale) => {
            if !(scale.is_finite() && scale > 0.0) {
                return Err(ConversionError::new(
                    "radiometric_scale",
                    format!("{scale} must be finite and positive"),
                ));
            }
            Some(PartCalibration {
                material: PrincipledParams::try_from(material).map_err(|e| e.within("material"))?,
                response: glint_calibration::server::response_from_message(response)
                    .map_err(|e| e.within("response"))?,
                radiometric_scale: scale,
            })
        }
        _ => {
            return Err(ConversionError::new(
                "material",
                "material, response and radiometric_scale go together: send all three or none",
            ));
        }
    };
    Ok(SessionRequest {
        part,
        initial_t_w_o,
        candidates,
        first_view: msg.first_view as usize,
        policy,
        max_views: msg.max_views as usize,
        entropy_threshold_nats,
        seed: msg.seed,
        calibration,
        error_model: msg
            .error_model
            .as_ref()
            .map(|m| glint_estimation::server::error_model_from_message(m, "error_model"))
            .transpose()?,
    })
}

fn covariance_message(covariance: &Option<Matrix6<f64>>) -> Option<v1::SymmetricMatrix6> {
    covariance.as_ref().map(Into::into)
}

/// A step as its message (NaN where a value does not exist, as the proto says).
pub fn step_message(step: &StepRecord) -> v1::SessionStep {
    v1::SessionStep {
        step: step.step as u32,
        view: step.view as u32,
        t_w_c: Some((&step.t_w_c).into()),
        view_points: step.view_points as u32,
        total_points: step.total_points as u32,
        t_w_o: Some((&step.t_w_o).into()),
        covariance: covariance_message(&step.covariance),
        entropy_nats: step.entropy_nats,
        predicted_entropy_nats: step.predicted_entropy_nats.unwrap_or(f64::NAN),
        candidate_entropies_nats: step
            .candidate_entropies_nats
            .iter()
            .map(|h| h.unwrap_or(f64::NAN))
            .collect(),
        times: Some(v1::StageTimes {
            capture_ms: step.times.capture_ms,
            refine_ms: step.times.refine_ms,
            predict_ms: step.times.predict_ms,
            plan_ms: step.times.plan_ms,
        }),
        refine_status: step.refine_status.clone(),
        next_view: step.next_view.map(|v| v as u32),
    }
}

fn state_message(state: SessionState) -> v1::SessionState {
    match state {
        SessionState::Created => v1::SessionState::Created,
        SessionState::Running => v1::SessionState::Running,
        SessionState::Converged => v1::SessionState::Converged,
        SessionState::BudgetSpent => v1::SessionState::BudgetSpent,
        SessionState::Cancelled => v1::SessionState::Cancelled,
        SessionState::Failed => v1::SessionState::Failed,
        SessionState::Interrupted => v1::SessionState::Interrupted,
    }
}

/// A session as its message (without captures).
pub fn session_message(session: &Session, part: &str) -> v1::Session {
    v1::Session {
        session_id: session.id.clone(),
        state: state_message(session.state) as i32,
        policy: policy_message(session.config.policy) as i32,
        max_views: session.config.max_views as u32,
        entropy_threshold_nats: session.config.entropy_threshold_nats.unwrap_or(0.0),
        steps: session.steps.iter().map(step_message).collect(),
        error: session.error.clone().unwrap_or_default(),
        part: part.to_owned(),
        candidates_t_w_c: session.config.candidates.iter().map(Into::into).collect(),
        initial_t_w_o: Some((&session.config.initial_t_w_o).into()),
    }
}

fn session_id(id: &str) -> Result<String, Status> {
    if id.is_empty() {
        return Err(Status::invalid_argument(
            "session_id: required (StartSession returns one)",
        ));
    }
    Ok(id.to_owned())
}

impl OrchestratorServer {
    async fn call<T: Send + 'static>(
        &self,
        f: impl FnOnce(&Orchestrator) -> Result<T, crate::stages::StageError> + Send + 'static,
    ) -> Result<T, Status> {
        let orchestrator = self.orchestrator.clone();
        glint_server::blocking(move || f(&orchestrator))
            .await?
            .map_err(|e| status_of(&e))
    }

    async fn message_of(&self, session: Session) -> Result<v1::Session, Status> {
        let id = session.id.clone();
        let part = self
            .call(move |o| Ok(o.part_name(&id)))
            .await?
            .unwrap_or_default();
        Ok(session_message(&session, &part))
    }
}

type EventStream = ReceiverStream<Result<v1::SessionEvent, Status>>;

#[tonic::async_trait]
impl OrchestratorService for OrchestratorServer {
    async fn start_session(
        &self,
        request: Request<v1::StartSessionRequest>,
    ) -> Result<Response<v1::StartSessionResponse>, Status> {
        let message = request.into_inner();
        // Decoding parses a mesh: on the blocking pool too.
        let decoded = glint_server::blocking(move || session_request(&message)).await??;
        let session_id = self.call(move |o| o.start(decoded)).await?;
        Ok(Response::new(v1::StartSessionResponse { session_id }))
    }

    type RunSessionStream = EventStream;

    async fn run_session(
        &self,
        request: Request<v1::RunSessionRequest>,
    ) -> Result<Response<Self::RunSessionStream>, Status> {
        let id = session_id(&request.get_ref().session_id)?;
        // Unknown, already running or no place free: answer at once rather than as a
        // stream's error. A place is taken here, so the run below cannot be refused.
        let known = self.orchestrator.clone();
        let check_id = id.clone();
        glint_server::blocking(move || {
            if known.state(&check_id)?.is_final() {
                Ok(())
            } else {
                known.reserve(&check_id)
            }
        })
        .await?
        .map_err(|e| status_of(&e))?;
        let (tx, rx) = tokio::sync::mpsc::channel(64);
        let orchestrator = self.orchestrator.clone();
        tokio::task::spawn_blocking(move || {
            // A client that goes away does not stop the session: it runs to its end.
            let result = orchestrator.run_reserved(&id, |step| {
                let event = v1::SessionEvent {
                    event: Some(v1::session_event::Event::Step(step_message(step))),
                };
                let _ = tx.blocking_send(Ok(event));
            });
            let last = match result {
                Ok(session) => {
                    let part = orchestrator.part_name(&id).unwrap_or_default();
                    Ok(v1::SessionEvent {
                        event: Some(v1::session_event::Event::Finished(session_message(
                            &session, &part,
                        ))),
                    })
                }
                Err(e) => Err(status_of(&e)),
            };
            let _ = tx.blocking_send(last);
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }

    async fn get_session(
        &self,
        request: Request<v1::GetSessionRequest>,
    ) -> Result<Response<v1::Session>, Status> {
        let id = session_id(&request.get_ref().session_id)?;
        let session = self.call(move |o| o.get(&id)).await?;
        Ok(Response::new(self.message_of(session).await?))
    }

    async fn list_sessions(
        &self,
        _request: Request<v1::ListSessionsRequest>,
    ) -> Result<Response<v1::ListSessionsResponse>, Status> {
        let sessions = self.call(|o| o.list()).await?;
        let mut out = Vec::with_capacity(sessions.len());
        for s in sessions {
            out.push(self.message_of(s).await?);
        }
        Ok(Response::new(v1::ListSessionsResponse { sessions: out }))
    }

    async fn cancel_session(
        &self,
        request: Request<v1::CancelSessionRequest>,
    ) -> Result<Response<v1::Session>, Status> {
        let id = session_id(&request.get_ref().session_id)?;
        let session = self.call(move |o| o.cancel(&id)).await?;
        Ok(Response::new(self.message_of(session).await?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn start_request() -> v1::StartSessionRequest {
        v1::StartSessionRequest {
            part: Some(v1::PartSpec {
                part: Some(v1::part_spec::Part::Builtin("zigzag".into())),
            }),
            initial_t_w_o: Some((&Isometry3::identity()).into()),
            policy: v1::ViewPolicy::Random as i32,
            max_views: 3,
            ..Default::default()
        }
    }

    #[test]
    fn a_start_request_decodes_and_bad_fields_are_named() {
        let ok = session_request(&start_request()).unwrap();
        assert!(matches!(ok.part, PartSource::Builtin(Part::Zigzag)));
        assert_eq!(ok.candidates, Err(DEFAULT_CANDIDATES));

        let field = |m: v1::StartSessionRequest| session_request(&m).unwrap_err().field;
        let mut bad = start_request();
        bad.part = Some(v1::PartSpec {
            part: Some(v1::part_spec::Part::Builtin("spoon".into())),
        });
        assert_eq!(field(bad), "part.builtin");
        let mut bad = start_request();
        bad.initial_t_w_o
            .as_mut()
            .unwrap()
            .rotation
            .as_mut()
            .unwrap()
            .w = 2.0;
        assert_eq!(field(bad), "initial_t_w_o.rotation");
        let mut bad = start_request();
        bad.candidates_t_w_c = vec![
            (&Isometry3::identity()).into(),
            v1::Pose {
                translation_m: Some(v1::Vector3 {
                    x: f64::NAN,
                    y: 0.0,
                    z: 0.0,
                }),
                ..(&Isometry3::identity()).into()
            },
        ];
        assert_eq!(field(bad), "candidates_t_w_c[1].translation_m.x");
        let mut bad = start_request();
        bad.max_views = 0;
        assert_eq!(field(bad), "max_views");
        let mut bad = start_request();
        bad.policy = 0;
        assert_eq!(field(bad), "policy");
        let mut bad = start_request();
        bad.radiometric_scale = 1.0;
        assert_eq!(field(bad), "material");
    }
}
