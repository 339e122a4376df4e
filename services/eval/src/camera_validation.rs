//! The mock camera validated on geometry with a known answer, the way
//! hardware is validated (issue 16 item 4), never against the claims it will later test.
//!
//! For each part (its diffuse twin and its shiny ground-truth material, same drop), each shot
//! count K and each window radius r: the distance of every matched depth point of a part pixel
//! to the true model surface (|SDF| of the point in the pixel's true instance frame), its
//! median and 90th percentile, the share more than 2 mm off, and the coverage (part pixels with
//! depth); the same binned by the pixel's distance to the nearest true depth edge; and a diffuse
//! plane at 0.6 m seen head-on (depth RMSE without the 5 mm outliers, coverage). Each view is
//! rendered once for the largest K (one path trace per camera, every pattern evaluated from it)
//! and read out once per shot; the smaller K use the first K shots, and every (K, r) matches the
//! same read-outs. Wrong depth (> 2 mm off) is attributed to a cause per pixel
//! ([`glint_camera::effects::wrong_depth_causes`]): a window on a depth edge, clipping,
//! inter-reflected light behind the surface (a mirror image) or in front of it, or other.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use glint_camera::capture::{CaptureConfig, MockSliCamera, depth_quality};
use glint_camera::edge_errors::distance_to_depth_edge;
use glint_camera::effects::{WRONG_DEPTH_M, WrongDepthCauses, direct_share, wrong_depth_causes};
use glint_camera::materials;
use glint_camera::setup::{BinSetup, BinSetupSpec, capture_seed};
use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::{DepthMap, Image};
use glint_geometry::io::write_file_atomically;
use glint_geometry::parts::Part;
use glint_geometry::sdf::{SdfConfig, SdfGrid};
use glint_render::rig::SliRig;
use glint_render::stereo::StereoMatcherConfig;
use nalgebra::Isometry3;

/// The settings of one validation run (`glint eval camera`'s flags).
#[derive(Clone, Debug)]
pub struct CameraValidation {
    /// The parts, each in a bin of its own.
    pub parts: Vec<Part>,
    /// Shot counts K to compare (1..=64).
    pub shots: Vec<u32>,
    /// Window radii r to compare (px; the window is (2r+1)²; 1..=32).
    pub window_radius_px: Vec<u32>,
    /// Parts per bin.
    pub instances: u32,
    /// Views per part (on the capture cap above the bin).
    pub views: u32,
    /// Camera resolution (width, height), px.
    pub resolution: (u32, u32),
    /// Samples per pixel of the renders.
    pub spp: u32,
    /// Seed of the drops and the captures.
    pub seed: u64,
    /// Output directory: `camera.md`, `camera_parts.csv`, `camera_wrong_depth.csv`,
    /// `camera_plane.csv`.
    pub out: PathBuf,
}

/// Upper ends (inclusive, L∞ px) of the distance-to-depth-edge bins; a last bin takes the rest.
const EDGE_BINS_PX: [u32; 3] = [1, 3, 7];

/// Surface distances of one pixel set, and how many pixels it had.
#[derive(Clone, Debug, Default)]
struct Distances {
    pixels: usize,
    /// |point → true surface| of the pixels with depth, metres.
    valid_m: Vec<f64>,
}

impl Distances {
    fn coverage(&self) -> f64 {
        self.valid_m.len() as f64 / self.pixels.max(1) as f64
    }
    /// (median, 90th percentile, share > 2 mm) in mm, mm and [0, 1]; NaN when empty.
    fn summary(&self) -> (f64, f64, f64) {
        if self.valid_m.is_empty() {
            return (f64::NAN, f64::NAN, f64::NAN);
        }
        let mut d = self.valid_m.clone();
        d.sort_by(f64::total_cmp);
        let at = |q: f64| d[((d.len() - 1) as f64 * q).round() as usize] * 1e3;
        let wrong = d.iter().filter(|&&x| x > WRONG_DEPTH_M).count() as f64 / d.len() as f64;
        (at(0.5), at(0.9), wrong)
    }
}

/// One (material, K, r) cell: all part pixels, and per edge-distance bin.
#[derive(Clone, Debug)]
struct Cell {
    all: Distances,
    bins: Vec<Distances>,
    causes: WrongDepthCauses,
}

impl Cell {
    fn new() -> Self {
        Self {
            all: Distances::default(),
            bins: vec![Distances::default(); EDGE_BINS_PX.len() + 1],
            causes: WrongDepthCauses::default(),
        }
    }
}

/// The matcher at window radius `r`: the camera's default otherwise, with its small edge
/// windows only where they are smaller than the main window.
fn matcher_at(base: &StereoMatcherConfig, r: u32) -> StereoMatcherConfig {
    StereoMatcherConfig {
        window_radius_px: r,
        edge_windows: base.edge_windows.filter(|e| e.window_radius_px < r),
        ..*base
    }
}

/// Runs the validation, writes its files to `args.out` and returns the markdown tables.
pub fn run(args: &CameraValidation) -> anyhow::Result<String> {
    anyhow::ensure!(
        !args.shots.is_empty() && args.shots.iter().all(|&k| (1..=64).contains(&k)),
        "--shots: counts in 1..=64"
    );
    anyhow::ensure!(
        !args.window_radius_px.is_empty()
            && args.window_radius_px.iter().all(|&r| (1..=32).contains(&r)),
        "--window-radius-px: radii in 1..=32"
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let parts = &args.parts;
    let k_max = *args.shots.iter().max().unwrap_or(&1);
    let spec = BinSetupSpec {
        instances: args.instances,
        seed: args.seed,
        width_px: args.resolution.0,
        height_px: args.resolution.1,
        samples_per_pixel: args.spp,
    };
    let mut csv = String::from(
        "part,material,shots,window_radius_px,part_pixels,coverage,median_mm,p90_mm,share_over_2mm",
    );
    for (i, hi) in EDGE_BINS_PX.iter().enumerate() {
        let lo = if i == 0 { 0 } else { EDGE_BINS_PX[i - 1] + 1 };
        write!(
            csv,
            ",edge_{lo}_{hi}_coverage,edge_{lo}_{hi}_median_mm,edge_{lo}_{hi}_p90_mm"
        )?;
    }
    let last = EDGE_BINS_PX[EDGE_BINS_PX.len() - 1] + 1;
    writeln!(
        csv,
        ",edge_{last}_up_coverage,edge_{last}_up_median_mm,edge_{last}_up_p90_mm"
    )?;
    let mut causes_csv = String::from(
        "part,material,shots,window_radius_px,valid,wrong,edge,saturated,mirror_image,inter_reflection,other\n",
    );
    let mut causes_md = String::from(
        "Accepted depth more than 2 mm off the true surface, by cause (each wrong pixel takes the \
         first that applies): the window holds a true depth edge; the window is clipped in some \
         shot; inter-reflected light dominates (direct share < 0.6 under the white pattern) and \
         the depth lies behind the surface (a mirror image) or in front (inter-reflection); \
         other. Causes in % of the wrong pixels.\n\n\
         | part | material | K | window | wrong / valid | edge | saturated | mirror image | inter-reflection | other |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let mut table = format!(
        "Mock camera against known geometry: {} parts × {} views, {} instances, {}×{}, {} spp \
         multi-path, seed {}. Distance of each depth point of a part pixel to the true model \
         surface; coverage = part pixels with depth. Edge bins: L∞ distance to the nearest true \
         depth edge.\n\n\
         | part | material | K | window | coverage | median (mm) | p90 (mm) | > 2 mm | \
         cov / median / p90 at edge 0–1 px | at 2–3 px | at 4–7 px | at ≥ 8 px |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---|---|---|---|\n",
        parts.len(),
        args.views,
        args.instances,
        args.resolution.0,
        args.resolution.1,
        args.spp,
        args.seed
    );
    let bar = crate::progress::bar((parts.len() * 2) as u64, "parts × materials");
    for part in parts {
        let mesh = part.mesh();
        let sdf = SdfGrid::build(&mesh, &SdfConfig::default())
            .with_context(|| format!("SDF of the {}", part.display_name()))?;
        let shiny = BinSetup::new(&mesh, materials::ground_truth(*part), &spec)?;
        let matte = shiny.repainted(&mesh, materials::diffuse_twin())?;
        for (material, setup) in [("diffuse", &matte), ("shiny", &shiny)] {
            let mut cells = vec![Cell::new(); args.shots.len() * args.window_radius_px.len()];
            for (view, t_w_c) in setup.views(args.views as usize).iter().enumerate() {
                let seed = capture_seed(args.seed, view);
                let camera = MockSliCamera {
                    config: CaptureConfig {
                        shots: k_max,
                        ..setup.config.clone()
                    },
                    ..setup.camera()
                };
                let rendered = camera.render_shots(t_w_c, seed);
                let shots = camera.read_out_shots(&rendered, seed);
                let truth = &rendered.truth;
                let edge = distance_to_depth_edge(&truth.depth_m);
                let share = direct_share(&camera, t_w_c, seed ^ 0x5A5A);
                for (ik, &k) in args.shots.iter().enumerate() {
                    let lefts: Vec<_> = shots[..k as usize].iter().map(|p| &p[0]).collect();
                    let rights: Vec<_> = shots[..k as usize].iter().map(|p| &p[1]).collect();
                    for (ir, &r) in args.window_radius_px.iter().enumerate() {
                        let matcher = MockSliCamera {
                            rig: camera.rig,
                            scene: camera.scene,
                            config: CaptureConfig {
                                matcher: matcher_at(&setup.config.matcher, r),
                                ..camera.config.clone()
                            },
                        };
                        let (depth, _) = matcher.match_shots(&lefts, &rights)?;
                        let cell = &mut cells[ik * args.window_radius_px.len() + ir];
                        let distances = accumulate(
                            cell,
                            &depth,
                            truth.label.data(),
                            &edge,
                            &setup.rig.stereo.intrinsics,
                            t_w_c,
                            &setup.poses,
                            &sdf,
                        );
                        cell.causes.add(&wrong_depth_causes(
                            &distances,
                            &depth,
                            truth,
                            &edge,
                            &share,
                            &lefts,
                            setup.config.sensor.max_dn(),
                            r,
                        ));
                    }
                }
            }
            for (ik, &k) in args.shots.iter().enumerate() {
                for (ir, &r) in args.window_radius_px.iter().enumerate() {
                    let cell = &cells[ik * args.window_radius_px.len() + ir];
                    let (median, p90, wrong) = cell.all.summary();
                    write!(
                        csv,
                        "{},{material},{k},{r},{},{:.4},{median:.3},{p90:.3},{wrong:.4}",
                        part.name(),
                        cell.all.pixels,
                        cell.all.coverage()
                    )?;
                    let side = 2 * r + 1;
                    write!(
                        table,
                        "| {} | {material} | {k} | {side}×{side} | {:.3} | {median:.3} | {p90:.3} | {wrong:.3} |",
                        part.display_name(),
                        cell.all.coverage()
                    )?;
                    for bin in &cell.bins {
                        let (m, p, _) = bin.summary();
                        write!(csv, ",{:.4},{m:.3},{p:.3}", bin.coverage())?;
                        write!(table, " {:.2} / {m:.2} / {p:.2} |", bin.coverage())?;
                    }
                    csv.push('\n');
                    table.push('\n');
                    let c = &cell.causes;
                    writeln!(
                        causes_csv,
                        "{},{material},{k},{r},{},{},{},{},{},{},{}",
                        part.name(),
                        c.valid,
                        c.wrong,
                        c.edge,
                        c.saturated,
                        c.mirror_image,
                        c.inter_reflection,
                        c.other
                    )?;
                    let of_wrong = |n: usize| 100.0 * n as f64 / c.wrong.max(1) as f64;
                    writeln!(
                        causes_md,
                        "| {} | {material} | {k} | {side}×{side} | {:.1} % | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} |",
                        part.display_name(),
                        100.0 * c.wrong as f64 / c.valid.max(1) as f64,
                        of_wrong(c.edge),
                        of_wrong(c.saturated),
                        of_wrong(c.mirror_image),
                        of_wrong(c.inter_reflection),
                        of_wrong(c.other)
                    )?;
                }
            }
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let plane = plane_table(args)?;
    table.push('\n');
    table.push_str(&causes_md);
    table.push('\n');
    table.push_str(&plane.0);
    write_file_atomically(
        &args.out.join("camera_wrong_depth.csv"),
        causes_csv.as_bytes(),
    )?;
    write_file_atomically(&args.out.join("camera_parts.csv"), csv.as_bytes())?;
    write_file_atomically(&args.out.join("camera_plane.csv"), plane.1.as_bytes())?;
    write_file_atomically(&args.out.join("camera.md"), table.as_bytes())?;
    Ok(table)
}

/// Adds one view's matched depth to `cell`: every part pixel (true label 1..=N) counts, the
/// ones with depth give |SDF| of their point in their true instance's frame. Returns that
/// distance per pixel, metres (NaN without depth or off the parts).
#[allow(clippy::too_many_arguments)]
fn accumulate(
    cell: &mut Cell,
    depth: &DepthMap,
    labels: &[u16],
    edge: &Image<u32>,
    intrinsics: &PinholeIntrinsics,
    t_w_c: &Isometry3<f64>,
    poses: &[Isometry3<f64>],
    sdf: &SdfGrid,
) -> Vec<f64> {
    let w = depth.depth_m.width() as usize;
    let mut distances = vec![f64::NAN; labels.len()];
    for (i, &label) in labels.iter().enumerate() {
        if label == 0 || label as usize > poses.len() {
            continue;
        }
        let bin = EDGE_BINS_PX
            .iter()
            .position(|&hi| edge.data()[i] <= hi)
            .unwrap_or(EDGE_BINS_PX.len());
        cell.all.pixels += 1;
        cell.bins[bin].pixels += 1;
        let z = depth.depth_m.data()[i];
        if !z.is_finite() {
            continue;
        }
        let (u, v) = ((i % w) as u32, (i / w) as u32);
        let p_c = intrinsics.unproject(&PinholeIntrinsics::pixel_centre(u, v), z as f64);
        let p_o = poses[label as usize - 1].inverse_transform_point(&(t_w_c * p_c));
        let d = sdf.sample(&p_o).distance_m.abs();
        cell.all.valid_m.push(d);
        cell.bins[bin].valid_m.push(d);
        distances[i] = d;
    }
    distances
}

/// The diffuse plane at 0.6 m, head-on, per K and r: (markdown, CSV).
fn plane_table(args: &CameraValidation) -> anyhow::Result<(String, String)> {
    let scene = glint_camera::setup::plane_scene(1.0, materials::diffuse_twin())?;
    let rig = SliRig::ensenso_n35().resized(args.resolution.0, args.resolution.1)?;
    let t_w_c = glint_camera::setup::looking_down(0.6);
    let k_max = *args.shots.iter().max().unwrap_or(&1);
    let base = CaptureConfig {
        samples_per_pixel: args.spp,
        shots: k_max,
        ..CaptureConfig::for_rig(&rig)?
    };
    let camera = MockSliCamera {
        rig,
        scene: &scene,
        config: base.clone(),
    };
    let seed = capture_seed(args.seed, 0);
    let rendered = camera.render_shots(&t_w_c, seed);
    let shots = camera.read_out_shots(&rendered, seed);
    let r_max = *args.window_radius_px.iter().max().unwrap_or(&1);
    let mut md = String::from(
        "Diffuse plane at 0.6 m, head-on (depth RMSE without > 5 mm outliers; eligible pixels: \
         the largest window fits).\n\n| K | window | coverage | RMSE (mm) | > 5 mm |\n|---:|---:|---:|---:|---:|\n",
    );
    let mut csv = String::from("shots,window_radius_px,eligible,coverage,rmse_mm,outliers_5mm\n");
    for &k in &args.shots {
        let lefts: Vec<_> = shots[..k as usize].iter().map(|p| &p[0]).collect();
        let rights: Vec<_> = shots[..k as usize].iter().map(|p| &p[1]).collect();
        for &r in &args.window_radius_px {
            let matcher = MockSliCamera {
                rig,
                scene: &scene,
                config: CaptureConfig {
                    matcher: matcher_at(&base.matcher, r),
                    ..base.clone()
                },
            };
            let (depth, match_status) = matcher.match_shots(&lefts, &rights)?;
            let capture = glint_camera::capture::StereoCapture {
                t_w_c,
                left: shots[0][0].clone(),
                right: shots[0][1].clone(),
                later_shots: Vec::new(),
                depth,
                match_status,
            };
            let q = depth_quality(&capture, &rendered.truth, &rig, r_max, Some(1));
            writeln!(
                md,
                "| {k} | {0}×{0} | {1:.4} | {2:.3} | {3} |",
                2 * r + 1,
                q.coverage(),
                q.rmse_m * 1e3,
                q.outliers_5mm
            )?;
            writeln!(
                csv,
                "{k},{r},{},{:.5},{:.4},{}",
                q.eligible,
                q.coverage(),
                q.rmse_m * 1e3,
                q.outliers_5mm
            )?;
        }
    }
    Ok((md, csv))
}
