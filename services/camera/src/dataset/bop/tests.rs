//! BOP round trips, hand-written real-dataset layouts, and malformed input.

use std::path::{Path, PathBuf};

use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::{DepthMap, Image};
use glint_geometry::{Part, Symmetry, TriMesh};
use nalgebra::{Isometry3, Point3, Vector3};
use rand::{Rng, SeedableRng};

use super::*;
use crate::dataset::{DatasetError, PatternImage, StereoSide};

const WIDTH: u32 = 8;
const HEIGHT: u32 = 6;

fn intrinsics() -> PinholeIntrinsics {
    PinholeIntrinsics::new(WIDTH, HEIGHT, 7.3, 7.1, 4.2, 2.9).unwrap()
}

fn pose(t: [f64; 3], axis_angle: [f64; 3]) -> Isometry3<f64> {
    Isometry3::new(Vector3::from(t), Vector3::from(axis_angle))
}

/// Everything the synthetic scene was written from.
struct SyntheticScene {
    dir: PathBuf,
    t_c_w: [Option<Isometry3<f64>>; 2],
    gts: [Vec<BopGt>; 2],
    infos: [Vec<BopGtInfo>; 2],
    depths: [DepthMap; 2],
    grays: [Image<u8>; 2],
    /// `[image][gt index]`: (full, visible).
    masks: [Vec<(Image<u8>, Image<u8>)>; 2],
    left: PatternImage,
    right: PatternImage,
    materials: serde_json::Value,
}

/// Two images, three GT instances (two in image 0, one in image 1), depth with NaN and 0,
/// masks written directly and from a label image, patterns at 8 and 16 bits.
fn write_synthetic_scene(root: &Path) -> SyntheticScene {
    let dir = root.join("test").join("000001");
    let mut writer = BopSceneWriter::create(&dir, BopSceneWriter::DEFAULT_DEPTH_SCALE_MM).unwrap();
    let t_c_w = [Some(pose([0.1, -0.2, 0.9], [2.9, 0.3, -0.4])), None];
    let gts = [
        vec![
            BopGt {
                obj_id: 1,
                t_c_o: pose([0.0123456789, -0.0456, 0.61234567891], [0.1, -0.2, 0.3]),
            },
            BopGt {
                obj_id: 2,
                // Nearly a half turn: quaternion ↔ matrix conversions are hardest there.
                t_c_o: pose(
                    [-0.07, 0.031, 0.7],
                    [0.0, std::f64::consts::PI - 1e-5, 0.001],
                ),
            },
        ],
        vec![BopGt {
            obj_id: 1,
            t_c_o: pose([0.02, 0.01, 1.1], [-1.2, 0.5, 0.25]),
        }],
    ];
    let n = (WIDTH * HEIGHT) as usize;
    let mut depths = Vec::new();
    let mut grays = Vec::new();
    let mut all_masks = Vec::new();
    let mut all_infos = Vec::new();
    for im_id in 0..2u32 {
        let z: Vec<f32> = (0..n)
            .map(|i| match i % 11 {
                3 => f32::NAN,
                7 => 0.0,
                _ => 0.4 + 0.013_712_34 * i as f32 + 0.1 * im_id as f32,
            })
            .collect();
        let depth = DepthMap::new(Image::new(WIDTH, HEIGHT, z).unwrap());
        let gray = Image::new(
            WIDTH,
            HEIGHT,
            (0..n).map(|i| (i * 5 + im_id as usize) as u8).collect(),
        )
        .unwrap();
        writer
            .set_camera(im_id, &intrinsics(), t_c_w[im_id as usize].as_ref())
            .unwrap();
        writer.write_depth(im_id, &depth).unwrap();
        writer.write_gray(im_id, &gray).unwrap();
        writer.set_gt(im_id, &gts[im_id as usize]);

        // Instance k covers columns 2k..2k+3 (full); its visible part is where the label
        // image says 10 + k: the next instance occludes its right column.
        let count = gts[im_id as usize].len();
        let mut labels = Image::filled(WIDTH, HEIGHT, 0u16).unwrap();
        let mut masks = Vec::new();
        for k in 0..count as u32 {
            let mut full = Image::filled(WIDTH, HEIGHT, 0u8).unwrap();
            for v in 1..HEIGHT - 1 {
                for u in 2 * k..2 * k + 3 {
                    full.set(u, v, 255);
                    labels.set(u, v, 10 + k as u16);
                }
            }
            masks.push(full);
        }
        let mapping: Vec<(u16, usize)> = (0..count).map(|k| (10 + k as u16, k)).collect();
        writer
            .write_masks_from_labels(im_id, MaskKind::Visible, &labels, &mapping)
            .unwrap();
        let mut pairs = Vec::new();
        let mut infos = Vec::new();
        for (k, full) in masks.into_iter().enumerate() {
            writer.write_mask(im_id, k, MaskKind::Full, &full).unwrap();
            let label = 10 + k as u16;
            let visible = Image::new(
                WIDTH,
                HEIGHT,
                labels
                    .data()
                    .iter()
                    .map(|&l| if l == label { 255 } else { 0 })
                    .collect(),
            )
            .unwrap();
            infos.push(BopGtInfo::from_masks(&full, &visible, Some(&depth)).unwrap());
            pairs.push((full, visible));
        }
        writer.set_gt_info(im_id, &infos);
        depths.push(depth);
        grays.push(gray);
        all_masks.push(pairs);
        all_infos.push(infos);
    }
    let left = PatternImage::Bits8(
        Image::new(WIDTH, HEIGHT, (0..n).map(|i| (255 - i) as u8).collect()).unwrap(),
    );
    let right = PatternImage::Bits16(
        Image::new(WIDTH, HEIGHT, (0..n).map(|i| (i * 1361) as u16).collect()).unwrap(),
    );
    writer.write_pattern(0, StereoSide::Left, &left).unwrap();
    writer.write_pattern(0, StereoSide::Right, &right).unwrap();
    let materials =
        serde_json::json!({"0": [{"bsdf": "principled", "roughness": 0.12}], "note": "π"});
    writer.set_gt_materials(materials.clone());
    assert_eq!(writer.finish().unwrap(), dir);

    fn pair<T>(v: Vec<T>) -> [T; 2] {
        v.try_into().ok().expect("two images")
    }
    SyntheticScene {
        dir,
        t_c_w,
        gts,
        infos: pair(all_infos),
        depths: pair(depths),
        grays: pair(grays),
        masks: pair(all_masks),
        left,
        right,
        materials,
    }
}

fn pose_errors(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    (
        (a.translation.vector - b.translation.vector).norm(),
        a.rotation.angle_to(&b.rotation),
    )
}

#[test]
fn a_synthetic_scene_round_trips() {
    let root = tempfile::tempdir().unwrap();
    let scene = write_synthetic_scene(root.path());
    let reader = BopSceneReader::open(&scene.dir).unwrap();
    assert_eq!(reader.image_ids(), vec![0, 1]);
    assert_eq!(reader.models_dir(), Some(root.path().join("models")));

    let (mut worst_t_m, mut worst_r_rad, mut worst_depth_m) = (0.0f64, 0.0f64, 0.0f64);
    for im_id in 0..2u32 {
        let i = im_id as usize;
        let camera = reader.camera(im_id).unwrap();
        let (k, expected) = (camera.intrinsics, intrinsics());
        assert_eq!((k.width_px, k.height_px), (WIDTH, HEIGHT));
        for (a, b) in [
            (k.fx_px, expected.fx_px),
            (k.fy_px, expected.fy_px),
            (k.cx_px, expected.cx_px),
            (k.cy_px, expected.cy_px),
        ] {
            assert!((a - b).abs() < 1e-12, "{a} {b}");
        }
        assert_eq!(camera.depth_scale_mm, Some(0.1));
        match (&camera.t_c_w, &scene.t_c_w[i]) {
            (Some(read), Some(written)) => {
                let (t, r) = pose_errors(read, written);
                worst_t_m = worst_t_m.max(t);
                worst_r_rad = worst_r_rad.max(r);
            }
            (None, None) => {}
            other => panic!("t_c_w of image {im_id}: {other:?}"),
        }

        let gts = reader.gt(im_id).unwrap();
        assert_eq!(gts.len(), scene.gts[i].len());
        for (read, written) in gts.iter().zip(&scene.gts[i]) {
            assert_eq!(read.obj_id, written.obj_id);
            let (t, r) = pose_errors(&read.t_c_o, &written.t_c_o);
            worst_t_m = worst_t_m.max(t);
            worst_r_rad = worst_r_rad.max(r);
        }
        assert_eq!(reader.gt_info(im_id).unwrap(), scene.infos[i].as_slice());

        let depth = reader.depth(im_id).unwrap();
        for (read, written) in depth
            .depth_m
            .data()
            .iter()
            .zip(scene.depths[i].depth_m.data())
        {
            if written.is_nan() || *written == 0.0 {
                assert!(read.is_nan());
            } else {
                worst_depth_m = worst_depth_m.max((*read as f64 - *written as f64).abs());
            }
        }
        assert_eq!(reader.gray(im_id).unwrap(), scene.grays[i]);
        for (k, (full, visible)) in scene.masks[i].iter().enumerate() {
            assert_eq!(&reader.mask(im_id, k, MaskKind::Full).unwrap(), full);
            assert_eq!(&reader.mask(im_id, k, MaskKind::Visible).unwrap(), visible);
        }
    }
    // JSON keeps every f64 exactly (shortest round-trip decimal), so the only losses are
    // m → mm → m (a few ulp) and matrix ↔ quaternion (≈ 1e-16 rad).
    eprintln!(
        "round trip: translation {worst_t_m:.2e} m, rotation {worst_r_rad:.2e} rad, depth \
         {worst_depth_m:.2e} m (bound 5e-5 m)"
    );
    assert!(worst_t_m < 1e-9 && worst_r_rad < 1e-9);
    // Half a 0.1 mm unit, plus f32 rounding of depths near 1 m.
    assert!(worst_depth_m <= 0.05e-3 + 2e-7, "{worst_depth_m}");

    assert_eq!(reader.pattern(0, StereoSide::Left).unwrap(), scene.left);
    assert_eq!(reader.pattern(0, StereoSide::Right).unwrap(), scene.right);
    assert!(reader.pattern(1, StereoSide::Left).is_err());
    assert_eq!(reader.gt_materials().unwrap(), Some(scene.materials));
}

#[test]
fn written_json_is_bop_shaped() {
    let root = tempfile::tempdir().unwrap();
    let scene = write_synthetic_scene(root.path());
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(scene.dir.join(name)).unwrap()).unwrap()
    };
    let cameras = read("scene_camera.json");
    let k = cameras["0"]["cam_K"].as_array().unwrap();
    assert_eq!(k.len(), 9);
    // BOP's principal point is Glint's minus half a pixel.
    assert!((k[2].as_f64().unwrap() - 3.7).abs() < 1e-12);
    assert_eq!(cameras["0"]["depth_scale"], 0.1);
    assert_eq!(cameras["0"]["cam_t_w2c"].as_array().unwrap().len(), 3);
    assert!(cameras["1"].get("cam_R_w2c").is_none());
    let gt = read("scene_gt.json");
    assert_eq!(gt["0"][1]["obj_id"], 2);
    let t_mm = gt["0"][0]["cam_t_m2c"][2].as_f64().unwrap();
    assert!((t_mm - 612.34567891).abs() < 1e-9);
    let info = read("scene_gt_info.json");
    assert_eq!(info["0"][0]["bbox_obj"], serde_json::json!([0, 1, 3, 4]));
    for leftover in std::fs::read_dir(&scene.dir).unwrap() {
        let name = leftover.unwrap().file_name();
        assert!(!name.to_string_lossy().ends_with(".tmp"), "{name:?}");
    }
}

/// A T-LESS-style scene written by hand: `rgb/`, extra keys, no `cam_R_w2c`, float32
/// rotations, no masks and no GT info.
#[test]
fn a_hand_written_t_less_style_scene_reads() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("test_primesense").join("000002");
    std::fs::create_dir_all(dir.join("depth")).unwrap();
    std::fs::create_dir_all(dir.join("rgb")).unwrap();
    std::fs::write(
        dir.join("scene_camera.json"),
        r#"{
  "0": {"cam_K": [1075.65091572, 0.0, 364.06888344, 0.0, 1073.90347929, 301.72159802, 0.0, 0.0, 1.0], "depth_scale": 0.1, "elev": 75, "mode": 0},
  "3": {"cam_K": [1075.65091572, 0.0, 359.5, 0.0, 1073.90347929, 299.5, 0.0, 0.0, 1.0], "depth_scale": 0.1, "elev": 75, "mode": 0}
}"#,
    )
    .unwrap();
    // A rotation of 30° about z, rounded to 8 digits as the datasets' float32 values are.
    std::fs::write(
        dir.join("scene_gt.json"),
        r#"{
  "0": [{"cam_R_m2c": [0.86602539, -0.5, 0.0, 0.5, 0.86602539, 0.0, 0.0, 0.0, 1.0], "cam_t_m2c": [-12.5, 33.25, 651.0], "obj_id": 5}],
  "3": []
}"#,
    )
    .unwrap();
    let units = Image::new(
        4,
        3,
        vec![6510u16, 0, 6520, 6530, 1, 2, 3, 0, 65535, 9, 9, 9],
    )
    .unwrap();
    let rgb = image::RgbImage::from_fn(4, 3, |u, v| {
        image::Rgb([(u * 60) as u8, (v * 100) as u8, 7])
    });
    for im_id in ["000000", "000003"] {
        crate::dataset::image_files::write_png_u16(
            &dir.join("depth").join(format!("{im_id}.png")),
            &units,
        )
        .unwrap();
        rgb.save(dir.join("rgb").join(format!("{im_id}.png")))
            .unwrap();
    }

    let reader = BopSceneReader::open(&dir).unwrap();
    assert_eq!(reader.image_ids(), vec![0, 3]);
    let camera = reader.camera(0).unwrap();
    assert_eq!(
        (camera.intrinsics.width_px, camera.intrinsics.height_px),
        (4, 3)
    );
    assert!((camera.intrinsics.cx_px - 364.56888344).abs() < 1e-9);
    assert!((camera.intrinsics.cy_px - 302.22159802).abs() < 1e-9);
    assert_eq!(camera.depth_scale_mm, Some(0.1));
    assert_eq!(camera.t_c_w, None);

    let gt = reader.gt(0).unwrap();
    assert_eq!(gt[0].obj_id, 5);
    let expected = pose([-0.0125, 0.03325, 0.651], [0.0, 0.0, 30f64.to_radians()]);
    let (t, r) = pose_errors(&gt[0].t_c_o, &expected);
    assert!(t < 1e-15 && r < 1e-7, "{t} {r}");
    assert_eq!(reader.gt(3), Some(&[][..]));
    assert!(reader.gt_info(0).is_none());

    let depth = reader.depth(3).unwrap();
    assert!((depth.depth_m.data()[0] - 0.651).abs() < 1e-7);
    assert!(depth.depth_m.data()[1].is_nan());
    assert!((depth.depth_m.data()[8] - 6.5535).abs() < 1e-6);
    let gray = reader.gray(0).unwrap();
    assert_eq!((gray.width(), gray.height()), (4, 3));
    assert_eq!(
        gray.data(),
        image::DynamicImage::ImageRgb8(rgb)
            .to_luma8()
            .as_raw()
            .as_slice()
    );

    let err = reader.mask(0, 0, MaskKind::Visible).unwrap_err();
    assert!(
        err.to_string().contains("mask_visib/000000_000000.png"),
        "{err}"
    );
    let err = reader.camera(1).unwrap_err();
    assert_eq!(err.key(), Some("/1"));
    assert_eq!(reader.gt_materials().unwrap(), None);
}

#[test]
fn the_image_size_falls_back_to_camera_json_or_an_argument() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("val").join("000000");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("scene_camera.json"),
        r#"{"0": {"cam_K": [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]}}"#,
    )
    .unwrap();
    let reader = BopSceneReader::open(&dir).unwrap();
    let err = reader.camera(0).unwrap_err();
    assert!(err.to_string().contains("with_image_size"), "{err}");
    assert!(!reader.has_gt());
    let err = reader.depth(0).unwrap_err();
    assert_eq!(err.key(), Some("/0/depth_scale"));

    let camera = BopCamera {
        intrinsics: PinholeIntrinsics::new(640, 480, 500.0, 500.0, 320.0, 240.0).unwrap(),
        depth_scale_mm: Some(1.0),
        t_c_w: None,
    };
    write_dataset_camera(&root.path().join("camera.json"), &camera).unwrap();
    assert_eq!(
        read_dataset_camera(&root.path().join("camera.json")).unwrap(),
        camera
    );
    let from_file = reader.camera(0).unwrap();
    assert_eq!(from_file.intrinsics, camera.intrinsics);
    assert_eq!(from_file.depth_scale_mm, None);
    let given = reader.with_image_size(64, 48).camera(0).unwrap();
    assert_eq!(
        (given.intrinsics.width_px, given.intrinsics.cx_px),
        (64, 320.0)
    );
}

/// XYZ-IBD's test scenes suffix every file with the sensor.
#[test]
fn multi_sensor_scenes_open_per_sensor() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("test").join("000001");
    std::fs::create_dir_all(dir.join("gray_xyz")).unwrap();
    std::fs::create_dir_all(dir.join("depth_xyz")).unwrap();
    let camera = r#"{"0": {"cam_K": [2000, 0, 719.5, 0, 2000, 539.5, 0, 0, 1], "depth_scale": 0.1, "cam_R_w2c": [1, 0, 0, 0, 1, 0, 0, 0, 1], "cam_t_w2c": [0, 0, 1000]}}"#;
    for sensor in ["xyz", "photoneo"] {
        std::fs::write(dir.join(format!("scene_camera_{sensor}.json")), camera).unwrap();
    }
    let gray = Image::filled(6, 4, 100u8).unwrap();
    crate::dataset::image_files::write_png_u8(&dir.join("gray_xyz/000000.png"), &gray).unwrap();
    let depth = Image::filled(6, 4, 7000u16).unwrap();
    crate::dataset::image_files::write_png_u16(&dir.join("depth_xyz/000000.png"), &depth).unwrap();

    let err = BopSceneReader::open(&dir).unwrap_err();
    let message = err.to_string();
    assert!(
        message.contains("scene_camera.json") && message.contains("photoneo, xyz"),
        "{message}"
    );

    let reader = BopSceneReader::open_sensor(&dir, "xyz").unwrap();
    let camera = reader.camera(0).unwrap();
    assert_eq!(camera.intrinsics.width_px, 6);
    let t_c_w = camera.t_c_w.unwrap();
    assert!((t_c_w.translation.vector - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-15);
    assert_eq!(reader.gray(0).unwrap(), gray);
    assert!((reader.depth(0).unwrap().depth_m.data()[0] - 0.7).abs() < 1e-7);
    assert!(!reader.has_gt());
}

/// Writes `scene_camera.json` (and a valid `scene_gt.json`) and returns the open error.
fn open_with_camera_json(camera_json: &str) -> DatasetError {
    open_with(camera_json, r#"{"0": []}"#)
}

fn open_with(camera_json: &str, gt_json: &str) -> DatasetError {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene_camera.json"), camera_json).unwrap();
    std::fs::write(dir.path().join("scene_gt.json"), gt_json).unwrap();
    BopSceneReader::open(dir.path()).unwrap_err()
}

const GOOD_CAMERA: &str =
    r#"{"0": {"cam_K": [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1], "depth_scale": 0.1}}"#;

#[test]
fn malformed_files_are_errors_naming_file_and_key() {
    let err = open_with_camera_json(r#"{"0": {"cam_K": [500, 0, 319.5"#);
    assert!(matches!(err, DatasetError::Json { line: 1, .. }), "{err:?}");
    assert!(err.to_string().contains("scene_camera.json"), "{err}");

    let cases = [
        (r#"{"3": {"depth_scale": 0.1}}"#, "/3/cam_K", "missing"),
        (
            r#"{"3": {"cam_K": [500, 0, 319.5, 0, 500, 239.5, 0, 0]}}"#,
            "/3/cam_K",
            "found an array of 8",
        ),
        (
            r#"{"3": {"cam_K": [500, 0, 319.5, 0, "500", 239.5, 0, 0, 1]}}"#,
            "/3/cam_K/4",
            "expected a number",
        ),
        (
            r#"{"3": {"cam_K": [500, 2, 319.5, 0, 500, 239.5, 0, 0, 1]}}"#,
            "/3/cam_K",
            "skew",
        ),
        (
            r#"{"3": {"cam_K": [-5, 0, 319.5, 0, 500, 239.5, 0, 0, 1]}}"#,
            "/3/cam_K",
            "positive",
        ),
        (
            r#"{"3": {"cam_K": [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1], "depth_scale": 0}}"#,
            "/3/depth_scale",
            "positive",
        ),
        (
            r#"{"3": {"cam_K": [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1], "cam_R_w2c": [1, 0, 0, 0, 1, 0, 0, 0, 1]}}"#,
            "/3/cam_t_w2c",
            "missing",
        ),
        (
            r#"{"3": {"cam_K": [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1], "cam_R_w2c": [1, 0, 0, 0, 1, 0, 0, 0, 1.01], "cam_t_w2c": [0, 0, 0]}}"#,
            "/3/cam_R_w2c",
            "RᵀR",
        ),
        (
            r#"{"x3": {"cam_K": [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]}}"#,
            "/x3",
            "image id",
        ),
        (r#"[1, 2]"#, "/ (the top level)", "expected an object"),
        (r#"{"3": {"cam_model": {}}}"#, "/3", "cam_model"),
    ];
    for (json, key, words) in cases {
        let err = open_with_camera_json(json);
        assert_eq!(err.key(), Some(key), "{json}: {err}");
        let message = err.to_string();
        assert!(
            message.contains("scene_camera.json") && message.contains(words),
            "{json}: {message}"
        );
    }

    let gt_cases = [
        (
            r#"{"0": [{"obj_id": 1, "cam_R_m2c": [1, 0, 0, 0, 1, 0, 0, 0, 1], "cam_t_m2c": [0, 0, 500]}, {"obj_id": 2, "cam_R_m2c": [1, 0, 0, 0, 1, 0, 0, 0.1, 1], "cam_t_m2c": [0, 0, 500]}]}"#,
            "/0/1/cam_R_m2c",
            "not a rotation",
        ),
        (
            r#"{"0": [{"obj_id": 1, "cam_R_m2c": [-1, 0, 0, 0, 1, 0, 0, 0, 1], "cam_t_m2c": [0, 0, 500]}]}"#,
            "/0/0/cam_R_m2c",
            "reflection",
        ),
        (
            r#"{"0": [{"cam_R_m2c": [1, 0, 0, 0, 1, 0, 0, 0, 1], "cam_t_m2c": [0, 0, 500]}]}"#,
            "/0/0/obj_id",
            "missing",
        ),
        (
            r#"{"0": [{"obj_id": -4, "cam_R_m2c": [1, 0, 0, 0, 1, 0, 0, 0, 1], "cam_t_m2c": [0, 0, 500]}]}"#,
            "/0/0/obj_id",
            "out of range",
        ),
        (r#"{"0": {"obj_id": 1}}"#, "/0", "expected an array"),
    ];
    for (json, key, words) in gt_cases {
        let err = open_with(GOOD_CAMERA, json);
        assert_eq!(err.key(), Some(key), "{json}: {err}");
        let message = err.to_string();
        assert!(
            message.contains("scene_gt.json") && message.contains(words),
            "{json}: {message}"
        );
    }

    let dir = tempfile::tempdir().unwrap();
    let err = BopSceneReader::open(dir.path()).unwrap_err();
    assert!(matches!(err, DatasetError::Read { .. }), "{err:?}");
    assert!(err.to_string().contains("scene_camera.json"), "{err}");
}

#[test]
fn gt_info_must_match_the_gt() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene_camera.json"), GOOD_CAMERA).unwrap();
    std::fs::write(dir.path().join("scene_gt.json"), r#"{"0": []}"#).unwrap();
    let info = r#"{"0": [{"bbox_obj": [1, 2, 3, 4], "bbox_visib": [-1, -1, -1, -1], "px_count_all": 12, "px_count_valid": 10, "px_count_visib": 0, "visib_fract": 0.0}]}"#;
    std::fs::write(dir.path().join("scene_gt_info.json"), info).unwrap();
    let err = BopSceneReader::open(dir.path()).unwrap_err();
    assert_eq!(err.key(), Some("/0"));
    assert!(err.to_string().contains("scene_gt_info.json"), "{err}");

    std::fs::write(
        dir.path().join("scene_gt_info.json"),
        info.replace("0.0}", "1.5}"),
    )
    .unwrap();
    let err = BopSceneReader::open(dir.path()).unwrap_err();
    assert_eq!(err.key(), Some("/0/0/visib_fract"), "{err}");
}

#[test]
fn the_writer_refuses_what_it_cannot_store() {
    let dir = tempfile::tempdir().unwrap();
    assert!(BopSceneWriter::create(dir.path().join("a"), 0.0).is_err());

    let scene = dir.path().join("000000");
    let mut writer = BopSceneWriter::create(&scene, 0.1).unwrap();
    let mut z = vec![0.5f32; (WIDTH * HEIGHT) as usize];
    z[(2 * WIDTH + 5) as usize] = 7.0; // beyond 6.5535 m
    let err = writer
        .write_depth(0, &DepthMap::new(Image::new(WIDTH, HEIGHT, z).unwrap()))
        .unwrap_err();
    assert!(
        matches!(err, DatasetError::Pixel { u: 5, v: 2, .. }),
        "{err:?}"
    );
    let message = err.to_string();
    assert!(
        message.contains("depth/000000.png") && message.contains("16-bit"),
        "{message}"
    );
    assert!(!scene.join("depth/000000.png").exists());

    // Sizes must agree within an image.
    writer.set_camera(0, &intrinsics(), None).unwrap();
    let err = writer
        .write_gray(0, &Image::filled(3, 3, 0u8).unwrap())
        .unwrap_err();
    assert!(err.to_string().contains("3×3"), "{err}");

    // A mask for a GT instance that does not exist.
    writer
        .write_mask(
            0,
            1,
            MaskKind::Full,
            &Image::filled(WIDTH, HEIGHT, 255u8).unwrap(),
        )
        .unwrap();
    writer.set_gt(
        0,
        &[BopGt {
            obj_id: 1,
            t_c_o: Isometry3::identity(),
        }],
    );
    let err = writer.finish().unwrap_err();
    assert!(err.to_string().contains("000000_000001.png"), "{err}");
    assert!(!scene.join("scene_gt.json").exists());

    // GT info that does not match the GT, and GT without a camera.
    let mut writer = BopSceneWriter::create(&scene, 0.1).unwrap();
    writer.set_camera(0, &intrinsics(), None).unwrap();
    let empty = Image::filled(WIDTH, HEIGHT, 0u8).unwrap();
    let info = BopGtInfo::from_masks(&empty, &empty, None).unwrap();
    writer.set_gt_info(0, &[info.clone(), info]);
    assert!(
        writer
            .finish()
            .unwrap_err()
            .to_string()
            .contains("2 GT infos for 0")
    );
    let mut writer = BopSceneWriter::create(&scene, 0.1).unwrap();
    writer.set_gt(4, &[]);
    assert!(writer.finish().unwrap_err().to_string().contains("image 4"));

    let mut writer = BopSceneWriter::create(&scene, 0.1).unwrap();
    let labels = Image::filled(WIDTH, HEIGHT, 1u16).unwrap();
    assert!(
        writer
            .write_masks_from_labels(0, MaskKind::Visible, &labels, &[(1, 0), (2, 0)])
            .is_err()
    );
}

/// Corrupted JSON must give `Ok` or `Err`, never a panic.
#[test]
fn mutated_json_never_panics() {
    let root = tempfile::tempdir().unwrap();
    let scene = write_synthetic_scene(root.path());
    let files = ["scene_camera.json", "scene_gt.json", "scene_gt_info.json"];
    let originals: Vec<Vec<u8>> = files
        .iter()
        .map(|name| std::fs::read(scene.dir.join(name)).unwrap())
        .collect();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(0x0062_6f70);
    let mut outcomes = [0usize; 2];
    for round in 0..600 {
        let which = round % files.len();
        let mut mutant = originals[which].clone();
        for _ in 0..rng.random_range(1..=3) {
            let at = rng.random_range(0..mutant.len());
            mutant[at] = b"0123456789-.e,[]{}\": x"[rng.random_range(0..22)];
        }
        if round % 5 == 0 {
            mutant.truncate(rng.random_range(0..mutant.len()));
        }
        std::fs::write(scene.dir.join(files[which]), &mutant).unwrap();
        let result = BopSceneReader::open(&scene.dir).and_then(|reader| {
            for im_id in reader.image_ids() {
                reader.camera(im_id)?;
            }
            Ok(())
        });
        outcomes[result.is_ok() as usize] += 1;
        std::fs::write(scene.dir.join(files[which]), &originals[which]).unwrap();
    }
    assert!(outcomes[0] > 100, "{outcomes:?}");
}

/// An axis-aligned box mesh, `size` in metres, centred on the origin.
fn box_mesh(size: [f32; 3]) -> TriMesh {
    let h = [size[0] / 2.0, size[1] / 2.0, size[2] / 2.0];
    let vertices = (0..8)
        .map(|i| {
            Point3::new(
                if i & 1 == 0 { -h[0] } else { h[0] },
                if i & 2 == 0 { -h[1] } else { h[1] },
                if i & 4 == 0 { -h[2] } else { h[2] },
            )
        })
        .collect();
    let triangles = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    TriMesh::new(vertices, triangles)
}

#[test]
fn models_round_trip_with_diameters_and_symmetries() {
    let dir = tempfile::tempdir().unwrap();
    let models_dir = dir.path().join("models");
    let cuboid = box_mesh([0.04, 0.02, 0.01]);
    let cuboid_symmetry: Symmetry = "dihedral:z:2:x".parse().unwrap();
    let parts: Vec<(TriMesh, Symmetry)> =
        Part::ALL.iter().map(|p| (p.mesh(), p.symmetry())).collect();
    let mut models: Vec<(u32, &TriMesh, &Symmetry)> = vec![(1, &cuboid, &cuboid_symmetry)];
    for (i, (mesh, symmetry)) in parts.iter().enumerate() {
        models.push((i as u32 + 2, mesh, symmetry));
    }
    let written = write_models(&models_dir, &models).unwrap();
    let read = read_models_info(&models_dir.join("models_info.json")).unwrap();
    assert_eq!(read.len(), models.len());

    let expected_cuboid = (0.04f64.powi(2) + 0.02f64.powi(2) + 0.01f64.powi(2)).sqrt();
    assert!(
        (read[&1].diameter_m - expected_cuboid).abs() < 1e-8,
        "{}",
        read[&1].diameter_m
    );
    for ((obj_id, mesh, symmetry), info) in models.iter().zip(&written) {
        let back = &read[obj_id];
        assert!((back.diameter_m - info.diameter_m).abs() < 1e-12);
        let bbox = back.bbox.unwrap();
        let diagonal = bbox.size_m.norm();
        assert!(back.diameter_m <= diagonal + 1e-9 && back.diameter_m >= bbox.size_m.max() - 1e-9);
        // Glint's own keys give the group back exactly, tolerance included.
        assert_eq!(&back.symmetry.to_glint(0.0).unwrap(), *symmetry);
        // BOP's lists alone give the same group, without Glint's tolerance.
        let bop_only = ModelSymmetry {
            glint: None,
            ..back.symmetry.clone()
        };
        let recognised = bop_only.to_glint(0.0).unwrap();
        assert!(
            same_group(&recognised, symmetry),
            "object {obj_id}: {recognised} vs {symmetry}"
        );
        assert_eq!(
            recognised.to_string(),
            symmetry.to_string(),
            "object {obj_id}"
        );

        let loaded = read_model(&models_dir, *obj_id).unwrap();
        assert_eq!(loaded.mesh.vertices.len(), mesh.vertices.len());
        let worst = loaded
            .mesh
            .vertices
            .iter()
            .zip(&mesh.vertices)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-7, "object {obj_id}: {worst} m");
    }
    assert!(
        write_models(
            &models_dir,
            &[
                (1, &cuboid, &cuboid_symmetry),
                (1, &cuboid, &cuboid_symmetry)
            ]
        )
        .is_err()
    );
}

/// Whether two groups have the same elements (and continuous axis, either direction).
fn same_group(a: &Symmetry, b: &Symmetry) -> bool {
    let contains = |x: &Symmetry, y: &Symmetry| {
        y.discrete_rotations()
            .iter()
            .all(|r| x.discrete_rotations().iter().any(|q| q.angle_to(r) < 1e-9))
    };
    let axes_match = match (a.continuous_axis(), b.continuous_axis()) {
        (Some(p), Some(q)) => p.dot(&q).abs() > 1.0 - 1e-12,
        (None, None) => true,
        _ => false,
    };
    a.discrete_order() == b.discrete_order() && contains(a, b) && contains(b, a) && axes_match
}

#[test]
fn bop_symmetry_lists_are_recognised_or_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("models_info.json");
    std::fs::write(
        &path,
        r#"{
  "1": {"diameter": 102.1, "min_x": -10, "min_y": -10, "min_z": -40, "size_x": 20, "size_y": 20, "size_z": 80,
        "symmetries_continuous": [{"axis": [0, 0, -1], "offset": [0, 0, 0]}]},
  "2": {"diameter": 50, "symmetries_discrete": [[-1, 0, 0, 0.01, 0, -1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]]},
  "3": {"diameter": 50, "symmetries_discrete": [[1, 0, 0, 0, 0, 0.7071068, -0.7071068, 0, 0, 0.7071068, 0.7071068, 0, 0, 0, 0, 1]]},
  "4": {"diameter": 50, "symmetries_continuous": [{"axis": [0, 0, 1], "offset": [5, 0, 0]}]},
  "5": {"diameter": 50}
}"#,
    )
    .unwrap();
    let infos = read_models_info(&path).unwrap();
    assert_eq!(
        infos[&1].symmetry.to_glint(0.0).unwrap().to_string(),
        "continuous:z"
    );
    assert!((infos[&1].bbox.unwrap().size_m.z - 0.08).abs() < 1e-15);
    let two = infos[&2].symmetry.to_glint(1e-4).unwrap();
    assert_eq!(two.to_string(), "discrete:z:2");
    assert!((two.tolerance_m - 1e-5).abs() < 1e-12);
    assert!(
        infos[&2]
            .symmetry
            .to_glint(1e-6)
            .unwrap_err()
            .contains("0.010 mm")
    );
    // A 45° turn alone does not close into a group of order 2.
    assert!(infos[&3].symmetry.to_glint(0.0).is_err());
    assert!(infos[&4].symmetry.to_glint(1e-3).is_err());
    assert!(infos[&5].bbox.is_none());
    assert_eq!(
        infos[&5].symmetry.to_glint(0.0).unwrap().to_string(),
        "none"
    );

    std::fs::write(&path, r#"{"1": {"diameter": -3}}"#).unwrap();
    assert_eq!(
        read_models_info(&path).unwrap_err().key(),
        Some("/1/diameter")
    );
    std::fs::write(
        &path,
        r#"{"1": {"diameter": 3, "symmetries_discrete": [[1, 0, 0]]}}"#,
    )
    .unwrap();
    assert_eq!(
        read_models_info(&path).unwrap_err().key(),
        Some("/1/symmetries_discrete/0")
    );
    std::fs::write(
        &path,
        r#"{"1": {"diameter": 3, "glint_symmetry": "discrete:q:2"}}"#,
    )
    .unwrap();
    assert_eq!(
        read_models_info(&path).unwrap_err().key(),
        Some("/1/glint_symmetry")
    );
}

#[test]
fn large_meshes_get_a_subsampled_diameter_through_the_extremes() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let mut vertices: Vec<Point3<f32>> = (0..EXACT_DIAMETER_MAX_VERTICES + 10_000)
        .map(|_| Point3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    vertices.push(Point3::new(-0.5, -0.5, -0.5));
    vertices.push(Point3::new(1.5, 1.5, 1.5));
    let mesh = TriMesh::new(vertices, vec![[0, 1, 2]]);
    let diameter = mesh_diameter_m(&mesh);
    assert!((diameter - 12f64.sqrt()).abs() < 1e-6, "{diameter}");
    assert_eq!(mesh_diameter_m(&TriMesh::default()), 0.0);
}
