//! Sessions survive a crash of the orchestrator (`glint serve orchestrator --state DIR`):
//! SIGKILL in the middle of a capture, of a refinement and of a fan-out to the render
//! workers; each time the orchestrator restarts on the same directory, shows the session as
//! INTERRUPTED with every step completed before the kill, and RunSession resumes it after its
//! last completed step. The session ends exactly as one that was never interrupted: the same
//! views, poses and entropies bit for bit, each step once. A damaged state directory stops
//! the server with a message that names what is damaged.

mod common;

use common::argv;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use glint_client::{MockSession, prepare_mock_session};
use glint_geometry::Part;
use glint_orchestrator::session::ViewPolicy;
use glint_proto::v1;
use glint_proto::v1::orchestrator_service_client::OrchestratorServiceClient;

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .unwrap()
}

/// `glint serve orchestrator --state DIR` over the stages of a `glint serve all`, with its
/// debug log (where each stage starts) read line by line.
struct Orchestrator {
    child: Child,
    addr: String,
    log: mpsc::Receiver<String>,
}

impl Orchestrator {
    fn start(stages: &str, state: &std::path::Path) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_glint"))
            .args(["serve", "orchestrator", "--listen", "127.0.0.1:0"])
            .args([
                "--camera",
                stages,
                "--estimation",
                stages,
                "--workers",
                stages,
            ])
            .arg("--state")
            .arg(state)
            .env("RUST_LOG", "info,glint_orchestrator::session=debug")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (tx, log) = mpsc::channel();
        let stderr = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let addr = lines
            .by_ref()
            .map_while(Result::ok)
            .find_map(|l| l.trim().strip_prefix("listening on ").map(str::to_owned))
            .expect("the orchestrator prints its address");
        std::thread::spawn(move || lines.for_each(drop));
        Self { child, addr, log }
    }

    /// Waits for a log line with every one of `words`.
    fn wait_for(&self, words: &[&str]) -> String {
        let deadline = Instant::now() + Duration::from_secs(300);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self
                .log
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("no log line with {words:?} in time"));
            if words.iter().all(|w| line.contains(w)) {
                return line;
            }
        }
    }

    fn kill(mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }
}

impl Drop for Orchestrator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

async fn client(addr: &str) -> OrchestratorServiceClient<tonic::transport::Channel> {
    OrchestratorServiceClient::connect(format!("http://{addr}"))
        .await
        .unwrap()
}

/// RunSession's steps and final session; `None` as the final state when the stream broke
/// (the orchestrator was killed).
async fn run(addr: &str, id: &str) -> (Vec<v1::SessionStep>, Option<v1::Session>) {
    let mut stream = client(addr)
        .await
        .run_session(v1::RunSessionRequest {
            session_id: id.into(),
        })
        .await
        .unwrap()
        .into_inner();
    let mut steps = Vec::new();
    loop {
        match stream.message().await {
            Ok(Some(event)) => match event.event {
                Some(v1::session_event::Event::Step(step)) => steps.push(step),
                Some(v1::session_event::Event::Finished(s)) => return (steps, Some(s)),
                None => {}
            },
            Ok(None) | Err(_) => return (steps, None),
        }
    }
}

#[test]
fn a_session_killed_during_capture_refine_and_fan_out_resumes_with_nothing_lost_or_repeated() {
    let rt = runtime();
    let stages = common::serve(argv("all --listen 127.0.0.1:0", &[]));
    let spec = MockSession {
        part: Part::Zigzag,
        instances: 4,
        policy: ViewPolicy::Nbv,
        max_views: 3,
        entropy_threshold_nats: -1000.0,
        candidates: 8,
        seed: 5,
        width_px: 320,
        height_px: 256,
        samples_per_pixel: 1,
    };
    let prepared = rt
        .block_on(prepare_mock_session(
            &stages.addr,
            &spec,
            None,
            &Default::default(),
        ))
        .unwrap();

    // The reference: the same session, never interrupted, on the stages' own orchestrator.
    let reference = rt.block_on(async {
        let id = client(&stages.addr)
            .await
            .start_session(prepared.request.clone())
            .await
            .unwrap()
            .into_inner()
            .session_id;
        run(&stages.addr, &id).await
    });
    let reference_steps = reference.0;
    assert_eq!(reference_steps.len(), 3, "{:?}", reference.1);
    // Steps compare without their stage times, as printed (NaN, "no value" on the wire,
    // prints equal to itself).
    let comparable = |s: &v1::SessionStep| {
        format!(
            "{:?}",
            v1::SessionStep {
                times: None,
                ..s.clone()
            }
        )
    };

    let state = tempfile::tempdir().unwrap();
    let orchestrator = Orchestrator::start(&stages.addr, state.path());
    let id = rt.block_on(async {
        client(&orchestrator.addr)
            .await
            .start_session(prepared.request.clone())
            .await
            .unwrap()
            .into_inner()
            .session_id
    });

    // Kill points, each in step 1, after step 0 completed: its capture, then (the capture
    // kept) its refinement, then its fan-out to the render workers.
    let mut orchestrator = Some(orchestrator);
    for (kill_point, completed) in [("capturing", 1), ("refining", 1), ("predicting", 1)] {
        let o = orchestrator.take().unwrap();
        let addr = o.addr.clone();
        let id_run = id.clone();
        let runner = rt.spawn(async move { run(&addr, &id_run).await });
        o.wait_for(&[kill_point, "step=1"]);
        o.kill();
        let (_, finished) = rt.block_on(runner).unwrap();
        assert!(
            finished.is_none(),
            "killed at {kill_point}: the stream broke"
        );

        let restarted = Orchestrator::start(&stages.addr, state.path());
        let session = rt.block_on(async {
            client(&restarted.addr)
                .await
                .get_session(v1::GetSessionRequest {
                    session_id: id.clone(),
                })
                .await
                .unwrap()
                .into_inner()
        });
        assert_eq!(
            session.state,
            v1::SessionState::Interrupted as i32,
            "after the kill at {kill_point}"
        );
        assert_eq!(
            session.steps.len(),
            completed,
            "after the kill at {kill_point}"
        );
        assert_eq!(
            comparable(&session.steps[0]),
            comparable(&reference_steps[0])
        );
        orchestrator = Some(restarted);
    }

    // The last restart runs it to its end.
    let o = orchestrator.take().unwrap();
    let (steps, finished) = rt.block_on(run(&o.addr, &id));
    let finished = finished.expect("the resumed session finishes");
    assert_eq!(
        finished.state,
        v1::SessionState::BudgetSpent as i32,
        "{}",
        finished.error
    );
    // Replayed step 0, then steps 1 and 2: each once, equal to the uninterrupted session's
    // (the captures are seeded per step, the predictions per candidate).
    assert_eq!(
        steps.iter().map(comparable).collect::<Vec<_>>(),
        reference_steps.iter().map(comparable).collect::<Vec<_>>()
    );
    assert_eq!(finished.steps.len(), 3);
    // Step 1's capture was taken before the kill in its refinement and reused after it.
    let capture_ms: Vec<f64> = steps
        .iter()
        .map(|s| s.times.as_ref().map_or(-1.0, |t| t.capture_ms))
        .collect();
    assert!(
        capture_ms[1] == 0.0,
        "step 1 was captured again: {capture_ms:?}"
    );
    // Three captures and one mesh in the blob directory: nothing kept twice.
    let blobs = walk(&state.path().join("blobs"));
    assert_eq!(blobs.len(), 4, "{blobs:?}");
    o.kill();
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files.extend(walk(&path));
        } else {
            files.push(path);
        }
    }
    files
}

#[test]
fn a_damaged_state_directory_stops_the_server_with_what_to_do() {
    let state = tempfile::tempdir().unwrap();
    std::fs::write(state.path().join("sessions.redb"), b"not a database at all").unwrap();
    let out = common::glint(argv(
        "serve orchestrator --listen 127.0.0.1:0 --camera 127.0.0.1:9 \
        --estimation 127.0.0.1:9 --workers 127.0.0.1:9 --state {}",
        &[state.path().to_str().unwrap()],
    ));
    assert!(!out.status.success());
    let said = common::printed(&out);
    assert!(said.contains("sessions.redb"), "{said}");
    assert!(said.contains("move the state directory aside"), "{said}");
}
