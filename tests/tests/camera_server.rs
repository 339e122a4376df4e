//! The mock camera over real gRPC on loopback:
//! (a) a full 1280×1024 capture through `Capture`, read by a tonic client with default limits,
//!     is bit for bit the library's capture of the same set-up, pose and seed;
//! (b) `RemoteCamera` (the orchestrator's camera stage over gRPC) gives exactly what the
//!     in-process `MockCamera` gives: rig, depth, every shot's images, noise shots; the scene's
//!     mesh hash, ground truth, candidate views and an exposure stack agree with the library;
//! (c) bad input answers INVALID_ARGUMENT naming the field, and a camera without a scene
//!     FAILED_PRECONDITION.

use std::time::Duration;

use glint_camera::materials;
use glint_camera::server::{
    Camera, DEPTH_ARRAY, NOISE_ARRAYS, SERVICE_NAMES, exposure_array_name, left_array_name,
    right_array_name,
};
use glint_camera::setup::{BinSetup, BinSetupSpec};
use glint_e2e::TestServer;
use glint_geometry::Part;
use glint_geometry::image::{DepthMap, Image};
use glint_orchestrator::local::MockCamera;
use glint_orchestrator::remote::Endpoint;
use glint_orchestrator::remote::camera::RemoteCamera;
use glint_orchestrator::stages::{CameraStage, StageError};
use glint_proto::chunks::{ArrayAssembler, AssembledArray};
use glint_proto::v1;
use glint_proto::v1::camera_service_client::CameraServiceClient;
use glint_proto::v1::mock_camera_service_client::MockCameraServiceClient;
use nalgebra::{Isometry3, Point3, Vector3};
use tonic::Code;
use tonic::transport::Channel;

const PART: Part = Part::Zigzag;

fn spec(instances: u32, width_px: u32, height_px: u32) -> BinSetupSpec {
    BinSetupSpec {
        instances,
        seed: 4,
        width_px,
        height_px,
        samples_per_pixel: 1,
    }
}

fn scene_request(spec: &BinSetupSpec) -> v1::SetUpSceneRequest {
    v1::SetUpSceneRequest {
        part: Some(v1::PartSpec {
            part: Some(v1::part_spec::Part::Builtin(PART.name().into())),
        }),
        instances: spec.instances,
        material: None,
        seed: spec.seed,
        width_px: spec.width_px,
        height_px: spec.height_px,
        samples_per_pixel: spec.samples_per_pixel,
    }
}

/// The set-up the server builds for `spec`, in-process.
fn library_setup(spec: &BinSetupSpec) -> BinSetup {
    BinSetup::new(&PART.mesh(), materials::ground_truth(PART), spec).unwrap()
}

async fn start_camera() -> TestServer {
    TestServer::start_services(Camera::new().into_routes(), &SERVICE_NAMES).await
}

async fn clients(
    server: &TestServer,
) -> (
    CameraServiceClient<Channel>,
    MockCameraServiceClient<Channel>,
) {
    // Default settings: 4 MiB receive limit.
    let channel = tonic::transport::Endpoint::from_shared(server.target.clone())
        .unwrap()
        .connect()
        .await
        .unwrap();
    (
        CameraServiceClient::new(channel.clone()),
        MockCameraServiceClient::new(channel),
    )
}

/// `t` after the wire's round trip (the receiver renormalises the quaternion, which may move
/// its last bits), repeated until it no longer changes, so that the server and the library
/// render the very same pose.
fn wire_exact(t: Isometry3<f64>) -> Isometry3<f64> {
    let mut t = t;
    for _ in 0..8 {
        let back = Isometry3::try_from(&v1::Pose::from(&t)).unwrap();
        if back == t {
            return t;
        }
        t = back;
    }
    panic!("the pose's wire form does not settle");
}

fn same_depth(a: &DepthMap, b: &DepthMap) -> bool {
    let bits =
        |d: &DepthMap| -> Vec<u32> { d.depth_m.data().iter().map(|z| z.to_bits()).collect() };
    (a.depth_m.width(), a.depth_m.height()) == (b.depth_m.width(), b.depth_m.height())
        && bits(a) == bits(b)
}

/// Reads a capture stream with a plain client, as any user would.
async fn read_stream(
    mut stream: tonic::Streaming<v1::CaptureChunk>,
) -> (v1::CaptureHeader, Vec<(String, AssembledArray)>, usize) {
    use v1::capture_chunk::Part;
    let Some(v1::CaptureChunk {
        part: Some(Part::Header(header)),
    }) = stream.message().await.unwrap()
    else {
        panic!("a capture stream starts with its header");
    };
    let mut assembler = ArrayAssembler::new(header.arrays.clone(), "arrays").unwrap();
    let mut chunks = 0;
    while let Some(message) = stream.message().await.unwrap() {
        let Some(Part::Chunk(chunk)) = message.part else {
            panic!("only chunks after the header");
        };
        assert!(chunk.data.len() <= glint_proto::chunks::CHUNK_BYTES);
        assembler.push(chunk).unwrap();
        chunks += 1;
    }
    (header, assembler.finish().unwrap(), chunks)
}

fn image_of(array: &AssembledArray) -> Image<u16> {
    let AssembledArray::Image(msg) = array else {
        panic!("an image");
    };
    assert_eq!(msg.pixel_space, v1::PixelSpace::CameraResponse as i32);
    Image::<u16>::try_from(msg).unwrap()
}

/// (a) A full-resolution capture through the stream is the library's, bit for bit.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_resolution_capture_streams_bit_identical_to_the_library() {
    let spec = spec(2, 1280, 1024);
    let server = start_camera().await;
    let (mut camera, mut mock) = clients(&server).await;
    mock.set_up_scene(scene_request(&spec)).await.unwrap();

    let setup = library_setup(&spec);
    let t_w_c = wire_exact(setup.views(3)[1]);
    let seed = 77;
    let stream = camera
        .capture(v1::CaptureRequest {
            t_w_c: Some(v1::Pose::from(&t_w_c)),
            seed,
            noise_shots: true,
        })
        .await
        .unwrap()
        .into_inner();
    let (header, arrays, chunks) = read_stream(stream).await;

    let (capture, noise, _truth) = tokio::task::spawn_blocking(move || {
        setup
            .camera()
            .capture_with_noise_shots(&t_w_c, seed, true)
            .unwrap()
    })
    .await
    .unwrap();
    let shots = capture.shots();
    assert!(shots >= 1);
    let mut names: Vec<String> = (0..shots).map(left_array_name).collect();
    names.extend((0..shots).map(right_array_name));
    names.push(DEPTH_ARRAY.into());
    names.extend(NOISE_ARRAYS.map(String::from));
    assert_eq!(
        arrays.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>(),
        names
    );
    // 2K + 2 images of 2.5 MiB (3 chunks each) and a 5 MiB depth map (5 chunks).
    assert_eq!(chunks, (2 * shots + 2) * 3 + 5);
    for (side, images) in [capture.shot_images(0), capture.shot_images(1)]
        .into_iter()
        .enumerate()
    {
        for (k, expected) in images.into_iter().enumerate() {
            let got = image_of(&arrays[side * shots + k].1);
            assert_eq!((got.width(), got.height()), (1280, 1024));
            assert!(got == *expected, "{} differs", arrays[side * shots + k].0);
        }
    }
    let AssembledArray::Depth(depth) = &arrays[2 * shots].1 else {
        panic!("depth after the images");
    };
    assert!(same_depth(
        &DepthMap::try_from(depth).unwrap(),
        &capture.depth
    ));
    let noise = noise.unwrap();
    for (i, expected) in noise.iter().enumerate() {
        assert!(image_of(&arrays[2 * shots + 1 + i].1) == *expected);
    }
    assert_eq!(
        Isometry3::try_from(header.t_w_c.as_ref().unwrap()).unwrap(),
        t_w_c
    );
    assert_eq!(header.max_dn, 255);
    assert!(header.capture_ms > 0.0);
    server.stop().await.unwrap().unwrap();
}

/// (b) The orchestrator's camera stage over gRPC is the in-process one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn remote_camera_captures_what_the_mock_camera_captures() {
    let spec = spec(3, 320, 256);
    let server = start_camera().await;
    let (mut camera, mut mock) = clients(&server).await;
    let set_up = mock
        .set_up_scene(scene_request(&spec))
        .await
        .unwrap()
        .into_inner();
    let setup = library_setup(&spec);
    let mesh = set_up.mesh.unwrap();
    assert_eq!(mesh.sha256_hex, PART.mesh().content_sha256_hex());
    assert_eq!(mesh.name, PART.name());
    assert_eq!(set_up.instances, 3);

    // Ground truth (evaluation only) and candidate views: the library's, to rounding.
    let truth = mock
        .get_ground_truth(v1::GetGroundTruthRequest::default())
        .await
        .unwrap()
        .into_inner();
    let close = |a: &Isometry3<f64>, b: &Isometry3<f64>| {
        (a.translation.vector - b.translation.vector).norm() < 1e-12
            && a.rotation.angle_to(&b.rotation) < 1e-9
    };
    assert_eq!(truth.t_w_o.len(), setup.poses.len());
    for (pose, expected) in truth.t_w_o.iter().zip(&setup.poses) {
        assert!(close(&Isometry3::try_from(pose).unwrap(), expected));
    }
    let views = camera
        .list_candidate_views(v1::ListCandidateViewsRequest {
            count: 6,
            distance_m: 0.0,
            cap_half_angle_deg: 0.0,
            target_w_m: None,
        })
        .await
        .unwrap()
        .into_inner()
        .t_w_c;
    assert_eq!(views.len(), 6);
    for (pose, expected) in views.iter().zip(&setup.views(6)) {
        assert!(close(&Isometry3::try_from(pose).unwrap(), expected));
    }

    // An exposure stack: the library's.
    let t_w_c = wire_exact(setup.views(6)[2]);
    let exposures_s = vec![2e-3, 8e-3];
    let stream = camera
        .capture_exposure_stack(v1::CaptureExposureStackRequest {
            t_w_c: Some(v1::Pose::from(&t_w_c)),
            exposures_s: exposures_s.clone(),
            seed: 3,
        })
        .await
        .unwrap()
        .into_inner();
    let (header, arrays, _) = read_stream(stream).await;
    assert_eq!(header.exposures_s, exposures_s);
    let (stack, _) = setup
        .camera()
        .capture_exposure_stack(&t_w_c, &exposures_s, 3)
        .unwrap();
    assert_eq!(arrays.len(), 2);
    for (k, (name, array)) in arrays.iter().enumerate() {
        assert_eq!(*name, exposure_array_name(k));
        assert!(image_of(array) == stack.left[k]);
    }

    // The camera stage: RemoteCamera against MockCamera on the same set-up.
    let remote = RemoteCamera::new(
        tokio::runtime::Handle::current(),
        Endpoint::new(&server.target, Duration::from_secs(120)),
    )
    .unwrap();
    let local = MockCamera { setup };
    let (remote_view, local_view, remote_info, local_info, bad) =
        tokio::task::spawn_blocking(move || {
            let remote_info = remote.info().unwrap();
            let remote_view = remote.capture(&t_w_c, 9).unwrap();
            let local_view = local.capture(&t_w_c, 9).unwrap();
            let mut nan = t_w_c;
            nan.translation.vector.x = f64::NAN;
            let bad = remote.capture(&nan, 9).unwrap_err();
            (
                remote_view,
                local_view,
                remote_info,
                local.info().unwrap(),
                bad,
            )
        })
        .await
        .unwrap();
    assert_eq!(remote_info, local_info);
    let (r, l) = (&remote_view.measurement, &local_view.measurement);
    assert_eq!(r.t_w_c, l.t_w_c);
    assert_eq!(r.stereo, l.stereo);
    assert_eq!(r.max_dn, l.max_dn);
    assert_eq!(r.left.len(), local_info.shots as usize);
    assert!(r.left == l.left, "left pattern images differ");
    assert!(r.right == l.right, "right pattern images differ");
    assert!(same_depth(&r.depth, &l.depth), "depth differs");
    assert!(l.noise_shots.is_some());
    assert!(r.noise_shots == l.noise_shots, "noise shots differ");
    let StageError::InvalidArgument { field, .. } = bad else {
        panic!("a NaN pose is the caller's error: {bad:?}");
    };
    assert_eq!(field, "t_w_c.translation_m.x");
    server.stop().await.unwrap().unwrap();
}

fn assert_invalid(status: &tonic::Status, field: &str) {
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(
        status.message().starts_with(&format!("{field}: ")),
        "{field}: {}",
        status.message()
    );
}

/// (c) Bad input names its field; a camera without a scene asks for one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_requests_name_the_field_and_a_sceneless_camera_asks_for_a_scene() {
    let server = start_camera().await;
    let (mut camera, mut mock) = clients(&server).await;
    let spec = spec(2, 64, 48);
    let setup = library_setup(&spec);
    let good = wire_exact(setup.views(1)[0]);
    let capture = |t_w_c: v1::Pose| v1::CaptureRequest {
        t_w_c: Some(t_w_c),
        seed: 1,
        noise_shots: false,
    };

    // No scene yet.
    for status in [
        camera
            .capture(capture(v1::Pose::from(&good)))
            .await
            .unwrap_err(),
        camera.get_rig(v1::GetRigRequest {}).await.unwrap_err(),
        mock.get_ground_truth(v1::GetGroundTruthRequest::default())
            .await
            .unwrap_err(),
    ] {
        assert_eq!(status.code(), Code::FailedPrecondition, "{status:?}");
        assert!(
            status.message().contains("SetUpScene"),
            "{}",
            status.message()
        );
    }

    // Bad scenes.
    let mut unknown = scene_request(&spec);
    unknown.part = Some(v1::PartSpec {
        part: Some(v1::part_spec::Part::Builtin("sprocket".into())),
    });
    let status = mock.set_up_scene(unknown).await.unwrap_err();
    assert_invalid(&status, "part.builtin");
    for part in Part::ALL {
        assert!(
            status.message().contains(part.name()),
            "{}",
            status.message()
        );
    }
    let status = mock
        .set_up_scene(v1::SetUpSceneRequest {
            instances: 0,
            ..scene_request(&spec)
        })
        .await
        .unwrap_err();
    assert_invalid(&status, "instances");

    mock.set_up_scene(scene_request(&spec)).await.unwrap();
    camera.get_rig(v1::GetRigRequest {}).await.unwrap();

    // Bad poses.
    let mut nan = v1::Pose::from(&good);
    nan.translation_m.as_mut().unwrap().x = f64::NAN;
    assert_invalid(
        &camera.capture(capture(nan)).await.unwrap_err(),
        "t_w_c.translation_m.x",
    );
    let mut long = v1::Pose::from(&good);
    long.rotation.as_mut().unwrap().w *= 1.5;
    assert_invalid(
        &camera.capture(capture(long)).await.unwrap_err(),
        "t_w_c.rotation",
    );
    let missing = v1::CaptureRequest {
        t_w_c: None,
        ..capture(v1::Pose::from(&good))
    };
    assert_invalid(&camera.capture(missing).await.unwrap_err(), "t_w_c");
    // Half a metre above the bin, looking up.
    let away = Isometry3::face_towards(
        &Point3::new(0.0, 0.0, 0.5),
        &Point3::new(0.0, 0.0, 1.5),
        &Vector3::y(),
    );
    let status = camera
        .capture(capture(v1::Pose::from(&away)))
        .await
        .unwrap_err();
    assert_invalid(&status, "t_w_c");
    assert!(
        status.message().contains("misses the bin"),
        "{}",
        status.message()
    );
    let status = camera
        .capture_exposure_stack(v1::CaptureExposureStackRequest {
            t_w_c: Some(v1::Pose::from(&good)),
            exposures_s: vec![2e-3, 1e-3],
            seed: 0,
        })
        .await
        .unwrap_err();
    assert_invalid(&status, "exposures_s");
    let status = camera
        .list_candidate_views(v1::ListCandidateViewsRequest {
            count: 0,
            ..Default::default()
        })
        .await
        .unwrap_err();
    assert_invalid(&status, "count");
    // The good pose still captures.
    let stream = camera
        .capture(capture(v1::Pose::from(&good)))
        .await
        .unwrap()
        .into_inner();
    let (_, arrays, _) = read_stream(stream).await;
    assert!(arrays.iter().all(|(name, _)| !name.starts_with("noise")));
    server.stop().await.unwrap().unwrap();
}
