//! Matcher tests on synthetic random-dot pairs at N35 geometry (reduced to 320×256 with the
//! same field of view, fx = 270.8 px, so the tests stay fast; the full-resolution run is the
//! ignored `full_resolution_n35`).

use super::synthetic::{DotPattern, Paint, Plane, Scene, Texture};
use super::*;
use glint_geometry::camera::StereoRig;
use glint_geometry::image::Image;

const W: u32 = 320;
const H: u32 = 256;
/// Read noise, ≈ 1 DN of an 8-bit sensor.
const NOISE: f64 = 0.004;

fn test_rig() -> StereoRig {
    let n35 = StereoRig::ensenso_n35();
    StereoRig::new(n35.intrinsics.resized(W, H).unwrap(), n35.baseline_m).unwrap()
}

fn test_config(rig: &StereoRig) -> StereoMatcherConfig {
    StereoMatcherConfig::for_depth_range(rig, 0.4, 1.2).unwrap()
}

fn scene(
    width: u32,
    height: u32,
    planes: Vec<Plane>,
    paint: Vec<([f64; 4], Paint)>,
    seed: u64,
) -> Scene {
    Scene {
        width,
        height,
        planes,
        pattern: Texture::projector_like(seed),
        exposure: 0.6,
        paint,
        noise_std: NOISE,
        subsamples: 4,
        seed,
    }
}

/// Disparity error statistics over the pixels of `region` that `keep` accepts.
#[derive(Debug)]
struct Errors {
    pixels: usize,
    valid: usize,
    rmse_px: f64,
    max_abs_px: f64,
    /// Depth RMSE (m) from the same pixels.
    depth_rmse_m: f64,
}

impl Errors {
    fn coverage(&self) -> f64 {
        self.valid as f64 / self.pixels.max(1) as f64
    }
}

fn errors(
    scene: &Scene,
    rig: &StereoRig,
    result: &StereoResult,
    region: PixelRect,
    keep: impl Fn(u32, u32) -> bool,
) -> Errors {
    let depth = disparity_to_depth(result, rig);
    let (mut pixels, mut valid, mut sum2, mut max_abs, mut depth_sum2) = (0, 0, 0.0, 0.0f64, 0.0);
    for v in region.v_min..region.v_end() as u32 {
        for u in region.u_min..region.u_end() as u32 {
            if !keep(u, v) {
                continue;
            }
            pixels += 1;
            let d = result.disparity_px.get(u, v).unwrap();
            if result.status.get(u, v) != Some(MatchStatus::Valid) {
                assert!(d.is_nan());
                continue;
            }
            valid += 1;
            let truth = scene.true_disparity(u, v);
            let e = d as f64 - truth;
            sum2 += e * e;
            max_abs = max_abs.max(e.abs());
            let z = depth.get(u, v).unwrap() as f64;
            depth_sum2 += (z - rig.depth_from_disparity(truth)).powi(2);
        }
    }
    let n = valid.max(1) as f64;
    Errors {
        pixels,
        valid,
        rmse_px: (sum2 / n).sqrt(),
        max_abs_px: max_abs,
        depth_rmse_m: (depth_sum2 / n).sqrt(),
    }
}

/// Pixels whose window and every candidate's right window fit: away from the borders.
fn interior(config: &StereoMatcherConfig) -> PixelRect {
    let r = config.window_radius_px;
    let u0 = config.disparity_range.max_px() + r;
    PixelRect::new(u0, r, W - r - u0, H - 2 * r)
}

fn status_summary(result: &StereoResult) -> String {
    let counts = result.status_counts();
    MatchStatus::ALL
        .iter()
        .filter(|s| counts[**s as usize] > 0)
        .map(|s| format!("{}: {}", s.name(), counts[*s as usize]))
        .collect::<Vec<_>>()
        .join(", ")
}

#[test]
fn fronto_parallel_plane_at_0_6_m() {
    let rig = test_rig();
    let config = test_config(&rig);
    let scene = scene(W, H, vec![Plane::fronto(&rig, 0.6)], vec![], 1);
    let (left, right) = scene.render_pair();
    let result = match_stereo(&left, &right, &config, None).unwrap();
    let e = errors(&scene, &rig, &result, interior(&config), |_, _| true);
    // F = −f·b/d² at 0.6 m: z²/(f·b) = 0.36 / 27.40 = 13.1 mm per pixel of disparity.
    let f_m_per_px = rig.depth_per_disparity(rig.disparity_from_depth(0.6)).abs();
    println!(
        "fronto 0.6 m: disparity RMSE {:.4} px (max {:.3}), coverage {:.2} %, depth RMSE {:.3} mm (|F| = {:.2} mm/px); {}",
        e.rmse_px,
        e.max_abs_px,
        100.0 * e.coverage(),
        1e3 * e.depth_rmse_m,
        1e3 * f_m_per_px,
        status_summary(&result)
    );
    assert!(e.rmse_px < 0.1, "{e:?}");
    assert!(e.coverage() > 0.99, "{e:?}");
    // σ_z ≈ |F| σ_d to first order; 2 % slack for the second-order term.
    assert!(
        e.depth_rmse_m < 1.02 * f_m_per_px * e.rmse_px + 1e-6,
        "{e:?}"
    );
    assert!(e.depth_rmse_m < 1.02 * f_m_per_px * 0.1);
}

#[test]
fn slanted_plane() {
    let rig = test_rig();
    let config = test_config(&rig);
    // Tilted 35° about y and 20° about x at 0.6 m: the disparity changes by du, dv px per px.
    let (ty, tx) = (35f64.to_radians(), 20f64.to_radians());
    let normal = [ty.sin() * tx.cos(), tx.sin(), -ty.cos() * tx.cos()];
    let plane = Plane::from_point_normal(&rig, [0.0, 0.0, 0.6], normal);
    let scene = scene(W, H, vec![plane], vec![], 2);
    let (left, right) = scene.render_pair();
    let result = match_stereo(&left, &right, &config, None).unwrap();
    let e = errors(&scene, &rig, &result, interior(&config), |_, _| true);
    println!(
        "slanted plane (∂d/∂u = {:.3}, ∂d/∂v = {:.3}): disparity RMSE {:.4} px (max {:.3}), coverage {:.2} %; {}",
        plane.du,
        plane.dv,
        e.rmse_px,
        e.max_abs_px,
        100.0 * e.coverage(),
        status_summary(&result)
    );
    assert!(plane.du.abs() > 0.05 && plane.dv.abs() > 0.02, "{plane:?}");
    assert!(e.rmse_px < 0.15, "{e:?}");
    assert!(e.coverage() > 0.98, "{e:?}");
}

#[test]
fn textureless_dark_and_saturated_regions_are_missing() {
    let rig = test_rig();
    let config = test_config(&rig);
    let textureless = [90.0, 30.0, 150.0, 90.0];
    let dark = [180.0, 30.0, 240.0, 90.0];
    let saturated = [120.0, 150.0, 200.0, 220.0];
    let paint = vec![
        (textureless, Paint::Constant(0.3)),
        // Pattern spread ≈ 0.001 under read noise 0.004: noise ≫ signal.
        (dark, Paint::Gain(0.005)),
        // Clipped to 1.0 even at the pattern's floor (0.05 · 0.6 · 40 = 1.2).
        (saturated, Paint::Gain(40.0)),
    ];
    let scene = scene(W, H, vec![Plane::fronto(&rig, 0.6)], paint, 3);
    let (left, right) = scene.render_pair();
    let result = match_stereo(&left, &right, &config, None).unwrap();
    let r = config.window_radius_px as f64;
    let inside = |rect: [f64; 4], u: u32, v: u32| {
        let (x, y) = (u as f64 + 0.5, v as f64 + 0.5);
        x > rect[0] + r + 1.0
            && x < rect[2] - r - 1.0
            && y > rect[1] + r + 1.0
            && y < rect[3] - r - 1.0
    };
    for (name, rect) in [
        ("textureless", textureless),
        ("dark", dark),
        ("saturated", saturated),
    ] {
        let (mut pixels, mut no_texture, mut missing) = (0, 0, 0);
        for v in 0..H {
            for u in 0..W {
                if inside(rect, u, v) {
                    pixels += 1;
                    let status = result.status.get(u, v).unwrap();
                    no_texture += (status == MatchStatus::NoTexture) as usize;
                    missing += (!status.is_valid()) as usize;
                }
            }
        }
        println!("{name}: {pixels} px, {no_texture} no texture, {missing} missing");
        assert_eq!(missing, pixels, "{name}");
        assert!(
            no_texture as f64 >= 0.95 * pixels as f64,
            "{name}: {no_texture}/{pixels}"
        );
    }
    // The saturated patch really is flat at 1.0 in both images.
    assert_eq!(left.get(160, 185), Some(1.0));
    // Elsewhere the plane is still measured.
    let outside = |u, v| {
        [textureless, dark, saturated].iter().all(|rect| {
            let (x, y) = (u as f64 + 0.5, v as f64 + 0.5);
            x < rect[0] - r - 1.0
                || x > rect[2] + r + 1.0
                || y < rect[1] - r - 1.0
                || y > rect[3] + r + 1.0
        })
    };
    let e = errors(&scene, &rig, &result, interior(&config), outside);
    println!(
        "around them: RMSE {:.4} px, coverage {:.2} %",
        e.rmse_px,
        100.0 * e.coverage()
    );
    assert!(e.rmse_px < 0.1 && e.coverage() > 0.98, "{e:?}");
}

/// Pixels whose centre lies within this distance (px) of a depth edge — the two pixels on either
/// side — may take either side's disparity: a window matcher localises edges to ±2 px. Over 25
/// seeds of the occlusion scene (`occluded_band_is_rejected_over_seeds`), at most 4 % of them
/// were off by > 2 px, and every pixel beyond them was within 0.77 px.
const EDGE_RING_PX: f64 = 1.5;

/// Distance (px) from a pixel centre to the outline of `rect` (0 on it).
fn distance_to_outline(rect: [f64; 4], u: u32, v: u32) -> f64 {
    let (x, y) = (u as f64 + 0.5, v as f64 + 0.5);
    let inside = x >= rect[0] && x < rect[2] && y >= rect[1] && y < rect[3];
    if inside {
        (x - rect[0])
            .min(rect[2] - x)
            .min(y - rect[1])
            .min(rect[3] - y)
    } else {
        let dx = (rect[0] - x).max(x - rect[2]).max(0.0);
        let dy = (rect[1] - y).max(y - rect[3]).max(0.0);
        dx.max(dy)
    }
}

#[test]
fn occluded_band_is_rejected() {
    check_occlusion(4);
}

/// Runs the occlusion check on 24 more seeds.
#[test]
#[ignore]
fn occluded_band_is_rejected_over_seeds() {
    for seed in 100..124 {
        check_occlusion(seed);
    }
}

fn check_occlusion(seed: u64) {
    let rig = test_rig();
    let config = test_config(&rig);
    // A 0.5 m square in front of a 0.8 m wall. The right camera sees the square shifted left by
    // Δd more than the wall, hiding the wall band [u0 − Δd, u0) left of it from the right view.
    let wall = Plane::fronto(&rig, 0.8);
    let square_rect = [160.0, 70.0, 240.0, 190.0];
    let square = Plane::fronto(&rig, 0.5).cut(square_rect);
    let delta_d = square.d0 - wall.d0;
    let scene = scene(W, H, vec![wall, square], vec![], seed);
    let (left, right) = scene.render_pair();
    let result = match_stereo(&left, &right, &config, None).unwrap();
    let r = config.window_radius_px as f64;
    let error = |u: u32, v: u32| {
        (result.disparity_px.get(u, v).unwrap() as f64 - scene.true_disparity(u, v)).abs()
    };

    let band = |u: u32, v: u32| {
        let (x, y) = (u as f64 + 0.5, v as f64 + 0.5);
        x >= square_rect[0] - delta_d
            && x < square_rect[0]
            && y >= square_rect[1]
            && y < square_rect[3]
    };
    // Away from the band's ends (where shifted windows, reaching 2r rows, see the visible wall
    // above and below) and from its sides: the square's edge, and the wall's visibility edge
    // (both localised to ±2 px).
    let band_core = |u: u32, v: u32| {
        let (x, y) = (u as f64 + 0.5, v as f64 + 0.5);
        band(u, v)
            && x >= square_rect[0] - delta_d + EDGE_RING_PX
            && x < square_rect[0] - EDGE_RING_PX
            && y >= square_rect[1] + 2.0 * r
            && y < square_rect[3] - 2.0 * r
    };
    let (mut band_pixels, mut band_valid, mut band_wrong) = (0, 0, 0);
    let (mut core_pixels, mut core_lr, mut core_valid) = (0, 0, 0);
    let (mut ring_pixels, mut ring_wrong) = (0, 0);
    for v in 0..H {
        for u in interior(&config).u_min..W {
            let status = result.status.get(u, v).unwrap();
            let near_edge = distance_to_outline(square_rect, u, v) <= EDGE_RING_PX;
            if near_edge {
                ring_pixels += 1;
                ring_wrong += (status.is_valid() && error(u, v) > 2.0) as usize;
            } else if band(u, v) {
                band_pixels += 1;
                band_valid += status.is_valid() as usize;
                band_wrong += (status.is_valid() && error(u, v) > 1.0) as usize;
            }
            if band_core(u, v) {
                core_pixels += 1;
                core_lr += (status == MatchStatus::LeftRightInconsistent) as usize;
                core_valid += status.is_valid() as usize;
            }
        }
    }
    let elsewhere = |u, v| !band(u, v) && distance_to_outline(square_rect, u, v) > EDGE_RING_PX;
    let e = errors(&scene, &rig, &result, interior(&config), elsewhere);
    println!(
        "occlusion: band (Δd = {delta_d:.2} px) beyond 2 px of the edge: {band_pixels} px, {band_valid} valid, \
         {band_wrong} off by > 1 px; its core: {core_pixels} px, {core_lr} left-right inconsistent, {core_valid} valid; \
         within 2 px of the square's outline: {ring_wrong} of {ring_pixels} off by > 2 px; \
         elsewhere max error {:.3} px, RMSE {:.4} px, coverage {:.2} %; {}",
        e.max_abs_px,
        e.rmse_px,
        100.0 * e.coverage(),
        status_summary(&result)
    );
    // The band is missing (a few pixels may borrow a correct wall disparity from the visible
    // wall through a shifted window, never a wrong one), mostly flagged by the left-right check.
    assert!(
        core_valid as f64 <= 0.01 * core_pixels as f64,
        "{core_valid}/{core_pixels}"
    );
    assert_eq!(band_wrong, 0);
    assert!(
        core_lr as f64 > 0.6 * core_pixels as f64,
        "{core_lr}/{core_pixels}"
    );
    // Pixels on the depth edge itself may go either way (the edge is localised to ±2 px).
    assert!(
        ring_wrong as f64 <= 0.1 * ring_pixels as f64,
        "{ring_wrong}/{ring_pixels}"
    );
    assert!(e.max_abs_px <= 2.0, "{e:?}");
    assert!(e.coverage() > 0.99, "{e:?}");
}

#[test]
fn roi_matches_like_the_full_image() {
    let rig = test_rig();
    let config = test_config(&rig);
    let scene = scene(
        W,
        H,
        vec![
            Plane::fronto(&rig, 0.7),
            Plane::fronto(&rig, 0.55).cut([150.0, 60.0, 210.0, 150.0]),
        ],
        vec![],
        5,
    );
    let (left, right) = scene.render_pair();
    let full = match_stereo(&left, &right, &config, None).unwrap();
    let roi = PixelRect::new(130, 40, 100, 80);
    let part = match_stereo(&left, &right, &config, Some(roi)).unwrap();
    // Both see the same pixels, but the working copies are centred on different means and the
    // running sums start elsewhere, so scores agree to f32 rounding only: a pixel right at a
    // threshold may flip, and the subpixel fit may move by a hair.
    let (mut compared, mut status_differs, mut max_diff) = (0, 0, 0.0f32);
    for v in 0..H {
        for u in 0..W {
            let (s, d) = (
                part.status.get(u, v).unwrap(),
                part.disparity_px.get(u, v).unwrap(),
            );
            if !roi.contains(u, v) {
                assert_eq!(s, MatchStatus::OutOfRoi);
                assert!(d.is_nan());
                continue;
            }
            // The speckle filter sees only the ROI, so regions cut by its edge may differ.
            let fs = full.status.get(u, v).unwrap();
            if s == MatchStatus::Speckle || fs == MatchStatus::Speckle {
                continue;
            }
            compared += 1;
            status_differs += (s != fs) as usize;
            if s.is_valid() && fs.is_valid() {
                max_diff = max_diff.max((d - full.disparity_px.get(u, v).unwrap()).abs());
            }
        }
    }
    println!(
        "ROI vs full image: {status_differs} of {compared} statuses differ, max disparity difference {max_diff} px"
    );
    assert!(status_differs as f64 <= 0.002 * compared as f64);
    assert!(max_diff < 0.1);
    assert!(part.roi_coverage() > 0.85, "{}", part.roi_coverage());
}

#[test]
fn invalid_inputs_are_errors() {
    let rig = test_rig();
    let config = test_config(&rig);
    let image = Image::filled(W, H, 0.5f32).unwrap();
    let small = Image::filled(W, H - 1, 0.5f32).unwrap();
    assert!(matches!(
        match_stereo(&image, &small, &config, None),
        Err(StereoError::SizeMismatch { .. })
    ));
    let mut nan = image.clone();
    nan.set(200, 100, f32::NAN);
    assert!(matches!(
        match_stereo(&nan, &image, &config, None),
        Err(StereoError::NonFinite {
            side: Side::Left,
            u: 200,
            v: 100,
            ..
        })
    ));
    let mut inf = image.clone();
    inf.set(150, 10, f32::INFINITY);
    assert!(matches!(
        match_stereo(&image, &inf, &config, None),
        Err(StereoError::NonFinite {
            side: Side::Right,
            ..
        })
    ));
    assert!(matches!(
        match_stereo(&image, &image, &config, Some(PixelRect::new(10, 10, 0, 5))),
        Err(StereoError::EmptyRoi { .. })
    ));
    assert!(matches!(
        match_stereo(
            &image,
            &image,
            &config,
            Some(PixelRect::new(300, 10, 40, 5))
        ),
        Err(StereoError::RoiOutsideImage { .. })
    ));
    assert!(matches!(
        match_stereo(
            &image,
            &image,
            &config,
            Some(PixelRect::new(u32::MAX, 10, u32::MAX, 5))
        ),
        Err(StereoError::RoiOutsideImage { .. })
    ));
    // Ranges: inverted, non-positive, non-finite depths; disparities wider than the image.
    for (near, far) in [
        (1.2, 0.4),
        (0.0, 1.0),
        (-0.5, 1.0),
        (0.4, f64::NAN),
        (0.5, 0.5),
        (1e-9, 1.0),
    ] {
        assert!(
            matches!(
                DisparityRange::from_depth_range(&rig, near, far),
                Err(StereoError::BadDepthRange { .. }) | Err(StereoError::BadDisparityRange { .. })
            ),
            "{near}..{far}"
        );
    }
    assert!(matches!(
        DisparityRange::new(50, 10),
        Err(StereoError::BadDisparityRange { .. })
    ));
    // The full-resolution default range (90..=275) on a 256-px-wide image.
    let narrow = Image::filled(256, 200, 0.5f32).unwrap();
    assert!(matches!(
        match_stereo(&narrow, &narrow, &StereoMatcherConfig::default(), None),
        Err(StereoError::DisparityRangeTooWide { .. })
    ));
    let bad_configs = [
        StereoMatcherConfig {
            window_radius_px: 0,
            ..config
        },
        StereoMatcherConfig {
            min_window_std: f32::NAN,
            ..config
        },
        StereoMatcherConfig {
            min_correlation: 1.5,
            ..config
        },
        StereoMatcherConfig {
            uniqueness_margin: 1.0,
            ..config
        },
        StereoMatcherConfig {
            left_right_max_diff_px: Some(-1.0),
            ..config
        },
        StereoMatcherConfig {
            speckle: Some(SpeckleFilter {
                min_region_px: 10,
                max_step_px: f32::INFINITY,
            }),
            ..config
        },
    ];
    for bad in bad_configs {
        assert!(
            matches!(
                match_stereo(&image, &image, &bad, None),
                Err(StereoError::BadParameter { .. })
            ),
            "{bad:?}"
        );
    }
    // A constant image is valid input: every pixel lacks texture, none panics.
    let flat = match_stereo(&image, &image, &config, None).unwrap();
    assert_eq!(flat.status_counts()[MatchStatus::Valid as usize], 0);
    // A 1×1 image and an ROI in the unmatched border are answered, not refused.
    let tiny = Image::filled(1, 1, 0.5f32).unwrap();
    let tiny_config = StereoMatcherConfig {
        disparity_range: DisparityRange::new(0, 0).unwrap(),
        ..config
    };
    let result = match_stereo(&tiny, &tiny, &tiny_config, None).unwrap();
    assert_eq!(result.status.get(0, 0), Some(MatchStatus::NoCandidate));
    let border = match_stereo(&image, &image, &config, Some(PixelRect::new(0, 0, 20, 20))).unwrap();
    assert!(
        border
            .status
            .data()
            .iter()
            .all(|s| matches!(s, MatchStatus::NoCandidate | MatchStatus::OutOfRoi))
    );
}

#[test]
fn disparity_to_depth_follows_z_equals_f_b_over_d() {
    let rig = test_rig();
    let config = test_config(&rig);
    let mut disparity = Image::filled(3, 1, f32::NAN).unwrap();
    disparity.set(0, 0, 45.66);
    disparity.set(1, 0, 0.0);
    let result = StereoResult {
        disparity_px: disparity,
        status: Image::filled(3, 1, MatchStatus::Valid).unwrap(),
        correlation: Image::filled(3, 1, 1.0).unwrap(),
        roi: PixelRect::full(3, 1),
        disparity_range: config.disparity_range,
    };
    let depth = disparity_to_depth(&result, &rig);
    let expected = rig.intrinsics.fx_px * rig.baseline_m / 45.66;
    assert!((depth.get(0, 0).unwrap() as f64 - expected).abs() < 1e-6);
    assert_eq!(depth.get(1, 0), None);
    assert_eq!(depth.get(2, 0), None);
    // The default range covers the N35's 0.4–1.2 m with a pixel to spare on each end.
    let range = StereoMatcherConfig::default().disparity_range;
    let n35 = StereoRig::ensenso_n35();
    assert!((range.min_px() as f64) < n35.disparity_from_depth(1.2) - 1.0);
    assert!((range.max_px() as f64) > n35.disparity_from_depth(0.4) + 1.0);
}

/// The measurement behind the defaults: accuracy, coverage and discontinuity errors over the
/// window size, window shifting, subpixel fit and rejection thresholds, on both textures, plus
/// a low-SNR plane (read noise 0.02 under a pattern spread of ≈ 0.035) and pure noise (no
/// pattern, noise 0.02: every valid pixel there is a false match). Run with
/// `cargo test --release -p glint-render stereo::tests::parameter_sweep -- --ignored --nocapture`.
#[test]
#[ignore]
fn parameter_sweep() {
    let rig = test_rig();
    let base = test_config(&rig);
    let (ty, tx) = (35f64.to_radians(), 20f64.to_radians());
    let slanted = Plane::from_point_normal(
        &rig,
        [0.0, 0.0, 0.6],
        [ty.sin() * tx.cos(), tx.sin(), -ty.cos() * tx.cos()],
    );
    let square_rect = [160.0, 70.0, 240.0, 190.0];
    let wall = Plane::fronto(&rig, 0.8);
    let square = Plane::fronto(&rig, 0.5).cut(square_rect);
    let delta_d = square.d0 - wall.d0;
    let fronto = Plane::fronto(&rig, 0.6);
    let make = |dots: bool, planes: Vec<Plane>, exposure: f64, noise: f64, seed: u64| {
        let mut scene = scene(W, H, planes, vec![], seed);
        if dots {
            scene.pattern = Texture::Dots(DotPattern::random(W, H, 0.15, 0.8, 0.1, seed));
        }
        (scene.exposure, scene.noise_std) = (exposure, noise);
        scene
    };
    let scenes: Vec<Scene> = [false, true]
        .into_iter()
        .flat_map(|dots| {
            [
                make(dots, vec![fronto], 0.6, NOISE, 11),
                make(dots, vec![slanted], 0.6, NOISE, 12),
                make(dots, vec![wall, square], 0.6, NOISE, 13),
                make(dots, vec![fronto], 0.1, 0.02, 14),
                make(dots, vec![fronto], 0.0, 0.02, 15),
            ]
        })
        .collect();
    let pairs: Vec<_> = scenes.iter().map(|s| s.render_pair()).collect();
    let band = |u: u32, v: u32| {
        let (x, y) = (u as f64 + 0.5, v as f64 + 0.5);
        x >= square_rect[0] - delta_d
            && x < square_rect[0]
            && y >= square_rect[1]
            && y < square_rect[3]
    };
    let mut configs = vec![];
    for r in [3, 4, 5, 6, 7] {
        configs.push(StereoMatcherConfig {
            window_radius_px: r,
            ..base
        });
    }
    for g in [None, Some(0.05), Some(0.15), Some(0.2)] {
        configs.push(StereoMatcherConfig {
            shifted_window_min_gain: g,
            ..base
        });
    }
    configs.push(StereoMatcherConfig {
        subpixel: SubpixelFit::Equiangular,
        ..base
    });
    for m in [0.0, 0.05, 0.25] {
        configs.push(StereoMatcherConfig {
            uniqueness_margin: m,
            ..base
        });
    }
    for c in [-1.0, 0.3, 0.4, 0.6, 0.7] {
        configs.push(StereoMatcherConfig {
            min_correlation: c,
            ..base
        });
    }
    println!("rows: projector-like texture, then Gaussian dots");
    println!(
        "r fit   uniq  minc  shift | fronto RMSE cov% | slanted RMSE cov% | occlusion: >2px (>2px from edge) cov% band-valid \
         | low SNR RMSE cov% >1px% | noise valid%"
    );
    for config in configs {
        let mut line = format!(
            "{} {:5} {:.2} {:5.2} {:5} |",
            config.window_radius_px,
            if config.subpixel == SubpixelFit::Parabola {
                "parab"
            } else {
                "equi"
            },
            config.uniqueness_margin,
            config.min_correlation,
            config
                .shifted_window_min_gain
                .map_or("none".to_string(), |g| format!("{g:.2}")),
        );
        for (i, (scene, (left, right))) in scenes.iter().zip(&pairs).enumerate() {
            let result = match_stereo(left, right, &config, None).unwrap();
            let region = interior(&config);
            if i == 5 {
                line += "\n                          |";
            }
            match i % 5 {
                0 | 1 => {
                    let e = errors(scene, &rig, &result, region, |_, _| true);
                    line += &format!(" {:.4} {:6.2} |", e.rmse_px, 100.0 * e.coverage());
                }
                2 => {
                    let e = errors(scene, &rig, &result, region, |u, v| !band(u, v));
                    let (mut bad, mut far_bad, mut band_valid) = (0, 0, 0);
                    for v in region.v_min..region.v_end() as u32 {
                        for u in region.u_min..region.u_end() as u32 {
                            let d = result.disparity_px.get(u, v).unwrap() as f64;
                            if band(u, v) {
                                band_valid += result.status.get(u, v).unwrap().is_valid() as usize;
                            } else if (d - scene.true_disparity(u, v)).abs() > 2.0 {
                                bad += 1;
                                far_bad += (distance_to_outline(square_rect, u, v) > EDGE_RING_PX)
                                    as usize;
                            }
                        }
                    }
                    line += &format!(
                        " {bad:5} ({far_bad:3}) {:6.2} {band_valid:5} |",
                        100.0 * e.coverage()
                    );
                }
                3 => {
                    let (mut valid, mut outliers, mut sum2, mut pixels) = (0, 0, 0.0, 0);
                    for v in region.v_min..region.v_end() as u32 {
                        for u in region.u_min..region.u_end() as u32 {
                            pixels += 1;
                            if result.status.get(u, v) == Some(MatchStatus::Valid) {
                                valid += 1;
                                let e = result.disparity_px.get(u, v).unwrap() as f64
                                    - scene.true_disparity(u, v);
                                if e.abs() > 1.0 {
                                    outliers += 1;
                                } else {
                                    sum2 += e * e;
                                }
                            }
                        }
                    }
                    let inliers = (valid - outliers).max(1) as f64;
                    line += &format!(
                        " {:.4} {:6.2} {:5.2} |",
                        (sum2 / inliers).sqrt(),
                        100.0 * valid as f64 / pixels as f64,
                        100.0 * outliers as f64 / valid.max(1) as f64
                    );
                }
                _ => {
                    let valid = result.status_counts()[MatchStatus::Valid as usize];
                    line += &format!(" {:6.2}", 100.0 * valid as f64 / region.area() as f64);
                }
            }
        }
        println!("{line}");
    }
}

/// The streaming kernel's scores against a brute-force f64 ZNCC, on a large image so that the
/// running sums travel far: the f32 sums must not drift.
#[test]
fn kernel_matches_brute_force_zncc() {
    use rand::{Rng, SeedableRng};
    let (w, h, r) = (400u32, 200u32, 4usize);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(9);
    let left: Vec<f32> = (0..w * h)
        .map(|_| 0.6 + 0.4 * rng.random::<f32>())
        .collect();
    // Right = left shifted by a smooth disparity field, plus noise.
    let truth = |u: u32, v: u32| 12.0 + 6.0 * (u as f32 / w as f32) + 2.0 * (v as f32 / h as f32);
    let mut right = vec![0.0f32; (w * h) as usize];
    for v in 0..h {
        for x in 0..w {
            let u = (x as f32 + truth(x, v)).round().min(w as f32 - 1.0) as u32;
            right[(v * w + x) as usize] = left[(v * w + u) as usize] + 0.05 * rng.random::<f32>();
        }
    }
    let (left, right) = (
        Image::new(w, h, left).unwrap(),
        Image::new(w, h, right).unwrap(),
    );
    let config = StereoMatcherConfig {
        disparity_range: DisparityRange::new(8, 24).unwrap(),
        window_radius_px: r as u32,
        min_window_std: 0.0,
        min_correlation: -1.0,
        uniqueness_margin: 0.0,
        shifted_window_min_gain: None,
        subpixel: SubpixelFit::Parabola,
        left_right_max_diff_px: None,
        edge_windows: None,
        speckle: None,
    };
    let result = match_stereo(&left, &right, &config, None).unwrap();
    let zncc = |u: usize, v: usize, d: usize| {
        let (mut sl, mut sr, mut sll, mut srr, mut slr) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for y in v - r..=v + r {
            for x in u - r..=u + r {
                let a = left.get(x as u32, y as u32).unwrap() as f64;
                let b = right.get((x - d) as u32, y as u32).unwrap() as f64;
                (sl, sr, sll, srr, slr) = (sl + a, sr + b, sll + a * a, srr + b * b, slr + a * b);
            }
        }
        let n = ((2 * r + 1) * (2 * r + 1)) as f64;
        (slr - sl * sr / n) / ((sll - sl * sl / n) * (srr - sr * sr / n)).sqrt()
    };
    let (mut checked, mut worst_score, mut worst_disparity) = (0, 0.0f64, 0.0f64);
    for v in (r..h as usize - r).step_by(7) {
        for u in (24 + r..w as usize - r).step_by(5) {
            let curve: Vec<f64> = (8..=24).map(|d| zncc(u, v, d)).collect();
            let (k, &best) = curve
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .unwrap();
            let got = result.correlation.get(u as u32, v as u32).unwrap() as f64;
            worst_score = worst_score.max((got - best).abs());
            if result.status.get(u as u32, v as u32) == Some(MatchStatus::Valid) {
                let (m, c, p) = (curve[k - 1], curve[k], curve[k + 1]);
                let expected = (8 + k) as f64 + 0.5 * (m - p) / (m - 2.0 * c + p);
                worst_disparity = worst_disparity.max(
                    (result.disparity_px.get(u as u32, v as u32).unwrap() as f64 - expected).abs(),
                );
                checked += 1;
            }
        }
    }
    println!(
        "kernel vs f64 brute force over {checked} pixels: score error ≤ {worst_score:.2e}, disparity error ≤ {worst_disparity:.2e} px"
    );
    assert!(checked > 1000);
    assert!(worst_score < 1e-4, "{worst_score}");
    assert!(worst_disparity < 2e-3, "{worst_disparity}");
}

/// One full-resolution N35 match with the default configuration: accuracy, coverage and time.
/// `cargo test --release -p glint-render stereo::tests::full_resolution_n35 -- --ignored --nocapture`
#[test]
#[ignore]
fn full_resolution_n35() {
    let rig = StereoRig::ensenso_n35();
    let config = StereoMatcherConfig::default();
    let (w, h) = (rig.intrinsics.width_px, rig.intrinsics.height_px);
    let (ty, tx) = (25f64.to_radians(), 10f64.to_radians());
    let wall = Plane::from_point_normal(
        &rig,
        [0.0, 0.0, 0.7],
        [ty.sin() * tx.cos(), tx.sin(), -ty.cos() * tx.cos()],
    );
    let part_rect = [560.0, 400.0, 760.0, 600.0];
    let part = Plane::fronto(&rig, 0.55).cut(part_rect);
    let mut scene = scene(w, h, vec![wall, part], vec![], 21);
    scene.subsamples = 3;
    let start = std::time::Instant::now();
    let (left, right) = scene.render_pair();
    let render_s = start.elapsed().as_secs_f64();
    let mut times = vec![];
    let mut result = None;
    for _ in 0..3 {
        let start = std::time::Instant::now();
        result = Some(match_stereo(&left, &right, &config, None).unwrap());
        times.push(start.elapsed().as_secs_f64());
    }
    let result = result.unwrap();
    let r = config.window_radius_px;
    let u0 = config.disparity_range.max_px() + r;
    let interior = PixelRect::new(u0, r, w - r - u0, h - 2 * r);
    let keep = |u, v| distance_to_outline(part_rect, u, v) > config.disparity_range.count() as f64;
    let e = errors(&scene, &rig, &result, interior, keep);
    let roi = PixelRect::new(520, 360, 280, 280);
    let start = std::time::Instant::now();
    let roi_result = match_stereo(&left, &right, &config, Some(roi)).unwrap();
    let roi_s = start.elapsed().as_secs_f64();
    times.sort_by(f64::total_cmp);
    println!(
        "N35 1280×1024, D = {} disparities, {}×{} window, {} rayon threads: match {:.3} s (best of 3; all {:?}); \
         {}×{} ROI {:.3} s (coverage {:.2} %); rendering the pair took {render_s:.2} s",
        config.disparity_range.count(),
        2 * r + 1,
        2 * r + 1,
        rayon::current_num_threads(),
        times[0],
        times.iter().map(|t| format!("{t:.3}")).collect::<Vec<_>>(),
        roi.width,
        roi.height,
        roi_s,
        100.0 * roi_result.roi_coverage(),
    );
    println!(
        "  away from borders and the part's edges: disparity RMSE {:.4} px (max {:.3}), coverage {:.2} %, depth RMSE {:.3} mm; {}",
        e.rmse_px,
        e.max_abs_px,
        100.0 * e.coverage(),
        1e3 * e.depth_rmse_m,
        status_summary(&result)
    );
    assert!(e.rmse_px < 0.1 && e.coverage() > 0.99, "{e:?}");
    for (name, variant) in [
        (
            "no shifted windows",
            StereoMatcherConfig {
                shifted_window_min_gain: None,
                ..config
            },
        ),
        (
            "no left-right check",
            StereoMatcherConfig {
                left_right_max_diff_px: None,
                ..config
            },
        ),
        (
            "neither",
            StereoMatcherConfig {
                left_right_max_diff_px: None,
                shifted_window_min_gain: None,
                ..config
            },
        ),
    ] {
        let start = std::time::Instant::now();
        let _ = match_stereo(&left, &right, &variant, None).unwrap();
        println!("  {name}: {:.3} s", start.elapsed().as_secs_f64());
    }
}

/// A bar 12 px wide (a screw shank at 0.5 m, in this 320×256 rig) 0.1 m in front of a wall,
/// slanted 60° about the vertical and dimmed to 40 %, like a metal cylinder's flank: the
/// large window at its outline holds mostly wall texture. Returns, over the bar's pixels,
/// (pixels, valid, off by > 2 px) with and without edge windows.
fn thin_bar_errors(seed: u64) -> [(usize, usize, usize); 2] {
    let rig = test_rig();
    let wall = Plane::fronto(&rig, 0.6);
    let bar_rect = [200.0, 60.0, 212.0, 200.0];
    let (s, c) = (60f64.to_radians().sin(), 60f64.to_radians().cos());
    let k = rig.intrinsics;
    // The bar's centre line at 0.5 m, its normal turned 60° towards +x.
    let centre_x = (206.0 - k.cx_px) / k.fx_px * 0.5;
    let bar = Plane::from_point_normal(&rig, [centre_x, 0.0, 0.5], [s, 0.0, -c]).cut(bar_rect);
    let scene = scene(
        W,
        H,
        vec![wall, bar],
        vec![(bar_rect, Paint::Gain(0.4))],
        seed,
    );
    let (left, right) = scene.render_pair();
    let base = test_config(&rig);
    [
        base,
        StereoMatcherConfig {
            edge_windows: None,
            ..base
        },
    ]
    .map(|config| {
        let result = match_stereo(&left, &right, &config, None).unwrap();
        let (mut pixels, mut valid, mut wrong) = (0, 0, 0);
        for v in bar_rect[1] as u32..bar_rect[3] as u32 {
            for u in bar_rect[0] as u32..bar_rect[2] as u32 {
                pixels += 1;
                if result.status.get(u, v) == Some(MatchStatus::Valid) {
                    valid += 1;
                    let e =
                        result.disparity_px.get(u, v).unwrap() as f64 - scene.true_disparity(u, v);
                    wrong += (e.abs() > 2.0) as usize;
                }
            }
        }
        (pixels, valid, wrong)
    })
}

#[test]
fn edge_windows_keep_a_thin_bar_off_the_wall() {
    for seed in 1..4 {
        let [with, without] = thin_bar_errors(seed);
        println!("thin bar, seed {seed}: edge windows {with:?}, one window {without:?}");
        // Every bar pixel's 11×11 window straddles the outline, so one window gives most of
        // the bar the wall's disparity (measured 79–96 % of its matches); 7×7 windows fit on
        // the bar for its middle pixels. Measured: 2.0–3.2× fewer wrong pixels, coverage
        // within a few points.
        assert!(2 * with.2 < without.2, "{with:?} vs {without:?}");
        assert!(
            with.1 as f64 > 0.8 * without.1 as f64,
            "{with:?} vs {without:?}"
        );
    }
}

#[test]
fn near_depth_edges_marks_steps_and_hole_borders_within_the_radius() {
    // 12×5, ROI columns 1..=10: a 3 px step between columns 4 and 5, a hole at (9, 2).
    let (w, h) = (12u32, 5u32);
    let mut d = vec![50.0f32; (w * h) as usize];
    let mut status = vec![MatchStatus::Valid; (w * h) as usize];
    for v in 0..h as usize {
        for u in 0..w as usize {
            let i = v * w as usize + u;
            if u >= 5 {
                d[i] = 53.0;
            }
            if u == 0 || u == 11 {
                status[i] = MatchStatus::OutOfRoi;
                d[i] = f32::NAN;
            }
        }
    }
    d[2 * 12 + 9] = f32::NAN;
    status[2 * 12 + 9] = MatchStatus::NotUnique;
    let result = StereoResult {
        disparity_px: Image::new(w, h, d).unwrap(),
        status: Image::new(w, h, status).unwrap(),
        correlation: Image::filled(w, h, 1.0).unwrap(),
        roi: PixelRect::new(1, 0, 10, h),
        disparity_range: DisparityRange::new(40, 60).unwrap(),
    };
    let near = super::matcher::near_depth_edges(&result, 2.0, 1);
    let row: Vec<bool> = (0..12).map(|u| near[2 * 12 + u]).collect();
    // Step edge pixels 4, 5 dilated by 1: 3..=6; hole border 8, 9 (itself), 10 dilated: 7..=10;
    // the ROI's own border is no edge, and out-of-ROI pixels are never marked.
    let expected = [
        false, false, false, true, true, true, true, true, true, true, true, false,
    ];
    assert_eq!(row, expected);
    let top: Vec<bool> = (0..12).map(|u| near[u]).collect();
    assert_eq!(&top[1..3], &[false, false]);
    assert_eq!(&top[3..7], &[true, true, true, true]);
    // A 1 px step is no edge.
    let near = super::matcher::near_depth_edges(&result, 3.5, 0);
    assert_eq!(near.iter().filter(|&&n| n).count(), 5); // the hole and its 4 neighbours
}

/// A rectified (left, right) pair.
type Pair = (Image<f32>, Image<f32>);

/// K shots of a plane under K independent patterns: one pair per pattern seed.
fn plane_sequence(rig: &StereoRig, shots: u64) -> (Scene, Vec<Pair>) {
    let planes = || {
        vec![Plane::from_point_normal(
            rig,
            [0.0, 0.0, 0.6],
            [0.2, 0.1, -1.0],
        )]
    };
    let pairs = (0..shots)
        .map(|k| scene(W, H, planes(), vec![], 40 + k).render_pair())
        .collect();
    (scene(W, H, planes(), vec![], 40), pairs)
}

fn match_sequence(pairs: &[Pair], config: &StereoMatcherConfig) -> StereoResult {
    let left: Vec<&Image<f32>> = pairs.iter().map(|p| &p.0).collect();
    let right: Vec<&Image<f32>> = pairs.iter().map(|p| &p.1).collect();
    match_stereo_sequence(&left, &right, config, None).unwrap()
}

/// K copies of one pair: the space-time window holds each value K times, so its means, norms
/// and cross term all scale alike and every ZNCC is the single-shot one — up to f32 rounding of
/// the running sums (relative ~1e-6 of a score, far below the 1e-3 subpixel resolution that
/// would move a disparity by more than 1e-3 px).
#[test]
fn repeated_shots_match_like_one() {
    let rig = test_rig();
    let config = test_config(&rig);
    let (_, pairs) = plane_sequence(&rig, 1);
    let single = match_sequence(&pairs, &config);
    let repeated = match_sequence(&vec![pairs[0].clone(); 4], &config);
    let (mut same_status, mut max_diff) = (0usize, 0.0f32);
    let n = single.status.data().len();
    for i in 0..n {
        if single.status.data()[i] == repeated.status.data()[i] {
            same_status += 1;
        }
        let (a, b) = (
            single.disparity_px.data()[i],
            repeated.disparity_px.data()[i],
        );
        if a.is_finite() && b.is_finite() {
            max_diff = max_diff.max((a - b).abs());
        }
    }
    // A status can flip only where a score sits within rounding of a threshold: a handful.
    assert!(
        same_status as f64 >= 0.999 * n as f64,
        "{same_status} of {n}"
    );
    assert!(
        max_diff < 1e-3,
        "largest disparity difference {max_diff} px"
    );
    assert_eq!(
        match_stereo_sequence(&[], &[], &config, None).unwrap_err(),
        StereoError::ShotCount { left: 0, right: 0 }
    );
    let (l, r) = (&pairs[0].0, &pairs[0].1);
    assert_eq!(
        match_stereo_sequence(&[l, l], &[r], &config, None).unwrap_err(),
        StereoError::ShotCount { left: 2, right: 1 }
    );
}

/// Eight patterns against one with a 3×3 window on a slanted plane (the 11×11 single shot is
/// printed for reference). A single 3×3 shot has 9 samples of a ≈ 2.2 px binary texture: too
/// few to be unique, it loses coverage and makes gross errors. Eight shots hold 72 samples:
/// unique everywhere (coverage > 99 %, no error ≥ 1 px), and the disparity's Fisher
/// information is 8× (eq 2–3 summed over shots), so the noise part of the RMSE falls by
/// √8 ≈ 2.8; subpixel (pixel-locking) bias does not average over shots — the fractional
/// disparity is the same in every shot — so only a factor 2 is asserted.
#[test]
fn eight_shots_make_a_3x3_window_dense_and_accurate() {
    let rig = test_rig();
    let base = test_config(&rig);
    let small = StereoMatcherConfig {
        window_radius_px: 1,
        edge_windows: None,
        ..base
    };
    let (scene, pairs) = plane_sequence(&rig, 8);
    let region = interior(&base);
    let all = |_, _| true;
    let e_single_large = errors(
        &scene,
        &rig,
        &match_sequence(&pairs[..1], &base),
        region,
        all,
    );
    let e_single_small = errors(
        &scene,
        &rig,
        &match_sequence(&pairs[..1], &small),
        region,
        all,
    );
    let e_multi_small = errors(&scene, &rig, &match_sequence(&pairs, &small), region, all);
    println!(
        "slanted plane: 1 shot 11×11 {:.4} px, cov {:.3}; 1 shot 3×3 {:.4} px, cov {:.3}; 8 shots 3×3 {:.4} px, cov {:.3}",
        e_single_large.rmse_px,
        e_single_large.coverage(),
        e_single_small.rmse_px,
        e_single_small.coverage(),
        e_multi_small.rmse_px,
        e_multi_small.coverage()
    );
    assert!(e_multi_small.coverage() > 0.99, "{e_multi_small:?}");
    assert!(
        e_multi_small.rmse_px < 0.5 * e_single_small.rmse_px,
        "{e_multi_small:?} vs {e_single_small:?}"
    );
    assert!(e_multi_small.max_abs_px < 1.0, "{e_multi_small:?}");
    assert!(
        e_single_small.coverage() < e_multi_small.coverage() - 0.1,
        "{e_single_small:?}"
    );
}
