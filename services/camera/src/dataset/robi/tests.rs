//! The ROBI-layout reader on small files these tests write in that layout. The contents
//! are made up; only the layout is ROBI's.

use std::path::{Path, PathBuf};

use glint_geometry::image::Image;
use nalgebra::{Isometry3, Vector3};

use super::*;
use crate::dataset::image_files::write_png_u16;
use crate::dataset::transforms::matrix4_mm_from_isometry;

const WIDTH: u32 = 6;
const HEIGHT: u32 = 4;

fn pose(t: [f64; 3], axis_angle: [f64; 3]) -> Isometry3<f64> {
    Isometry3::new(Vector3::from(t), Vector3::from(axis_angle))
}

fn t_w_c(view: usize) -> Isometry3<f64> {
    pose(
        [0.1 * view as f64, -0.05, 0.8],
        [3.0, 0.1 * view as f64, 0.2],
    )
}

/// Object → camera poses the files are made from (in view 0): `Object_1`, `Object_2`,
/// `Object_10`.
fn t_c_o() -> [(&'static str, Isometry3<f64>); 3] {
    [
        ("Object_1", pose([0.01, 0.02, 0.6], [0.3, -0.2, 1.0])),
        ("Object_2", pose([-0.03, 0.0, 0.65], [0.0, 1.5, 0.0])),
        ("Object_10", pose([0.0, -0.04, 0.7], [-2.0, 0.5, 0.4])),
    ]
}

fn rows(m: &[f64; 16]) -> serde_json::Value {
    serde_json::json!([&m[0..4], &m[4..8], &m[8..12], &m[12..16]])
}

fn cam_pose_json(t_w_c: &Isometry3<f64>) -> String {
    serde_json::json!({"cam_pose": matrix4_mm_from_isometry(t_w_c)}).to_string()
}

fn camera() -> RobiDepthCamera {
    RobiDepthCamera {
        intrinsics: PinholeIntrinsics::new(WIDTH, HEIGHT, 5.0, 5.0, 3.0, 2.0).unwrap(),
        depth_unit_mm: 0.03125,
    }
}

/// `<root>/Made_up_part/Scene_1` in ROBI's layout with two Ensenso views.
fn write_scene(root: &Path) -> PathBuf {
    let scene = root.join("Made_up_part").join("Scene_1");
    let sensor = scene.join("Ensenso");
    std::fs::create_dir_all(sensor.join("Depth")).unwrap();
    std::fs::create_dir_all(sensor.join("StereoPattern")).unwrap();

    // Object → world; one matrix as nested rows, the others flat, as numpy accepts both.
    let mut gt = serde_json::Map::new();
    for (i, (name, t_c_o)) in t_c_o().iter().enumerate() {
        let m = matrix4_mm_from_isometry(&(t_w_c(0) * t_c_o));
        let value = if i == 1 {
            rows(&m)
        } else {
            serde_json::json!(m)
        };
        gt.insert(name.to_string(), value);
    }
    std::fs::write(
        scene.join("GT_world2obj.json"),
        serde_json::Value::Object(gt).to_string(),
    )
    .unwrap();
    std::fs::write(sensor.join("list.txt"), "view_0\nview_1\n\n").unwrap();

    let n = (WIDTH * HEIGHT) as u16;
    for view in 0..2 {
        let name = format!("view_{view}");
        // 0.6 m = 19200 units of 1/32 mm.
        let units = Image::new(
            WIDTH,
            HEIGHT,
            (0..n)
                .map(|i| if i == 5 { 0 } else { 19200 + 7 * i })
                .collect(),
        )
        .unwrap();
        write_png_u16(
            &sensor.join("Depth").join(format!("DEPTH_{name}.png")),
            &units,
        )
        .unwrap();
        std::fs::write(
            sensor.join("Depth").join(format!("DEPTH_{name}.json")),
            cam_pose_json(&t_w_c(view)),
        )
        .unwrap();
        let left =
            image::GrayImage::from_fn(WIDTH, HEIGHT, |u, v| image::Luma([(u * 40 + v) as u8]));
        left.save(
            sensor
                .join("StereoPattern")
                .join(format!("LEFT_{name}.bmp")),
        )
        .unwrap();
        let right = image::RgbImage::from_fn(WIDTH, HEIGHT, |u, _| image::Rgb([(u * 40) as u8; 3]));
        right
            .save(
                sensor
                    .join("StereoPattern")
                    .join(format!("RIGHT_{name}.bmp")),
            )
            .unwrap();
        let right_pose = t_w_c(view) * pose([0.10118, 0.0, 0.0], [0.0; 3]);
        std::fs::write(
            sensor
                .join("StereoPattern")
                .join(format!("RIGHT_{name}.json")),
            cam_pose_json(&right_pose),
        )
        .unwrap();
    }
    scene
}

#[test]
fn a_scene_in_robi_layout_reads() {
    let root = tempfile::tempdir().unwrap();
    let scene = write_scene(root.path());
    let reader = RobiSceneReader::open(&scene, RobiSensor::Ensenso, camera()).unwrap();
    let names: Vec<&str> = reader.objects().iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["Object_1", "Object_2", "Object_10"]);
    assert_eq!(reader.views(), ["view_0", "view_1"]);

    let mut worst = (0.0f64, 0.0f64);
    for ((name, expected), got) in t_c_o()
        .iter()
        .zip(reader.gt_in_depth_camera("view_0").unwrap())
    {
        assert_eq!(&got.name, name);
        worst.0 = worst
            .0
            .max((got.t_c_o.translation.vector - expected.translation.vector).norm());
        worst.1 = worst.1.max(got.t_c_o.rotation.angle_to(&expected.rotation));
    }
    assert!(worst.0 < 1e-12 && worst.1 < 1e-12, "{worst:?}");
    let view1 = reader.depth_t_w_c("view_1").unwrap();
    assert!((view1.translation.vector - t_w_c(1).translation.vector).norm() < 1e-15);

    let depth = reader.depth("view_0").unwrap();
    assert!((depth.depth_m.data()[0] - 0.6).abs() < 1e-7);
    assert!(depth.depth_m.data()[5].is_nan());
    assert!((depth.depth_m.data()[3] as f64 - (19200.0 + 21.0) * 0.03125e-3).abs() < 1e-7);

    let left = reader.pattern("view_1", StereoSide::Left).unwrap();
    assert_eq!(left.get(2, 3), Some(83));
    let right = reader.pattern("view_1", StereoSide::Right).unwrap();
    assert_eq!(right.get(4, 0), Some(160));
    let right_pose = reader.pattern_t_w_c("view_0", StereoSide::Right).unwrap();
    let baseline = (t_w_c(0).inverse() * right_pose).translation.vector;
    assert!((baseline - Vector3::new(0.10118, 0.0, 0.0)).norm() < 1e-12);
    // Left pattern poses were not written: the error names the file.
    let err = reader
        .pattern_t_w_c("view_0", StereoSide::Left)
        .unwrap_err();
    assert!(err.to_string().contains("LEFT_view_0.json"), "{err}");
}

#[test]
fn views_come_from_depth_files_without_a_list() {
    let root = tempfile::tempdir().unwrap();
    let scene = write_scene(root.path());
    let depth_dir = scene.join("Ensenso/Depth");
    std::fs::remove_file(scene.join("Ensenso/list.txt")).unwrap();
    for view in ["view_10", "view_2"] {
        std::fs::copy(
            depth_dir.join("DEPTH_view_1.png"),
            depth_dir.join(format!("DEPTH_{view}.png")),
        )
        .unwrap();
    }
    let reader = RobiSceneReader::open(&scene, RobiSensor::Ensenso, camera()).unwrap();
    assert_eq!(reader.views(), ["view_0", "view_1", "view_2", "view_10"]);
}

#[test]
fn bad_files_are_errors_naming_file_and_key() {
    let root = tempfile::tempdir().unwrap();
    let scene = write_scene(root.path());
    let open = || RobiSceneReader::open(&scene, RobiSensor::Ensenso, camera());

    std::fs::write(scene.join("Ensenso/list.txt"), "view_0\n../../etc\n").unwrap();
    let err = open().unwrap_err();
    assert!(matches!(err, DatasetError::Line { line: 2, .. }), "{err:?}");
    std::fs::write(scene.join("Ensenso/list.txt"), "view_0\n").unwrap();

    let gt_path = scene.join("GT_world2obj.json");
    let good_gt = std::fs::read_to_string(&gt_path).unwrap();
    let mut bad: serde_json::Value = serde_json::from_str(&good_gt).unwrap();
    bad["Object_2"][3][0] = 0.5.into();
    std::fs::write(&gt_path, bad.to_string()).unwrap();
    let err = open().unwrap_err();
    assert_eq!(err.key(), Some("/Object_2"), "{err}");
    assert!(err.to_string().contains("GT_world2obj.json") && err.to_string().contains("last row"));
    bad["Object_2"] = serde_json::json!([1, 2, 3]);
    std::fs::write(&gt_path, bad.to_string()).unwrap();
    assert_eq!(open().unwrap_err().key(), Some("/Object_2"));
    std::fs::write(&gt_path, &good_gt[..good_gt.len() / 2]).unwrap();
    assert!(matches!(open().unwrap_err(), DatasetError::Json { .. }));
    std::fs::write(&gt_path, good_gt).unwrap();

    let reader = open().unwrap();
    std::fs::write(
        scene.join("Ensenso/Depth/DEPTH_view_0.json"),
        r#"{"pose": []}"#,
    )
    .unwrap();
    let err = reader.depth_t_w_c("view_0").unwrap_err();
    assert_eq!(err.key(), Some("/cam_pose"));
    assert!(err.to_string().contains("DEPTH_view_0.json"), "{err}");

    let small = RobiDepthCamera {
        intrinsics: PinholeIntrinsics::new(3, 2, 5.0, 5.0, 1.5, 1.0).unwrap(),
        depth_unit_mm: 0.03125,
    };
    let reader = RobiSceneReader::open(&scene, RobiSensor::Ensenso, small).unwrap();
    let err = reader.depth("view_0").unwrap_err();
    assert!(
        err.to_string().contains("DEPTH_view_0.png") && err.to_string().contains("6×4"),
        "{err}"
    );

    let err = RobiSceneReader::open(&scene, RobiSensor::RealSense, camera()).unwrap_err();
    assert!(err.to_string().contains("RealSense"), "{err}");
}

#[test]
fn camera_files_and_models_read() {
    let dir = tempfile::tempdir().unwrap();
    let yml = dir.path().join("Ensenso_DEPTH.yml");
    std::fs::write(
        &yml,
        "depth_unit: 0.03125\nwidth: 1280\nheight: 1024\nfx: 1083.097046\nfy: 1083.097046\n\
         cx: 379.326874\ncy: 509.437195\n",
    )
    .unwrap();
    assert_eq!(
        RobiDepthCamera::read_yml(&yml).unwrap(),
        RobiDepthCamera::ensenso()
    );
    std::fs::write(
        &yml,
        "depth_scale: 0.5\nwidth: 4\nheight: 2\nfx: 3\nfy: 3\ncx: 1.5  # centre\ncy: 0.5\n",
    )
    .unwrap();
    let camera = RobiDepthCamera::read_yml(&yml).unwrap();
    assert_eq!((camera.depth_unit_mm, camera.intrinsics.cx_px), (0.5, 2.0));
    std::fs::write(&yml, "depth_unit: 0.5\nwidth: 4\nheight: 2\nfx: three\n").unwrap();
    let err = RobiDepthCamera::read_yml(&yml).unwrap_err();
    assert!(matches!(err, DatasetError::Line { line: 4, .. }), "{err:?}");
    std::fs::write(&yml, "width: 4\nheight: 2\nfx: 3\nfy: 3\ncx: 1\ncy: 1\n").unwrap();
    assert_eq!(
        RobiDepthCamera::read_yml(&yml).unwrap_err().key(),
        Some("depth_unit")
    );

    let stl = dir.path().join("part.stl");
    std::fs::write(
        &stl,
        "solid t\n\
         facet normal 0 0 -1\nouter loop\nvertex 0 0 0\nvertex 0 10 0\nvertex 10 0 0\nendloop\nendfacet\n\
         facet normal 0 -1 0\nouter loop\nvertex 0 0 0\nvertex 10 0 0\nvertex 0 0 10\nendloop\nendfacet\n\
         facet normal -1 0 0\nouter loop\nvertex 0 0 0\nvertex 0 0 10\nvertex 0 10 0\nendloop\nendfacet\n\
         facet normal 1 1 1\nouter loop\nvertex 10 0 0\nvertex 0 10 0\nvertex 0 0 10\nendloop\nendfacet\n\
         endsolid t\n",
    )
    .unwrap();
    let model = read_robi_model(&stl).unwrap();
    assert_eq!(
        (model.mesh.vertices.len(), model.mesh.triangles.len()),
        (4, 4)
    );
    let (_, max) = model.mesh.aabb().unwrap();
    assert!((max.x - 0.01).abs() < 1e-9);
}
