//! The calibration server over real gRPC on loopback: a mock camera's exposure stack streamed in
//! chunks gives the same response as the library call; bad input answers INVALID_ARGUMENT
//! naming the field; health reports SERVING, and NOT_SERVING once shutdown begins.

use glint_e2e::TestServer;
use std::time::Duration;

use glint_calibration::response::{DebevecConfig, ExposureStack, calibrate};
use glint_calibration::server::{Calibration, SERVICE_NAME, response_to_message};
use glint_camera::materials;
use glint_camera::setup::{BinSetup, BinSetupSpec};
use glint_client::calibration::exposure_stack_messages;
use glint_geometry::Part;
use glint_proto::v1;
use glint_proto::v1::calibration_service_client::CalibrationServiceClient;
use glint_server::HealthStatus;
use tokio_stream::StreamExt;
use tonic_health::pb::HealthCheckRequest;
use tonic_health::pb::health_client::HealthClient;

/// A small white-pattern exposure stack of a Zigzag bin from the mock camera.
fn mock_stack() -> glint_camera::exposure::ExposureStack {
    let setup = BinSetup::new(
        &Part::Zigzag.mesh(),
        materials::ground_truth(Part::Zigzag),
        &BinSetupSpec {
            instances: 3,
            seed: 2,
            width_px: 96,
            height_px: 80,
            samples_per_pixel: 2,
        },
    )
    .unwrap();
    let t_w_c = setup.views(1)[0];
    let exposures_s = [0.5e-3, 1e-3, 2e-3, 4e-3, 8e-3, 16e-3, 32e-3];
    setup
        .camera()
        .capture_exposure_stack(&t_w_c, &exposures_s, 5)
        .unwrap()
        .0
}

/// The stack as `CalibrateResponse`'s stream, with `bit_depth` in its header.
fn stream_of(
    stack: &glint_camera::exposure::ExposureStack,
    bit_depth: u32,
) -> Vec<v1::ExposureStackChunk> {
    exposure_stack_messages(&stack.left, &stack.exposures_s, bit_depth)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn calibrate_response_over_grpc_matches_the_library() {
    let server = TestServer::start(
        tonic::service::Routes::new(Calibration.into_service()),
        SERVICE_NAME,
    )
    .await;
    let target = server.target.clone();

    // Default client limits: every message of the stream is under 4 MiB.
    let mut client = CalibrationServiceClient::connect(target.clone())
        .await
        .unwrap();
    let stack = mock_stack();
    let bits = u32::from(stack.bit_depth);
    let reply = client
        .calibrate_response(tokio_stream::iter(stream_of(&stack, bits)))
        .await
        .unwrap()
        .into_inner();
    let direct = calibrate(
        &ExposureStack::new(
            stack.left.clone(),
            stack.exposures_s.clone(),
            stack.bit_depth,
        )
        .unwrap(),
        &DebevecConfig::default(),
    )
    .unwrap();
    let got = reply.response.unwrap();
    let want = response_to_message(&direct);
    // The same deterministic solve on the same bytes: identical numbers.
    assert_eq!(got, want);
    assert_eq!(reply.samples_used as usize, direct.solve.samples);

    // Bad input: the field is named and the code is INVALID_ARGUMENT.
    let bad_depth = client
        .calibrate_response(tokio_stream::iter(stream_of(&stack, 0)))
        .await
        .unwrap_err();
    assert_eq!(bad_depth.code(), tonic::Code::InvalidArgument);
    assert!(
        bad_depth.message().contains("header.bit_depth"),
        "{bad_depth:?}"
    );
    let mut truncated = stream_of(&stack, bits);
    truncated.pop();
    let early_end = client
        .calibrate_response(tokio_stream::iter(truncated))
        .await
        .unwrap_err();
    assert_eq!(early_end.code(), tonic::Code::InvalidArgument);
    assert!(
        early_end.message().contains("header.arrays"),
        "{early_end:?}"
    );
    let mut one = stream_of(&stack, bits);
    one.truncate(2); // the header and one image's chunk, but the header declares seven
    if let Some(v1::exposure_stack_chunk::Part::Header(h)) = &mut one[0].part {
        h.arrays.truncate(1);
        h.exposures_s.truncate(1);
    }
    let single = client
        .calibrate_response(tokio_stream::iter(one))
        .await
        .unwrap_err();
    assert_eq!(single.code(), tonic::Code::InvalidArgument, "{single:?}");
    assert!(single.message().contains("at least 2"), "{single:?}");

    // Health goes NOT_SERVING as soon as shutdown begins (a watcher sees it while the server
    // drains).
    let channel = tonic::transport::Endpoint::from_shared(target.clone())
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut watch = HealthClient::new(channel)
        .watch(HealthCheckRequest {
            service: SERVICE_NAME.into(),
        })
        .await
        .unwrap()
        .into_inner();
    let first = watch.next().await.unwrap().unwrap();
    assert_eq!(first.status(), HealthStatus::Serving);
    let stopped = server.stop();
    let next = tokio::time::timeout(Duration::from_secs(5), watch.next())
        .await
        .expect("a status change within 5 s")
        .unwrap()
        .unwrap();
    assert_eq!(next.status(), HealthStatus::NotServing);
    tokio::time::timeout(Duration::from_secs(5), stopped)
        .await
        .expect("the server stops within its drain bound")
        .unwrap()
        .unwrap();
}

/// A capture reader that reads nothing: the requests below fail validation before any read.
struct NoCaptures;

impl glint_calibration::bsdf_fit::scene_fit::CaptureReader for NoCaptures {
    fn capture(
        &self,
        dir: &std::path::Path,
    ) -> Result<
        glint_calibration::bsdf_fit::scene_fit::Capture,
        glint_calibration::bsdf_fit::scene_fit::CaptureReadError,
    > {
        Err(glint_calibration::bsdf_fit::scene_fit::CaptureReadError(
            format!("{}: not read in this test", dir.display()).into(),
        ))
    }

    fn exposure_stack(
        &self,
        dir: &std::path::Path,
    ) -> Result<ExposureStack, glint_calibration::bsdf_fit::scene_fit::CaptureReadError> {
        self.capture(dir).map(|_| unreachable!())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fit_bsdf_names_the_bad_field() {
    let plain = TestServer::start(
        tonic::service::Routes::new(Calibration.into_service()),
        SERVICE_NAME,
    )
    .await;
    let server = TestServer::start(
        tonic::service::Routes::new(
            Calibration
                .with_capture_reader(std::sync::Arc::new(NoCaptures))
                .into_service(),
        ),
        SERVICE_NAME,
    )
    .await;
    let shipped = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../assets/calibration/zigzag/response.json");
    let response =
        response_to_message(&glint_calibration::response::ResponseTable::load(&shipped).unwrap());
    let dir = tempfile::tempdir().unwrap();
    let good = v1::FitBsdfRequest {
        scene_dir: dir.path().to_str().unwrap().to_owned(),
        response: Some(response),
        views: vec![0],
        iterations: 5,
        starts: vec![0.5],
        known_metallic: None,
    };
    let status = |target: String, request: v1::FitBsdfRequest| async move {
        let mut client = CalibrationServiceClient::connect(target).await.unwrap();
        client.fit_bsdf(request).await.map(|_| ()).unwrap_err()
    };
    // Without a capture reader the server does not fit.
    let s = status(plain.target.clone(), good.clone()).await;
    assert_eq!(s.code(), tonic::Code::Unimplemented, "{s:?}");

    let cases = [
        (
            v1::FitBsdfRequest {
                scene_dir: dir.path().join("missing").to_str().unwrap().to_owned(),
                ..good.clone()
            },
            "scene_dir",
        ),
        (
            v1::FitBsdfRequest {
                scene_dir: String::new(),
                ..good.clone()
            },
            "scene_dir",
        ),
        (
            v1::FitBsdfRequest {
                response: None,
                ..good.clone()
            },
            "response",
        ),
        (
            v1::FitBsdfRequest {
                iterations: 20_000,
                ..good.clone()
            },
            "iterations",
        ),
        (
            v1::FitBsdfRequest {
                starts: vec![0.5, 1.0],
                ..good.clone()
            },
            "starts[1]",
        ),
        (
            v1::FitBsdfRequest {
                known_metallic: Some(1.5),
                ..good.clone()
            },
            "known_metallic",
        ),
        (
            v1::FitBsdfRequest {
                known_metallic: Some(f64::NAN),
                ..good.clone()
            },
            "known_metallic",
        ),
        // An empty folder is no capture.
        (good.clone(), "scene_dir"),
    ];
    for (request, field) in cases {
        let s = status(server.target.clone(), request).await;
        assert_eq!(s.code(), tonic::Code::InvalidArgument, "{s:?}");
        assert!(s.message().starts_with(field), "{field}: {s:?}");
    }
}
