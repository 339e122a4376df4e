//! Active sessions end to end over real gRPC on loopback: `glint serve all` as a process,
//! driven by Glint's Rust client (`glint_client`, the code `glint session run` and the demo
//! run). A session converges and its pose error falls; StartSession and RunSession name the
//! field of bad input; health turns NOT_SERVING when the server is told to stop.

mod common;

use common::argv;

use std::time::Duration;

use glint_client::{MockSession, run_mock_session};
use glint_geometry::Part;
use glint_orchestrator::session::ViewPolicy;
use glint_proto::v1;
use glint_proto::v1::orchestrator_service_client::OrchestratorServiceClient;
use tonic::Code;

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .unwrap()
}

/// A small bin (debug build, 2 cores): 640×512 px, 1 sample per pixel.
fn small_session(policy: ViewPolicy, max_views: u32, entropy_threshold_nats: f64) -> MockSession {
    MockSession {
        part: Part::Zigzag,
        instances: 4,
        policy,
        max_views,
        entropy_threshold_nats,
        candidates: 12,
        seed: 3,
        width_px: 640,
        height_px: 512,
        samples_per_pixel: 1,
    }
}

/// Runs `spec` on the `glint serve all` at `addr`, with the shipped calibration, and checks
/// that the session did not fail.
fn session_on(addr: &str, spec: &MockSession) -> glint_client::RunOutcome {
    let outcome = runtime()
        .block_on(run_mock_session(
            addr,
            addr,
            spec,
            None,
            &Default::default(),
            |_, _| {},
        ))
        .unwrap();
    assert!(
        outcome.session.error.is_empty(),
        "{}",
        outcome.session.error
    );
    outcome
}

#[test]
fn a_session_over_grpc_converges_and_its_pose_error_falls() {
    let server = common::serve(argv("all --listen 127.0.0.1:0", &[]));
    // Stop once the pose is known to 0.4 mm and 0.4° per axis: a robot's placing tolerance,
    // not a number read off a run. The session's covariance is the shipped error model's
    // (the Zigzag's per-view bias is 0.3–0.4 mm, 0.5–0.6°), so one view cannot claim it and
    // a few views can.
    let threshold = glint_estimation::nbv::entropy_of_axis_sigmas(0.4e-3, 0.4f64.to_radians());
    let spec = small_session(ViewPolicy::Nbv, 6, threshold);
    let outcome = session_on(&server.addr, &spec);
    assert_eq!(
        outcome.session.state,
        v1::SessionState::Converged as i32,
        "entropies {:?}",
        outcome
            .steps
            .iter()
            .map(|s| s.entropy_nats)
            .collect::<Vec<_>>()
    );
    let last = outcome.steps.last().unwrap();
    assert!(last.entropy_nats < threshold);
    // Only the last step is below the threshold (the session stops there).
    for step in &outcome.steps[..outcome.steps.len() - 1] {
        assert!(step.entropy_nats >= threshold);
    }
    // Every view after the first was chosen by prediction, among views not taken.
    let mut taken = Vec::new();
    for step in &outcome.steps {
        assert!(
            !taken.contains(&step.view),
            "view {} taken twice",
            step.view
        );
        taken.push(step.view);
        assert_eq!(
            step.candidate_entropies_nats.is_empty(),
            step.next_view.is_none()
        );
    }
    for step in &outcome.steps[1..] {
        assert!(step.predicted_entropy_nats.is_finite());
    }
    // The pose error falls from the detector's (3.1 mm / 3.4° off on this bin) in translation.
    // A pose converged to 0.4 mm / 0.4° per axis lies within a few of those σ of the truth
    // when the covariance is honest, so 2 mm bounds the translation with margin. Rotation is held to the paper's 5° test only:
    // at 640×512 and 1 sample per pixel the Zigzag's 20 mm leaves few pixels, and on this bin
    // the refiner's back-face test (which drops the grazing faces' points) ends at 4.1°, from
    // 3.4°.
    let first = &outcome.initial_deviation;
    let final_error = outcome.deviations.last().unwrap();
    assert!(
        final_error.translation_mm() < 2.0,
        "{} mm",
        final_error.translation_mm()
    );
    assert!(final_error.translation_mm() < first.translation_mm());
    assert!(
        final_error.is_correct(&glint_geometry::pose_deviation::CorrectThreshold::MM5_DEG5),
        "{final_error:?} from {first:?}; per step {:?}",
        outcome.deviations
    );

    // The same server takes the next session on a mock set up anew at another resolution.
    let again = MockSession {
        width_px: 320,
        height_px: 256,
        ..small_session(ViewPolicy::MaxDistance, 1, 0.0)
    };
    let outcome = session_on(&server.addr, &again);
    assert_eq!(outcome.steps.len(), 1);
}

/// The INVALID_ARGUMENT (or other) status `request` gets, with its message.
async fn start(
    client: &mut OrchestratorServiceClient<glint_client::AuthChannel>,
    request: v1::StartSessionRequest,
) -> tonic::Status {
    client
        .start_session(request)
        .await
        .expect_err("the request is refused")
}

#[test]
fn bad_session_requests_are_refused_naming_the_field() {
    let server = common::serve(argv("all --listen 127.0.0.1:0", &[]));
    runtime().block_on(async {
        let mut client = OrchestratorServiceClient::new(
            glint_client::channel(&server.addr, &Default::default())
                .await
                .unwrap(),
        );
        let zigzag = v1::PartSpec {
            part: Some(v1::part_spec::Part::Builtin("zigzag".into())),
        };
        let pose = |x: f64, q: [f64; 4]| v1::Pose {
            translation_m: Some(v1::Vector3 { x, y: 0.0, z: 0.5 }),
            rotation: Some(v1::UnitQuaternion {
                w: q[0],
                x: q[1],
                y: q[2],
                z: q[3],
            }),
            ..Default::default()
        };
        let good = v1::StartSessionRequest {
            part: Some(zigzag),
            initial_t_w_o: Some(pose(0.0, [1.0, 0.0, 0.0, 0.0])),
            policy: v1::ViewPolicy::MaxDistance as i32,
            max_views: 3,
            ..Default::default()
        };
        let cases = [
            (
                v1::StartSessionRequest {
                    initial_t_w_o: Some(pose(f64::NAN, [1.0, 0.0, 0.0, 0.0])),
                    ..good.clone()
                },
                "initial_t_w_o.translation_m.x",
            ),
            (
                v1::StartSessionRequest {
                    initial_t_w_o: Some(pose(0.0, [0.5, 0.0, 0.0, 0.0])),
                    ..good.clone()
                },
                "initial_t_w_o.rotation",
            ),
            (
                v1::StartSessionRequest {
                    candidates_t_w_c: vec![
                        pose(0.0, [1.0, 0.0, 0.0, 0.0]),
                        pose(f64::INFINITY, [1.0, 0.0, 0.0, 0.0]),
                    ],
                    ..good.clone()
                },
                "candidates_t_w_c[1].translation_m.x",
            ),
            (
                v1::StartSessionRequest {
                    max_views: 0,
                    ..good.clone()
                },
                "max_views",
            ),
            (
                v1::StartSessionRequest {
                    part: Some(v1::PartSpec {
                        part: Some(v1::part_spec::Part::Builtin("teapot".into())),
                    }),
                    ..good.clone()
                },
                "part.builtin",
            ),
            (
                v1::StartSessionRequest {
                    policy: 99,
                    ..good.clone()
                },
                "policy",
            ),
            (
                v1::StartSessionRequest {
                    entropy_threshold_nats: f64::NAN,
                    ..good.clone()
                },
                "entropy_threshold_nats",
            ),
            (
                v1::StartSessionRequest {
                    radiometric_scale: 2.0,
                    ..good.clone()
                },
                "material",
            ),
        ];
        for (request, field) in cases {
            let status = start(&mut client, request).await;
            assert_eq!(status.code(), Code::InvalidArgument, "{field}: {status:?}");
            assert!(
                status.message().starts_with(field),
                "{field}: {:?}",
                status.message()
            );
        }
        // No mock scene is set up yet: the camera's candidate views cannot be had.
        let status = start(&mut client, good.clone()).await;
        assert_eq!(status.code(), Code::FailedPrecondition, "{status:?}");
        // An unknown session is NOT_FOUND, naming it.
        let status = client
            .run_session(v1::RunSessionRequest {
                session_id: "s999999".into(),
            })
            .await
            .expect_err("no such session");
        assert_eq!(status.code(), Code::NotFound);
        assert!(status.message().contains("s999999"), "{status:?}");
        // A request over gRPC's 4 MiB message limit (a 5 MiB "mesh") is refused whole before
        // it is decoded — tonic answers OUT_OF_RANGE saying the limit — and the server goes
        // on serving.
        let oversized = v1::StartSessionRequest {
            part: Some(v1::PartSpec {
                part: Some(v1::part_spec::Part::Mesh(v1::MeshFile {
                    data: vec![b' '; 5 << 20],
                    ..Default::default()
                })),
            }),
            ..good.clone()
        };
        let status = start(&mut client, oversized).await;
        assert_eq!(status.code(), Code::OutOfRange, "{status:?}");
        assert!(status.message().contains("4194304"), "{status:?}");
        let status = start(&mut client, good.clone()).await;
        assert_eq!(status.code(), Code::FailedPrecondition, "{status:?}");
    });
}

#[test]
fn serve_all_turns_not_serving_when_told_to_stop() {
    use tonic_health::pb::health_check_response::ServingStatus;
    use tonic_health::pb::{HealthCheckRequest, health_client::HealthClient};
    let mut server = common::serve(argv("all --listen 127.0.0.1:0", &[]));
    runtime().block_on(async {
        let channel = glint_client::channel(&server.addr, &Default::default())
            .await
            .unwrap();
        let mut watch = HealthClient::new(channel)
            .watch(HealthCheckRequest {
                service: "glint.v1.OrchestratorService".into(),
            })
            .await
            .unwrap()
            .into_inner();
        let first = watch.message().await.unwrap().unwrap();
        assert_eq!(first.status(), ServingStatus::Serving);
        let pid = server.child.id().to_string();
        let killed = std::process::Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap();
        assert!(killed.success());
        let next = tokio::time::timeout(Duration::from_secs(10), watch.message())
            .await
            .expect("health changes within the bound")
            .unwrap()
            .unwrap();
        assert_eq!(next.status(), ServingStatus::NotServing);
    });
    // And the process ends cleanly within its drain bound (10 s by default).
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(status) = server.child.try_wait().unwrap() {
            break status;
        }
        assert!(started.elapsed() < Duration::from_secs(20), "still running");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success(), "{status:?}");
}

#[test]
fn sessions_beyond_the_orchestrators_limit_wait_their_turn_and_all_complete() {
    // 6 clients at once against a `glint serve all` that runs 2 sessions at a time: the
    // others are refused with RESOURCE_EXHAUSTED and a retry hint, wait, and complete. Its
    // stage services take one call at a time: the two running sessions' stage calls are
    // refused when they meet, and the orchestrator waits the hint and calls again.
    let out = common::glint(argv(
        "bench load --sessions 6 --concurrency 6 --max-running 2 \
        --max-concurrent-calls 1 --policy max-distance --timeout-s 300",
        &[],
    ));
    let said = common::printed(&out);
    assert!(out.status.success(), "{said}");
    // The table's row: | sessions | clients | max running | completed | failed | refused | …
    let row: Vec<&str> = said
        .lines()
        .find(|l| l.starts_with("| 6 | 6 | 2 |"))
        .unwrap_or_else(|| panic!("no result row in {said}"))
        .split('|')
        .map(str::trim)
        .collect();
    assert_eq!(row[4], "6", "completed: {said}");
    assert_eq!(row[5], "0", "failed: {said}");
    let refused: u32 = row[6].parse().unwrap();
    assert!(
        refused > 0,
        "6 sessions on 2 places must see refusals: {said}"
    );
}

#[test]
fn the_demo_runs_a_session_through_its_servers_and_writes_its_report() {
    let out = tempfile::tempdir().unwrap();
    let dir = out.path().join("report");
    // A small bin at a quarter of the resolution, with a quick first calibration.
    let demo = |more: &str| {
        let mut args = argv(
            "demo --out {} --resolution 320x256 --spp 1 --candidates 6 --instances 3",
            &[dir.to_str().unwrap()],
        );
        args.extend(argv(more, &[]));
        common::glint(&args)
    };
    let run = demo("--max-views 2 --calibration-spp 4 --calibration-iterations 10");
    let said = common::printed(&run);
    assert!(run.status.success(), "{said}");
    assert!(said.contains("Report:"), "{said}");
    // The first run calibrated the part through the calibration service and cached it.
    assert!(said.contains("Calibration (first run only)"), "{said}");
    let cache = dir.join("calibration").join("zigzag");
    let material =
        glint_calibration::material_file::MaterialFile::load(&cache.join("material.json")).unwrap();
    assert!(material.radiometric_scale().is_some(), "{material:?}");
    glint_calibration::response::ResponseTable::load(&cache.join("response.json")).unwrap();
    for file in ["index.html", "session.png", "steps.txt"] {
        assert!(dir.join(file).is_file(), "{file} missing: {said}");
    }
    // The NBV policy's report shows the σ̌_z map predicted for the view chosen after step 0.
    let maps = std::fs::read_dir(dir.join("captures"))
        .unwrap()
        .filter_map(Result::ok)
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with("step00_next_view_sigma")
        })
        .count();
    assert!(maps >= 1, "no predicted map in the report: {said}");

    // The next run reads the cache instead of calibrating again.
    let again = demo("--max-views 1");
    let said = common::printed(&again);
    assert!(again.status.success(), "{said}");
    assert!(said.contains("Calibration: cached in"), "{said}");
    assert!(!said.contains("first run only"), "{said}");
}
