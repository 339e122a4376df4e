//! `glint bench load`: many concurrent sessions against one orchestrator (a `glint serve all`
//! process this command starts on loopback, or `--orchestrator`), each client retrying a
//! refused RunSession after the server's retry hint. Prints the sessions completed, the
//! refusals (load shed), step latency percentiles, throughput and the server's peak RSS.

use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use glint_client::{MockSession, PreparedSession, channel, prepare_mock_session};
use glint_geometry::Part;
use glint_orchestrator::session::ViewPolicy;
use glint_proto::v1;
use glint_proto::v1::orchestrator_service_client::OrchestratorServiceClient;
use glint_server::process::ServerProcess;
use glint_server::security::ClientSecurity;

#[derive(clap::Args)]
pub struct LoadBenchArgs {
    /// Sessions in all.
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub sessions: u32,
    /// Clients at once, each running sessions one after another.
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub concurrency: u32,
    /// The started server's --max-running-sessions (ignored with --orchestrator).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub max_running: u32,
    /// The started server's --max-concurrent-calls per stage service (ignored with
    /// --orchestrator): sessions whose stage calls are refused wait the hint and call again.
    #[arg(long, default_value_t = glint_server::load::DEFAULT_MAX_CONCURRENT_CALLS as u32,
          value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub max_concurrent_calls: u32,
    #[arg(long, default_value = "zigzag", value_parser = crate::mesh_cmd::parse_part)]
    pub part: Part,
    /// nbv, nbv-const-sigma, random or max-distance.
    #[arg(long, default_value = "nbv")]
    pub policy: ViewPolicy,
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub max_views: u32,
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(2..=1000))]
    pub candidates: u32,
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    #[arg(long, default_value = "320x256", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub spp: u32,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Give up (and fail) after this many seconds: a deadlock or an unbounded queue shows here.
    #[arg(long, default_value_t = 900.0)]
    pub timeout_s: f64,
    /// The started server keeps its sessions here (`glint serve all --state DIR`) instead of
    /// in memory (ignored with --orchestrator).
    #[arg(long, value_name = "DIR")]
    pub state: Option<std::path::PathBuf>,
    /// Instead of starting `glint serve all`: this orchestrator (its mock camera at --camera).
    #[arg(long)]
    pub orchestrator: Option<String>,
    #[arg(long)]
    pub camera: Option<String>,
    #[command(flatten)]
    pub security: crate::security_args::ClientSecurityArgs,
}

/// What the clients saw.
#[derive(Default)]
struct Tally {
    completed: u32,
    failed: Vec<String>,
    refused: u32,
    /// Time from RunSession (or the previous step) to each step, ms.
    step_ms: Vec<f64>,
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = (p / 100.0 * (sorted.len() - 1) as f64).round() as usize;
    sorted[rank.min(sorted.len() - 1)]
}

/// Peak resident memory of process `pid`, MiB (Linux: VmHWM).
fn peak_rss_mib(pid: u32) -> Option<f64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// One session: start it, then run it, waiting out each refusal as the server asks.
async fn one_session(
    orchestrator: &str,
    prepared: &PreparedSession,
    security: &ClientSecurity,
    tally: &std::sync::Mutex<Tally>,
) -> anyhow::Result<()> {
    let mut client = OrchestratorServiceClient::new(channel(orchestrator, security).await?);
    let id = client
        .start_session(prepared.request.clone())
        .await
        .map_err(glint_client::status)?
        .into_inner()
        .session_id;
    let stream = loop {
        match client
            .run_session(v1::RunSessionRequest {
                session_id: id.clone(),
            })
            .await
        {
            Ok(stream) => break stream.into_inner(),
            Err(s) if s.code() == tonic::Code::ResourceExhausted => {
                let wait_ms = glint_server::load::retry_pushback(&s)
                    .context("a refusal without grpc-retry-pushback-ms")?
                    .as_millis() as u64;
                if let Ok(mut t) = tally.lock() {
                    t.refused += 1;
                }
                tokio::time::sleep(Duration::from_millis(wait_ms)).await;
            }
            Err(s) => return Err(glint_client::status(s)),
        }
    };
    let mut stream = stream;
    let mut last = Instant::now();
    let mut steps_ms = Vec::new();
    let mut finished = None;
    while let Some(event) = stream.message().await.map_err(glint_client::status)? {
        match event.event {
            Some(v1::session_event::Event::Step(_)) => {
                steps_ms.push(last.elapsed().as_secs_f64() * 1e3);
                last = Instant::now();
            }
            Some(v1::session_event::Event::Finished(s)) => finished = Some(s),
            None => {}
        }
    }
    let session = finished.context("the stream ended without the session's final state")?;
    anyhow::ensure!(session.error.is_empty(), "session {id}: {}", session.error);
    if let Ok(mut t) = tally.lock() {
        t.step_ms.extend(steps_ms);
    }
    Ok(())
}

pub fn run(args: &LoadBenchArgs) -> anyhow::Result<()> {
    let timeout = Duration::try_from_secs_f64(args.timeout_s).map_err(|_| {
        anyhow::anyhow!("--timeout-s: {} is not a number of seconds", args.timeout_s)
    })?;
    let security = args.security.client()?;
    let max_running = args.max_running.to_string();
    let max_calls = args.max_concurrent_calls.to_string();
    let (server, orchestrator) = match &args.orchestrator {
        Some(o) => (None, o.clone()),
        None => {
            let program = std::env::current_exe().context("finding this binary")?;
            let mut flags = vec![
                "all",
                "--listen",
                "127.0.0.1:0",
                "--max-running-sessions",
                &max_running,
                "--max-concurrent-calls",
                &max_calls,
            ];
            let token = args
                .security
                .token_file
                .as_ref()
                .map(|p| p.to_string_lossy().into_owned());
            if let Some(t) = &token {
                flags.extend(["--token-file", t]);
            }
            let state = args
                .state
                .as_ref()
                .map(|p| p.to_string_lossy().into_owned());
            if let Some(dir) = &state {
                flags.extend(["--state", dir]);
            }
            let server = ServerProcess::spawn(&program, &flags)?;
            let addr = server.addr.clone();
            (Some(server), addr)
        }
    };
    let camera = args.camera.clone().unwrap_or_else(|| orchestrator.clone());
    let spec = MockSession {
        part: args.part,
        instances: args.instances,
        policy: args.policy,
        max_views: args.max_views,
        entropy_threshold_nats: 0.0,
        candidates: args.candidates,
        seed: args.seed,
        width_px: args.resolution.0,
        height_px: args.resolution.1,
        samples_per_pixel: args.spp,
    };
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let prepared =
        Arc::new(runtime.block_on(prepare_mock_session(&camera, &spec, None, &security))?);
    let tally = Arc::new(std::sync::Mutex::new(Tally::default()));
    let next = Arc::new(AtomicU32::new(0));
    let bar = glint_eval::progress::bar(u64::from(args.sessions), "sessions");
    let started = Instant::now();
    let outcome = runtime.block_on(async {
        let mut clients = tokio::task::JoinSet::new();
        for _ in 0..args.concurrency.min(args.sessions) {
            let (orchestrator, prepared, security, tally, next, bar) = (
                orchestrator.clone(),
                prepared.clone(),
                security.clone(),
                tally.clone(),
                next.clone(),
                bar.clone(),
            );
            let sessions = args.sessions;
            clients.spawn(async move {
                while next.fetch_add(1, Ordering::SeqCst) < sessions {
                    let result = one_session(&orchestrator, &prepared, &security, &tally).await;
                    if let Ok(mut t) = tally.lock() {
                        match result {
                            Ok(()) => t.completed += 1,
                            Err(e) => t.failed.push(format!("{e:#}")),
                        }
                    }
                    bar.inc(1);
                }
            });
        }
        tokio::time::timeout(timeout, async {
            while clients.join_next().await.is_some() {}
        })
        .await
    });
    bar.finish_and_clear();
    let wall_s = started.elapsed().as_secs_f64();
    let rss = server.as_ref().and_then(|s| peak_rss_mib(s.child.id()));
    drop(server);
    anyhow::ensure!(
        outcome.is_ok(),
        "the sessions did not finish within --timeout-s {}",
        args.timeout_s
    );
    let tally = tally
        .lock()
        .map_err(|_| anyhow::anyhow!("a client panicked"))?;
    let mut steps = tally.step_ms.clone();
    steps.sort_by(f64::total_cmp);
    println!(
        "{} sessions ({} policy, {} views, {} candidates, {}×{} px, {} spp) from {} clients at \
         once against {}{}:\n\n\
         | sessions | clients | max running | completed | failed | refused (RESOURCE_EXHAUSTED) | steps | step p50 ms | step p99 ms | wall s | sessions/min | server peak RSS MiB |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n\
         | {} | {} | {} | {} | {} | {} | {} | {:.0} | {:.0} | {wall_s:.1} | {:.1} | {} |",
        args.sessions,
        args.policy.name(),
        args.max_views,
        args.candidates,
        args.resolution.0,
        args.resolution.1,
        args.spp,
        args.concurrency,
        orchestrator,
        if args.orchestrator.is_none() {
            " (glint serve all, started here)"
        } else {
            ""
        },
        args.sessions,
        args.concurrency,
        if args.orchestrator.is_none() {
            max_running.as_str()
        } else {
            "?"
        },
        tally.completed,
        tally.failed.len(),
        tally.refused,
        steps.len(),
        percentile(&steps, 50.0),
        percentile(&steps, 99.0),
        f64::from(tally.completed) / wall_s * 60.0,
        rss.map_or_else(|| "-".into(), |r| format!("{r:.0}")),
    );
    if let Some(first) = tally.failed.first() {
        anyhow::bail!("{} sessions failed; the first: {first}", tally.failed.len());
    }
    Ok(())
}
