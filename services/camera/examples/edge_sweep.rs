//! Matcher variants on the same captures: renders `glint capture`'s scenes once (a bin of one
//! part, shiny and diffuse twin, the same views) and re-matches the read-out pattern images
//! with each variant, printing part coverage, RMSE, the share off by > 5 mm, and where the
//! wrong pixels are relative to depth edges. The evidence behind the matcher's defaults for
//! small parts (issue 3).
//!
//! `cargo run --release -p glint-camera --example edge_sweep -- chrome-screw [views] [variants]`
//! with variants a comma list of the names below (default: all). "one-window" is the matcher
//! before edge windows (`StereoMatcherConfig::edge_windows = None`).

use glint_camera::bin::{BinSpec, bin_scene, drop_parts};
use glint_camera::capture::{
    CaptureConfig, CaptureTruth, DepthQuality, MockSliCamera, StereoCapture, depth_quality,
};
use glint_camera::edge_errors::errors_by_edge_distance;
use glint_camera::{materials, views};
use glint_geometry::parts::Part;
use glint_render::rig::SliRig;
use glint_render::stereo::{EdgeWindows, StereoMatcherConfig};

fn variants(base: &StereoMatcherConfig) -> Vec<(&'static str, StereoMatcherConfig)> {
    let with = |f: &dyn Fn(&mut StereoMatcherConfig)| {
        let mut c = *base;
        f(&mut c);
        c
    };
    let edge = |r: u32| {
        Some(EdgeWindows {
            window_radius_px: r,
            step_px: 2.0,
        })
    };
    vec![
        ("default", *base),
        ("one-window", with(&|c| c.edge_windows = None)),
        (
            "one-window r4",
            with(&|c| {
                c.window_radius_px = 4;
                c.edge_windows = None
            }),
        ),
        (
            "one-window r3",
            with(&|c| {
                c.window_radius_px = 3;
                c.edge_windows = None
            }),
        ),
        ("edge r4", with(&|c| c.edge_windows = edge(4))),
        ("edge r2", with(&|c| c.edge_windows = edge(2))),
        (
            "one-window gain0.05",
            with(&|c| {
                c.edge_windows = None;
                c.shifted_window_min_gain = Some(0.05)
            }),
        ),
        (
            "one-window lr0.5",
            with(&|c| {
                c.edge_windows = None;
                c.left_right_max_diff_px = Some(0.5)
            }),
        ),
        (
            "one-window uniq0.3",
            with(&|c| {
                c.edge_windows = None;
                c.uniqueness_margin = 0.3
            }),
        ),
        (
            "one-window corr0.7",
            with(&|c| {
                c.edge_windows = None;
                c.min_correlation = 0.7
            }),
        ),
    ]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let part: Part = args
        .get(1)
        .map_or("chrome-screw", String::as_str)
        .parse()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let view_count: usize = args.get(2).map_or(Ok(4), |s| s.parse())?;
    let wanted: Option<Vec<String>> = args
        .get(3)
        .map(|s| s.split(',').map(str::to_owned).collect());
    // The scene and views of `glint capture --part P --instances 8 --seed 1`.
    let rig = SliRig::ensenso_n35();
    let bin = BinSpec::default();
    let mesh = part.mesh();
    let poses = drop_parts(&mesh, 8, &bin, 1)?;
    let shiny = bin_scene(&mesh, &poses, materials::ground_truth(part), &bin)?;
    let matte = bin_scene(&mesh, &poses, materials::diffuse_twin(), &bin)?;
    let config = CaptureConfig::for_rig(&rig)?;
    let views = views::spherical_cap(view_count, 0.5, 35.0, bin.centre(), rig.stereo.baseline_m);
    let scenes = [("shiny", &shiny), ("diffuse", &matte)];
    let mut captures: Vec<Vec<(StereoCapture, CaptureTruth)>> = vec![Vec::new(), Vec::new()];
    for (k, t_w_c) in views.iter().enumerate() {
        let seed = 1000 + k as u64;
        for (i, (_, scene)) in scenes.iter().enumerate() {
            let camera = MockSliCamera {
                rig,
                scene,
                config: config.clone(),
            };
            captures[i].push(camera.capture(t_w_c, seed)?);
        }
    }
    let labels: Vec<u16> = (1..=8).collect();
    println!(
        "| variant | material | part pixels | coverage | RMSE (mm) | > 5 mm | > 5 mm at 0–2 px | > 5 mm at ≥ 3 px |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|");
    for (name, matcher) in variants(&config.matcher) {
        if wanted
            .as_ref()
            .is_some_and(|w| !w.iter().any(|x| x == name))
        {
            continue;
        }
        for (i, (material, scene)) in scenes.iter().enumerate() {
            let camera = MockSliCamera {
                rig,
                scene,
                config: CaptureConfig {
                    matcher,
                    ..config.clone()
                },
            };
            let mut qualities = Vec::new();
            let (mut near_edge, mut far_edge) = (0usize, 0usize);
            for (capture, truth) in &captures[i] {
                let (depth, match_status) = camera.match_pair(&capture.left, &capture.right)?;
                let rematched = StereoCapture {
                    depth,
                    match_status,
                    ..capture.clone()
                };
                for &label in &labels {
                    // The base radius decides eligibility, so every variant has the same
                    // pixels; like `glint capture`'s totals, instances with fewer than 200
                    // eligible pixels are left out.
                    let q = depth_quality(
                        &rematched,
                        truth,
                        &rig,
                        config.matcher.window_radius_px,
                        Some(label),
                    );
                    if q.eligible >= 200 {
                        qualities.push(q);
                    }
                }
                let bins = errors_by_edge_distance(&rematched, truth, &labels, &[2]);
                near_edge += bins[0].farther_5mm + bins[0].nearer_5mm;
                far_edge += bins[1].farther_5mm + bins[1].nearer_5mm;
            }
            let q = DepthQuality::pooled(qualities);
            println!(
                "| {name} | {material} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
                q.eligible,
                q.coverage(),
                q.rmse_m * 1e3,
                q.outlier_share(),
                near_edge as f64 / q.valid.max(1) as f64,
                far_edge as f64 / q.valid.max(1) as f64,
            );
        }
    }
    Ok(())
}
