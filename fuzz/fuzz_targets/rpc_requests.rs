//! Every RPC request's proto → core conversion, as the servers run it before any work: the
//! first byte picks the message, the rest is its protobuf encoding. Decoding may fail (that is
//! tonic's job to answer); a message that decodes must be converted or refused, never panic.
#![no_main]

use glint_camera::bin::BinSpec;
use glint_geometry::sdf::SdfConfig;
use glint_proto::v1;
use libfuzzer_sys::fuzz_target;
use nalgebra::Isometry3;
use prost::Message;

fn decoded<M: Message + Default>(bytes: &[u8]) -> Option<M> {
    M::decode(bytes).ok()
}

fuzz_target!(|data: &[u8]| {
    let Some((&pick, bytes)) = data.split_first() else {
        return;
    };
    let bin = BinSpec::default();
    match pick % 12 {
        // CameraService
        0 => {
            if let Some(m) = decoded::<v1::SetUpSceneRequest>(bytes) {
                let _ = glint_camera::server::scene_request(&m);
            }
        }
        1 => {
            if let Some(m) = decoded::<v1::ListCandidateViewsRequest>(bytes) {
                let _ = glint_camera::server::candidate_views(&m, &bin, 0.1);
            }
        }
        2 => {
            if let Some(m) = decoded::<v1::CaptureRequest>(bytes)
                && let Some(pose) = &m.t_w_c
                && let Ok(t_w_c) = Isometry3::try_from(pose)
            {
                let _ = glint_camera::server::check_aim(&bin, &t_w_c, "t_w_c");
            }
        }
        3 => {
            if let Some(m) = decoded::<v1::CaptureExposureStackRequest>(bytes) {
                let _ = glint_camera::server::check_exposures(&m.exposures_s);
                if let Some(pose) = &m.t_w_c {
                    let _ = Isometry3::try_from(pose);
                }
            }
        }
        // CalibrationService (FitBsdf lists the folder it names, nothing more)
        4 => {
            if let Some(m) = decoded::<v1::FitBsdfRequest>(bytes) {
                let _ = glint_calibration::server::fit_request(&m);
            }
        }
        5 => {
            if let Some(m) = decoded::<v1::ResponseCurve>(bytes) {
                let _ = glint_calibration::server::response_from_message(&m);
            }
        }
        // EstimationService
        6 => {
            if let Some(m) = decoded::<v1::RefineHeader>(bytes) {
                let _ = glint_estimation::server::decode_header(&m);
            }
        }
        7 => {
            if let Some(m) = decoded::<v1::RefineResponse>(bytes) {
                let _ = glint_estimation::server::refinement_from_message(&m);
            }
        }
        // UncertaintyService
        8 => {
            if let Some(m) = decoded::<v1::RegisterObjectRequest>(bytes) {
                // Coarse voxels: the fuzzer's meshes, not the SDF, are under test.
                let sdf = SdfConfig {
                    voxel_size_m: 2e-3,
                    ..SdfConfig::default()
                };
                let _ = glint_uncertainty::server::decode_object(&m, &sdf);
            }
        }
        9 => {
            if let Some(m) = decoded::<v1::PredictCandidatesRequest>(bytes) {
                let _ = glint_uncertainty::server::decode_poses(&m);
            }
        }
        10 => {
            if let Some(m) = decoded::<v1::GetRigResponse>(bytes) {
                let _ = glint_uncertainty::server::rig_from_message(&m);
            }
            if let Some(m) = decoded::<v1::SensorNoiseModel>(bytes) {
                let _ = glint_uncertainty::server::noise_from_message(&m);
            }
        }
        // OrchestratorService
        _ => {
            if let Some(m) = decoded::<v1::StartSessionRequest>(bytes) {
                let _ = glint_orchestrator::server::session_request(&m);
            }
        }
    }
});
