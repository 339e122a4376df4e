//! Glint's Rust client: one active session on any deployment's orchestrator, run as a robot
//! cell's client runs it — `glint session run`, the demo (`cargo run --release`), the
//! end-to-end tests and `glint bench fanout` share this one code path.
//!
//! A session on the mock camera: set up its bin (`MockCameraService.SetUpScene`), take the
//! camera's candidate views, ask a stand-in detector for the initial pose (the mock's ground
//! truth perturbed as in `glint eval refine`, evaluation only), start the session and read its
//! steps as the orchestrator streams them, each scored against the mock's truth.

pub mod calibration;

use std::time::Duration;

use anyhow::Context;
use glint_calibration::server::response_to_message;
use glint_eval::active::stand_in_detector;
use glint_geometry::Part;
use glint_geometry::pose_deviation::{PoseDeviation, pose_deviation};
use glint_orchestrator::server::policy_message;
use glint_orchestrator::session::ViewPolicy;
use glint_orchestrator::stages::PartCalibration;
use glint_proto::v1;
use glint_proto::v1::camera_service_client::CameraServiceClient;
use glint_proto::v1::mock_camera_service_client::MockCameraServiceClient;
use glint_proto::v1::orchestrator_service_client::OrchestratorServiceClient;
pub use glint_server::security::{AuthChannel, ClientSecurity};
use nalgebra::Isometry3;

/// A channel to `addr` (HOST:PORT or a URI), connected within 5 s, over TLS and with a token
/// as `security` says.
pub async fn channel(addr: &str, security: &ClientSecurity) -> anyhow::Result<AuthChannel> {
    let target = security.uri(addr);
    let channel = security
        .endpoint(addr)?
        .connect_timeout(Duration::from_secs(5))
        .connect()
        .await
        .with_context(|| format!("connecting to {target}"))?;
    Ok(security.authorize(channel)?)
}

/// A status as an error a person can read: its code and message.
pub fn status(e: tonic::Status) -> anyhow::Error {
    anyhow::anyhow!("{}: {}", e.code(), e.message())
}

/// A session on the mock camera's bin.
#[derive(Clone, Debug)]
pub struct MockSession {
    /// The part in the bin (and the session's part).
    pub part: Part,
    /// Parts dropped into the bin.
    pub instances: u32,
    pub policy: ViewPolicy,
    pub max_views: u32,
    /// Stop below this pose entropy, nats (0: the budget only).
    pub entropy_threshold_nats: f64,
    /// Candidate views, the camera's own.
    pub candidates: u32,
    /// Seed of the bin, the detector's error and the session.
    pub seed: u64,
    /// Image size, px, and samples per pixel of the mock's renders.
    pub width_px: u32,
    pub height_px: u32,
    pub samples_per_pixel: u32,
}

/// What a run gives: the steps as streamed, the final session, and the pose errors against
/// the mock's truth (the detector's first).
pub struct RunOutcome {
    pub steps: Vec<v1::SessionStep>,
    pub session: v1::Session,
    pub deviations: Vec<PoseDeviation>,
    pub initial_deviation: PoseDeviation,
}

/// An entropy with two decimals, or "-" when there is none (NaN on the wire).
fn nats_or_dash(h: f64) -> String {
    if h.is_finite() {
        format!("{h:.2}")
    } else {
        "-".into()
    }
}

/// The per-step table's header.
pub fn table_header() -> String {
    format!(
        "{:>4} {:>5} {:>7} {:>8} {:>10} {:>10} {:>8} {:>7} {:>9} {:>9} {:>9}  {}",
        "step",
        "view",
        "points",
        "total",
        "h_pred",
        "h",
        "err_mm",
        "err_deg",
        "capture_s",
        "refine_s",
        "predict_s",
        "refine"
    )
}

/// One step's row; `deviation` is the pose error against the truth, when known.
pub fn table_row(step: &v1::SessionStep, deviation: Option<&PoseDeviation>) -> String {
    let times = step.times.unwrap_or_default();
    let (mm, deg) = deviation.map_or_else(
        || ("-".to_owned(), "-".to_owned()),
        |d| {
            (
                format!("{:.2}", d.translation_mm()),
                format!("{:.2}", d.rotation_deg()),
            )
        },
    );
    format!(
        "{:>4} {:>5} {:>7} {:>8} {:>10} {:>10.2} {:>8} {:>7} {:>9.2} {:>9.2} {:>9.2}  {}",
        step.step,
        step.view,
        step.view_points,
        step.total_points,
        nats_or_dash(step.predicted_entropy_nats),
        step.entropy_nats,
        mm,
        deg,
        times.capture_ms * 1e-3,
        times.refine_ms * 1e-3,
        times.predict_ms * 1e-3,
        step.refine_status
    )
}

/// A pose the server sent.
pub fn pose(p: &Option<v1::Pose>, what: &str) -> anyhow::Result<Isometry3<f64>> {
    Isometry3::try_from(
        p.as_ref()
            .with_context(|| format!("the server sent no {what}"))?,
    )
    .map_err(|e| anyhow::anyhow!("the server's {what}: {e}"))
}

/// The name of a session state on the wire.
pub fn state_name(state: i32) -> &'static str {
    v1::SessionState::try_from(state).map_or("?", |s| s.as_str_name())
}

/// A session ready to start on a mock bin: the request (the stand-in detector's pose, the
/// camera's candidates) and what scores its steps against the mock's truth.
#[derive(Clone)]
pub struct PreparedSession {
    pub request: v1::StartSessionRequest,
    /// The target instance's true pose and the part's symmetry (evaluation only).
    pub gt_t_w_o: Isometry3<f64>,
    pub symmetry: glint_geometry::Symmetry,
    pub initial_deviation: PoseDeviation,
    /// What the detector did, in a sentence.
    pub detector_line: String,
}

impl PreparedSession {
    pub fn deviation(&self, t_w_o: &Isometry3<f64>) -> PoseDeviation {
        pose_deviation(t_w_o, &self.gt_t_w_o, &self.symmetry)
    }
}

/// Sets up the mock bin on `camera` and asks the stand-in detector for the initial pose;
/// the session's request carries `calibration` for its render workers (`None`: the
/// orchestrator's shipped one). Sessions started from it share the bin.
pub async fn prepare_mock_session(
    camera: &str,
    spec: &MockSession,
    calibration: Option<&PartCalibration>,
    security: &ClientSecurity,
) -> anyhow::Result<PreparedSession> {
    let part = v1::PartSpec {
        part: Some(v1::part_spec::Part::Builtin(spec.part.name().into())),
    };
    let mut mock = MockCameraServiceClient::new(channel(camera, security).await?);
    mock.set_up_scene(v1::SetUpSceneRequest {
        part: Some(part.clone()),
        instances: spec.instances,
        material: None,
        seed: spec.seed,
        width_px: spec.width_px,
        height_px: spec.height_px,
        samples_per_pixel: spec.samples_per_pixel,
    })
    .await
    .map_err(status)
    .context("setting up the mock bin")?;
    // The session's candidates are the camera's own; the detector looked from the first.
    let candidates = CameraServiceClient::new(channel(camera, security).await?)
        .list_candidate_views(v1::ListCandidateViewsRequest {
            count: spec.candidates,
            ..Default::default()
        })
        .await
        .map_err(status)?
        .into_inner()
        .t_w_c;
    let first_t_w_c = pose(&candidates.first().cloned(), "first candidate")?;
    let truth = mock
        .get_ground_truth(v1::GetGroundTruthRequest {
            visibility_from_t_w_c: Some((&first_t_w_c).into()),
        })
        .await
        .map_err(status)?
        .into_inner();
    let gt: Vec<Isometry3<f64>> = truth
        .t_w_o
        .iter()
        .map(|p| pose(&Some(p.clone()), "ground-truth pose"))
        .collect::<Result<_, _>>()?;
    let visibility: Vec<(f64, f64)> = truth
        .visibility
        .iter()
        .map(|v| (v.visib_fract, f64::from(v.px_count_all)))
        .collect();
    let symmetry = spec.part.symmetry();
    let guess = stand_in_detector(&gt, &visibility, &first_t_w_c, &symmetry, spec.seed)
        .context("the mock bin holds no instance")?;
    let gt_t_w_o = gt[guess.target];
    let initial_deviation = pose_deviation(&guess.initial_t_w_o, &gt_t_w_o, &symmetry);
    let detector_line = format!(
        "Initial pose: a stand-in detector (ground truth perturbed as in `glint eval \
         refine`), {:.1} mm / {:.1}° off; instance {} of {}, {:.0} % visible from the \
         first view.",
        initial_deviation.translation_mm(),
        initial_deviation.rotation_deg(),
        guess.target + 1,
        gt.len(),
        100.0 * guess.visib_fract
    );
    let request = v1::StartSessionRequest {
        part: Some(part),
        initial_t_w_o: Some((&guess.initial_t_w_o).into()),
        candidates_t_w_c: candidates,
        policy: policy_message(spec.policy) as i32,
        max_views: spec.max_views,
        entropy_threshold_nats: spec.entropy_threshold_nats,
        seed: spec.seed,
        material: calibration.map(|c| v1::PrincipledMaterial::from(&c.material)),
        response: calibration.map(|c| response_to_message(&c.response)),
        radiometric_scale: calibration.map_or(0.0, |c| c.radiometric_scale),
        ..Default::default()
    };
    Ok(PreparedSession {
        request,
        gt_t_w_o,
        symmetry,
        initial_deviation,
        detector_line,
    })
}

/// Starts `prepared` on `orchestrator` and reads its steps as they stream; `on_row` gets
/// each printed line, with the step it reports if it is a step's row.
pub async fn run_prepared_session(
    orchestrator: &str,
    prepared: &PreparedSession,
    security: &ClientSecurity,
    mut on_row: impl FnMut(&str, Option<&v1::SessionStep>),
) -> anyhow::Result<RunOutcome> {
    let mut client = OrchestratorServiceClient::new(channel(orchestrator, security).await?);
    // "VIEW_POLICY_NBV_CONST_SIGMA" → "nbv-const-sigma", as the CLI names it.
    let policy = v1::ViewPolicy::try_from(prepared.request.policy).map_or("?".into(), |p| {
        p.as_str_name()
            .trim_start_matches("VIEW_POLICY_")
            .to_lowercase()
            .replace('_', "-")
    });
    let id = client
        .start_session(prepared.request.clone())
        .await
        .map_err(status)
        .context("starting the session")?
        .into_inner()
        .session_id;
    on_row(&format!("Session {id}, policy {policy}."), None);
    on_row(&table_header(), None);
    let mut steps = Vec::new();
    let mut deviations = Vec::new();
    let session = stream_session(&mut client, &id, |step| {
        let d = prepared.deviation(&pose(&step.t_w_o, "step pose")?);
        on_row(&table_row(step, Some(&d)), Some(step));
        deviations.push(d);
        steps.push(step.clone());
        Ok(())
    })
    .await?;
    Ok(RunOutcome {
        steps,
        session,
        deviations,
        initial_deviation: prepared.initial_deviation,
    })
}

/// Runs session `id` (RunSession: a created session starts, an interrupted one resumes after
/// its completed steps, which come first) and hands each step to `on_step` as it streams;
/// returns the session's final state.
pub async fn stream_session(
    client: &mut OrchestratorServiceClient<AuthChannel>,
    id: &str,
    mut on_step: impl FnMut(&v1::SessionStep) -> anyhow::Result<()>,
) -> anyhow::Result<v1::Session> {
    let mut stream = client
        .run_session(v1::RunSessionRequest {
            session_id: id.to_owned(),
        })
        .await
        .map_err(status)?
        .into_inner();
    let mut finished = None;
    while let Some(event) = stream.message().await.map_err(status)? {
        match event.event {
            Some(v1::session_event::Event::Step(step)) => on_step(&step)?,
            Some(v1::session_event::Event::Finished(session)) => finished = Some(session),
            None => {}
        }
    }
    finished.context("the session's stream ended without its final state")
}

/// Sets up the mock bin on `camera`, asks the stand-in detector, runs a session on
/// `orchestrator` with `calibration` for its render workers (`None`: the orchestrator's
/// shipped one); `on_row` gets each printed line, with the step it reports if it is a step's
/// row.
pub async fn run_mock_session(
    orchestrator: &str,
    camera: &str,
    spec: &MockSession,
    calibration: Option<&PartCalibration>,
    security: &ClientSecurity,
    mut on_row: impl FnMut(&str, Option<&v1::SessionStep>),
) -> anyhow::Result<RunOutcome> {
    let prepared = prepare_mock_session(camera, spec, calibration, security).await?;
    on_row(&prepared.detector_line, None);
    run_prepared_session(orchestrator, &prepared, security, on_row).await
}
