//! `glint session run|list|show|cancel`: a client of any deployment's orchestrator. `run`
//! sets up the mock camera's bin (`--part`), asks a stand-in detector for the initial pose
//! (the mock's ground truth perturbed, evaluation only), starts a session and prints a row per
//! step as the orchestrator streams it, with the pose error against the mock's truth.

use std::time::Duration;

use anyhow::Context;
use glint_eval::active::stand_in_detector;
use glint_geometry::Part;
use glint_geometry::pose_deviation::{PoseDeviation, pose_deviation};
use glint_orchestrator::server::policy_message;
use glint_orchestrator::session::ViewPolicy;
use glint_proto::v1;
use glint_proto::v1::mock_camera_service_client::MockCameraServiceClient;
use glint_proto::v1::orchestrator_service_client::OrchestratorServiceClient;
use nalgebra::Isometry3;
use tonic::transport::Channel;

#[derive(clap::Args)]
pub struct SessionArgs {
    #[command(subcommand)]
    pub command: SessionCommand,
    /// The orchestrator, HOST:PORT or http://HOST:PORT.
    #[arg(
        long,
        global = true,
        env = "GLINT_ORCHESTRATOR",
        default_value = "127.0.0.1:50051"
    )]
    pub orchestrator: String,
}

#[derive(clap::Subcommand)]
pub enum SessionCommand {
    /// Set up the mock bin, start a session and print a row per step.
    Run(RunArgs),
    /// Every session the orchestrator holds, one line each.
    List,
    /// One session's steps.
    Show { id: String },
    /// Stop a session at its next stage boundary.
    Cancel { id: String },
}

#[derive(clap::Args, Clone)]
pub struct RunArgs {
    /// The part in the mock bin.
    #[arg(long, default_value = "zigzag")]
    pub part: Part,
    /// The mock camera (its MockCameraService); default: the orchestrator's address (as
    /// `glint serve all` serves both).
    #[arg(long, env = "GLINT_CAMERA")]
    pub camera: Option<String>,
    /// nbv, nbv-const-sigma, random or max-distance.
    #[arg(long, default_value = "nbv")]
    pub policy: ViewPolicy,
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub max_views: u32,
    /// Stop below this pose entropy, nats (0: the budget only).
    #[arg(long, default_value_t = 0.0)]
    pub entropy_threshold_nats: f64,
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(2..=1000))]
    pub candidates: u32,
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    /// Seed of the bin, the detector's error and the session.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Camera resolution, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub spp: u32,
}

fn uri(addr: &str) -> String {
    if addr.contains("://") {
        addr.to_owned()
    } else {
        format!("http://{addr}")
    }
}

async fn channel(addr: &str) -> anyhow::Result<Channel> {
    let target = uri(addr);
    tonic::transport::Endpoint::from_shared(target.clone())
        .with_context(|| format!("{addr}: not an address; give HOST:PORT"))?
        .connect_timeout(Duration::from_secs(5))
        .connect()
        .await
        .with_context(|| format!("connecting to {target}"))
}

fn status(e: tonic::Status) -> anyhow::Error {
    anyhow::anyhow!("{}: {}", e.code(), e.message())
}

/// An entropy with two decimals, or "-" when there is none (NaN on the wire).
fn nats_or_dash(h: f64) -> String {
    if h.is_finite() {
        format!("{h:.2}")
    } else {
        "-".into()
    }
}

/// The per-step table's header, for `glint session run` and the demo.
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

/// What a run gives: the steps, the final session, and the truth it was scored against.
pub struct RunOutcome {
    pub steps: Vec<v1::SessionStep>,
    pub session: v1::Session,
    pub deviations: Vec<PoseDeviation>,
    pub initial_deviation: PoseDeviation,
}

fn pose(p: &Option<v1::Pose>, what: &str) -> anyhow::Result<Isometry3<f64>> {
    Isometry3::try_from(
        p.as_ref()
            .with_context(|| format!("the server sent no {what}"))?,
    )
    .map_err(|e| anyhow::anyhow!("the server's {what}: {e}"))
}

/// Sets up the mock bin, asks the stand-in detector, runs a session on the orchestrator;
/// `on_row` gets each printed row.
pub async fn run_remote(
    orchestrator: &str,
    args: &RunArgs,
    mut on_row: impl FnMut(&str),
) -> anyhow::Result<RunOutcome> {
    let camera_addr = args.camera.as_deref().unwrap_or(orchestrator);
    let mut mock = MockCameraServiceClient::new(channel(camera_addr).await?);
    let mut client = OrchestratorServiceClient::new(channel(orchestrator).await?);
    mock.set_up_scene(v1::SetUpSceneRequest {
        part: Some(v1::PartSpec {
            part: Some(v1::part_spec::Part::Builtin(args.part.name().into())),
        }),
        instances: args.instances,
        material: None,
        seed: args.seed,
        width_px: args.resolution.0,
        height_px: args.resolution.1,
        samples_per_pixel: args.spp,
    })
    .await
    .map_err(status)
    .context("setting up the mock bin")?;
    // The session's candidates are the camera's own; the detector looked from the first.
    let mut camera =
        v1::camera_service_client::CameraServiceClient::new(channel(camera_addr).await?);
    let candidates = camera
        .list_candidate_views(v1::ListCandidateViewsRequest {
            count: args.candidates,
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
    let symmetry = args.part.symmetry();
    let guess = stand_in_detector(&gt, &visibility, &first_t_w_c, &symmetry, args.seed)
        .context("the mock bin holds no instance")?;
    let gt_t_w_o = gt[guess.target];
    let deviation = |t: &Isometry3<f64>| pose_deviation(t, &gt_t_w_o, &symmetry);
    let initial_deviation = deviation(&guess.initial_t_w_o);
    on_row(&format!(
        "Initial pose: a stand-in detector (ground truth perturbed as in `glint eval refine`), \
         {:.1} mm / {:.1}° off; instance {} of {}, {:.0} % visible from the first view.",
        initial_deviation.translation_mm(),
        initial_deviation.rotation_deg(),
        guess.target + 1,
        gt.len(),
        100.0 * guess.visib_fract
    ));
    let id = client
        .start_session(v1::StartSessionRequest {
            part: Some(v1::PartSpec {
                part: Some(v1::part_spec::Part::Builtin(args.part.name().into())),
            }),
            initial_t_w_o: Some((&guess.initial_t_w_o).into()),
            candidates_t_w_c: candidates,
            policy: policy_message(args.policy) as i32,
            max_views: args.max_views,
            entropy_threshold_nats: args.entropy_threshold_nats,
            seed: args.seed,
            ..Default::default()
        })
        .await
        .map_err(status)
        .context("starting the session")?
        .into_inner()
        .session_id;
    on_row(&format!("Session {id}, policy {}.", args.policy.name()));
    on_row(&table_header());
    let mut stream = client
        .run_session(v1::RunSessionRequest {
            session_id: id.clone(),
        })
        .await
        .map_err(status)?
        .into_inner();
    let mut steps = Vec::new();
    let mut deviations = Vec::new();
    let mut finished = None;
    while let Some(event) = stream.message().await.map_err(status)? {
        match event.event {
            Some(v1::session_event::Event::Step(step)) => {
                let d = deviation(&pose(&step.t_w_o, "step pose")?);
                on_row(&table_row(&step, Some(&d)));
                deviations.push(d);
                steps.push(step);
            }
            Some(v1::session_event::Event::Finished(session)) => finished = Some(session),
            None => {}
        }
    }
    let session = finished.context("the session's stream ended without its final state")?;
    Ok(RunOutcome {
        steps,
        session,
        deviations,
        initial_deviation,
    })
}

fn state_name(state: i32) -> &'static str {
    v1::SessionState::try_from(state).map_or("?", |s| s.as_str_name())
}

fn session_line(s: &v1::Session) -> String {
    let last = s.steps.last();
    format!(
        "{}  {:<10} {:<28} views {:>2}/{:<2} h {}",
        s.session_id,
        s.part,
        state_name(s.state),
        s.steps.len(),
        s.max_views,
        last.map_or_else(|| "-".into(), |l| format!("{:.2}", l.entropy_nats))
    )
}

pub fn run(args: &SessionArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        match &args.command {
            SessionCommand::Run(run) => {
                let outcome = run_remote(&args.orchestrator, run, |row| println!("{row}")).await?;
                println!("{}", session_line(&outcome.session));
                if let Some(last) = outcome.deviations.last() {
                    println!(
                        "Pose error {:.2} mm / {:.2}° (detector) → {:.2} mm / {:.2}° after {} views.",
                        outcome.initial_deviation.translation_mm(),
                        outcome.initial_deviation.rotation_deg(),
                        last.translation_mm(),
                        last.rotation_deg(),
                        outcome.steps.len()
                    );
                }
                if !outcome.session.error.is_empty() {
                    anyhow::bail!("the session failed: {}", outcome.session.error);
                }
            }
            SessionCommand::List => {
                let mut client = OrchestratorServiceClient::new(channel(&args.orchestrator).await?);
                let list = client
                    .list_sessions(v1::ListSessionsRequest {})
                    .await
                    .map_err(status)?
                    .into_inner();
                for s in &list.sessions {
                    println!("{}", session_line(s));
                }
            }
            SessionCommand::Show { id } => {
                let mut client = OrchestratorServiceClient::new(channel(&args.orchestrator).await?);
                let s = client
                    .get_session(v1::GetSessionRequest {
                        session_id: id.clone(),
                    })
                    .await
                    .map_err(status)?
                    .into_inner();
                println!("{}", session_line(&s));
                println!("{}", table_header());
                for step in &s.steps {
                    println!("{}", table_row(step, None));
                }
                if !s.error.is_empty() {
                    println!("error: {}", s.error);
                }
            }
            SessionCommand::Cancel { id } => {
                let mut client = OrchestratorServiceClient::new(channel(&args.orchestrator).await?);
                let s = client
                    .cancel_session(v1::CancelSessionRequest {
                        session_id: id.clone(),
                    })
                    .await
                    .map_err(status)?
                    .into_inner();
                println!("{}", session_line(&s));
            }
        }
        Ok(())
    })
}
