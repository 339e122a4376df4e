//! `glint serve <stage>` and `glint healthcheck`: the stage servers over the libraries, and
//! the probe containers and scripts use. Flags fall back to environment variables
//! (`GLINT_LISTEN`, `GLINT_TARGET`, `GLINT_DRAIN_TIMEOUT_S`).

use std::time::Duration;

use anyhow::Context;
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
}

#[derive(clap::Subcommand, Clone, Copy, Debug)]
pub enum Stage {
    /// `glint.v1.CalibrationService`: camera response (Debevec–Malik) from a streamed stack.
    Calibration,
    /// `glint.v1.UncertaintyService`: a render worker (candidate-view prediction, eq 14–17).
    Uncertainty,
    /// `glint.v1.EstimationService`: multi-view SDF refinement with covariance (eq 1–11,
    /// 18–19) and the next view by minimum entropy (eq 20–23).
    Estimation,
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

pub fn serve(args: &ServeArgs) -> anyhow::Result<()> {
    let drain_timeout = seconds("--drain-timeout-s", args.drain_timeout_s)?;
    runtime()?.block_on(async {
        let listener = glint_server::bind(&args.listen).await?;
        let (routes, services) = match args.stage {
            Stage::Calibration => (
                tonic::service::Routes::new(glint_calibration::server::Calibration.into_service()),
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
        };
        // The bound address on stdout, so a script that passed port 0 can read it.
        println!("listening on {}", listener.local_addr()?);
        glint_server::serve(
            listener,
            routes,
            ServeConfig {
                services,
                drain_timeout,
            },
            glint_server::shutdown_signal(),
        )
        .await?;
        Ok(())
    })
}

pub fn healthcheck(args: &HealthcheckArgs) -> anyhow::Result<()> {
    let timeout = seconds("--timeout-s", args.timeout_s)?;
    let target = if args.target.contains("://") {
        args.target.clone()
    } else {
        format!("http://{}", args.target)
    };
    let status = runtime()?.block_on(glint_server::healthcheck(&target, &args.service, timeout))?;
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
