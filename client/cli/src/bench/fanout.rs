//! `glint bench fanout`: what spreading one next-best-view decision over render-worker
//! processes costs and gains.
//!
//! - On loopback (default): one decision over every candidate, in-process
//!   (`LocalPrediction`, all cores) against 1, 2, 4… `glint serve uncertainty` processes
//!   started from this binary and reached over gRPC (`RemotePrediction`, the orchestrator's
//!   pool), with the wire's bytes and time per candidate, and a model of N machines.
//! - Against a deployment (`--orchestrator`): whole sessions through its orchestrator, as a
//!   client runs them (`glint_client`), with the decision latency each step reports and the
//!   sessions per minute; scale its workers between runs (`docker compose up --scale
//!   uncertainty=N`).

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use glint_eval::metrics::median;
use glint_geometry::Part;
use glint_geometry::io::write_file_atomically;
use glint_orchestrator::local::LocalPrediction;
use glint_orchestrator::remote::prediction::{PoolConfig, RemotePrediction, WorkerSource};
use glint_orchestrator::session::ViewPolicy;
use glint_orchestrator::stages::{PredictionRequest, PredictionSigma, PredictionStage};
use glint_server::process::ServerProcess;

#[derive(clap::Args)]
pub struct FanoutBenchArgs {
    #[arg(long, default_value = "zigzag", value_parser = crate::mesh_cmd::parse_part)]
    pub part: Part,
    /// Candidates predicted per decision.
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(2..=1000))]
    pub candidates: u32,
    /// Worker processes to compare, comma-separated.
    #[arg(long, default_value = "1,2,4", value_delimiter = ',')]
    pub workers: Vec<u32>,
    /// Timed decisions per configuration (after one warm-up); the median is reported.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeats: u32,
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Instead: run sessions through this deployment's orchestrator, HOST:PORT.
    #[arg(long)]
    pub orchestrator: Option<String>,
    /// The deployment's mock camera (MockCameraService), HOST:PORT; default the orchestrator's.
    #[arg(long)]
    pub camera: Option<String>,
    /// Sessions against the deployment (one after another).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub sessions: u32,
    /// Views per session against the deployment.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(2..=64))]
    pub max_views: u32,
    /// Samples per pixel of the mock's captures in a deployment's sessions.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub spp: u32,
    /// A label for the deployment's row (e.g. "3 workers").
    #[arg(long, default_value = "deployment")]
    pub label: String,
    /// Also write the table as CSV here.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Token and TLS of the deployment's services.
    #[command(flatten)]
    pub security: crate::security_args::ClientSecurityArgs,
}

pub fn run(args: &FanoutBenchArgs) -> anyhow::Result<()> {
    match &args.orchestrator {
        Some(orchestrator) => deployment(args, orchestrator),
        None => loopback(args),
    }
}

/// One row of the loopback table.
struct Row {
    label: String,
    decision_ms: f64,
    request_bytes: usize,
    response_bytes: usize,
    calls: usize,
}

fn loopback(args: &FanoutBenchArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        !args.workers.is_empty() && args.workers.iter().all(|&n| (1..=16).contains(&n)),
        "--workers: give counts from 1 to 16, e.g. 1,2,4"
    );
    let (scene, object) = super::nbv::decision_scene(
        args.part,
        args.instances,
        args.seed,
        args.resolution,
        args.candidates,
        true,
    )?;
    // Poses as a worker decodes them, so every configuration predicts the same bits.
    let wire = |t: &nalgebra::Isometry3<f64>| {
        nalgebra::Isometry3::try_from(&glint_proto::v1::Pose::from(t))
            .map_err(|e| anyhow::anyhow!("{e}"))
    };
    let request = PredictionRequest {
        t_w_o: wire(&scene.initial_t_w_o)?,
        candidates: scene
            .candidates
            .iter()
            .enumerate()
            .map(|(i, t)| Ok((i as u32, wire(t)?)))
            .collect::<anyhow::Result<_>>()?,
        sigma: PredictionSigma::Rendered,
        seed: args.seed,
        with_maps: false,
    };
    let timed = |stage: &dyn PredictionStage| -> anyhow::Result<(f64, Vec<_>)> {
        let mut answer = stage
            .predict(&object, &request)
            .map_err(anyhow::Error::msg)?;
        let mut times = Vec::new();
        for _ in 0..args.repeats {
            let started = Instant::now();
            answer = stage
                .predict(&object, &request)
                .map_err(anyhow::Error::msg)?;
            times.push(started.elapsed().as_secs_f64() * 1e3);
        }
        Ok((median(times), answer))
    };
    let bar = glint_eval::progress::bar(1 + args.workers.len() as u64, "configurations");
    let (local_ms, local) = timed(&LocalPrediction::default())?;
    bar.inc(1);
    let mut rows = vec![Row {
        label: "in-process".into(),
        decision_ms: local_ms,
        request_bytes: 0,
        response_bytes: 0,
        calls: 0,
    }];
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let program = std::env::current_exe().context("finding this binary")?;
    for &n in &args.workers {
        let workers = (0..n)
            .map(|_| ServerProcess::spawn(&program, &["uncertainty", "--listen", "127.0.0.1:0"]))
            .collect::<Result<Vec<_>, _>>()?;
        let pool = RemotePrediction::new(
            runtime.handle().clone(),
            WorkerSource::Static(workers.iter().map(|w| w.addr.clone()).collect()),
            PoolConfig::default(),
        );
        let (ms, remote) = timed(&pool)?;
        // The same answers as in-process (each candidate is seeded by its index).
        anyhow::ensure!(
            remote.len() == local.len()
                && remote
                    .iter()
                    .zip(&local)
                    .all(|(r, l)| r.index == l.index && r.information == l.information),
            "{n} workers answered differently from the in-process prediction"
        );
        let stats = pool.stats();
        let decisions = 1 + args.repeats as usize;
        rows.push(Row {
            label: format!("{n} worker process{}", if n == 1 { "" } else { "es" }),
            decision_ms: ms,
            request_bytes: stats.request_bytes / decisions,
            response_bytes: stats.response_bytes / decisions,
            calls: stats.answered_by.values().sum::<usize>() / decisions,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();

    let c = args.candidates as f64;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    let mut table = format!(
        "One NBV decision on the {} ({} in the bin, {}×{} px, bin rendered): {} candidates, \
         median of {} after a warm-up, {cores} cores on this machine.\n\n\
         | predicted by | decision ms | ÷ in-process | per candidate ms | request B/cand. | response B/cand. | calls |\n\
         |---|---:|---:|---:|---:|---:|---:|\n",
        args.part.display_name(),
        args.instances,
        args.resolution.0,
        args.resolution.1,
        args.candidates,
        args.repeats,
    );
    let mut csv = String::from(
        "configuration,candidates,decision_ms,ratio_to_in_process,request_bytes,response_bytes,calls\n",
    );
    for r in &rows {
        let _ = writeln!(
            table,
            "| {} | {:.0} | {:.2} | {:.1} | {:.0} | {:.0} | {} |",
            r.label,
            r.decision_ms,
            r.decision_ms / local_ms,
            r.decision_ms / c,
            r.request_bytes as f64 / c,
            r.response_bytes as f64 / c,
            r.calls
        );
        let _ = writeln!(
            csv,
            "{},{},{:.3},{:.4},{},{},{}",
            r.label,
            args.candidates,
            r.decision_ms,
            r.decision_ms / local_ms,
            r.request_bytes,
            r.response_bytes,
            r.calls
        );
    }
    // The model: a candidate costs `cpu_ms` of one core (in-process, all cores busy), and
    // going over the wire to another process `wire_cpu_ms` more of one core (encoding,
    // decoding, the second process: what one worker process costs beyond in-process here,
    // on all cores); N machines of `cores` cores share the candidates in rounds, and every
    // byte crosses the orchestrator's link.
    let cpu_ms = local_ms * cores / c;
    let one_worker = &rows[1.min(rows.len() - 1)];
    let wire_cpu_ms = ((one_worker.decision_ms - local_ms) * cores / c).max(0.0);
    let bytes = (one_worker.request_bytes + one_worker.response_bytes) as f64 / c;
    let link_ms = c * bytes * 8.0 / 1e9 * 1e3;
    let _ = writeln!(
        table,
        "\nPer candidate: {cpu_ms:.1} ms of one core to predict, {wire_cpu_ms:.1} ms more over \
         the wire to another process, {bytes:.0} B both ways. Spread over N machines of \
         {cores} cores each as fast as this one, a decision takes about \
         ⌈C / (N·{cores})⌉ · ({cpu_ms:.1} + {wire_cpu_ms:.1}) ms + C · {bytes:.0} B at 1 Gb/s \
         ({link_ms:.1} ms):\n\n| machines | decision ms (model) | ÷ in-process here |\n|---:|---:|---:|"
    );
    for machines in [1u32, 2, 4, 8, 16] {
        let rounds = (c / (f64::from(machines) * cores)).ceil();
        let model_ms = rounds * (cpu_ms + wire_cpu_ms) + link_ms;
        let _ = writeln!(
            table,
            "| {machines} | {model_ms:.0} | {:.2} |",
            model_ms / local_ms
        );
    }
    println!("{table}");
    println!(
        "On this machine every worker process shares the same {cores} cores, so more processes \
         cannot be faster than in-process: the rows measure the fan-out's overhead, not its \
         speed-up; the model is what separate machines would give."
    );
    if let Some(path) = &args.csv {
        write_file_atomically(path, csv.as_bytes())?;
    }
    Ok(())
}

fn deployment(args: &FanoutBenchArgs, orchestrator: &str) -> anyhow::Result<()> {
    let camera = args.camera.as_deref().unwrap_or(orchestrator);
    let security = args.security.client()?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let bar = glint_eval::progress::bar(u64::from(args.sessions), "sessions");
    let started = Instant::now();
    let mut decisions_ms = Vec::new();
    let mut sessions_s = Vec::new();
    for k in 0..args.sessions {
        let spec = glint_client::MockSession {
            part: args.part,
            instances: args.instances,
            policy: ViewPolicy::Nbv,
            max_views: args.max_views,
            entropy_threshold_nats: 0.0,
            candidates: args.candidates,
            seed: args.seed + u64::from(k),
            width_px: args.resolution.0,
            height_px: args.resolution.1,
            samples_per_pixel: args.spp,
        };
        let t = Instant::now();
        let outcome = runtime.block_on(glint_client::run_mock_session(
            orchestrator,
            camera,
            &spec,
            None,
            &security,
            |_, _| {},
        ))?;
        anyhow::ensure!(
            outcome.session.error.is_empty(),
            "session {} failed: {}",
            outcome.session.session_id,
            outcome.session.error
        );
        sessions_s.push(t.elapsed().as_secs_f64());
        decisions_ms.extend(
            outcome
                .steps
                .iter()
                .filter(|s| s.next_view.is_some())
                .filter_map(|s| s.times.map(|t| t.predict_ms)),
        );
        bar.inc(1);
    }
    bar.finish_and_clear();
    let wall = started.elapsed();
    let per_minute =
        f64::from(args.sessions) / wall.max(Duration::from_millis(1)).as_secs_f64() * 60.0;
    let decision = median(decisions_ms.clone());
    let session = median(sessions_s);
    println!(
        "Sessions through {orchestrator} ({}, {} views, {} candidates, {}×{} px):\n\n\
         | deployment | sessions | decisions | decision ms (median) | session s (median) | sessions/min |\n\
         |---|---:|---:|---:|---:|---:|\n| {} | {} | {} | {decision:.0} | {session:.1} | {per_minute:.2} |",
        args.part.display_name(),
        args.max_views,
        args.candidates,
        args.resolution.0,
        args.resolution.1,
        args.label,
        args.sessions,
        decisions_ms.len(),
    );
    if let Some(path) = &args.csv {
        let csv = format!(
            "label,sessions,decisions,decision_ms_median,session_s_median,sessions_per_min\n{},{},{},{decision:.3},{session:.3},{per_minute:.4}\n",
            args.label,
            args.sessions,
            decisions_ms.len()
        );
        write_file_atomically(path, csv.as_bytes())?;
    }
    Ok(())
}
