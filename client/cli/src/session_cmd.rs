//! `glint session run|list|show|cancel|resume`: a client of any deployment's orchestrator. `run`
//! sets up the mock camera's bin (`--part`), asks a stand-in detector for the initial pose
//! (the mock's ground truth perturbed, evaluation only), starts a session and prints a row per
//! step as the orchestrator streams it, with the pose error against the mock's truth.

use anyhow::Context;
use glint_client::{
    MockSession, channel, run_mock_session, state_name, status, stream_session, table_header,
    table_row,
};
use glint_geometry::Part;
use glint_orchestrator::session::ViewPolicy;
use glint_orchestrator::stages::PartCalibration;
use glint_proto::v1;
use glint_proto::v1::orchestrator_service_client::OrchestratorServiceClient;

use crate::calibration_args::CalibrationArgs;

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
    /// Token and TLS.
    #[command(flatten)]
    pub security: crate::security_args::ClientSecurityArgs,
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
    /// Run a session the orchestrator holds (one created, or interrupted by a crash of an
    /// orchestrator with --state): its completed steps are printed again, then it goes on
    /// after the last one.
    Resume { id: String },
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
    /// The part's calibration for the render workers; without it, the orchestrator uses the
    /// one Glint ships for the part (the Zigzag's).
    #[command(flatten)]
    pub calibration: CalibrationArgs,
}

impl RunArgs {
    /// The session these flags ask for.
    pub fn spec(&self) -> MockSession {
        MockSession {
            part: self.part,
            instances: self.instances,
            policy: self.policy,
            max_views: self.max_views,
            entropy_threshold_nats: self.entropy_threshold_nats,
            candidates: self.candidates,
            seed: self.seed,
            width_px: self.resolution.0,
            height_px: self.resolution.1,
            samples_per_pixel: self.spp,
        }
    }
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
    let security = args.security.client()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        match &args.command {
            SessionCommand::Run(run) => {
                let calibration = match (&run.calibration.material, &run.calibration.response) {
                    (Some(_), Some(_)) => Some(
                        PartCalibration::from_files(&run.calibration.load(run.part)?)
                            .map_err(|e| anyhow::anyhow!("--material, --response: {e}"))?,
                    ),
                    _ => None,
                };
                let outcome = run_mock_session(
                    &args.orchestrator,
                    run.camera.as_deref().unwrap_or(&args.orchestrator),
                    &run.spec(),
                    calibration.as_ref(),
                    &security,
                    |row, _| println!("{row}"),
                )
                .await?;
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
                let mut client = OrchestratorServiceClient::new(channel(&args.orchestrator, &security).await?);
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
                let mut client = OrchestratorServiceClient::new(channel(&args.orchestrator, &security).await?);
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
            SessionCommand::Resume { id } => {
                let mut client = OrchestratorServiceClient::new(channel(&args.orchestrator, &security).await?);
                println!("{}", table_header());
                let s = stream_session(&mut client, id, |step| {
                    println!("{}", table_row(step, None));
                    Ok(())
                })
                .await?;
                println!("{}", session_line(&s));
                if !s.error.is_empty() {
                    anyhow::bail!("the session failed: {}", s.error);
                }
            }
            SessionCommand::Cancel { id } => {
                let mut client = OrchestratorServiceClient::new(channel(&args.orchestrator, &security).await?);
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
