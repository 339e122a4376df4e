//! The `glint` binary as a user runs it: exit codes, files written, messages on bad input.

mod common;

use std::path::Path;
use std::process::Output;

use common::{argv, glint};

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Asserts the run failed with `code` and a message, not a panic; returns stderr.
fn fails_cleanly(o: &Output, code: i32) -> String {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(code), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(!err.trim().is_empty());
    err
}

#[test]
fn export_then_info_round_trips_every_part() {
    let dir = tempfile::tempdir().unwrap();
    for part in ["eye-bolt", "tube-fitting", "chrome-screw", "gear", "zigzag"] {
        let ply = dir.path().join(format!("{part}.ply"));
        let png = dir.path().join(format!("{part}.png"));
        let o = glint(argv(
            "mesh export --part {} --out {} --preview {}",
            &[part, ply.to_str().unwrap(), png.to_str().unwrap()],
        ));
        assert!(o.status.success(), "{part}: {}", stderr(&o));
        let preview = image::open(&png).unwrap();
        assert_eq!((preview.width(), preview.height()), (512, 512));

        let o = glint(argv(
            "mesh info {} --unit mm --format json",
            &[ply.to_str().unwrap()],
        ));
        assert!(o.status.success(), "{part}: {}", stderr(&o));
        let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(info["watertight"], true, "{part}: {info}");
        assert!(
            info["warnings"].as_array().unwrap().is_empty(),
            "{part}: {info}"
        );
        // ROBI-like size: every part spans tens of millimetres.
        let extent: Vec<f64> = info["extent_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let longest = extent.iter().cloned().fold(0.0, f64::max);
        assert!((10.0..=100.0).contains(&longest), "{part}: {extent:?}");
    }
}

#[test]
fn bad_input_gets_a_clear_error_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.ply");
    let err = fails_cleanly(
        &glint(argv("mesh info {} --unit mm", &[missing.to_str().unwrap()])),
        1,
    );
    assert!(err.contains("missing.ply"), "{err}");

    let garbage = dir.path().join("garbage.stl");
    std::fs::write(
        &garbage,
        b"solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 nope\n",
    )
    .unwrap();
    let err = fails_cleanly(
        &glint(argv("mesh info {} --unit mm", &[garbage.to_str().unwrap()])),
        1,
    );
    assert!(err.contains("garbage.stl"), "{err}");

    // clap's usage errors exit with 2 and list what is valid.
    let err = fails_cleanly(
        &glint(argv("mesh export --part sprocket --out x.ply", &[])),
        2,
    );
    assert!(err.contains("chrome-screw"), "{err}");
    let err = fails_cleanly(
        &glint(argv(
            "mesh info {} --unit inch",
            &[garbage.to_str().unwrap()],
        )),
        2,
    );
    assert!(err.contains("mm"), "{err}");

    let nowhere = dir.path().join("no/such/dir/gear.ply");
    let err = fails_cleanly(
        &glint(argv(
            "mesh export --part gear --out {}",
            &[nowhere.to_str().unwrap()],
        )),
        1,
    );
    assert!(err.contains("does not exist"), "{err}");
    assert!(!Path::new(&nowhere).exists());
}

#[test]
fn capture_writes_a_bop_scene_that_reads_back() {
    use glint_camera::dataset::bop::BopSceneReader;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cap");
    let o = glint(argv(
        "capture --part gear --instances 3 --views 2 --seed 5 \
        --resolution 320x256 --spp 1 --out {}",
        &[out.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", stderr(&o));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("missing depth"), "{report}");

    let scene = BopSceneReader::open(out.join("test/000001")).unwrap();
    assert_eq!(scene.image_ids(), vec![0, 1]);
    for im_id in [0, 1] {
        let gts = scene.gt(im_id).unwrap();
        assert!(!gts.is_empty() && gts.len() <= 3);
        for gt in gts {
            // Views are 0.5 m from the bin's floor centre; parts lie within ~0.15 m of it.
            let z = gt.t_c_o.translation.z;
            assert!((0.35..0.65).contains(&z), "part at z = {z} m");
        }
        let depth = scene.depth(im_id).unwrap();
        assert_eq!((depth.depth_m.width(), depth.depth_m.height()), (320, 256));
        assert!(
            depth.coverage() > 0.05,
            "matched depth on the bin at least: {}",
            depth.coverage()
        );
        // The float EXR of the same view holds the same matched depth, unquantised.
        let exr = glint_render::exr_io::read_exr(&out.join(format!("view_{im_id:03}/capture.exr")))
            .unwrap();
        let names: Vec<&str> = exr.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names.len(), 4, "{names:?}");
        let exr_depth = &exr.iter().find(|(n, _)| n == "depth_m").unwrap().1;
        for (a, b) in exr_depth.data().iter().zip(depth.depth_m.data()) {
            assert_eq!(a.is_finite(), b.is_finite());
            if a.is_finite() {
                assert!(
                    (a - b).abs() <= 0.5e-4 + 1e-6,
                    "BOP depth is quantised to 0.1 mm: {a} vs {b}"
                );
            }
        }
    }
    assert!(scene.gt_materials().unwrap().is_some());
    // scene_gt_info: one entry per GT instance, visible ⊆ amodal, agreeing with the masks.
    for im_id in [0, 1] {
        let infos = scene.gt_info(im_id).unwrap();
        assert_eq!(infos.len(), scene.gt(im_id).unwrap().len());
        for (gt_index, info) in infos.iter().enumerate() {
            use glint_camera::dataset::bop::MaskKind;
            let count = |kind| {
                let m = scene.mask(im_id, gt_index, kind).unwrap();
                m.data().iter().filter(|&&x| x != 0).count() as u64
            };
            assert_eq!(info.px_count_all, count(MaskKind::Full));
            assert_eq!(info.px_count_visib, count(MaskKind::Visible));
            assert!(info.px_count_visib <= info.px_count_all && info.px_count_all > 0);
            assert!(info.px_count_valid <= info.px_count_all);
            let ratio = info.px_count_visib as f64 / info.px_count_all as f64;
            assert!((info.visib_fract - ratio).abs() < 1e-12);
        }
    }

    let err = fails_cleanly(
        &glint(argv("capture --part gear --resolution 12x7 --out x", &[])),
        2,
    );
    assert!(err.contains("64 to 8192"), "{err}");
}

#[test]
fn capture_exposure_stack_writes_the_calibration_layout() {
    use glint_camera::dataset::ExposureStackFiles;
    use glint_camera::dataset::bop::BopSceneReader;
    use glint_camera::dataset::rig_file::{read_gt_sensor_json, read_rig_json};
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("stack");
    let o = glint(argv(
        "capture --part gear --instances 3 --views 1 --resolution 160x128 \
        --spp 1 --exposure-stack 4,0.5,1 --out {}",
        &[out.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", stderr(&o));
    let scene_dir = out.join("test/000001");
    let stack = ExposureStackFiles::read(scene_dir.join("glint/exposure_stack/000000")).unwrap();
    assert_eq!(stack.exposures_s, vec![0.5e-3, 1e-3, 4e-3]);
    assert_eq!(
        (stack.pattern.as_str(), stack.camera.as_str()),
        ("white", "left")
    );
    assert_eq!(stack.bit_depth, 8);
    assert_eq!(stack.images.len(), 3);
    // The same radiance read out 8× longer: brighter on average, pixel for pixel mostly.
    let mean = |k: usize| {
        stack.images[k]
            .data()
            .iter()
            .map(|&d| d as f64)
            .sum::<f64>()
    };
    assert!(mean(2) > 2.0 * mean(0), "{} vs {}", mean(2), mean(0));
    let gt = glint_render::exr_io::read_exr(
        &scene_dir.join("glint/exposure_stack/000000/gt_left_radiance.exr"),
    )
    .unwrap();
    assert_eq!(gt[0].0, "gt_left_radiance");
    assert_eq!((gt[0].1.width(), gt[0].1.height()), (160, 128));
    let rig = read_rig_json(&scene_dir.join("glint/rig.json")).unwrap();
    assert_eq!(rig.stereo.intrinsics.width_px, 160);
    assert!((rig.stereo.baseline_m - 0.10118).abs() < 1e-9);
    let sensor = read_gt_sensor_json(&scene_dir.join("glint/gt_sensor.json")).unwrap();
    assert_eq!(sensor.bit_depth, stack.bit_depth);
    // The BOP files of the same view: camera pose, GT poses and masks.
    let scene = BopSceneReader::open(&scene_dir).unwrap();
    assert_eq!(scene.image_ids(), vec![0]);
    let camera = scene.camera(0).unwrap();
    assert_eq!(camera.intrinsics.width_px, 160);
    assert!(camera.t_c_w.is_some());
    let gts = scene.gt(0).unwrap();
    assert!(!gts.is_empty());
    assert_eq!(scene.gt_info(0).unwrap().len(), gts.len());
    let mask = scene
        .mask(0, 0, glint_camera::dataset::bop::MaskKind::Full)
        .unwrap();
    assert_eq!((mask.width(), mask.height()), (160, 128));

    let err = fails_cleanly(
        &glint(argv(
            "capture --part gear --exposure-stack 1 --out {}",
            &[out.to_str().unwrap()],
        )),
        2,
    );
    assert!(err.contains("at least 2"), "{err}");
}

#[test]
fn render_bench_exports_a_scene_for_mitsuba() {
    use glint_geometry::LengthUnit;
    use glint_geometry::io::read_mesh;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("mitsuba");
    let o = glint(argv(
        "bench render --part zigzag --instances 2 --mitsuba-export {} \
        --export-resolution 128x96 --export-spp 1",
        &[out.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", stderr(&o));
    let scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("scene.json")).unwrap()).unwrap();

    // Two parts and the bin, in the world frame and in metres: the parts lie inside the bin.
    let shapes = scene["shapes"].as_array().unwrap();
    assert_eq!(shapes.len(), 3, "{scene}");
    let mesh_of = |s: &serde_json::Value| {
        read_mesh(&out.join(s["file"].as_str().unwrap()), LengthUnit::Metre)
            .unwrap()
            .mesh
    };
    let bin = shapes.iter().find(|s| s["name"] == "bin").unwrap();
    let (bin_lo, bin_hi) = mesh_of(bin).aabb().unwrap();
    for s in shapes.iter().filter(|s| s["name"] != "bin") {
        let mesh = mesh_of(s);
        assert_eq!(mesh.triangles.len(), 708, "the zigzag's triangles");
        let (lo, hi) = mesh.aabb().unwrap();
        for k in 0..3 {
            assert!(lo[k] >= bin_lo[k] && hi[k] <= bin_hi[k], "{s}: {lo} {hi}");
        }
        let material = &scene["materials"][s["material"].as_u64().unwrap() as usize];
        assert_eq!(material["name"], "zigzag");
    }
    let k = &scene["camera"]["intrinsics"];
    assert_eq!(
        (k["width_px"].as_u64(), k["height_px"].as_u64()),
        (Some(128), Some(96))
    );
    assert!((k["fx_px"].as_f64().unwrap() - 1083.1 * 0.1).abs() < 1e-9);

    // Glint's renders: the same first camera ray per pixel, so multi-path only adds light.
    let renders = scene["renders"].as_array().unwrap();
    assert_eq!(renders.len(), 2);
    let radiance = |r: &serde_json::Value| {
        let channels =
            glint_render::exr_io::read_exr(&out.join(r["exr"].as_str().unwrap())).unwrap();
        let get = |name: &str| channels.iter().find(|(n, _)| n == name).unwrap().1.clone();
        let (radiance, depth, label) = (get("radiance"), get("depth_m"), get("label"));
        assert_eq!((radiance.width(), radiance.height()), (128, 96));
        for (d, l) in depth.data().iter().zip(label.data()) {
            assert_eq!(d.is_finite(), *l != 0.0, "depth where something is hit");
        }
        radiance
    };
    let (single, multi) = (radiance(&renders[0]), radiance(&renders[1]));
    assert_eq!(renders[0]["transport"], "single-path");
    assert!(single.data().iter().any(|&x| x > 0.0));
    for (s, m) in single.data().iter().zip(multi.data()) {
        assert!(s.is_finite() && *s >= 0.0);
        assert!(*m >= s * (1.0 - 1e-5), "multi-path {m} < single-path {s}");
    }
}

#[test]
fn refine_bench_prints_its_table_writes_csv_and_exports_problems() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("refine.csv");
    let export = dir.path().join("export");
    let o = glint(argv(
        "bench refine --part gear --points 300 --views 1,2 --threads 1 \
        --iterations 15 --repeats 1 --model-samples 3000 --csv {} \
        --export {}",
        &[csv.to_str().unwrap(), export.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    // Header, separator and one row per view count and method.
    let table: Vec<&str> = stdout.lines().filter(|l| l.starts_with("| ")).collect();
    assert_eq!(table.len(), 1 + 2 * 3, "{stdout}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 6);
    let mut methods: Vec<&str> = rows.iter().map(|r| r[col("method")]).collect();
    methods.sort();
    assert_eq!(
        methods,
        [
            "icp-p2p",
            "icp-p2p",
            "icp-p2plane",
            "icp-p2plane",
            "sdf",
            "sdf"
        ]
    );
    for r in &rows {
        assert_eq!(r.len(), header.len());
        let num = |name: &str| r[col(name)].parse::<f64>().unwrap();
        assert_eq!(num("points"), 300.0);
        // The initial pose is 3 mm / 3° off by construction; every method must get closer.
        assert!((num("initial_t_mm") - 3.0).abs() < 1e-6);
        assert!(num("t_err_mm") < num("initial_t_mm"), "{r:?}");
        assert!(num("r_err_deg") < num("initial_r_deg"), "{r:?}");
        assert!(num("time_ms_median") > 0.0 && num("point_evals_per_s") > 0.0);
        assert!(num("point_passes") >= num("iterations"));
    }
    for views in [1, 2] {
        let sub = export.join(format!("gear_p300_v{views}"));
        let unit = glint_geometry::mesh::LengthUnit::Metre;
        let data = glint_geometry::io::read_ply_points(&sub.join("points.ply"), unit).unwrap();
        assert_eq!(data.len(), 300);
        let model = glint_geometry::io::read_ply_points(&sub.join("model.ply"), unit).unwrap();
        assert_eq!(model.len(), 3000);
        let problem: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(sub.join("problem.json")).unwrap())
                .unwrap();
        assert_eq!(problem["t_o_w_init"].as_array().unwrap().len(), 16);
        assert_eq!(problem["t_o_w_gt"].as_array().unwrap().len(), 16);
        let glint: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(sub.join("glint.json")).unwrap())
                .unwrap();
        assert_eq!(glint["runs"].as_array().unwrap().len(), 3);
    }
}

#[test]
fn nbv_bench_judges_its_cheaper_decisions_by_the_full_one() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("variants.csv");
    let o = glint(argv(
        "bench nbv --part zigzag --candidates 4 --instances 3 --resolution 640x512 \
        --shortlist 2,9 --prediction-spp 1,2 --variants-csv {}",
        &[csv.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(&csv).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some(
            "threads,candidates,shortlist,prediction_spp,screen_ms,total_ms,chosen,\
             reference_rank,entropy_regret_nats"
        )
    );
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    // K ∈ {2, all (9 ≥ 4 candidates)} × spp ∈ {1, 2}.
    assert_eq!(rows.len(), 4, "{csv}");
    for row in &rows {
        let rank: usize = row[7].parse().unwrap();
        let regret: f64 = row[8].parse().unwrap();
        assert!((1..=4).contains(&rank) && regret >= 0.0, "{row:?}");
        // Rank 1 means no candidate has less entropy: no regret, and the converse.
        assert_eq!(rank == 1, regret == 0.0, "{row:?}");
    }
    // Every candidate at the workers' 2 spp is the full decision again, render seeds and all.
    let same = rows.iter().find(|r| r[2] == "4" && r[3] == "2").unwrap();
    assert_eq!((same[7].as_str(), same[8].as_str()), ("1", "0.000000"));
}

#[test]
fn nbv_bench_exports_its_candidates_and_crops_for_mitsuba() {
    use glint_geometry::LengthUnit;
    use glint_geometry::io::read_mesh;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("nbv");
    let csv = dir.path().join("nbv.csv");
    let o = glint(argv(
        "bench nbv --part zigzag --candidates 3 --instances 3 \
        --resolution 320x256 --csv {} --mitsuba-export {}",
        &[csv.to_str().unwrap(), out.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(&csv).unwrap();
    assert!(csv.starts_with("threads,candidates,render_ms,sigma_ms,fim_ms,entropy_ms,total_ms\n"));
    let scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("nbv_scene.json")).unwrap())
            .unwrap();
    assert_eq!(
        scene["glint"].as_array().unwrap().len(),
        2,
        "1 thread and all"
    );
    // The part (label 1, at the hypothesis pose) and the bin it lies in.
    let shapes = scene["shapes"].as_array().unwrap();
    assert_eq!(shapes.len(), 2, "{scene}");
    assert_eq!(shapes[0]["label"], 1);
    let mesh = |s: &serde_json::Value| {
        read_mesh(&out.join(s["file"].as_str().unwrap()), LengthUnit::Metre)
            .unwrap()
            .mesh
    };
    let (lo, hi) = mesh(&shapes[0]).aabb().unwrap();
    let centre_w = nalgebra::Point3::from(((lo.coords + hi.coords) / 2.0).cast::<f64>());

    let candidates = scene["candidates"].as_array().unwrap();
    assert_eq!(candidates.len(), 3);
    let matrix = |v: &serde_json::Value| {
        let rows: Vec<Vec<f64>> = serde_json::from_value(v.clone()).unwrap();
        nalgebra::Matrix4::from_fn(|r, c| rows[r][c])
    };
    let mut with_crops = 0;
    for c in candidates {
        let Some(crops) = c["crops"].as_array() else {
            continue;
        };
        with_crops += 1;
        let left = &c["cameras"][0];
        let k = &left["intrinsics"];
        assert_eq!(k["width_px"], 320, "full-sensor intrinsics");
        let num = |v: &serde_json::Value, key: &str| v[key].as_f64().unwrap();
        // The part's centre projects into the left crop.
        let p_c = matrix(&left["t_w_c"]).try_inverse().unwrap() * centre_w.to_homogeneous();
        let u = num(k, "fx_px") * p_c.x / p_c.z + num(k, "cx_px");
        let v = num(k, "fy_px") * p_c.y / p_c.z + num(k, "cy_px");
        let (l, r) = (&crops[0], &crops[1]);
        assert!(
            u >= num(l, "u_min") && u < num(l, "u_min") + num(l, "width"),
            "{c}"
        );
        assert!(
            v >= num(l, "v_min") && v < num(l, "v_min") + num(l, "height"),
            "{c}"
        );
        // The right crop has the left's size and rows, shifted left by at least the centre's
        // disparity f·b/z (b: the right camera's offset along the left's x).
        assert_eq!(
            (&r["width"], &r["height"], &r["v_min"]),
            (&l["width"], &l["height"], &l["v_min"])
        );
        let baseline_m = (matrix(&left["t_w_c"]).try_inverse().unwrap()
            * matrix(&c["cameras"][1]["t_w_c"]))[(0, 3)];
        let disparity = num(k, "fx_px") * baseline_m / p_c.z;
        assert!(
            num(l, "u_min") - num(r, "u_min") >= disparity.floor(),
            "{c}"
        );
    }
    assert!(
        with_crops >= 1,
        "the part is in view of some candidate: {scene}"
    );
}
