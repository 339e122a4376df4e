//! The dataset readers: Glint's rig, exposure-stack, reference-surface and camera files, the
//! BOP scene files (scene_camera, scene_gt, scene_gt_info, models_info) and ROBI's (object
//! poses, view list, camera yml). The first byte picks the file; the rest is written where the
//! reader looks for it (beside valid files for the others), and the reader runs on the folder.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glint_camera::dataset::ExposureStackFiles;
use glint_camera::dataset::bop::{BopSceneReader, read_dataset_camera, read_models_info};
use glint_camera::dataset::reference_file::read_reference_surface_json;
use glint_camera::dataset::rig_file::read_rig_json;
use glint_camera::dataset::robi::{RobiDepthCamera, RobiSceneReader, RobiSensor};
use libfuzzer_sys::fuzz_target;

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

fuzz_target!(|data: &[u8]| {
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
});
