//! `glint`: the command-line entry point of Glint.
//!
//! With no arguments it runs the main job, [`demo`], on embedded defaults.

mod bench;
mod calibrate_cmd;
mod calibration_args;
mod capture_cmd;
mod demo;
mod eval;
mod mesh_cmd;
mod mitsuba_export;
mod preview;
mod security_args;
mod serve_cmd;
mod session_cmd;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "glint",
    version,
    about = "Active 6D pose refinement of shiny parts with a structured-light camera"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// The main job: an active session on a mock bin, run through Glint's gRPC services served
    /// in this process; writes a report (index.html).
    Demo(demo::DemoArgs),
    /// Mock SLI camera: a bin of one part captured from several views.
    Capture(capture_cmd::CaptureArgs),
    /// The paper's experiments: Table I (refinement), Fig. 3 (depth uncertainty).
    #[command(subcommand)]
    Eval(eval::EvalCommand),
    /// Mesh tools: export a part, inspect a mesh file.
    #[command(subcommand)]
    Mesh(mesh_cmd::MeshCommand),
    /// Photometric calibration: camera response (Debevec–Malik).
    #[command(subcommand)]
    Calibrate(calibrate_cmd::CalibrateCommand),
    /// Benchmarks that print tables (and write CSV with --csv).
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Runs a stage's gRPC server (with health and reflection) until SIGTERM or Ctrl-C.
    Serve(serve_cmd::ServeArgs),
    /// Exits 0 only when the server (or --service) answers SERVING: for container probes.
    Healthcheck(serve_cmd::HealthcheckArgs),
    /// A client of an orchestrator: run, list, show or cancel active sessions.
    Session(session_cmd::SessionArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    // Servers log what they serve; the demo and the tools print their own tables, so only
    // warnings unless RUST_LOG says otherwise.
    let default_level = match cli.command {
        Some(Command::Serve(_)) => "info",
        _ => "warn",
    };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| default_level.into()),
        )
        .with_writer(std::io::stderr)
        // Colour codes only for a person at a terminal, not in log files and pipes.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let result = match cli.command {
        None => demo::run(&demo::DemoArgs::default()),
        Some(Command::Demo(args)) => demo::run(&args),
        Some(Command::Capture(args)) => capture_cmd::run(&args),
        Some(Command::Eval(cmd)) => eval::run(cmd),
        Some(Command::Mesh(cmd)) => mesh_cmd::run(cmd),
        Some(Command::Bench(cmd)) => bench::run(cmd),
        Some(Command::Calibrate(cmd)) => calibrate_cmd::run(cmd),
        Some(Command::Serve(args)) => serve_cmd::serve(&args),
        Some(Command::Healthcheck(args)) => serve_cmd::healthcheck(&args),
        Some(Command::Session(args)) => session_cmd::run(&args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
