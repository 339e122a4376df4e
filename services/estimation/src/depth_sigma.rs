//! Per-pixel depth uncertainty of an SLI stereo capture, from its pattern images (eq 1–5).
//!
//! The disparity `d` of a left pixel is modelled as the minimiser of the SSD photometric error
//! `e = I_L(u_L, v) − I_R(u_L − d, v)` over the matching window (eq 1). Its variance is the
//! inverse Fisher information of that error (eq 2), `σ_d² = (Σ_i J_i² / σ_e,i²)⁻¹` with
//! `J_i = ∂I/∂u` the x-gradient of the image over the window (eq 3), propagated to depth by
//! `σ_z² = F σ_d² Fᵀ`, `F = ∂z/∂d = −f·b/d²` (eq 4). The gradient is taken once from the left
//! image (window centred on `u_L`) and once from the right (window centred on `u_R = u_L − d`),
//! and the larger variance is kept (eq 5): depth is only as good as the weaker image.
//!
//! Multi-shot captures (K patterns matched together over space-time windows): the SSD of eq 1
//! sums over the window and the K shots, so the Fisher information of eq 2–3 sums the squared
//! x-gradients over both, `σ_d² = (Σ_k Σ_window J_k,i² / σ_e,k,i²)⁻¹`; K = 1 is the paper's
//! single-shot form.
//!
//! Image noise: `e` is the difference of two noisy pixels, so `σ_e,i² = 2 σ_I²(I_i)` with
//! `σ_I²(I)` the sensor's intensity-dependent noise variance. That comes from a
//! [`NoiseModel`] the camera user measures (two shots of a static scene, the photon-transfer
//! method), never from the simulator's settings.
//!
//! Intensities are normalised to full scale ([0, 1]); σ_z is in metres.

use glint_geometry::camera::StereoRig;
use glint_geometry::image::{DepthMap, Image, SummedAreaTable};

/// Why an uncertainty could not be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DepthSigmaError {
    /// Two images that must match pixel for pixel (the noise model's two shots, a left and a
    /// right shot, or the left image and the depth map) have different sizes; pass images
    /// from the same capture and crop them alike.
    #[error("{what}: images are {a_w}×{a_h} and {b_w}×{b_h} px; they must be the same size")]
    SizeMismatch {
        /// Which pair of images differs.
        what: &'static str,
        /// Width of the first image, px.
        a_w: u32,
        /// Height of the first image, px.
        a_h: u32,
        /// Width of the second image, px.
        b_w: u32,
        /// Height of the second image, px.
        b_h: u32,
    },
    /// The capture has no left shot, or a different number of right and left shots; pass the
    /// K pattern images of both cameras, in the same order.
    #[error(
        "a capture needs at least one shot and as many right as left shots; got {left} left \
         and {right} right"
    )]
    ShotCount {
        /// Number of left shots given.
        left: usize,
        /// Number of right shots given.
        right: usize,
    },
    /// Too few usable pixel pairs (finite, neither black nor saturated) to fit the noise model,
    /// or no intensity bin got enough of them; shoot a lit scene without over-exposing it.
    #[error(
        "noise model: only {pixels} unsaturated pixel pairs with signal; two shots of a lit, \
         static scene are needed"
    )]
    TooFewNoiseSamples {
        /// Usable pixel pairs found.
        pixels: usize,
    },
    /// The two noise-model shots differ by more than 0.2 of full scale RMS, far beyond sensor
    /// noise: the scene, the lighting or the camera changed between them; shoot again.
    #[error(
        "noise model: the two shots differ by {rms:.3} of full scale RMS, far more than sensor \
         noise; did the scene or the camera move between them?"
    )]
    ShotsDiffer {
        /// RMS difference of the two shots over the usable pixels, in full scale.
        rms: f64,
    },
}

/// The sensor's noise variance as a function of normalised intensity, σ_I²(I): a table over
/// equal-width intensity bins, linearly interpolated. Signal dependence matters: shot noise
/// grows with the signal, and the camera response reshapes it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseModel {
    /// σ_I² at the centre of bin k, `(k + ½)/n`, in (full scale)².
    pub variance_by_bin: Vec<f64>,
    /// Lowest variance ever returned: the quantisation noise of one digital number, 1/12 DN².
    pub floor_variance: f64,
}

impl NoiseModel {
    /// Bins of the intensity axis.
    pub const BINS: usize = 32;
    /// Pixel pairs a bin needs for its own estimate; emptier bins borrow their neighbours'.
    const MIN_BIN_SAMPLES: usize = 50;

    /// A model with the same variance everywhere.
    pub fn constant(variance: f64) -> Self {
        Self {
            variance_by_bin: vec![variance; Self::BINS],
            floor_variance: variance,
        }
    }

    /// Fits σ_I²(I) from two shots `a`, `b` of the same static scene with the same settings
    /// (normalised intensities), read with `max_dn` digital numbers full scale: per pixel,
    /// `(a − b)²/2` is an unbiased sample of σ_I² at intensity `(a + b)/2`. Pixels at or
    /// above full scale (saturated, no noise left) are skipped. A bin's variance is a robust
    /// mean: samples above 25× the bin's median are dropped (a pixel that changed, not
    /// noise).
    pub fn fit_from_pair(
        a: &Image<f32>,
        b: &Image<f32>,
        max_dn: u16,
    ) -> Result<Self, DepthSigmaError> {
        check_same_size("noise model shots", a, b)?;
        let n = Self::BINS;
        let mut samples: Vec<Vec<f64>> = vec![Vec::new(); n];
        let mut used = 0usize;
        let mut sum_sq = 0.0;
        let dn = 1.0 / max_dn.max(1) as f64;
        for (&x, &y) in a.data().iter().zip(b.data()) {
            let (x, y) = (x as f64, y as f64);
            if !(x.is_finite() && y.is_finite()) || x >= 1.0 - 0.5 * dn || y >= 1.0 - 0.5 * dn {
                continue;
            }
            let mean = 0.5 * (x + y);
            if mean <= 0.5 * dn {
                continue; // black: clipped at zero, no usable noise either
            }
            let bin = ((mean * n as f64) as usize).min(n - 1);
            let d = x - y;
            samples[bin].push(0.5 * d * d);
            sum_sq += d * d;
            used += 1;
        }
        if used < Self::MIN_BIN_SAMPLES {
            return Err(DepthSigmaError::TooFewNoiseSamples { pixels: used });
        }
        let rms = (sum_sq / used as f64).sqrt();
        if rms > 0.2 {
            return Err(DepthSigmaError::ShotsDiffer { rms });
        }
        let floor_variance = dn * dn / 12.0;
        let estimate: Vec<Option<f64>> = samples
            .iter_mut()
            .map(|s| {
                if s.len() < Self::MIN_BIN_SAMPLES {
                    return None;
                }
                s.sort_by(f64::total_cmp);
                let cap = 25.0 * s[s.len() / 2].max(floor_variance);
                let kept: Vec<f64> = s.iter().copied().filter(|&v| v <= cap).collect();
                Some((kept.iter().sum::<f64>() / kept.len() as f64).max(floor_variance))
            })
            .collect();
        // Empty bins take the nearest filled bin's value (constant extrapolation; the lower
        // bin on a tie). A filled bin is its own nearest.
        let filled: Vec<(usize, f64)> = estimate
            .iter()
            .enumerate()
            .filter_map(|(k, v)| v.map(|v| (k, v)))
            .collect();
        let variance_by_bin = (0..n)
            .map(|k| {
                filled
                    .iter()
                    .min_by_key(|(f, _)| f.abs_diff(k))
                    .map(|&(_, v)| v)
            })
            .collect::<Option<Vec<f64>>>()
            .ok_or(DepthSigmaError::TooFewNoiseSamples { pixels: used })?;
        Ok(Self {
            variance_by_bin,
            floor_variance,
        })
    }

    /// σ_I² at normalised intensity `i`, (full scale)².
    #[inline]
    pub fn variance(&self, i: f32) -> f64 {
        let n = self.variance_by_bin.len();
        let x = (i.clamp(0.0, 1.0) as f64) * n as f64 - 0.5;
        let k = (x.floor().max(0.0) as usize).min(n.saturating_sub(2));
        let t = (x - k as f64).clamp(0.0, 1.0);
        let v = if n < 2 {
            self.variance_by_bin[0]
        } else {
            self.variance_by_bin[k] * (1.0 - t) + self.variance_by_bin[k + 1] * t
        };
        v.max(self.floor_variance)
    }
}

fn check_same_size<T: Copy, U: Copy>(
    what: &'static str,
    a: &Image<T>,
    b: &Image<U>,
) -> Result<(), DepthSigmaError> {
    if a.width() != b.width() || a.height() != b.height() {
        return Err(DepthSigmaError::SizeMismatch {
            what,
            a_w: a.width(),
            a_h: a.height(),
            b_w: b.width(),
            b_h: b.height(),
        });
    }
    Ok(())
}

/// Per-pixel Fisher information of the disparity from one camera's K shots (equally sized),
/// `Σ_k (∂I_k/∂u)² / σ_e²(I_k)` summed over a window (eq 2–3 over the sequence), as a
/// summed-area table so any window costs O(1).
fn disparity_information_table(shots: &[Image<f32>], noise: &NoiseModel) -> SummedAreaTable {
    let (w, h) = shots
        .first()
        .map_or((0, 0), |i| (i.width() as usize, i.height() as usize));
    SummedAreaTable::from_fn(w, h, |u, v| {
        if u == 0 || u + 1 >= w {
            return 0.0;
        }
        shots
            .iter()
            .map(|image| {
                let row = &image.data()[v * w..(v + 1) * w];
                let gradient = 0.5 * (row[u + 1] as f64 - row[u - 1] as f64);
                gradient * gradient / (2.0 * noise.variance(row[u]))
            })
            .sum()
    })
}

/// σ_z (metres) of each pixel of `depth` (the left camera's, matched from the K shots `left[k]`,
/// `right[k]` with a `(2r + 1)²` × K space-time window, `r = window_radius_px`), by eq 1–5 with
/// the information summed over the shots; NaN where depth is missing or a window leaves the
/// image. A window without gradient gives +∞ (no information). One shot is the single-shot
/// camera.
pub fn depth_sigma(
    left: &[Image<f32>],
    right: &[Image<f32>],
    depth: &DepthMap,
    rig: &StereoRig,
    noise: &NoiseModel,
    window_radius_px: u32,
) -> Result<Image<f32>, DepthSigmaError> {
    depth_sigma_shifted(left, right, depth, rig, noise, window_radius_px, 0)
}

/// [`depth_sigma`] on crops of the rectified pair whose right crop starts `right_shift_px`
/// columns left of the left crop (same rows, same size): a left crop pixel `u` at disparity
/// `d` is matched at right crop column `u − d + right_shift_px`. Lets a caller crop each
/// camera to where the part is, instead of one crop wide enough for both.
pub fn depth_sigma_shifted(
    left: &[Image<f32>],
    right: &[Image<f32>],
    depth: &DepthMap,
    rig: &StereoRig,
    noise: &NoiseModel,
    window_radius_px: u32,
    right_shift_px: i64,
) -> Result<Image<f32>, DepthSigmaError> {
    let Some(first) = left.first() else {
        return Err(DepthSigmaError::ShotCount {
            left: left.len(),
            right: right.len(),
        });
    };
    if right.len() != left.len() {
        return Err(DepthSigmaError::ShotCount {
            left: left.len(),
            right: right.len(),
        });
    }
    for image in left.iter().chain(right) {
        check_same_size("left and right images", first, image)?;
    }
    check_same_size("left image and depth map", first, &depth.depth_m)?;
    let info_left = disparity_information_table(left, noise);
    let info_right = disparity_information_table(right, noise);
    let (w, h) = (first.width(), first.height());
    let r = window_radius_px as i64;
    let window = |table: &SummedAreaTable, u: i64, v: i64| -> Option<f64> {
        (u - r >= 0 && v - r >= 0 && u + r < w as i64 && v + r < h as i64).then(|| {
            table.sum(
                (u - r) as usize,
                (v - r) as usize,
                (u + r + 1) as usize,
                (v + r + 1) as usize,
            )
        })
    };
    let mut sigma = Image::filled_like(first, f32::NAN);
    for v in 0..h {
        for u in 0..w {
            let Some(z) = depth.get(u, v) else { continue };
            let d = rig.disparity_from_depth(z as f64);
            let (ui, vi) = (u as i64, v as i64);
            let Some(fisher_left) = window(&info_left, ui, vi) else {
                continue;
            };
            // The right window is centred on u_R = u − d (pixel-centre coordinates cancel);
            // between whole-pixel windows the information is interpolated linearly.
            let u_right = u as f64 - d + right_shift_px as f64;
            let (u0, t) = (u_right.floor() as i64, u_right - u_right.floor());
            let (Some(f0), Some(f1)) =
                (window(&info_right, u0, vi), window(&info_right, u0 + 1, vi))
            else {
                continue;
            };
            let fisher_right = f0 * (1.0 - t) + f1 * t;
            let fisher = fisher_left.min(fisher_right); // eq 5: the larger variance wins
            let f = rig.depth_per_disparity(d); // eq 4
            sigma.set(u, v, (f.abs() / fisher.sqrt()) as f32);
        }
    }
    Ok(sigma)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn rig() -> StereoRig {
        StereoRig::ensenso_n35()
    }

    fn one(image: &Image<f32>) -> &[Image<f32>] {
        std::slice::from_ref(image)
    }

    #[test]
    fn shifted_crops_give_the_full_images_sigma() {
        // eq 1–5 are local: σ_z of a left pixel from crops (the right one `shift` columns
        // further left) equals the full images' at the same pixel.
        // At 0.5 m the N35's disparity is ≈ 219 px.
        let (w, h) = (400u32, 40u32);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(8);
        let mut noisy = || {
            let data = (0..w * h)
                .map(|_| rand::Rng::random::<f32>(&mut rng) * 0.8 + 0.1)
                .collect();
            Image::new(w, h, data).unwrap()
        };
        let (left, right) = (noisy(), noisy());
        let rig = rig();
        let z = 0.5f32;
        let d = rig.disparity_from_depth(z as f64);
        let depth = DepthMap::new(Image::filled(w, h, z).unwrap());
        let noise = NoiseModel::constant(1e-4);
        let full = depth_sigma(one(&left), one(&right), &depth, &rig, &noise, 1).unwrap();
        let (u0, shift, cw) = (300u32, d.ceil() as u32 - 10, 40u32);
        let crop = |image: &Image<f32>, u: u32| {
            image
                .cropped(&glint_geometry::image::PixelRect::new(u, 0, cw, h))
                .unwrap()
        };
        let (lc, rc) = (crop(&left, u0), crop(&right, u0 - shift));
        let depth_c = DepthMap::new(Image::filled(cw, h, z).unwrap());
        let part = depth_sigma_shifted(
            one(&lc),
            one(&rc),
            &depth_c,
            &rig,
            &noise,
            1,
            i64::from(shift),
        )
        .unwrap();
        let mut compared = 0;
        for v in 0..h {
            for u in 0..cw {
                // Windows and their gradient stencils inside both crops (a crop's edge
                // column has no central difference).
                let u_right = u as f64 - d + f64::from(shift);
                let inside = |x: f64| x >= 2.0 && x <= f64::from(cw) - 4.0;
                if !(inside(u as f64) && inside(u_right) && v >= 1 && v + 1 < h) {
                    continue;
                }
                let (a, b) = (part.get(u, v).unwrap(), full.get(u + u0, v).unwrap());
                if a.is_finite() {
                    assert_eq!(a, b, "pixel ({u}, {v})");
                    compared += 1;
                }
            }
        }
        assert!(compared > 500, "{compared} pixels compared");
    }

    #[test]
    fn noise_model_recovers_signal_dependent_variance() {
        // σ² = a + b·I (read + shot noise), sampled on a ramp image.
        let (a, b) = (1e-5, 4e-4);
        let (w, h) = (256u32, 200u32);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let clean: Vec<f32> = (0..w * h)
            .map(|i| (i % w) as f32 / w as f32 * 0.95)
            .collect();
        let mut shot = || -> Image<f32> {
            let data = clean
                .iter()
                .map(|&i| {
                    let s = (a + b * i as f64).sqrt();
                    (i as f64 + Normal::new(0.0, s).unwrap().sample(&mut rng)) as f32
                })
                .collect();
            Image::new(w, h, data).unwrap()
        };
        let (x, y) = (shot(), shot());
        let model = NoiseModel::fit_from_pair(&x, &y, 65535).unwrap();
        for i in [0.1f32, 0.3, 0.5, 0.8] {
            let truth = a + b * i as f64;
            // Each bin holds ~1600 samples of a χ²₁-like variable: relative σ ≈ √(2/1600) = 3.5 %;
            // bins are 1/32 wide, so interpolation is exact for a linear law. 5σ: 18 %.
            let rel = (model.variance(i) - truth).abs() / truth;
            assert!(rel < 0.18, "I = {i}: {} vs {truth}", model.variance(i));
        }
    }

    #[test]
    fn noise_model_rejects_bad_shots() {
        let a = Image::filled(10, 10, 0.5f32).unwrap();
        let b = Image::filled(10, 11, 0.5f32).unwrap();
        assert!(matches!(
            NoiseModel::fit_from_pair(&a, &b, 255),
            Err(DepthSigmaError::SizeMismatch { .. })
        ));
        let saturated = Image::filled(100, 100, 1.0f32).unwrap();
        assert!(matches!(
            NoiseModel::fit_from_pair(&saturated, &saturated, 255),
            Err(DepthSigmaError::TooFewNoiseSamples { .. })
        ));
        let moved = Image::new(
            100,
            100,
            (0..10_000).map(|i| (i % 2) as f32 * 0.9).collect(),
        )
        .unwrap();
        let other = Image::new(
            100,
            100,
            (0..10_000).map(|i| ((i + 1) % 2) as f32 * 0.9).collect(),
        )
        .unwrap();
        assert!(matches!(
            NoiseModel::fit_from_pair(&moved, &other, 255),
            Err(DepthSigmaError::ShotsDiffer { .. })
        ));
    }

    /// A sinusoidal texture along x, `I = c + A sin(ω u)`, on a fronto-parallel plane: the
    /// window information has a closed form, so σ_z can be checked exactly.
    #[test]
    fn sigma_z_matches_the_closed_form_on_a_sinusoid() {
        let rig = rig();
        // A whole-pixel disparity (≈ 0.6 m) so the right window needs no interpolation.
        let d = 183.0;
        let z = rig.depth_from_disparity(d);
        let (w, h) = (400u32, 40u32);
        let (c, amp, omega) = (0.5f64, 0.2f64, 0.7f64);
        let left = Image::new(
            w,
            h,
            (0..w * h)
                .map(|i| (c + amp * (omega * (i % w) as f64).sin()) as f32)
                .collect(),
        )
        .unwrap();
        // The right image sees the same texture shifted by d.
        let right = Image::new(
            w,
            h,
            (0..w * h)
                .map(|i| (c + amp * (omega * ((i % w) as f64 + d)).sin()) as f32)
                .collect(),
        )
        .unwrap();
        let depth = DepthMap::new(Image::filled(w, h, z as f32).unwrap());
        let variance = 1e-4;
        let noise = NoiseModel::constant(variance);
        let r = 5u32;
        let sigma = depth_sigma(one(&left), one(&right), &depth, &rig, &noise, r).unwrap();
        // Central difference of a sinusoid: A sin(ω) cos(ω u); its square summed over a window
        // of n = 2r+1 columns × n rows ≈ n² A² sin²ω / 2 (the cos² averages to ½ over many
        // periods; with n = 11 and ω = 0.7 the window spans 1.2 periods, so compute it exactly
        // at the probed pixel instead).
        let (u, v) = (300u32, 20u32);
        let n = (2 * r + 1) as f64;
        let fisher = || -> f64 {
            (0..2 * r + 1)
                .map(|k| {
                    let x = u as f64 - r as f64 + k as f64;
                    let g = amp * omega.sin() * (omega * x).cos();
                    g * g
                })
                .sum::<f64>()
                * n
                / (2.0 * variance)
        };
        // The right window centred on u − d sees the same texture phase as the left one.
        let expected_fisher = fisher();
        let f = rig.depth_per_disparity(d);
        let expected = f.abs() / expected_fisher.sqrt();
        let got = sigma.get(u, v).unwrap() as f64;
        // Only f32 rounding of the images separates the two.
        assert!(
            (got - expected).abs() / expected < 1e-3,
            "{got} vs {expected}"
        );
        // Border pixels whose window leaves the image have no value.
        assert!(sigma.get(2, v).unwrap().is_nan());
        // Doubling the noise variance scales σ_z by √2.
        let noisier = depth_sigma(
            one(&left),
            one(&right),
            &depth,
            &rig,
            &NoiseModel::constant(2.0 * variance),
            r,
        )
        .unwrap();
        let ratio = noisier.get(u, v).unwrap() as f64 / got;
        assert!((ratio - 2f64.sqrt()).abs() < 1e-4, "{ratio}");
    }

    #[test]
    fn sigma_z_grows_with_depth_squared_and_follows_the_weaker_image() {
        let rig = rig();
        let (w, h) = (600u32, 30u32);
        let textured = Image::new(
            w,
            h,
            (0..w * h)
                .map(|i| 0.5 + 0.3 * ((i % w) as f32 * 1.3).sin())
                .collect(),
        )
        .unwrap();
        let noise = NoiseModel::constant(1e-4);
        let at = |z: f64| {
            let depth = DepthMap::new(Image::filled(w, h, z as f32).unwrap());
            depth_sigma(one(&textured), one(&textured), &depth, &rig, &noise, 4).unwrap()
        };
        let (s1, s2) = (at(0.5), at(1.0));
        // F = f·b/d² ∝ z², and the same texture gives the same information: ratio 4, up to
        // the right window landing on another phase of the sinusoid (a few % on this texture).
        let ratio = s2.get(500, 15).unwrap() / s1.get(500, 15).unwrap();
        assert!((ratio - 4.0).abs() < 0.4, "{ratio}");
        // A flat right image carries no information: σ_z is infinite (eq 5 keeps the worse).
        let flat = Image::filled(w, h, 0.5f32).unwrap();
        let depth = DepthMap::new(Image::filled(w, h, 0.5).unwrap());
        let s = depth_sigma(one(&textured), one(&flat), &depth, &rig, &noise, 4).unwrap();
        assert!(s.get(500, 15).unwrap().is_infinite());
        // Missing depth stays missing.
        let mut holes = Image::filled(w, h, 0.5f32).unwrap();
        holes.set(500, 15, f32::NAN);
        let s = depth_sigma(
            one(&textured),
            one(&textured),
            &DepthMap::new(holes),
            &rig,
            &noise,
            4,
        )
        .unwrap();
        assert!(s.get(500, 15).unwrap().is_nan());
    }

    /// The sinusoid pair of the closed-form test at angular frequency `omega`.
    fn sinusoid_pair(omega: f64, amp: f64, d: f64) -> (Image<f32>, Image<f32>) {
        let (w, h) = (400u32, 40u32);
        let image = |shift: f64| {
            let data = (0..w * h)
                .map(|i| (0.5 + amp * (omega * ((i % w) as f64 + shift)).sin()) as f32)
                .collect();
            Image::new(w, h, data).unwrap()
        };
        (image(0.0), image(d))
    }

    /// eq 2–3 over a sequence: the information of the shots adds. K copies of one pair divide
    /// σ_z by √K; two different pairs give 1/σ² = 1/σ_A² + 1/σ_B² (left and right windows see
    /// the same phase here, so eq 5's minimum does not switch sides). Only f32 rounding of the
    /// σ images separates the two sides (relative 1e-7; 1e-5 asserted).
    #[test]
    fn information_adds_over_shots() {
        let rig = rig();
        let d = 183.0;
        let z = rig.depth_from_disparity(d);
        let (a_left, a_right) = sinusoid_pair(0.7, 0.2, d);
        let (b_left, b_right) = sinusoid_pair(1.1, 0.1, d);
        let depth = DepthMap::new(Image::filled(400, 40, z as f32).unwrap());
        let noise = NoiseModel::constant(1e-4);
        let sigma = |left: &[Image<f32>], right: &[Image<f32>]| {
            depth_sigma(left, right, &depth, &rig, &noise, 2)
                .unwrap()
                .get(300, 20)
                .unwrap() as f64
        };
        let single = sigma(one(&a_left), one(&a_right));
        let four = sigma(&vec![a_left.clone(); 4], &vec![a_right.clone(); 4]);
        assert!(
            (four * 2.0 / single - 1.0).abs() < 1e-5,
            "{four} vs {single}"
        );
        let b = sigma(one(&b_left), one(&b_right));
        let both = sigma(
            &[a_left.clone(), b_left.clone()],
            &[a_right.clone(), b_right.clone()],
        );
        let expected = (single.powi(-2) + b.powi(-2)).powf(-0.5);
        assert!((both / expected - 1.0).abs() < 1e-5, "{both} vs {expected}");
        assert!(matches!(
            depth_sigma(
                &[a_left.clone(), b_left],
                one(&a_right),
                &depth,
                &rig,
                &noise,
                2
            ),
            Err(DepthSigmaError::ShotCount { left: 2, right: 1 })
        ));
        assert!(matches!(
            depth_sigma(&[], &[], &depth, &rig, &noise, 2),
            Err(DepthSigmaError::ShotCount { left: 0, right: 0 })
        ));
    }

    #[test]
    fn mismatched_sizes_are_errors() {
        let a = Image::filled(10, 10, 0.5f32).unwrap();
        let b = Image::filled(11, 10, 0.5f32).unwrap();
        let depth = DepthMap::new(Image::filled(10, 10, 0.5f32).unwrap());
        let noise = NoiseModel::constant(1e-4);
        assert!(matches!(
            depth_sigma(one(&a), one(&b), &depth, &rig(), &noise, 2),
            Err(DepthSigmaError::SizeMismatch {
                what: "left and right images",
                ..
            })
        ));
    }
}
