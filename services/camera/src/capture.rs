//! The mock SLI camera's capture: render the left and right random-pattern images with the
//! physically based renderer, read them out through the sensor (noise, response, saturation,
//! quantisation), and match them with the stereo matcher. Missing depth emerges from that
//! physics; nothing is masked by hand.

use glint_geometry::image::{DepthMap, Image, normalised_intensity};
use glint_render::integrator::{LightTransport, RenderSettings, render};
use glint_render::projector::Pattern;
use glint_render::rig::SliRig;
use glint_render::scene::Scene;
use glint_render::sensor::Sensor;
use glint_render::stereo::{
    DisparityRange, MatchStatus, StereoError, StereoMatcherConfig, disparity_to_depth, match_stereo,
};
use nalgebra::Isometry3;

/// How the mock camera images a scene.
#[derive(Clone, Debug)]
pub struct CaptureConfig {
    pub transport: LightTransport,
    pub samples_per_pixel: u32,
    pub sensor: Sensor,
    pub matcher: StereoMatcherConfig,
    /// Fraction of lit projector pixels in the random-dot pattern.
    pub pattern_fill: f64,
    /// Seed of the (fixed, hardware) dot pattern.
    pub pattern_seed: u64,
}

impl CaptureConfig {
    /// Multi-path (inter-reflections included), 4 samples per pixel, the default sensor, and a
    /// matcher searching the depths 0.3–1.2 m of `rig`.
    pub fn for_rig(rig: &SliRig) -> Result<Self, StereoError> {
        let matcher = StereoMatcherConfig {
            disparity_range: DisparityRange::from_depth_range(&rig.stereo, 0.3, 1.2)?,
            ..StereoMatcherConfig::default()
        };
        Ok(Self {
            transport: LightTransport::MULTI_PATH_DEFAULT,
            samples_per_pixel: 4,
            sensor: Sensor::default(),
            matcher,
            pattern_fill: 0.5,
            pattern_seed: 0x5EED,
        })
    }
}

/// One stereo capture from one viewpoint.
#[derive(Clone, Debug)]
pub struct StereoCapture {
    /// Left camera → world.
    pub t_w_c: Isometry3<f64>,
    /// Pattern images as read out (digital numbers, camera-response encoded).
    pub left: Image<u16>,
    pub right: Image<u16>,
    /// Matched depth in the left camera, NaN where matching failed.
    pub depth: DepthMap,
    /// Why each left pixel has or lacks depth.
    pub match_status: Image<MatchStatus>,
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
    #[error("stereo matching: {0}")]
    Stereo(#[from] StereoError),
    /// The exposure times of an exposure stack are unusable.
    #[error("exposure stack: {problem}")]
    Exposures { problem: String },
}

/// A simulated structured-light camera looking at a fixed scene.
pub struct MockSliCamera<'a> {
    pub rig: SliRig,
    pub scene: &'a Scene,
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

    /// Renders both cameras' radiance for a rig pose under `pattern`.
    pub fn render_pair(
        &self,
        t_w_c: &Isometry3<f64>,
        pattern: Pattern,
        seed: u64,
    ) -> [glint_render::integrator::RenderOutput; 2] {
        let projector = self.rig.projector(t_w_c, pattern);
        let settings = |s: u64| RenderSettings {
            transport: self.config.transport,
            samples_per_pixel: self.config.samples_per_pixel,
            roi: None,
            seed: s,
        };
        let [left, right] = self.rig.cameras(t_w_c);
        [
            render(self.scene, &left, &projector, &settings(seed)),
            render(self.scene, &right, &projector, &settings(seed ^ 0xA5A5)),
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
        let max_dn = self.config.sensor.max_dn();
        let result = match_stereo(
            &normalised_intensity(left, max_dn),
            &normalised_intensity(right, max_dn),
            &self.config.matcher,
            None,
        )?;
        Ok((disparity_to_depth(&result, &self.rig.stereo), result.status))
    }

    /// Captures the random-pattern stereo pair from left-camera pose `t_w_c` and matches it;
    /// the ground truth comes beside it, for evaluation only. `seed` drives the sampling and
    /// the sensor noise.
    pub fn capture(
        &self,
        t_w_c: &Isometry3<f64>,
        seed: u64,
    ) -> Result<(StereoCapture, CaptureTruth), CaptureError> {
        let renders = self.render_pair(t_w_c, self.pattern(), seed);
        self.capture_rendered(t_w_c, renders, seed)
    }

    /// The sensor read-out and matching half of [`Self::capture`], on radiance already
    /// rendered with [`Self::render_pair`] for the pattern: repeated captures of a static
    /// scene differ only in sensor noise, so they can share one render (the radiance of a
    /// static scene does not change between shots).
    pub fn capture_rendered(
        &self,
        t_w_c: &Isometry3<f64>,
        [left_render, right_render]: [glint_render::integrator::RenderOutput; 2],
        seed: u64,
    ) -> Result<(StereoCapture, CaptureTruth), CaptureError> {
        let sensor = &self.config.sensor;
        let left = sensor.read_out(&left_render.radiance, seed.wrapping_add(1));
        let right = sensor.read_out(&right_render.radiance, seed.wrapping_add(2));
        let (depth, match_status) = self.match_pair(&left, &right)?;
        let capture = StereoCapture {
            t_w_c: *t_w_c,
            left,
            right,
            depth,
            match_status,
        };
        Ok((capture, CaptureTruth::from_render(left_render)))
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
    use glint_geometry::TriMesh;
    use glint_render::scene::SceneInstance;
    use nalgebra::{Point3, Vector3};

    #[test]
    fn diffuse_plane_at_0_6_m_gives_accurate_dense_depth() {
        let half = 1.0f32;
        let plane = TriMesh::new(
            vec![
                Point3::new(-half, -half, 0.0),
                Point3::new(half, -half, 0.0),
                Point3::new(half, half, 0.0),
                Point3::new(-half, half, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let instance = SceneInstance {
            mesh: 0,
            t_w_o: Isometry3::identity(),
            material: 0,
            label: 1,
        };
        let scene =
            Scene::build(&[plane], vec![instance], vec![materials::diffuse_twin()]).unwrap();
        let rig = SliRig::ensenso_n35();
        // Looking straight down at the plane from 0.6 m.
        let t_w_c = Isometry3::face_towards(
            &Point3::new(0.0, 0.0, 0.6),
            &Point3::origin(),
            &Vector3::y(),
        );
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
