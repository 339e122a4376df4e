//! Bounded load over real gRPC: a stage server at its bound of calls at work refuses the next
//! call at once with RESOURCE_EXHAUSTED and a retry pushback, keeps answering health checks,
//! and admits calls again as soon as a place is free.

use std::time::{Duration, Instant};

use glint_calibration::server::{Calibration, SERVICE_NAME};
use glint_e2e::TestServer;
use glint_proto::v1;
use glint_proto::v1::calibration_service_client::CalibrationServiceClient;
use glint_server::HealthStatus;
use glint_server::load::{CallLimits, retry_pushback};
use glint_server::security::{ClientSecurity, ServerSecurity};
use tokio_stream::wrappers::ReceiverStream;

/// The header of a stack of two exposures that declares no images, `bit_depth` bits.
fn header_only(bit_depth: u32) -> v1::ExposureStackChunk {
    v1::ExposureStackChunk {
        part: Some(v1::exposure_stack_chunk::Part::Header(
            v1::ExposureStackHeader {
                exposures_s: vec![1e-3, 2e-3],
                arrays: Vec::new(),
                bit_depth,
                lambda: 0.0,
                samples: 0,
            },
        )),
    }
}

/// A header of 0 bits: refused at once as INVALID_ARGUMENT by an admitted call.
fn bad_header() -> v1::ExposureStackChunk {
    header_only(0)
}

type HeldCall =
    tokio::task::JoinHandle<Result<tonic::Response<v1::CalibrateResponseResponse>, tonic::Status>>;

/// A call that stays at work: its request stream (a valid header, no images) stays open until
/// the returned sender is dropped; then it ends, refused for its content.
async fn hold_a_place(
    client: &CalibrationServiceClient<tonic::transport::Channel>,
) -> (tokio::sync::mpsc::Sender<v1::ExposureStackChunk>, HeldCall) {
    let (hold, open_stream) = tokio::sync::mpsc::channel(4);
    // Valid (8 bits), so the call reads on until its stream ends.
    let header = header_only(8);
    hold.send(header).await.unwrap();
    let mut client = client.clone();
    let held = tokio::spawn(async move {
        client
            .calibrate_response(ReceiverStream::new(open_stream))
            .await
    });
    (hold, held)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_at_its_bound_refuses_at_once_and_admits_again_when_a_place_frees() {
    let mut limits = CallLimits::each(&[SERVICE_NAME], 1, &[]);
    limits.retry_after = Duration::from_millis(250);
    let server = TestServer::start_with(
        tonic::service::Routes::new(Calibration.into_service()),
        &[SERVICE_NAME],
        ServerSecurity::default(),
        &ClientSecurity::default(),
        limits,
    )
    .await;
    let mut client = CalibrationServiceClient::connect(server.target.clone())
        .await
        .unwrap();

    // Until the held call is admitted, a quick call may still get in (and is refused for its
    // content) — or take the place first, and the held call is refused instead: then it is
    // made again. Once it is at work, the next call is refused for load.
    let started = Instant::now();
    let (mut hold, mut held) = hold_a_place(&client).await;
    let refused = loop {
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "the held call was never admitted"
        );
        if held.is_finished() {
            (hold, held) = hold_a_place(&client).await;
        }
        let status = client
            .calibrate_response(tokio_stream::iter([bad_header()]))
            .await
            .unwrap_err();
        match status.code() {
            tonic::Code::ResourceExhausted => break status,
            tonic::Code::InvalidArgument => tokio::time::sleep(Duration::from_millis(20)).await,
            other => panic!("unexpected {other:?}: {status:?}"),
        }
    };
    assert!(refused.message().contains(SERVICE_NAME), "{refused:?}");
    assert_eq!(retry_pushback(&refused), Some(Duration::from_millis(250)));
    let refused_in = Instant::now();
    let again = client
        .calibrate_response(tokio_stream::iter([bad_header()]))
        .await
        .unwrap_err();
    assert_eq!(again.code(), tonic::Code::ResourceExhausted);
    assert!(
        refused_in.elapsed() < Duration::from_secs(2),
        "a refusal took {:?}: it must not wait for a place",
        refused_in.elapsed()
    );

    // Health is never bounded.
    let status = glint_server::healthcheck(
        &server.target,
        SERVICE_NAME,
        Duration::from_secs(5),
        &ClientSecurity::default(),
    )
    .await
    .unwrap();
    assert_eq!(status, HealthStatus::Serving);

    // The held call ends (its stream closes with no images: refused for its content) and
    // frees its place: the next call is admitted and judged on its content.
    drop(hold);
    let ended = held.await.unwrap().unwrap_err();
    assert_eq!(ended.code(), tonic::Code::InvalidArgument, "{ended:?}");
    let admitted = client
        .calibrate_response(tokio_stream::iter([bad_header()]))
        .await
        .unwrap_err();
    assert_eq!(
        admitted.code(),
        tonic::Code::InvalidArgument,
        "{admitted:?}"
    );
    assert!(
        admitted.message().contains("header.bit_depth"),
        "{admitted:?}"
    );
    server.stop().await.unwrap().unwrap();
}
