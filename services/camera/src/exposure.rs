//! Exposure stacks: the projector shows its white pattern and the left camera takes the same
//! view at several exposure times Δt — the input of the camera-response calibration
//! (Debevec–Malik, the paper's eq 12: I = g(E·Δt)).
//!
//! The radiance does not depend on Δt, so it is rendered once; each Δt is a separate sensor
//! read-out (its own shot and read noise) of that one radiance image.

use glint_geometry::image::Image;
use glint_render::integrator::{RenderSettings, render};
use glint_render::projector::Pattern;
use glint_render::sensor::Sensor;
use nalgebra::Isometry3;

use crate::capture::{CaptureError, CaptureTruth, MockSliCamera};

/// One white-pattern exposure stack of the left camera.
#[derive(Clone, Debug)]
pub struct ExposureStack {
    /// Left camera → world.
    pub t_w_c: Isometry3<f64>,
    /// Exposure times Δt, seconds, increasing.
    pub exposures_s: Vec<f64>,
    /// The left image at each Δt (same order), the sensor's digital numbers.
    pub left: Vec<Image<u16>>,
    /// The sensor's bit depth (DNs run 0 ..= 2^bits − 1).
    pub bit_depth: u8,
}

/// Checks an exposure list: at least 2 times, each finite and > 0, no two equal. Returns them
/// sorted increasing.
pub fn validated_exposures(exposures_s: &[f64]) -> Result<Vec<f64>, CaptureError> {
    let bad = |problem: String| CaptureError::Exposures { problem };
    if exposures_s.len() < 2 {
        return Err(bad(format!(
            "{} exposure time(s) given; a stack needs at least 2",
            exposures_s.len()
        )));
    }
    if let Some(x) = exposures_s.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
        return Err(bad(format!(
            "exposure time {x} s must be finite and positive"
        )));
    }
    let mut sorted = exposures_s.to_vec();
    sorted.sort_by(f64::total_cmp);
    if let Some(pair) = sorted.windows(2).find(|p| p[0] == p[1]) {
        return Err(bad(format!(
            "exposure time {} s is given twice; the times must be distinct",
            pair[0]
        )));
    }
    Ok(sorted)
}

impl MockSliCamera<'_> {
    /// Takes a white-pattern exposure stack from left-camera pose `t_w_c`: one render of the
    /// left radiance (the capture's light transport and samples), read out through the
    /// configured sensor with its exposure time replaced by each of `exposures_s` (seconds;
    /// validated by [`validated_exposures`], returned sorted), each read-out with its own noise
    /// seed derived from `seed`. The ground truth (the left radiance under the white pattern,
    /// its depth and labels) comes beside the stack, for evaluation only.
    pub fn capture_exposure_stack(
        &self,
        t_w_c: &Isometry3<f64>,
        exposures_s: &[f64],
        seed: u64,
    ) -> Result<(ExposureStack, CaptureTruth), CaptureError> {
        let exposures_s = validated_exposures(exposures_s)?;
        let [left, _] = self.rig.cameras(t_w_c);
        let projector = self.rig.projector(t_w_c, Pattern::White);
        let render = render(
            self.scene,
            &left,
            &projector,
            &RenderSettings {
                transport: self.config.transport,
                samples_per_pixel: self.config.samples_per_pixel,
                roi: None,
                seed,
            },
        );
        let radiance = &render.radiance;
        let images = exposures_s
            .iter()
            .enumerate()
            .map(|(k, &dt)| {
                let sensor = Sensor {
                    exposure_s: dt as f32,
                    ..self.config.sensor.clone()
                };
                // Distinct, well-separated noise streams per exposure.
                let noise_seed = seed ^ (k as u64 + 1).wrapping_mul(0xD1B5_4A32_D192_ED03);
                sensor.read_out(radiance, noise_seed)
            })
            .collect();
        let stack = ExposureStack {
            t_w_c: *t_w_c,
            exposures_s,
            left: images,
            bit_depth: self.config.sensor.bit_depth,
        };
        Ok((stack, CaptureTruth::from_render(render)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::CaptureConfig;
    use crate::materials;
    use glint_geometry::TriMesh;
    use glint_render::integrator::LightTransport;
    use glint_render::rig::SliRig;
    use glint_render::scene::{Scene, SceneInstance};
    use glint_render::sensor::ResponseCurve;
    use nalgebra::{Point3, Vector3};

    fn plane_camera_scene() -> Scene {
        let plane = TriMesh::cuboid([0.0, 0.0, -0.005], [1.0, 1.0, 0.005]);
        let instance = SceneInstance {
            mesh: 0,
            t_w_o: Isometry3::identity(),
            material: 0,
            label: 1,
        };
        Scene::build(&[plane], vec![instance], vec![materials::diffuse_twin()]).unwrap()
    }

    #[test]
    fn exposures_are_validated_and_sorted() {
        assert_eq!(
            validated_exposures(&[2e-3, 1e-3]).unwrap(),
            vec![1e-3, 2e-3]
        );
        for bad in [
            &[1e-3][..],
            &[],
            &[1e-3, 0.0],
            &[1e-3, -1e-3],
            &[1e-3, f64::NAN],
            &[1e-3, f64::INFINITY],
            &[1e-3, 2e-3, 1e-3],
        ] {
            let err = validated_exposures(bad).unwrap_err().to_string();
            assert!(err.contains("exposure"), "{bad:?}: {err}");
        }
    }

    /// With a linear response, no saturation and a flat lit plane, the mean DN must scale
    /// linearly with Δt, and each read-out must carry its own noise.
    #[test]
    fn stack_scales_with_exposure_and_has_independent_noise() {
        let scene = plane_camera_scene();
        let rig = SliRig::ensenso_n35().resized(160, 128).unwrap();
        let mut config = CaptureConfig::for_rig(&rig).unwrap();
        config.transport = LightTransport::SinglePath;
        config.samples_per_pixel = 1;
        config.sensor.response = ResponseCurve::Linear;
        config.sensor.bit_depth = 12;
        let camera = MockSliCamera {
            rig,
            scene: &scene,
            config,
        };
        let t_w_c = Isometry3::face_towards(
            &Point3::new(0.0, 0.0, 0.6),
            &Point3::origin(),
            &Vector3::y(),
        );
        // Plane at 0.6 m sits at ~40 % of full well at 10 ms: 2 and 4 ms stay well below it.
        let (stack, truth) = camera
            .capture_exposure_stack(&t_w_c, &[4e-3, 2e-3, 4e-3 + 1e-9], 3)
            .unwrap();
        assert_eq!(stack.exposures_s, vec![2e-3, 4e-3, 4e-3 + 1e-9]);
        assert_eq!(stack.left.len(), 3);
        assert_eq!(stack.bit_depth, 12);
        let mean = |img: &Image<u16>| {
            img.data().iter().map(|&d| d as f64).sum::<f64>() / img.data().len() as f64
        };
        let (m2, m4) = (mean(&stack.left[0]), mean(&stack.left[1]));
        // Expected ratio 2; quantisation rounding (±0.5 DN) and shot noise over 20k pixels
        // move each mean by far less than 1 %.
        assert!((m4 / m2 - 2.0).abs() < 0.02, "means {m2} and {m4}");
        // The noiseless expectation from the GT radiance: shot and read noise are zero-mean,
        // so the means agree to their standard error (< 0.1 DN here) plus rounding.
        let sensor = Sensor {
            exposure_s: 4e-3,
            ..camera.config.sensor.clone()
        };
        let expected = truth
            .left_radiance
            .data()
            .iter()
            .map(|&l| sensor.noiseless_dn(l) as f64)
            .sum::<f64>()
            / truth.left_radiance.data().len() as f64;
        assert!((m4 - expected).abs() < 0.5, "{m4} vs {expected}");
        // Two almost equal exposures: different noise, so the images differ pixel by pixel.
        let differing = stack.left[1]
            .data()
            .iter()
            .zip(stack.left[2].data())
            .filter(|(a, b)| a != b)
            .count();
        assert!(differing > stack.left[1].data().len() / 4, "{differing}");
    }
}
