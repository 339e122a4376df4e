//! `glint serve <stage>` and `glint healthcheck`: the stage servers over the libraries, and
//! the probe containers and scripts use. Flags fall back to environment variables
//! (`GLINT_LISTEN`, `GLINT_TARGET`, `GLINT_DRAIN_TIMEOUT_S`, and the camera's initial scene
//! `GLINT_CAMERA_PART`, `GLINT_CAMERA_INSTANCES`, …).

use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use glint_orchestrator::server::OrchestratorServer;
use glint_orchestrator::service::Orchestrator;
use glint_server::{HealthStatus, ServeConfig};

#[derive(clap::Args)]
pub struct ServeArgs {
    #[command(subcommand)]
    pub stage: Stage,
    /// Address to listen on, HOST:PORT (port 0: any free port, printed on start).
    #[arg(
        long,
        global = true,
        env = "GLINT_LISTEN",
        default_value = "127.0.0.1:50051"
    )]
    pub listen: String,
    /// After SIGTERM/Ctrl-C, seconds open calls get to finish before the server stops.
    #[arg(
        long,
        global = true,
        env = "GLINT_DRAIN_TIMEOUT_S",
        default_value_t = 10.0
    )]
    pub drain_timeout_s: f64,
    /// Calls at work per stage service at most (camera, calibration, uncertainty, estimation;
    /// the orchestrator bounds its sessions itself). A call beyond it is refused at once with
    /// RESOURCE_EXHAUSTED and a retry hint (grpc-retry-pushback-ms) instead of queueing.
    #[arg(long, global = true, env = "GLINT_MAX_CONCURRENT_CALLS",
          default_value_t = glint_server::load::DEFAULT_MAX_CONCURRENT_CALLS as u32,
          value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub max_concurrent_calls: u32,
    /// Token and TLS.
    #[command(flatten)]
    pub security: crate::security_args::ServerSecurityArgs,
}

/// The bounds of `services` at `per_service` calls each; the orchestrator admits sessions
/// itself.
fn call_limits(services: &[&'static str], per_service: usize) -> glint_server::load::CallLimits {
    glint_server::load::CallLimits::each(
        services,
        per_service,
        &[glint_orchestrator::server::SERVICE_NAME],
    )
}

#[derive(clap::Subcommand, Clone, Debug)]
pub enum Stage {
    /// `glint.v1.CameraService` and `glint.v1.MockCameraService`: the mock structured-light
    /// camera (scene set-up, rig, candidate views, captures, exposure stacks).
    Camera(CameraArgs),
    /// `glint.v1.CalibrationService`: camera response (Debevec–Malik) from a streamed stack.
    Calibration,
    /// `glint.v1.UncertaintyService`: a render worker (candidate-view prediction, eq 14–17).
    Uncertainty,
    /// `glint.v1.EstimationService`: multi-view SDF refinement with covariance (eq 1–11,
    /// 18–19) and the next view by minimum entropy (eq 20–23).
    Estimation,
    /// `glint.v1.OrchestratorService`: active sessions over a camera, an estimator and render
    /// workers reached by gRPC.
    Orchestrator(OrchestratorArgs),
    /// Every service in one process on one port (the orchestrator reaches the others, and
    /// the render workers given by --workers, through that port).
    All(AllArgs),
}

/// Where the orchestrator's stages are and how it fans out.
#[derive(clap::Args, Clone, Debug)]
pub struct OrchestratorArgs {
    /// The camera (CameraService), HOST:PORT.
    #[arg(long, env = "GLINT_CAMERA_ADDR")]
    pub camera: String,
    /// The estimator (EstimationService), HOST:PORT.
    #[arg(long, env = "GLINT_ESTIMATION_ADDR")]
    pub estimation: String,
    /// The render workers (UncertaintyService): HOST:PORT[,HOST:PORT...], or dns:HOST:PORT to
    /// re-resolve a name before every decision (a compose service, a headless Service).
    #[arg(long, env = "GLINT_WORKERS")]
    pub workers: String,
    #[command(flatten)]
    pub fan_out: FanOutArgs,
    #[command(flatten)]
    pub state: StateArgs,
}

/// Where the orchestrator keeps its sessions.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct StateArgs {
    /// Keep sessions in this directory (a redb database and a blob directory of captures,
    /// created if missing), so that they survive a crash or restart: an interrupted session
    /// resumes after its last completed step when RunSession is called again. Without it,
    /// sessions live in memory and end with the process.
    #[arg(long = "state", value_name = "DIR", env = "GLINT_STATE_DIR")]
    pub dir: Option<std::path::PathBuf>,
}

impl StateArgs {
    /// The session store these flags ask for.
    pub fn store(&self) -> anyhow::Result<Arc<dyn glint_orchestrator::store::SessionStore>> {
        Ok(match &self.dir {
            Some(dir) => Arc::new(
                glint_orchestrator::store::DiskStore::open(dir)
                    .with_context(|| format!("--state {}", dir.display()))?,
            ),
            None => Arc::new(glint_orchestrator::store::MemoryStore::default()),
        })
    }
}

/// How the orchestrator spreads and bounds its calls.
#[derive(clap::Args, Clone, Debug)]
pub struct FanOutArgs {
    /// Requests in flight per render worker.
    #[arg(long, env = "GLINT_IN_FLIGHT_PER_WORKER", default_value_t = 2,
          value_parser = clap::value_parser!(u32).range(1..=64))]
    pub in_flight_per_worker: u32,
    /// Deadline of every call to a stage, seconds (sent as grpc-timeout).
    #[arg(long, env = "GLINT_CALL_DEADLINE_S", default_value_t = 120.0)]
    pub call_deadline_s: f64,
    /// Sessions run at once at most; RunSession beyond it answers RESOURCE_EXHAUSTED with a
    /// retry hint (grpc-retry-pushback-ms) instead of queueing.
    #[arg(long, env = "GLINT_MAX_RUNNING_SESSIONS", default_value_t = glint_orchestrator::service::DEFAULT_MAX_RUNNING as u32,
          value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub max_running_sessions: u32,
    /// What the orchestrator knows of the cell: `standard-bin` (Glint's bin: rendered with the
    /// part, its floor's points dropped) or `none` (the part alone, as the paper renders it).
    #[arg(long, env = "GLINT_CELL", default_value = "standard-bin",
          value_parser = ["standard-bin", "none"])]
    pub cell: String,
}

#[derive(clap::Args, Clone, Debug)]
pub struct AllArgs {
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Render workers besides this process's own: HOST:PORT[,...] or dns:HOST:PORT. Default:
    /// this process's UncertaintyService.
    #[arg(long, env = "GLINT_WORKERS")]
    pub workers: Option<String>,
    #[command(flatten)]
    pub fan_out: FanOutArgs,
    #[command(flatten)]
    pub state: StateArgs,
}

/// The mock camera's initial scene, as `SetUpScene` would set it up; without `--part` the
/// camera starts empty and waits for a client's `SetUpScene`.
#[derive(clap::Args, Clone, Debug)]
pub struct CameraArgs {
    /// A built-in part dropped into the bin: eye-bolt, tube-fitting, chrome-screw, gear, zigzag.
    #[arg(long, env = "GLINT_CAMERA_PART")]
    pub part: Option<String>,
    /// Copies dropped into the bin, 1 to 40.
    #[arg(long, env = "GLINT_CAMERA_INSTANCES", default_value_t = 8)]
    pub instances: u32,
    /// Seed of the drop (the instances' poses).
    #[arg(long, env = "GLINT_CAMERA_SEED", default_value_t = 1)]
    pub seed: u64,
    /// Image width, px (0 with --height-px 0: the N35's 1280).
    #[arg(long, env = "GLINT_CAMERA_WIDTH_PX", default_value_t = 0)]
    pub width_px: u32,
    /// Image height, px (0 with --width-px 0: the N35's 1024).
    #[arg(long, env = "GLINT_CAMERA_HEIGHT_PX", default_value_t = 0)]
    pub height_px: u32,
    /// Samples per pixel of the renders, 1 to 1024 (0: 4).
    #[arg(long, env = "GLINT_CAMERA_SPP", default_value_t = 0)]
    pub spp: u32,
}

impl CameraArgs {
    /// No initial scene: the camera waits for a client's `SetUpScene`.
    pub fn empty() -> Self {
        Self {
            part: None,
            instances: 8,
            seed: 1,
            width_px: 0,
            height_px: 0,
            spp: 0,
        }
    }

    /// The camera server, with the initial scene set up when `--part` is given.
    fn camera(&self) -> anyhow::Result<glint_camera::server::Camera> {
        let camera = glint_camera::server::Camera::new();
        if let Some(part) = &self.part {
            use glint_proto::v1;
            let request = v1::SetUpSceneRequest {
                part: Some(v1::PartSpec {
                    part: Some(v1::part_spec::Part::Builtin(part.clone())),
                }),
                instances: self.instances,
                material: None,
                seed: self.seed,
                width_px: self.width_px,
                height_px: self.height_px,
                samples_per_pixel: self.spp,
            };
            // The request's field names are the flags' (part.builtin is --part).
            let scene = camera.set_up(&request).map_err(|status| {
                anyhow::anyhow!(
                    "the initial scene (--part, --instances, --width-px, --height-px, --spp): {}",
                    status.message()
                )
            })?;
            let mesh = scene.mesh.unwrap_or_default();
            println!(
                "scene: {} × {} (mesh sha256 {})",
                scene.instances, mesh.name, mesh.sha256_hex
            );
        }
        Ok(camera)
    }
}

#[derive(clap::Args)]
pub struct HealthcheckArgs {
    /// The server, e.g. http://127.0.0.1:50051 (a bare HOST:PORT gets http://).
    #[arg(long, env = "GLINT_TARGET", default_value = "http://127.0.0.1:50051")]
    pub target: String,
    /// The service to ask about (e.g. glint.v1.CalibrationService); empty: the whole server.
    #[arg(long, default_value = "")]
    pub service: String,
    /// Seconds to wait for an answer.
    #[arg(long, default_value_t = 3.0)]
    pub timeout_s: f64,
    /// TLS (and a token, though health checks need none).
    #[command(flatten)]
    pub security: crate::security_args::ClientSecurityArgs,
}

fn seconds(flag: &str, s: f64) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(s)
        .map_err(|_| anyhow::anyhow!("{flag}: {s} is not a non-negative number of seconds"))
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

/// The calibration server, reading FitBsdf's captures with glint-camera's reader.
fn calibration_server() -> glint_calibration::server::CalibrationServer {
    glint_calibration::server::Calibration
        .with_capture_reader(Arc::new(crate::calibrate_cmd::CameraCaptures))
}

/// The orchestrator over gRPC stages at `camera`, `estimation` and `workers`.
fn orchestrator(
    camera: &str,
    estimation: &str,
    workers: &str,
    fan_out: &FanOutArgs,
    state: &StateArgs,
    security: &glint_server::security::ClientSecurity,
) -> anyhow::Result<Arc<Orchestrator>> {
    use glint_orchestrator::remote::{self, prediction};
    let deadline = seconds("--call-deadline-s", fan_out.call_deadline_s)?;
    anyhow::ensure!(
        deadline > Duration::ZERO,
        "--call-deadline-s: must be positive"
    );
    let handle = tokio::runtime::Handle::current();
    let endpoint = |addr: &str| remote::Endpoint::secured(addr, deadline, security.clone());
    let source =
        prediction::WorkerSource::parse(workers).map_err(|e| anyhow::anyhow!("--workers: {e}"))?;
    let pool = prediction::RemotePrediction::new(
        handle.clone(),
        source,
        prediction::PoolConfig {
            in_flight_per_worker: fan_out.in_flight_per_worker as usize,
            call_deadline: deadline,
            ..prediction::PoolConfig::default()
        },
    )
    .with_security(security.clone());
    let camera = remote::camera::RemoteCamera::new(handle.clone(), endpoint(camera))
        .map_err(|e| anyhow::anyhow!("--camera: {e}"))?;
    let estimation = remote::estimation::RemoteEstimation::new(handle, endpoint(estimation))
        .map_err(|e| anyhow::anyhow!("--estimation: {e}"))?;
    let cell = match fan_out.cell.as_str() {
        "none" => glint_orchestrator::session::Cell::unknown(),
        _ => glint_orchestrator::session::Cell::standard_bin(),
    };
    Ok(Arc::new(
        Orchestrator::new(
            Arc::new(camera),
            Arc::new(estimation),
            Arc::new(pool),
            cell,
            state.store()?,
        )
        .with_max_running(fan_out.max_running_sessions as usize),
    ))
}

/// Every service on one port: the routes, their names, and the orchestrator, which reaches
/// the other stages (and, without `--workers`, its render worker) through `own`, the port's
/// address.
fn all_services(
    own: &str,
    all: &AllArgs,
    security: &glint_server::security::ClientSecurity,
) -> anyhow::Result<(tonic::service::Routes, Vec<&'static str>, Arc<Orchestrator>)> {
    let workers = all.workers.as_deref().unwrap_or(own);
    let orchestrator = orchestrator(own, own, workers, &all.fan_out, &all.state, security)?;
    let routes = all
        .camera
        .camera()?
        .into_routes()
        .add_service(calibration_server().into_service())
        .add_service(glint_uncertainty::server::Uncertainty::default().into_service())
        .add_service(glint_estimation::server::Estimation::default().into_service())
        .add_service(OrchestratorServer::new(orchestrator.clone()).into_service());
    let mut services = glint_camera::server::SERVICE_NAMES.to_vec();
    services.extend([
        glint_calibration::server::SERVICE_NAME,
        glint_uncertainty::server::SERVICE_NAME,
        glint_estimation::server::SERVICE_NAME,
        glint_orchestrator::server::SERVICE_NAME,
    ]);
    Ok((routes, services, orchestrator))
}

/// `glint serve all` inside this process on a free loopback port (the demo's deployment).
pub struct InProcessServer {
    pub addr: std::net::SocketAddr,
    /// The orchestrator the server runs, for readers in this process.
    pub orchestrator: Arc<Orchestrator>,
    stop: tokio::sync::oneshot::Sender<()>,
    task: tokio::task::JoinHandle<Result<(), glint_server::ServerError>>,
}

impl InProcessServer {
    /// Binds 127.0.0.1:0 and serves every service there until [`Self::stop`].
    pub async fn start(all: &AllArgs, drain_timeout: Duration) -> anyhow::Result<Self> {
        let listener = glint_server::bind("127.0.0.1:0").await?;
        let addr = listener.local_addr()?;
        let (routes, services, orchestrator) =
            all_services(&addr.to_string(), all, &Default::default())?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(glint_server::serve(
            listener,
            routes,
            ServeConfig {
                call_limits: call_limits(
                    &services,
                    glint_server::load::DEFAULT_MAX_CONCURRENT_CALLS,
                ),
                services,
                drain_timeout,
                security: Default::default(),
            },
            async {
                let _ = stopped.await;
            },
        ));
        Ok(Self {
            addr,
            orchestrator,
            stop,
            task,
        })
    }

    /// Stops serving (health NOT_SERVING, open calls drained within the bound) and waits.
    pub async fn stop(self) -> anyhow::Result<()> {
        let _ = self.stop.send(());
        self.task
            .await
            .context("the in-process server panicked")??;
        Ok(())
    }
}

pub fn serve(args: &ServeArgs) -> anyhow::Result<()> {
    let drain_timeout = seconds("--drain-timeout-s", args.drain_timeout_s)?;
    let security = args.security.server()?;
    let outbound = match &args.stage {
        Stage::Orchestrator(_) | Stage::All(_) => args.security.outbound()?,
        _ => Default::default(),
    };
    runtime()?.block_on(async {
        let listener = glint_server::bind(&args.listen).await?;
        let (routes, services) = match &args.stage {
            Stage::Camera(camera) => {
                let camera = camera.camera()?;
                (
                    camera.into_routes(),
                    glint_camera::server::SERVICE_NAMES.to_vec(),
                )
            }
            Stage::Calibration => (
                tonic::service::Routes::new(calibration_server().into_service()),
                vec![glint_calibration::server::SERVICE_NAME],
            ),
            Stage::Uncertainty => (
                tonic::service::Routes::new(
                    glint_uncertainty::server::Uncertainty::default().into_service(),
                ),
                vec![glint_uncertainty::server::SERVICE_NAME],
            ),
            Stage::Estimation => (
                tonic::service::Routes::new(
                    glint_estimation::server::Estimation::default().into_service(),
                ),
                vec![glint_estimation::server::SERVICE_NAME],
            ),
            Stage::Orchestrator(o) => (
                tonic::service::Routes::new(
                    OrchestratorServer::new(orchestrator(
                        &o.camera,
                        &o.estimation,
                        &o.workers,
                        &o.fan_out,
                        &o.state,
                        &outbound,
                    )?)
                    .into_service(),
                ),
                vec![glint_orchestrator::server::SERVICE_NAME],
            ),
            Stage::All(all) => {
                let (routes, services, _) =
                    all_services(&listener.local_addr()?.to_string(), all, &outbound)?;
                (routes, services)
            }
        };
        // The bound address on stdout, so a script that passed port 0 can read it.
        println!(
            "{}{}",
            glint_server::process::LISTENING_PREFIX,
            listener.local_addr()?
        );
        glint_server::serve(
            listener,
            routes,
            ServeConfig {
                call_limits: call_limits(&services, args.max_concurrent_calls as usize),
                services,
                drain_timeout,
                security,
            },
            glint_server::shutdown_signal(),
        )
        .await?;
        Ok(())
    })
}

pub fn healthcheck(args: &HealthcheckArgs) -> anyhow::Result<()> {
    let timeout = seconds("--timeout-s", args.timeout_s)?;
    let security = args.security.client()?;
    let target = security.uri(&args.target);
    let status = runtime()?.block_on(glint_server::healthcheck(
        &target,
        &args.service,
        timeout,
        &security,
    ))?;
    let what = if args.service.is_empty() {
        "the server"
    } else {
        &args.service
    };
    anyhow::ensure!(
        status == HealthStatus::Serving,
        "{target}: {what} is {}",
        status.as_str_name()
    );
    println!("{target}: {what} is SERVING");
    Ok(())
}
