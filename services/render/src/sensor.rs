//! The camera sensor: radiance × exposure → electrons (with shot and read noise) → the camera
//! response g → quantised digital numbers (eq 12: I = g(E·Δt)).

use glint_geometry::image::Image;
use rand::SeedableRng;
use rand_distr::{Distribution, Poisson, StandardNormal};
use rayon::prelude::*;

/// A monotone camera response `g`: normalised exposure x = electrons / full well, in [0, ∞),
/// to normalised intensity in [0, 1]; everything at or above x = 1 saturates.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ResponseCurve {
    /// `g(x) = x` (up to saturation).
    Linear,
    /// `g(x) = x^(1/γ)`.
    Gamma {
        /// Exponent γ > 0; γ > 1 brightens the darks.
        gamma: f32,
    },
    /// A film-like S-curve: `g(x) = ½ (1 + tanh(c·(x^(1/γ) − ½)) / tanh(c/2))`, monotone with
    /// g(0) = 0 and g(1) = 1; `contrast` c > 0 sets the steepness of the middle.
    SCurve {
        /// Exponent γ > 0 applied before the S-curve.
        gamma: f32,
        /// Steepness c > 0 of the middle of the curve.
        contrast: f32,
    },
}

impl ResponseCurve {
    /// g(x) for normalised exposure x (clamped to [0, 1]).
    #[inline]
    pub fn apply(&self, x: f32) -> f32 {
        let x = x.clamp(0.0, 1.0);
        match *self {
            ResponseCurve::Linear => x,
            ResponseCurve::Gamma { gamma } => x.powf(1.0 / gamma),
            ResponseCurve::SCurve { gamma, contrast } => {
                let y = x.powf(1.0 / gamma);
                0.5 * (1.0 + (contrast * (y - 0.5)).tanh() / (0.5 * contrast).tanh())
            }
        }
    }

    /// g⁻¹(i) for normalised intensity i in [0, 1], by bisection (g is monotone).
    pub fn invert(&self, i: f32) -> f32 {
        let (mut lo, mut hi) = (0.0f32, 1.0f32);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if self.apply(mid) < i {
                lo = mid
            } else {
                hi = mid
            }
        }
        0.5 * (lo + hi)
    }
}

/// Sensor parameters. Noise is physical: Poisson shot noise on the collected electrons and
/// Gaussian read noise, before the response and quantisation.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sensor {
    /// Exposure time Δt, seconds.
    pub exposure_s: f32,
    /// Electrons collected per unit radiance (W·sr⁻¹·m⁻²) per second of exposure: pixel area,
    /// lens étendue and quantum efficiency in one number.
    pub electrons_per_radiance_s: f32,
    /// Electrons at saturation.
    pub full_well_e: f32,
    /// Read noise, electrons RMS.
    pub read_noise_e: f32,
    /// Camera response g from normalised exposure (electrons / full well) to normalised
    /// intensity, before quantisation.
    pub response: ResponseCurve,
    /// Output bits per pixel (8 or 10 … 16).
    pub bit_depth: u8,
}

impl Default for Sensor {
    /// An industrial CMOS sensor: 10 ms, 10 000 e⁻ full well, 6 e⁻ read noise, gamma 2.2 S-curve,
    /// 8 bits. The radiance gain puts a 50 % grey diffuse surface 0.6 m from a 1 W/sr projector
    /// (L = 0.5/π · 1/0.36 ≈ 0.44) at ~40 % of full well.
    fn default() -> Self {
        Self {
            exposure_s: 0.01,
            electrons_per_radiance_s: 9.0e5,
            full_well_e: 10_000.0,
            read_noise_e: 6.0,
            response: ResponseCurve::SCurve {
                gamma: 2.2,
                contrast: 2.0,
            },
            bit_depth: 8,
        }
    }
}

impl Sensor {
    /// Largest digital number.
    pub fn max_dn(&self) -> u16 {
        ((1u32 << self.bit_depth.clamp(1, 16)) - 1) as u16
    }

    /// Expected electrons for a radiance (no noise, no saturation).
    #[inline]
    pub fn mean_electrons(&self, radiance: f32) -> f32 {
        radiance.max(0.0) * self.exposure_s * self.electrons_per_radiance_s
    }

    /// The digital number a noiseless pixel of `radiance` reads.
    #[inline]
    pub fn noiseless_dn(&self, radiance: f32) -> u16 {
        self.quantise(self.mean_electrons(radiance))
    }

    #[inline]
    fn quantise(&self, electrons: f32) -> u16 {
        let i = self.response.apply(electrons / self.full_well_e);
        (i * self.max_dn() as f32).round() as u16
    }

    /// Reads out a radiance image: seeded shot and read noise, saturation, response,
    /// quantisation. Reproducible for a given `seed` whatever the thread count.
    pub fn read_out(&self, radiance: &Image<f32>, seed: u64) -> Image<u16> {
        let width = radiance.width() as usize;
        let mut dn = Image::filled_like(radiance, 0u16);
        let read_sigma_e = self.read_noise_sigma_e();
        let rows = dn.data_mut().par_chunks_mut(width);
        rows.enumerate().for_each(|(row, out)| {
            let mut rng = rand_pcg::Pcg64::seed_from_u64(
                seed ^ (row as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            for (col, o) in out.iter_mut().enumerate() {
                let mean = self
                    .mean_electrons(radiance.data()[row * width + col])
                    .min(4.0 * self.full_well_e);
                let shot = if mean > 0.0 {
                    Poisson::new(mean as f64).map_or(mean, |p| p.sample(&mut rng) as f32)
                } else {
                    0.0
                };
                // σ·z with z ~ N(0, 1) from the same stream: what `Normal::new(0, σ).sample`
                // draws, without its fallible constructor.
                let z: f32 = StandardNormal.sample(&mut rng);
                *o = self.quantise(shot + read_sigma_e * z);
            }
        });
        dn
    }

    /// The read noise's standard deviation in electrons: `read_noise_e`, with a negative, NaN
    /// or infinite value read as 0 (noise-free).
    fn read_noise_sigma_e(&self) -> f32 {
        let sigma = self.read_noise_e.max(0.0); // NaN.max(0) is 0
        if sigma.is_finite() { sigma } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn responses_are_monotone_and_invertible() {
        for g in [
            ResponseCurve::Linear,
            ResponseCurve::Gamma { gamma: 2.2 },
            ResponseCurve::SCurve {
                gamma: 2.2,
                contrast: 2.0,
            },
        ] {
            assert_eq!(g.apply(0.0), 0.0);
            assert!((g.apply(1.0) - 1.0).abs() < 1e-6);
            assert_eq!(g.apply(3.0), g.apply(1.0), "saturates");
            let mut last = -1.0;
            for k in 0..=1000 {
                let x = k as f32 / 1000.0;
                let y = g.apply(x);
                assert!(y >= last, "{g:?} not monotone at {x}");
                last = y;
                // Bisection to 2⁻⁴⁰ is limited by f32: within 1e-5 wherever g' is not tiny.
                if (0.01..0.99).contains(&x) {
                    assert!((g.invert(y) - x).abs() < 1e-4, "{g:?} at {x}");
                }
            }
        }
    }

    #[test]
    fn read_out_noise_matches_shot_plus_read_noise() {
        let sensor = Sensor {
            response: ResponseCurve::Linear,
            bit_depth: 16,
            ..Sensor::default()
        };
        // 2 000 expected electrons: σ² = 2000 (shot) + 36 (read) → σ ≈ 45.1 e⁻.
        let radiance = 2000.0 / (sensor.exposure_s * sensor.electrons_per_radiance_s);
        let img = Image::filled(200, 200, radiance).unwrap();
        let out = sensor.read_out(&img, 1);
        let e_per_dn = sensor.full_well_e / sensor.max_dn() as f32;
        let e: Vec<f64> = out
            .data()
            .iter()
            .map(|&d| (d as f32 * e_per_dn) as f64)
            .collect();
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        let var = e.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (e.len() - 1) as f64;
        // 40 000 samples: the mean is within 4σ/√n ≈ 0.9 e⁻, the variance within ~3 %.
        assert!((mean - 2000.0).abs() < 1.0, "mean {mean}");
        assert!((var / 2036.0 - 1.0).abs() < 0.05, "variance {var}");
        assert_eq!(out, sensor.read_out(&img, 1), "seeded");
        assert_ne!(out, sensor.read_out(&img, 2));
    }

    #[test]
    fn bright_pixels_saturate() {
        let sensor = Sensor::default();
        assert_eq!(sensor.noiseless_dn(1e6), sensor.max_dn());
        assert_eq!(sensor.noiseless_dn(0.0), 0);
    }
}
