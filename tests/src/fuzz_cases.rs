//! The fuzz targets' bodies, one function per target: `fuzz/` runs them under libFuzzer
//! (`cargo +nightly fuzz run NAME` there), and `tests/fuzz_corpus.rs` runs every input kept in
//! `fuzz/corpus/NAME/` through them on every `cargo test`, so that what the fuzzer explored, and
//! any crash it found, stays covered. Each takes arbitrary bytes (the first byte picks the
//! format or message where a target covers several); it returns on any input a reader may
//! refuse and panics only on a bug: a panic inside Glint, or a result that breaks what the
//! reader promises.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glint_calibration::material_file::MaterialFile;
use glint_calibration::response::ResponseTable;
use glint_camera::bin::BinSpec;
use glint_camera::dataset::ExposureStackFiles;
use glint_camera::dataset::bop::{BopSceneReader, read_dataset_camera, read_models_info};
use glint_camera::dataset::reference_file::read_reference_surface_json;
use glint_camera::dataset::rig_file::read_rig_json;
use glint_camera::dataset::robi::{RobiDepthCamera, RobiSceneReader, RobiSensor};
use glint_geometry::TriMesh;
use glint_geometry::io::{MeshFormat, read_mesh_from_bytes};
use glint_geometry::mesh::LengthUnit;
use glint_geometry::sdf::SdfConfig;
use glint_orchestrator::store::capture_file::{from_bytes, to_bytes};
use glint_proto::chunks::{ArrayAssembler, MAX_STREAM_BYTES};
use glint_proto::v1;
use nalgebra::Isometry3;
use prost::Message;

/// A target's body: arbitrary bytes in, a panic only on a bug.
pub type FuzzBody = fn(&[u8]);

/// Every target, by the name of its `fuzz/fuzz_targets/` file and corpus folder.
pub const TARGETS: [(&str, FuzzBody); 7] = [
    ("mesh_files", mesh_files),
    ("canonical_mesh", canonical_mesh),
    ("calibration_files", calibration_files),
    ("dataset_files", dataset_files),
    ("capture_file", capture_file),
    ("rpc_requests", rpc_requests),
    ("chunk_streams", chunk_streams),
];

/// The PLY, OBJ and STL readers (`glint mesh`, `RegisterObject`'s and `Refine`'s mesh files,
/// BOP models): the first byte picks the format, the rest is the file.
pub fn mesh_files(data: &[u8]) {
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let format = [MeshFormat::Ply, MeshFormat::Obj, MeshFormat::Stl][pick as usize % 3];
    let unit = if pick & 0x80 == 0 {
        LengthUnit::Millimetre
    } else {
        LengthUnit::Metre
    };
    if let Ok(loaded) = read_mesh_from_bytes(file, format, unit, "fuzz") {
        // Whatever reads must be a mesh the rest of Glint can use.
        assert!(
            loaded
                .mesh
                .vertices
                .iter()
                .all(|v| v.coords.iter().all(|x| x.is_finite()))
        );
    }
}

/// The session store's mesh blob (`TriMesh::from_canonical_bytes`): whatever it accepts
/// round-trips to the same bytes.
pub fn canonical_mesh(data: &[u8]) {
    if let Some(mesh) = TriMesh::from_canonical_bytes(data) {
        assert_eq!(mesh.canonical_bytes(), data);
    }
}

/// The calibration files Glint reads: the camera response (`glint calibrate response`) and the
/// fitted material (`glint calibrate bsdf`). The first byte picks the file.
pub fn calibration_files(data: &[u8]) {
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(file) else {
        return;
    };
    let origin = Path::new("fuzz.json");
    if pick % 2 == 0 {
        if let Ok(table) = ResponseTable::parse(text, origin) {
            // A table that parses answers every query without panicking.
            for dn in [0, 1, table.max_dn / 2, table.max_dn] {
                let _ = table.ln_exposure(dn);
                let _ = table.weight(dn);
            }
            for ln_x in [-20.0, 0.0, 20.0, f64::NAN] {
                let _ = table.intensity(ln_x);
            }
        }
    } else if let Ok(material) = MaterialFile::parse(text, origin) {
        let _ = material.params();
        let _ = material.radiometric_scale();
    }
}

/// A valid one-image `scene_camera.json`, so the scene files after it get read.
const SCENE_CAMERA: &str = r#"{"0": {"cam_K":[1083.1,0.0,639.5,0.0,1083.1,511.5,0.0,0.0,1.0],"depth_scale":0.1,"cam_R_w2c":[1,0,0,0,1,0,0,0,1],"cam_t_w2c":[0,0,500]}}"#;

/// A folder of this process's own, removed when the process ends normally.
fn root() -> &'static Path {
    static ROOT: OnceLock<tempfile::TempDir> = OnceLock::new();
    ROOT.get_or_init(|| tempfile::tempdir().expect("a temporary folder"))
        .path()
}

fn write(path: &Path, bytes: &[u8]) {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).expect("a folder");
    }
    std::fs::write(path, bytes).expect("a file");
}

/// A fresh folder for one input.
fn fresh(name: &str) -> PathBuf {
    let dir = root().join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a folder");
    dir
}

/// The dataset readers: Glint's rig, exposure-stack, reference-surface and camera files, the
/// BOP scene files (scene_camera, scene_gt, scene_gt_info, models_info) and ROBI's (object
/// poses, view list, camera yml). The first byte picks the file; the rest is written where the
/// reader looks for it (beside valid files for the others), and the reader runs on the folder.
pub fn dataset_files(data: &[u8]) {
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let dir = fresh("case");
    match pick % 10 {
        0 => {
            write(&dir.join("rig.json"), file);
            let _ = read_rig_json(&dir.join("rig.json"));
        }
        1 => {
            write(&dir.join("stack.json"), file);
            let _ = ExposureStackFiles::read(&dir);
        }
        2 => {
            write(&dir.join("scene_camera.json"), file);
            let _ = BopSceneReader::open(&dir);
        }
        3 => {
            write(&dir.join("scene_camera.json"), SCENE_CAMERA.as_bytes());
            write(&dir.join("scene_gt.json"), file);
            let _ = BopSceneReader::open(&dir);
        }
        4 => {
            write(&dir.join("scene_camera.json"), SCENE_CAMERA.as_bytes());
            write(&dir.join("scene_gt_info.json"), file);
            let _ = BopSceneReader::open(&dir);
        }
        5 => {
            write(&dir.join("models_info.json"), file);
            let _ = read_models_info(&dir.join("models_info.json"));
        }
        6 => {
            write(&dir.join("camera.json"), file);
            let _ = read_dataset_camera(&dir.join("camera.json"));
        }
        7 => {
            write(&dir.join("reference_surface.json"), file);
            let _ = read_reference_surface_json(&dir.join("reference_surface.json"));
        }
        8 => {
            write(&dir.join("GT_world2obj.json"), file);
            write(&dir.join("Ensenso").join("list.txt"), b"DEPTH_0000\n");
            let _ = RobiSceneReader::open(&dir, RobiSensor::Ensenso, RobiDepthCamera::ensenso());
        }
        _ => {
            write(&dir.join("camera.yml"), file);
            let _ = RobiDepthCamera::read_yml(&dir.join("camera.yml"));
        }
    }
}

/// The session store's capture blobs (`GLINTCAP` v1): whatever reads writes back the same.
pub fn capture_file(data: &[u8]) {
    if let Ok(view) = from_bytes(data) {
        let again = to_bytes(&view).expect("a capture read back writes");
        let view_again = from_bytes(&again).expect("a written capture reads");
        assert_eq!(to_bytes(&view_again).expect("writes"), again);
    }
}

fn decoded<M: Message + Default>(bytes: &[u8]) -> Option<M> {
    M::decode(bytes).ok()
}

/// Every RPC request's proto → core conversion, as the servers run it before any work: the
/// first byte picks the message, the rest is its protobuf encoding. Decoding may fail (that is
/// tonic's job to answer); a message that decodes must be converted or refused, never panic.
pub fn rpc_requests(data: &[u8]) {
    let Some((&pick, bytes)) = data.split_first() else {
        return;
    };
    let bin = BinSpec::default();
    match pick % 14 {
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
        // EstimationService: PlanNextView, PoseEntropy, RegisterMesh
        12 => {
            if let Some(m) = decoded::<v1::PlanNextViewRequest>(bytes)
                && let Ok((collected, candidates, taken)) =
                    glint_estimation::server::plan_request(&m)
            {
                let prior = glint_estimation::nbv::PosePrior::default();
                let _ =
                    glint_estimation::nbv::plan_next_view(&collected, &candidates, &taken, &prior);
            }
            if let Some(m) = decoded::<v1::PoseEntropyRequest>(bytes)
                && let Ok(information) =
                    glint_estimation::server::matrix(&m.information, "information")
            {
                let prior = glint_estimation::nbv::PosePrior::default();
                let _ = glint_estimation::nbv::pose_entropy_nats(&information, &prior);
            }
        }
        13 => {
            if let Some(m) = decoded::<v1::MeshFile>(bytes) {
                let _ = glint_geometry::io::LoadedMesh::try_from(&m);
            }
        }
        // OrchestratorService
        _ => {
            if let Some(m) = decoded::<v1::StartSessionRequest>(bytes) {
                let _ = glint_orchestrator::server::session_request(&m);
            }
        }
    }
}

/// The reassembly of chunked arrays (captures, exposure stacks, refine views): a header list
/// and a chunk sequence, as any client may send them, must assemble or be refused — never
/// panic, never allocate past the stream limit. Input: a u16 length, that many bytes of an
/// `ExposureStackHeader` (its `arrays`), then length-delimited `BytesChunk`s.
pub fn chunk_streams(data: &[u8]) {
    if data.len() < 2 {
        return;
    }
    let n = u16::from_le_bytes([data[0], data[1]]) as usize;
    let Some(header_bytes) = data.get(2..2 + n) else {
        return;
    };
    let Ok(header) = v1::ExposureStackHeader::decode(header_bytes) else {
        return;
    };
    let Ok(mut assembler) = ArrayAssembler::new(header.arrays, "arrays") else {
        return;
    };
    let mut rest = &data[2 + n..];
    while !rest.is_empty() {
        let Ok(chunk) = v1::BytesChunk::decode_length_delimited(&mut rest) else {
            return;
        };
        if assembler.push(chunk).is_err() {
            return;
        }
    }
    if let Ok(arrays) = assembler.finish() {
        let total: usize = arrays
            .iter()
            .map(|(_, a)| match a {
                glint_proto::chunks::AssembledArray::Image(m) => m.data.len(),
                glint_proto::chunks::AssembledArray::Depth(m) => m.data.len(),
            })
            .sum();
        assert!(total as u64 <= MAX_STREAM_BYTES);
        for (_, array) in arrays {
            match array {
                glint_proto::chunks::AssembledArray::Image(m) => {
                    let _ = glint_geometry::image::Image::<u16>::try_from(m);
                }
                glint_proto::chunks::AssembledArray::Depth(m) => {
                    let _ = glint_geometry::image::DepthMap::try_from(m);
                }
            }
        }
    }
}
