//! The mock SLI camera's capture: render the left and right random-pattern images with the
//! physically based renderer, read them out through the sensor (noise, response, saturation,
//! quantisation), and match them with the stereo matcher. Missing depth emerges from that
//! physics; nothing is masked by hand.

use glint_geometry::image::{DepthMap, Image, normalised_intensity};
use glint_render::integrator::{LightTransport, RenderOutput, RenderSettings, render};
use glint_render::pattern_record::record_pattern_paths;
use glint_render::projector::Pattern;
use glint_render::rig::SliRig;
use glint_render::scene::Scene;
use glint_render::sensor::Sensor;
use glint_render::stereo::{
    DisparityRange, MatchStatus, StereoError, StereoMatcherConfig, disparity_to_depth,
    match_stereo_sequence,
};
use nalgebra::Isometry3;

/// How the mock camera images a scene.
#[derive(Clone, Debug)]
pub struct CaptureConfig {
    /// Which light paths the renders follow (single-path or with inter-reflections).
    pub transport: LightTransport,
    /// Path samples per pixel of each camera's render, ≥ 1 (0 counts as 1).
    pub samples_per_pixel: u32,
    /// The sensor that reads rendered radiance out as digital numbers (noise, response,
    /// saturation, quantisation).
    pub sensor: Sensor,
    /// The stereo matcher that turns the read-out pattern images into depth.
    pub matcher: StereoMatcherConfig,
    /// Fraction of lit projector pixels in the random-dot pattern.
    pub pattern_fill: f64,
    /// Seed of the (fixed, hardware) dot pattern of the first shot.
    pub pattern_seed: u64,
    /// Patterns projected per capture, K ≥ 1 (0 counts as 1): a left and a right image under
    /// each, matched together by the spatio-temporal matcher (like the N35's FlexView
    /// sequence). Shot 0 shows the `pattern_seed` pattern; shot k a pattern re-drawn with its
    /// own seed ([`MockSliCamera::shot_pattern`]). K = 1 is the single-shot camera.
    pub shots: u32,
}

/// Shots per capture of the default camera ([`CaptureConfig::for_rig`]): 8 patterns matched
/// with 3×3 space-time windows ([`default_window_radius_px`]).
///
/// Chosen on known geometry alone (`glint eval camera --parts all --shots 1,2,4,8,16
/// --window-radius-px 1,2,3,5 --views 2 --resolution 640x512 --spp 2`, 8 instances, seed 1):
/// on the five parts' diffuse twins, K = 8 with 3×3 windows puts depth points a mean (over
/// parts) median 0.34 mm and 90th percentile 1.0 mm from the true surface, 3.4 % more than
/// 2 mm off, at 88 % coverage — against 0.62 / 4.1 mm, 17 % and 67 % for the single-shot
/// 11×11 camera; on the shiny parts 24 % are more than 2 mm off instead of 44 % with more
/// correct depth (42 % of part pixels within 2 mm instead of 28 %). The plane at 0.6 m keeps
/// 99.99 % coverage (0.72 mm RMSE at that resolution, 0.36 mm single-shot 11×11). K = 16
/// gains 0.03 mm of median for twice the shots; larger windows at K = 8 bias edges
/// (90th percentile 1.6 mm at 5×5, 4.5 mm at 11×11).
pub const DEFAULT_SHOTS: u32 = 8;

/// The camera's matching window radius for a capture of `shots` patterns, px, from the same
/// table as [`DEFAULT_SHOTS`] (the window with the most part pixels within 2 mm of the true
/// surface on the diffuse twins at that K): 11×11 for one shot (the single-shot matcher's own
/// choice, see `StereoMatcherConfig`), 5×5 for 2–3 shots (a 3×3 window over 2 shots is not
/// unique enough: 44 % coverage), 3×3 from 4 shots on.
pub fn default_window_radius_px(shots: u32) -> u32 {
    match shots {
        0 | 1 => 5,
        2 | 3 => 2,
        _ => 1,
    }
}

impl CaptureConfig {
    /// Multi-path (inter-reflections included), 4 samples per pixel, the default sensor,
    /// [`DEFAULT_SHOTS`] patterns, and a matcher searching the depths 0.3–1.2 m of `rig`.
    pub fn for_rig(rig: &SliRig) -> Result<Self, StereoError> {
        Self::for_rig_and_shots(rig, DEFAULT_SHOTS)
    }

    /// [`Self::for_rig`] with `shots` patterns per capture and the window for that many
    /// ([`default_window_radius_px`]; the small edge windows only where smaller than it).
    pub fn for_rig_and_shots(rig: &SliRig, shots: u32) -> Result<Self, StereoError> {
        let defaults = StereoMatcherConfig::default();
        let window_radius_px = default_window_radius_px(shots);
        let matcher = StereoMatcherConfig {
            disparity_range: DisparityRange::from_depth_range(&rig.stereo, 0.3, 1.2)?,
            window_radius_px,
            edge_windows: defaults
                .edge_windows
                .filter(|e| e.window_radius_px < window_radius_px),
            ..defaults
        };
        Ok(Self {
            transport: LightTransport::MULTI_PATH_DEFAULT,
            samples_per_pixel: 4,
            sensor: Sensor::default(),
            matcher,
            pattern_fill: 0.5,
            pattern_seed: 0x5EED,
            shots: shots.max(1),
        })
    }
}

/// Two more read-outs of one shot's left radiance ([`MockSliCamera::noise_shots`]).
pub type NoiseShots = [Image<u16>; 2];

/// One stereo capture from one viewpoint.
#[derive(Clone, Debug)]
pub struct StereoCapture {
    /// Left camera → world.
    pub t_w_c: Isometry3<f64>,
    /// Left pattern image of shot 1 as read out (digital numbers, camera-response encoded).
    pub left: Image<u16>,
    /// Right pattern image of shot 1, as [`Self::left`].
    pub right: Image<u16>,
    /// Shots 2..=K of a multi-shot capture, `[left, right]` each, in projection order (empty
    /// for a single shot); `left`, `right` above are shot 1.
    pub later_shots: Vec<[Image<u16>; 2]>,
    /// Matched depth in the left camera, NaN where matching failed.
    pub depth: DepthMap,
    /// Why each left pixel has or lacks depth.
    pub match_status: Image<MatchStatus>,
}

impl StereoCapture {
    /// Shot count K.
    pub fn shots(&self) -> usize {
        1 + self.later_shots.len()
    }

    /// The left (`side` 0) or right (1) images of all K shots, in projection order.
    pub fn shot_images(&self, side: usize) -> Vec<&Image<u16>> {
        let first = if side == 0 { &self.left } else { &self.right };
        std::iter::once(first)
            .chain(self.later_shots.iter().map(|pair| &pair[side.min(1)]))
            .collect()
    }
}

/// The noiseless radiance of every shot of a capture from one viewpoint, rendered once: a
/// static scene's radiance does not change between captures, so repeated captures can share it
/// and differ only in sensor noise ([`MockSliCamera::capture_rendered`]).
#[derive(Clone, Debug)]
pub struct RenderedShots {
    /// Left camera radiance under each shot's pattern, W·sr⁻¹·m⁻², K images.
    pub left: Vec<Image<f32>>,
    /// Right camera radiance under each shot's pattern, W·sr⁻¹·m⁻², K images.
    pub right: Vec<Image<f32>>,
    /// The left camera's ground truth (radiance under shot 0's pattern), evaluation only.
    pub truth: CaptureTruth,
    /// Rays traced for all shots together.
    pub rays_traced: u64,
}

/// What the simulator knows about a capture and a real camera would not: ground truth, for
/// evaluation only. The mock camera returns it beside the measurement ([`StereoCapture`],
/// [`crate::exposure::ExposureStack`]) as a separate type, so that estimators and predictors,
/// which take the measurement, cannot read it.
#[derive(Clone, Debug)]
pub struct CaptureTruth {
    /// The left camera's radiance with the capture's light transport, W·sr⁻¹·m⁻² (under the
    /// first shot's pattern for a pattern capture, the white pattern for an exposure stack).
    pub left_radiance: Image<f32>,
    /// Depth z of the first surface through each left pixel centre, metres; NaN where nothing
    /// is hit.
    pub depth_m: Image<f32>,
    /// Instance label of that surface, 0 where nothing is hit.
    pub label: Image<u16>,
}

impl CaptureTruth {
    /// The truth of a left-camera render.
    pub fn from_render(render: glint_render::integrator::RenderOutput) -> Self {
        Self {
            left_radiance: render.radiance,
            depth_m: render.depth_m,
            label: render.label,
        }
    }
}

/// Why a capture failed.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The stereo matcher rejected its input or configuration (e.g. left and right shot
    /// counts differ); see the [`StereoError`].
    #[error("stereo matching: {0}")]
    Stereo(#[from] StereoError),
    /// The exposure times of an exposure stack are unusable.
    #[error("exposure stack: {problem}")]
    Exposures {
        /// What is wrong with the exposure times.
        problem: String,
    },
}

/// A simulated structured-light camera looking at a fixed scene.
pub struct MockSliCamera<'a> {
    /// The stereo cameras and projector, posed relative to the left camera.
    pub rig: SliRig,
    /// The scene it looks at, in the world frame.
    pub scene: &'a Scene,
    /// How it renders, reads out and matches.
    pub config: CaptureConfig,
}

impl MockSliCamera<'_> {
    /// The pattern the projector shows for depth captures.
    pub fn pattern(&self) -> Pattern {
        let k = &self.rig.projector_intrinsics;
        Pattern::random_dots(
            k.width_px,
            k.height_px,
            self.config.pattern_fill,
            self.config.pattern_seed,
        )
    }

    /// The pattern of shot `k` (0-based): shot 0 is [`Self::pattern`], later shots are re-drawn
    /// random dots with the same fill and a seed of their own.
    pub fn shot_pattern(&self, k: u32) -> Pattern {
        let p = &self.rig.projector_intrinsics;
        let seed = if k == 0 {
            self.config.pattern_seed
        } else {
            self.config.pattern_seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        };
        Pattern::random_dots(p.width_px, p.height_px, self.config.pattern_fill, seed)
    }

    /// Renders both cameras' radiance for every shot of a capture from rig pose `t_w_c`.
    /// One shot is a direct render ([`Self::render_pair`]); K > 1 shots trace each camera's
    /// paths once and evaluate the K patterns from that [`glint_render::pattern_record`]
    /// (light transport is linear in the pattern), with the same seeds, so shot 0 equals the
    /// single-shot render up to f32 rounding.
    pub fn render_shots(&self, t_w_c: &Isometry3<f64>, seed: u64) -> RenderedShots {
        let shots = self.config.shots.max(1);
        if shots == 1 {
            let [left, right] = self.render_pair(t_w_c, self.pattern(), seed);
            return RenderedShots {
                rays_traced: left.rays_traced + right.rays_traced,
                left: vec![left.radiance.clone()],
                right: vec![right.radiance],
                truth: CaptureTruth::from_render(left),
            };
        }
        let projector = self.rig.projector(t_w_c, Pattern::White);
        let [left_camera, right_camera] = self.rig.cameras(t_w_c);
        let record = |camera, s| {
            record_pattern_paths(self.scene, camera, &projector, &self.render_settings(s))
        };
        let (left_record, right_record) = (
            record(&left_camera, seed),
            record(&right_camera, seed ^ 0xA5A5),
        );
        let patterns: Vec<Pattern> = (0..shots).map(|k| self.shot_pattern(k)).collect();
        let left = left_record.radiances(&patterns);
        let right = right_record.radiances(&patterns);
        RenderedShots {
            truth: CaptureTruth {
                left_radiance: left[0].clone(),
                depth_m: left_record.depth_m.clone(),
                label: left_record.label.clone(),
            },
            left,
            right,
            rays_traced: left_record.rays_traced + right_record.rays_traced,
        }
    }

    fn render_settings(&self, seed: u64) -> RenderSettings {
        RenderSettings {
            transport: self.config.transport,
            samples_per_pixel: self.config.samples_per_pixel,
            roi: None,
            seed,
        }
    }

    /// Renders both cameras' radiance for a rig pose under `pattern`.
    pub fn render_pair(
        &self,
        t_w_c: &Isometry3<f64>,
        pattern: Pattern,
        seed: u64,
    ) -> [RenderOutput; 2] {
        let projector = self.rig.projector(t_w_c, pattern);
        let [left, right] = self.rig.cameras(t_w_c);
        [
            render(self.scene, &left, &projector, &self.render_settings(seed)),
            render(
                self.scene,
                &right,
                &projector,
                &self.render_settings(seed ^ 0xA5A5),
            ),
        ]
    }

    /// Matches a pair of read-out pattern images (digital numbers) with the configured
    /// matcher: depth in the left camera (NaN where nothing matched) and why each pixel has
    /// or lacks it.
    pub fn match_pair(
        &self,
        left: &Image<u16>,
        right: &Image<u16>,
    ) -> Result<(DepthMap, Image<MatchStatus>), CaptureError> {
        self.match_shots(&[left], &[right])
    }

    /// Matches the K shots of a capture (read-out digital numbers, `left[k]` and `right[k]`
    /// under pattern k) with the configured matcher's space-time windows.
    pub fn match_shots(
        &self,
        left: &[&Image<u16>],
        right: &[&Image<u16>],
    ) -> Result<(DepthMap, Image<MatchStatus>), CaptureError> {
        let max_dn = self.config.sensor.max_dn();
        let normalise = |images: &[&Image<u16>]| -> Vec<Image<f32>> {
            images
                .iter()
                .map(|dn| normalised_intensity(dn, max_dn))
                .collect()
        };
        let (left, right) = (normalise(left), normalise(right));
        let result = match_stereo_sequence(
            &left.iter().collect::<Vec<_>>(),
            &right.iter().collect::<Vec<_>>(),
            &self.config.matcher,
            None,
        )?;
        Ok((disparity_to_depth(&result, &self.rig.stereo), result.status))
    }

    /// The sensor read-out of every shot of `rendered`, `[left, right]` per shot: each its own
    /// shot and read noise; shot 0 uses the single-shot camera's noise seeds, `seed + 1` (left)
    /// and `seed + 2` (right), shot k > 0 seeds of its own.
    pub fn read_out_shots(&self, rendered: &RenderedShots, seed: u64) -> Vec<[Image<u16>; 2]> {
        let sensor = &self.config.sensor;
        rendered
            .left
            .iter()
            .zip(&rendered.right)
            .enumerate()
            .map(|(k, (l, r))| {
                let base = if k == 0 {
                    seed
                } else {
                    seed ^ (k as u64).wrapping_mul(0xD1B5_4A32_D192_ED03)
                };
                [
                    sensor.read_out(l, base.wrapping_add(1)),
                    sensor.read_out(r, base.wrapping_add(2)),
                ]
            })
            .collect()
    }

    /// Captures the random-pattern stereo pair from left-camera pose `t_w_c` and matches it;
    /// the ground truth comes beside it, for evaluation only. `seed` drives the sampling and
    /// the sensor noise.
    pub fn capture(
        &self,
        t_w_c: &Isometry3<f64>,
        seed: u64,
    ) -> Result<(StereoCapture, CaptureTruth), CaptureError> {
        let rendered = self.render_shots(t_w_c, seed);
        self.capture_rendered(t_w_c, &rendered, seed)
    }

    /// [`Self::capture`] and, when `noise_shots`, [`Self::noise_shots`] of the same render:
    /// a capture as the camera stage delivers it (in-process and over gRPC alike).
    pub fn capture_with_noise_shots(
        &self,
        t_w_c: &Isometry3<f64>,
        seed: u64,
        noise_shots: bool,
    ) -> Result<(StereoCapture, Option<NoiseShots>, CaptureTruth), CaptureError> {
        let rendered = self.render_shots(t_w_c, seed);
        let (capture, truth) = self.capture_rendered(t_w_c, &rendered, seed)?;
        let noise = if noise_shots {
            self.noise_shots(&rendered, seed)
        } else {
            None
        };
        Ok((capture, noise, truth))
    }

    /// Two more read-outs of the first shot's left radiance: what a user takes to measure the
    /// sensor's noise (two shots of a static scene, photon transfer). Seeds `seed ^ 11` and
    /// `seed ^ 12`, as the experiments' recorded scenes.
    pub fn noise_shots(&self, rendered: &RenderedShots, seed: u64) -> Option<[Image<u16>; 2]> {
        let radiance = rendered.left.first()?;
        let sensor = &self.config.sensor;
        Some([
            sensor.read_out(radiance, seed ^ 11),
            sensor.read_out(radiance, seed ^ 12),
        ])
    }

    /// The sensor read-out and matching half of [`Self::capture`], on radiance already
    /// rendered with [`Self::render_shots`]: repeated captures of a static scene differ only in
    /// sensor noise, so they can share one render. Each shot is its own read-out through the
    /// configured sensor ([`Self::read_out_shots`]).
    pub fn capture_rendered(
        &self,
        t_w_c: &Isometry3<f64>,
        rendered: &RenderedShots,
        seed: u64,
    ) -> Result<(StereoCapture, CaptureTruth), CaptureError> {
        if rendered.left.is_empty() || rendered.left.len() != rendered.right.len() {
            return Err(StereoError::ShotCount {
                left: rendered.left.len(),
                right: rendered.right.len(),
            }
            .into());
        }
        let mut pairs = self.read_out_shots(rendered, seed);
        let lefts: Vec<&Image<u16>> = pairs.iter().map(|p| &p[0]).collect();
        let rights: Vec<&Image<u16>> = pairs.iter().map(|p| &p[1]).collect();
        let (depth, match_status) = self.match_shots(&lefts, &rights)?;
        let [left, right] = pairs.remove(0);
        let capture = StereoCapture {
            t_w_c: *t_w_c,
            left,
            right,
            later_shots: pairs,
            depth,
            match_status,
        };
        Ok((capture, rendered.truth.clone()))
    }
}

/// How well a capture's depth matches ground truth over a set of pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthQuality {
    /// Pixels that could have depth: a ground-truth surface (of the chosen instance) whose
    /// match window fits in both images.
    pub eligible: usize,
    /// Eligible pixels with a matched depth.
    pub valid: usize,
    /// RMS of matched − true depth over the valid pixels, metres (NaN when none).
    pub rmse_m: f64,
    /// Valid pixels more than 5 mm off: wrong depth rather than noisy depth.
    pub outliers_5mm: usize,
}

impl DepthQuality {
    /// valid / eligible.
    pub fn coverage(&self) -> f64 {
        if self.eligible == 0 {
            f64::NAN
        } else {
            self.valid as f64 / self.eligible as f64
        }
    }
    /// The missing-depth fraction, 1 − coverage.
    pub fn missing_fraction(&self) -> f64 {
        1.0 - self.coverage()
    }

    /// Valid pixels more than 5 mm off, as a share of the valid pixels.
    pub fn outlier_share(&self) -> f64 {
        self.outliers_5mm as f64 / self.valid.max(1) as f64
    }

    /// Several pixel sets' quality as one: counts add, the RMSE is over all their inliers.
    pub fn pooled(parts: impl IntoIterator<Item = DepthQuality>) -> DepthQuality {
        let (mut eligible, mut valid, mut outliers_5mm) = (0, 0, 0);
        let (mut sum_sq, mut inliers) = (0.0, 0usize);
        for q in parts {
            eligible += q.eligible;
            valid += q.valid;
            outliers_5mm += q.outliers_5mm;
            let n = q.valid - q.outliers_5mm;
            if n > 0 {
                sum_sq += q.rmse_m * q.rmse_m * n as f64;
                inliers += n;
            }
        }
        DepthQuality {
            eligible,
            valid,
            rmse_m: if inliers > 0 {
                (sum_sq / inliers as f64).sqrt()
            } else {
                f64::NAN
            },
            outliers_5mm,
        }
    }
}

/// Compares `capture.depth` with its ground truth `truth` on the pixels of instance `label`,
/// or on every surface pixel when `label` is `None`. The RMSE excludes the 5 mm outliers,
/// which are counted separately.
pub fn depth_quality(
    capture: &StereoCapture,
    truth: &CaptureTruth,
    rig: &SliRig,
    window_radius_px: u32,
    label: Option<u16>,
) -> DepthQuality {
    let (w, h) = (truth.depth_m.width(), truth.depth_m.height());
    let r = window_radius_px as f64;
    let mut quality = DepthQuality {
        eligible: 0,
        valid: 0,
        rmse_m: f64::NAN,
        outliers_5mm: 0,
    };
    let mut sum_sq = 0.0;
    let mut inliers = 0usize;
    for v in 0..h {
        for u in 0..w {
            let z_true = truth.depth_m.get(u, v).unwrap_or(f32::NAN) as f64;
            let l = truth.label.get(u, v).unwrap_or(0);
            if !z_true.is_finite() || label.is_some_and(|want| want != l) {
                continue;
            }
            let d = rig.stereo.disparity_from_depth(z_true);
            let (uc, vc) = (u as f64 + 0.5, v as f64 + 0.5);
            let fits = uc - r - d >= 0.0
                && uc + r <= w as f64
                && vc - r >= 0.0
                && vc + r <= h as f64
                && uc - r >= 0.0;
            if !fits {
                continue;
            }
            quality.eligible += 1;
            if let Some(z) = capture.depth.get(u, v) {
                quality.valid += 1;
                let e = z as f64 - z_true;
                if e.abs() > 5e-3 {
                    quality.outliers_5mm += 1;
                } else {
                    sum_sq += e * e;
                    inliers += 1;
                }
            }
        }
    }
    if inliers > 0 {
        quality.rmse_m = (sum_sq / inliers as f64).sqrt();
    }
    quality
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::materials;

    /// A multi-shot capture of the plane at 0.6 m (320×256: 13.1 mm of depth per pixel of
    /// disparity) with a 5×5 window: K shots, each its own pattern and noise, K = 1 identical
    /// to the single-shot camera, and 8 shots make the small window as dense and accurate as
    /// the default 11×11 single shot (see the matcher's
    /// `eight_shots_make_a_3x3_window_dense_and_accurate` for why).
    #[test]
    fn multi_shot_capture_of_a_plane() {
        let scene = plane_scene();
        let rig = SliRig::ensenso_n35().resized(320, 256).unwrap();
        let t_w_c = looking_down(0.6);
        let base = CaptureConfig {
            samples_per_pixel: 1,
            ..CaptureConfig::for_rig(&rig).unwrap()
        };
        let camera = |shots: u32, radius: u32| MockSliCamera {
            rig,
            scene: &scene,
            config: CaptureConfig {
                shots,
                matcher: StereoMatcherConfig {
                    window_radius_px: radius,
                    edge_windows: base
                        .matcher
                        .edge_windows
                        .filter(|e| e.window_radius_px < radius),
                    ..base.matcher
                },
                ..base.clone()
            },
        };
        let single = camera(1, 5);
        let (one, truth) = single.capture(&t_w_c, 3).unwrap();
        assert_eq!(one.shots(), 1);
        // The single-shot camera is unchanged: its own render and matcher, seeds as before.
        let [l, r] = single.render_pair(&t_w_c, single.pattern(), 3);
        let sensor = &single.config.sensor;
        assert_eq!(one.left, sensor.read_out(&l.radiance, 4));
        assert_eq!(one.right, sensor.read_out(&r.radiance, 5));
        assert_eq!(truth.left_radiance.data(), l.radiance.data());
        let (eight, _) = camera(8, 2).capture(&t_w_c, 3).unwrap();
        assert_eq!(eight.shots(), 8);
        assert_eq!(eight.shot_images(1).len(), 8);
        // Each shot its own pattern: the left images differ well beyond noise.
        let differing = eight.shot_images(0)[1]
            .data()
            .iter()
            .zip(eight.left.data())
            .filter(|(a, b)| a.abs_diff(**b) > 20)
            .count();
        assert!(differing > eight.left.data().len() / 4, "{differing}");
        let quality = |c: &StereoCapture, radius| depth_quality(c, &truth, &rig, radius, Some(1));
        let (q1, q8) = (quality(&one, 5), quality(&eight, 2));
        let (q1_small, _) = camera(1, 2).capture(&t_w_c, 3).unwrap();
        let q1_small = quality(&q1_small, 2);
        eprintln!("plane: 1 shot 11×11 {q1:?}\n 1 shot 5×5 {q1_small:?}\n 8 shots 5×5 {q8:?}");
        assert!(q8.coverage() > 0.95, "{q8:?}");
        assert!(q8.coverage() >= q1.coverage() - 0.01, "{q8:?} vs {q1:?}");
        // 8 × 25 = 200 samples against 121 in the 11×11 window: no noisier, up to the
        // subpixel bias that shots do not average (20 % allowed); against the same 5×5 window
        // with one shot, 8× the information: the noise part falls by √8 ≈ 2.8, 1/0.6 asserted.
        assert!(q8.rmse_m < 1.2 * q1.rmse_m, "{q8:?} vs {q1:?}");
        assert!(q8.rmse_m < 0.6 * q1_small.rmse_m, "{q8:?} vs {q1_small:?}");
        assert_eq!(q8.outliers_5mm, 0, "{q8:?}");
        assert!(q1_small.coverage() < q8.coverage(), "{q1_small:?}");
    }

    fn plane_scene() -> Scene {
        crate::setup::plane_scene(1.0, materials::diffuse_twin()).unwrap()
    }

    use crate::setup::looking_down;

    #[test]
    fn diffuse_plane_at_0_6_m_gives_accurate_dense_depth() {
        let scene = plane_scene();
        let rig = SliRig::ensenso_n35();
        let t_w_c = looking_down(0.6);
        let config = CaptureConfig {
            samples_per_pixel: 1,
            ..CaptureConfig::for_rig(&rig).unwrap()
        };
        let camera = MockSliCamera {
            rig,
            scene: &scene,
            config,
        };
        let (capture, truth) = camera.capture(&t_w_c, 7).unwrap();
        let q = depth_quality(
            &capture,
            &truth,
            &rig,
            camera.config.matcher.window_radius_px,
            Some(1),
        );
        eprintln!(
            "plane at 0.6 m: coverage {:.4}, RMSE {:.3} mm, outliers {}",
            q.coverage(),
            q.rmse_m * 1e3,
            q.outliers_5mm
        );
        assert!(q.eligible > 900_000, "{q:?}");
        assert!(q.coverage() > 0.95, "{q:?}");
        assert!(q.rmse_m < 0.5e-3, "{q:?}");
        assert!(q.outliers_5mm < q.valid / 1000, "{q:?}");
    }
}
