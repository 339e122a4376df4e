//! The render worker over real gRPC on loopback: the Zigzag registered with its shipped
//! calibration, three candidates predicted; the Fisher information is bit for bit what
//! `predict_candidate` gives in-process for the same object, settings and seeds, and a repeated
//! request answers the same. Bad input answers INVALID_ARGUMENT naming the field, an unknown
//! object NOT_FOUND naming its hash.

use glint_e2e::TestServer;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glint_calibration::material_file::MaterialFile;
use glint_calibration::response::ResponseTable;
use glint_calibration::server::response_to_message;
use glint_estimation::depth_sigma::NoiseModel;
use glint_geometry::io::{PlyEncoding, read_mesh_from_bytes, write_ply_to_vec};
use glint_geometry::sdf::SdfGrid;
use glint_geometry::{LengthUnit, Part};
use glint_proto::v1;
use glint_proto::v1::uncertainty_service_client::UncertaintyServiceClient;
use glint_render::rig::SliRig;
use glint_uncertainty::server::{SERVICE_NAME, Uncertainty, noise_to_message, rig_to_message};
use glint_uncertainty::{
    CalibratedCamera, PredictionSettings, PredictorObject, candidate_seed, predict_candidate,
};
use nalgebra::{Isometry3, Point3, Vector3};
use tonic::Code;

/// The mock camera's exposure of a capture (its sensor's default), seconds.
const EXPOSURE_S: f64 = 0.01;
/// τ_σ for this 320×256 camera: the default is for 1280×1024, and σ̌_z scales as 1/f.
const TAU_SIGMA_M: f64 = 4.0 * 0.03e-3;

fn calibration_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/calibration/zigzag")
}

struct Fixture {
    request: v1::RegisterObjectRequest,
    /// The same object built in-process from the same files.
    object: PredictorObject,
    t_w_o: Isometry3<f64>,
    candidates: Vec<Isometry3<f64>>,
}

fn fixture() -> Fixture {
    let ply = write_ply_to_vec(
        &Part::Zigzag.mesh(),
        LengthUnit::Millimetre,
        PlyEncoding::BinaryLittleEndian,
    );
    let material = MaterialFile::load(&calibration_dir().join("material.json")).unwrap();
    let params = material.params().unwrap();
    let scale = material.radiometric_scale().unwrap();
    let response = ResponseTable::load(&calibration_dir().join("response.json")).unwrap();
    let rig = SliRig::ensenso_n35().resized(320, 256).unwrap();
    let noise = NoiseModel::constant(1e-5);

    let request = v1::RegisterObjectRequest {
        mesh: Some(v1::MeshFile {
            data: ply.clone(),
            format: "ply".into(),
            unit: v1::LengthUnit::Millimetre as i32,
            name: "zigzag".into(),
        }),
        material: Some(v1::PrincipledMaterial::from(&params)),
        response: Some(response_to_message(&response)),
        rig: Some(rig_to_message(&rig, 255, EXPOSURE_S)),
        radiometric_scale: scale,
        pattern_exposure_s: EXPOSURE_S,
        noise: Some(noise_to_message(&noise)),
        shots_per_capture: 8,
        pattern_fill: 0.5,
        surroundings: Vec::new(),
    };

    // In-process: the mesh as read from the same file, the refiner's SDF voxel.
    let mesh = read_mesh_from_bytes(
        &ply,
        glint_geometry::io::MeshFormat::Ply,
        LengthUnit::Millimetre,
        "zigzag",
    )
    .unwrap()
    .mesh;
    // The server's grid.
    let sdf = SdfGrid::build(&mesh, &glint_uncertainty::predict::prediction_grid_config()).unwrap();
    let object = PredictorObject {
        mesh: Arc::new(mesh),
        sdf: Arc::new(sdf),
        material: params,
        camera: CalibratedCamera::new(response, scale, EXPOSURE_S).unwrap(),
        rig,
        noise,
        surroundings: Vec::new(),
    };

    // The part lying at the bin's centre, tilted; candidates on the capture cap looking at it.
    let t_w_o = Isometry3::new(Vector3::new(0.0, 0.0, 0.01), Vector3::new(0.3, -0.2, 0.8));
    let candidates = glint_camera::views::spherical_cap(
        3,
        glint_camera::setup::VIEW_DISTANCE_M,
        glint_camera::setup::VIEW_CAP_DEG,
        Point3::new(0.0, 0.0, 0.01),
        rig.stereo.baseline_m,
    );
    Fixture {
        request,
        object,
        t_w_o,
        candidates,
    }
}

fn request_settings() -> v1::PredictionSettings {
    v1::PredictionSettings {
        tau_sigma_z_m: TAU_SIGMA_M,
        ..Default::default()
    }
}

fn predict_request(f: &Fixture, key: &str) -> v1::PredictCandidatesRequest {
    v1::PredictCandidatesRequest {
        object_sha256_hex: key.into(),
        t_w_o: Some(f.t_w_o.into()),
        candidates_t_w_c: f.candidates.iter().map(v1::Pose::from).collect(),
        candidate_indices: vec![4, 7, 11],
        settings: Some(request_settings()),
        seed: 42,
        with_sigma_maps: true,
    }
}

fn assert_invalid(status: &tonic::Status, field: &str) {
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(
        status.message().starts_with(field),
        "message {:?} does not name {field}",
        status.message()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn predict_candidates_over_grpc_matches_the_library() {
    let server = TestServer::start(
        tonic::service::Routes::new(Uncertainty::default().into_service()),
        SERVICE_NAME,
    )
    .await;
    let target = server.target.clone();
    let mut client = UncertaintyServiceClient::connect(target).await.unwrap();

    let f = fixture();
    let key = client
        .register_object(f.request.clone())
        .await
        .unwrap()
        .into_inner()
        .object_sha256_hex;
    assert_eq!(key.len(), 64);
    assert!(key.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')));
    // The same object again: the same key; a changed field: another.
    let again = client.register_object(f.request.clone()).await.unwrap();
    assert_eq!(again.into_inner().object_sha256_hex, key);
    let other = v1::RegisterObjectRequest {
        shots_per_capture: 4,
        ..f.request.clone()
    };
    let other = client.register_object(other).await.unwrap();
    assert_ne!(other.into_inner().object_sha256_hex, key);

    let request = predict_request(&f, &key);
    let reply = client
        .predict_candidates(request.clone())
        .await
        .unwrap()
        .into_inner();
    assert_eq!(reply.predictions.len(), 3);

    // In-process, the same object, settings and seeds, at the poses as the wire carries them
    // (the receiver renormalises a quaternion within its tolerance, which moves the last bits).
    let wire = |t: &Isometry3<f64>| Isometry3::try_from(v1::Pose::from(t)).unwrap();
    let t_w_o = wire(&f.t_w_o);
    let settings = PredictionSettings {
        tau_sigma_m: TAU_SIGMA_M,
        shots: 8,
        pattern_fill: 0.5,
        with_maps: true,
        ..PredictionSettings::default()
    };
    let mut seen = 0;
    for ((got, t_w_c), index) in reply
        .predictions
        .iter()
        .zip(&f.candidates)
        .zip(&request.candidate_indices)
    {
        let want = predict_candidate(
            &f.object,
            &t_w_o,
            &wire(t_w_c),
            &settings,
            candidate_seed(request.seed, *index),
        )
        .unwrap();
        assert_eq!(got.candidate_index, *index);
        let info = got.information.as_ref().unwrap();
        let want_info = v1::SymmetricMatrix6::from(&want.information);
        let bits =
            |m: &v1::SymmetricMatrix6| m.upper.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(info), bits(&want_info), "candidate {index}");
        assert_eq!(got.part_pixels, want.counts.part_pixels);
        assert_eq!(got.predicted_points, want.counts.kept);
        assert_eq!(got.missing_ratio, want.counts.missing_ratio);
        assert_eq!(got.missing_sigma, want.counts.missing_sigma);
        assert_eq!(got.missing_right_occluded, want.counts.right_occluded);
        assert_eq!(got.not_in_view, want.not_in_view);
        assert!(got.predict_ms > 0.0);
        if let (Some(map), Some(crop)) = (&got.sigma_z_m, want.crop) {
            assert_eq!((map.width_px, map.height_px), (crop.width, crop.height));
            assert_eq!((got.roi_u0_px, got.roi_v0_px), (crop.u_min, crop.v_min));
            assert_eq!(got.roi_pixels, crop.width * crop.height);
            let want_map = want.sigma_z_m.as_ref().unwrap();
            let got_bits: Vec<u32> = map
                .data
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            let want_bits: Vec<u32> = want_map.data().iter().map(|s| s.to_bits()).collect();
            assert_eq!(got_bits, want_bits);
        }
        if !got.not_in_view && got.predicted_points > 0 {
            seen += 1;
        }
    }
    assert!(seen >= 2, "the part should be seen from the cap: {reply:?}");

    // The same request again: the same answer.
    let second = client
        .predict_candidates(request.clone())
        .await
        .unwrap()
        .into_inner();
    for (a, b) in reply.predictions.iter().zip(&second.predictions) {
        assert_eq!(a.information, b.information);
        assert_eq!(a.sigma_z_m, b.sigma_z_m);
    }

    // An unknown object: NOT_FOUND naming its hash.
    let unknown = "0".repeat(64);
    let status = client
        .predict_candidates(predict_request(&f, &unknown))
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::NotFound, "{status:?}");
    assert!(status.message().contains(&unknown), "{}", status.message());

    // A NaN pose.
    let mut bad = request.clone();
    bad.t_w_o
        .as_mut()
        .unwrap()
        .translation_m
        .as_mut()
        .unwrap()
        .x = f64::NAN;
    let status = client.predict_candidates(bad).await.unwrap_err();
    assert_invalid(&status, "t_w_o");
    assert!(status.message().contains("NaN"), "{}", status.message());

    // No candidates.
    let mut bad = request.clone();
    bad.candidates_t_w_c.clear();
    bad.candidate_indices.clear();
    let status = client.predict_candidates(bad).await.unwrap_err();
    assert_invalid(&status, "candidates_t_w_c");

    // Indices that do not match the candidates.
    let mut bad = request.clone();
    bad.candidate_indices.pop();
    let status = client.predict_candidates(bad).await.unwrap_err();
    assert_invalid(&status, "candidate_indices");

    // A threshold the library rejects, named as the request's field.
    let mut bad = request.clone();
    bad.settings.as_mut().unwrap().tau_intensity_ratio = 2.0;
    let status = client.predict_candidates(bad).await.unwrap_err();
    assert_invalid(&status, "settings.tau_intensity_ratio");

    // A bad registration: the radiometric scale, and a nested field.
    for scale in [0.0, -1.0, f64::NAN] {
        let bad = v1::RegisterObjectRequest {
            radiometric_scale: scale,
            ..f.request.clone()
        };
        let status = client.register_object(bad).await.unwrap_err();
        assert_invalid(&status, "radiometric_scale");
        assert!(
            status.message().contains("finite and positive"),
            "{}",
            status.message()
        );
    }
    let mut bad = f.request.clone();
    bad.rig
        .as_mut()
        .unwrap()
        .stereo
        .as_mut()
        .unwrap()
        .baseline_m = 0.0;
    let status = client.register_object(bad).await.unwrap_err();
    assert_invalid(&status, "rig.stereo.baseline_m");

    server.stop().await.unwrap().unwrap();
}
