//! Initial poses like the paper's template detector (Line-2D, kept only within 30 mm/30°), and
//! the fit of their distribution to the paper's own initial row of Table I (issue 16 item 5).
//! Evaluation only: initial poses are drawn around the ground truth.

use glint_geometry::Symmetry;
use glint_geometry::parts::Part;
use glint_geometry::pose_deviation::{CorrectThreshold, PoseDeviation, pose_deviation};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rayon::prelude::*;

/// How initial poses are drawn around the ground truth, in the reference camera's frame.
///
/// A template detector localises a part well across the image and worse in depth: translation
/// error `N(0, diag(σ_lat², σ_lat², σ_depth²))` in the camera frame; rotation error `exp([ω]×)` applied about the object's origin with `ω ~ N(0, σ_rot² I)`;
/// draws beyond the paper's 30 mm/30° acceptance test (symmetry-aware) are redrawn.
///
/// The default is fitted ([`fit_initial_pose_shape`], `glint eval initial-poses`) so that its
/// own 5 mm/5° and 2 mm/2° rates, averaged over the five parts with their symmetries, are the
/// paper's initial row on `all` ([`PAPER_INITIAL_RATES_ALL`]), the ratio `σ_depth / σ_lat`
/// chosen among those that reach it by the paper's per-part rates; it is kept fixed afterwards.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialPoseNoise {
    /// σ_lat: standard deviation of the translation error along the camera's x and y, metres.
    pub lateral_sigma_m: f64,
    /// σ_depth: standard deviation of the translation error along the camera's z, metres.
    pub depth_sigma_m: f64,
    /// σ_rot: standard deviation of each component of the rotation error ω, radians.
    pub rotation_sigma_rad: f64,
}

impl Default for InitialPoseNoise {
    /// Fitted by `glint eval initial-poses` (20 000 draws per part on seed 16: the five parts'
    /// symmetries, uniformly random orientations; ratios 1–48): `σ_depth / σ_lat = 32`,
    /// `σ_lat = 0.528 mm` (`σ_depth = 16.9 mm`), `σ_rot = 2.229°`, which gives 21.1 % / 1.75 %
    /// on seed 1601 against the paper's 21.3 % / 1.77 %. Ratios below 2 cannot reach the 2/2
    /// rate; from 2 to 48 all reach the mean, with σ_rot between 0.6° and 2.3°: the paper's
    /// row leaves little room for rotation error. The per-part misfit falls from 7.8 (ratio 2)
    /// to 5.28 at 32 and rises to 5.36 at 48. A 2-D template detector places a part laterally to
    /// about a pixel (≈ 0.5 mm at 0.6 m) and in depth by its template's scale (a pixel of scale
    /// on a 50–70 px part is 1.5–2 %, 10–12 mm), a ratio of the same order.
    fn default() -> Self {
        Self::with_shape(
            FITTED_LATERAL_SIGMA_M,
            FITTED_DEPTH_TO_LATERAL,
            FITTED_ROTATION_SIGMA_RAD,
        )
    }
}

/// σ_lat of the fitted default, metres.
const FITTED_LATERAL_SIGMA_M: f64 = 0.528e-3;
/// σ_depth / σ_lat of the fitted default.
const FITTED_DEPTH_TO_LATERAL: f64 = 32.0;
/// σ_rot of the fitted default, radians.
const FITTED_ROTATION_SIGMA_RAD: f64 = 2.229 * std::f64::consts::PI / 180.0;

impl InitialPoseNoise {
    /// The distribution with `σ_lat = lateral_sigma_m`, `σ_depth = depth_to_lateral · σ_lat`
    /// and `σ_rot = rotation_sigma_rad`.
    pub fn with_shape(
        lateral_sigma_m: f64,
        depth_to_lateral: f64,
        rotation_sigma_rad: f64,
    ) -> Self {
        Self {
            lateral_sigma_m,
            depth_sigma_m: depth_to_lateral * lateral_sigma_m,
            rotation_sigma_rad,
        }
    }

    /// The pose that six standard normal draws `unit` (translation x, y, z, then ω) give
    /// around `t_c_o_gt`, before the acceptance test.
    fn perturb(&self, t_c_o_gt: &Isometry3<f64>, unit: &[f64; 6]) -> Isometry3<f64> {
        let dt = Vector3::new(
            unit[0] * self.lateral_sigma_m,
            unit[1] * self.lateral_sigma_m,
            unit[2] * self.depth_sigma_m,
        );
        let omega = Vector3::new(unit[3], unit[4], unit[5]) * self.rotation_sigma_rad;
        Isometry3::from_parts(
            Translation3::from(t_c_o_gt.translation.vector + dt),
            UnitQuaternion::from_scaled_axis(omega) * t_c_o_gt.rotation,
        )
    }

    /// An initial `t_c_o` around `t_c_o_gt` within 30 mm/30° of it.
    pub fn draw(
        &self,
        t_c_o_gt: &Isometry3<f64>,
        symmetry: &Symmetry,
        rng: &mut impl Rng,
    ) -> Isometry3<f64> {
        loop {
            let unit: [f64; 6] = std::array::from_fn(|_| rng.sample(StandardNormal));
            let candidate = self.perturb(t_c_o_gt, &unit);
            if pose_deviation(&candidate, t_c_o_gt, symmetry)
                .is_correct(&CorrectThreshold::MM30_DEG30)
            {
                return candidate;
            }
        }
    }

    /// A one-line description of the distribution for reports, in mm and degrees.
    pub fn describe(&self) -> String {
        format!(
            "translation N(0, diag({:.2}, {:.2}, {:.2} mm)²) in the reference camera (x, y lateral, z depth); \
             rotation exp(ω) about the object origin with ω ~ N(0, ({:.2}°)² I); redrawn unless within 30 mm/30°",
            self.lateral_sigma_m * 1e3,
            self.lateral_sigma_m * 1e3,
            self.depth_sigma_m * 1e3,
            self.rotation_sigma_rad.to_degrees()
        )
    }
}

/// Shares of poses correct within 5 mm/5° and within 2 mm/2°, in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialRates {
    /// Share within 5 mm/5°.
    pub mm5_deg5: f64,
    /// Share within 2 mm/2°.
    pub mm2_deg2: f64,
}

/// The paper's initial row of Table I on `all` (Line-2D poses kept within 30 mm/30°; the mean
/// of the five objects' rates).
pub const PAPER_INITIAL_RATES_ALL: InitialRates = InitialRates {
    mm5_deg5: 0.213,
    mm2_deg2: 0.0177,
};

/// The paper's initial row of Table I for one object.
pub fn paper_initial_rates(part: Part) -> InitialRates {
    let (mm5_deg5, mm2_deg2) = match part {
        Part::EyeBolt => (0.093, 0.0019),
        Part::TubeFitting => (0.184, 0.0087),
        Part::ChromeScrew => (0.345, 0.053),
        Part::Gear => (0.246, 0.013),
        Part::Zigzag => (0.199, 0.0114),
    };
    InitialRates { mm5_deg5, mm2_deg2 }
}

/// Fixed random draws to compare many distributions on (common random numbers): per symmetry,
/// `samples` uniformly random object orientations, each with six standard normal draws. A
/// pose drawn by [`InitialPoseNoise::draw`] is the first accepted of its draws, so the rate of
/// a distribution is the share correct among the accepted first draws.
#[derive(Clone, Debug)]
pub struct RateSample {
    groups: Vec<(Symmetry, Vec<Draw>)>,
}

/// One draw of a [`RateSample`]: the object's orientation and six standard normals.
type Draw = (UnitQuaternion<f64>, [f64; 6]);

impl RateSample {
    /// `samples` draws per symmetry from `seed`.
    pub fn new(symmetries: &[Symmetry], samples: usize, seed: u64) -> Self {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let groups = symmetries
            .iter()
            .map(|symmetry| {
                let draws = (0..samples)
                    .map(|_| {
                        let q: [f64; 4] = std::array::from_fn(|_| rng.sample(StandardNormal));
                        let orientation = UnitQuaternion::from_quaternion(Quaternion::new(
                            q[0], q[1], q[2], q[3],
                        ));
                        (
                            orientation,
                            std::array::from_fn(|_| rng.sample(StandardNormal)),
                        )
                    })
                    .collect();
                (symmetry.clone(), draws)
            })
            .collect();
        Self { groups }
    }

    /// The rates of `noise` per symmetry (in the order given to [`Self::new`]).
    pub fn rates(&self, noise: &InitialPoseNoise) -> Vec<InitialRates> {
        self.groups
            .par_iter()
            .map(|(symmetry, draws)| {
                let (mut accepted, mut mm5, mut mm2) = (0usize, 0usize, 0usize);
                for (orientation, unit) in draws {
                    let gt = Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.6), *orientation);
                    let deviation: PoseDeviation =
                        pose_deviation(&noise.perturb(&gt, unit), &gt, symmetry);
                    accepted += deviation.is_correct(&CorrectThreshold::MM30_DEG30) as usize;
                    mm5 += deviation.is_correct(&CorrectThreshold::MM5_DEG5) as usize;
                    mm2 += deviation.is_correct(&CorrectThreshold::MM2_DEG2) as usize;
                }
                let n = accepted.max(1) as f64;
                InitialRates {
                    mm5_deg5: mm5 as f64 / n,
                    mm2_deg2: mm2 as f64 / n,
                }
            })
            .collect()
    }

    /// The mean of [`Self::rates`] over the symmetries (the paper's `all`).
    pub fn mean_rates(&self, noise: &InitialPoseNoise) -> InitialRates {
        let rates = self.rates(noise);
        let n = rates.len().max(1) as f64;
        InitialRates {
            mm5_deg5: rates.iter().map(|r| r.mm5_deg5).sum::<f64>() / n,
            mm2_deg2: rates.iter().map(|r| r.mm2_deg2).sum::<f64>() / n,
        }
    }
}

/// Why no distribution of the given shape reaches the target rates.
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
pub enum InitialPoseFitError {
    /// The targets are not rates with 0 < 2/2 < 5/5 < 1.
    #[error(
        "target rates must satisfy 0 < 2 mm/2° rate < 5 mm/5° rate < 1, got {mm5_deg5} and {mm2_deg2}"
    )]
    BadTarget {
        /// The 5 mm/5° target.
        mm5_deg5: f64,
        /// The 2 mm/2° target.
        mm2_deg2: f64,
    },
    /// Even an exact rotation leaves the 2/2 rate below the target at the 5/5 target: the
    /// translation error's shape (`σ_depth / σ_lat`) cannot be that concentrated.
    #[error(
        "with exact rotations the 2 mm/2° rate is at most {best:.4} at the 5 mm/5° target, below the target {target:.4}"
    )]
    Unreachable {
        /// The largest reachable 2/2 rate.
        best: f64,
        /// The 2/2 target.
        target: f64,
    },
}

/// The [`InitialPoseNoise`] with `σ_depth = depth_to_lateral · σ_lat` (σ_lat and σ_rot free)
/// whose mean rates over `sample` are `target`. At a fixed σ_rot the 5/5 rate falls as σ_lat grows,
/// so σ_lat is found by bisection for the 5/5 target; along that curve the 2/2 rate falls as
/// σ_rot grows (translation and rotation errors share the 5/5 budget, and a shared budget
/// leaves fewer poses inside both smaller thresholds), so σ_rot is found by bisection for the
/// 2/2 target. Both in log space, to a relative step of 10⁻⁴.
pub fn fit_initial_pose_noise(
    sample: &RateSample,
    target: InitialRates,
    depth_to_lateral: f64,
) -> Result<InitialPoseNoise, InitialPoseFitError> {
    if !(0.0 < target.mm2_deg2 && target.mm2_deg2 < target.mm5_deg5 && target.mm5_deg5 < 1.0) {
        return Err(InitialPoseFitError::BadTarget {
            mm5_deg5: target.mm5_deg5,
            mm2_deg2: target.mm2_deg2,
        });
    }
    // σ_lat reaching the 5/5 target at σ_rot, and the 2/2 rate there.
    let at_rotation = |rotation_sigma_rad: f64| {
        let lateral = bisect_log(1e-5, 0.1, |s| {
            sample
                .mean_rates(&InitialPoseNoise::with_shape(
                    s,
                    depth_to_lateral,
                    rotation_sigma_rad,
                ))
                .mm5_deg5
                < target.mm5_deg5
        });
        let noise = InitialPoseNoise::with_shape(lateral, depth_to_lateral, rotation_sigma_rad);
        (noise, sample.mean_rates(&noise).mm2_deg2)
    };
    let (_, best) = at_rotation(1e-5);
    if best < target.mm2_deg2 {
        return Err(InitialPoseFitError::Unreachable {
            best,
            target: target.mm2_deg2,
        });
    }
    let rotation = bisect_log(1e-5, 0.5, |r| at_rotation(r).1 < target.mm2_deg2);
    Ok(at_rotation(rotation).0)
}

/// One candidate shape of [`fit_initial_pose_shape`]: the distribution fitted at a
/// `σ_depth / σ_lat` ratio, or why none reaches the target there, and how far its per-part
/// rates are from the paper's.
#[derive(Clone, Debug)]
pub struct ShapeCandidate {
    /// `σ_depth / σ_lat`.
    pub depth_to_lateral: f64,
    /// The fitted distribution at this ratio.
    pub fit: Result<InitialPoseNoise, InitialPoseFitError>,
    /// `Σ_parts (ln(r_5/5 / r̂_5/5))² + (ln(r_2/2 / r̂_2/2))²` of the fitted distribution's
    /// per-part rates `r` against the paper's `r̂` (rates floored at 10⁻⁴); infinite without a fit.
    pub per_part_misfit: f64,
}

/// The three-parameter fit: at each ratio `σ_depth / σ_lat` of `ratios`, the distribution that
/// reaches `target` on the mean over `sample`'s symmetries ([`fit_initial_pose_noise`]); the
/// ratio is then chosen by the paper's per-part rates `per_part` (in `sample`'s symmetry
/// order), which the mean alone leaves free: the candidate of least
/// [`ShapeCandidate::per_part_misfit`] comes first, the others follow in `ratios`' order.
pub fn fit_initial_pose_shape(
    sample: &RateSample,
    target: InitialRates,
    per_part: &[InitialRates],
    ratios: &[f64],
) -> Vec<ShapeCandidate> {
    let mut candidates: Vec<ShapeCandidate> = ratios
        .iter()
        .map(|&depth_to_lateral| {
            let fit = fit_initial_pose_noise(sample, target, depth_to_lateral);
            let per_part_misfit = match &fit {
                Ok(noise) => sample
                    .rates(noise)
                    .iter()
                    .zip(per_part)
                    .map(|(ours, paper)| {
                        let log_ratio = |a: f64, b: f64| (a.max(1e-4) / b.max(1e-4)).ln();
                        log_ratio(ours.mm5_deg5, paper.mm5_deg5).powi(2)
                            + log_ratio(ours.mm2_deg2, paper.mm2_deg2).powi(2)
                    })
                    .sum(),
                Err(_) => f64::INFINITY,
            };
            ShapeCandidate {
                depth_to_lateral,
                fit,
                per_part_misfit,
            }
        })
        .collect();
    if let Some(best) = (0..candidates.len()).min_by(|&a, &b| {
        candidates[a]
            .per_part_misfit
            .total_cmp(&candidates[b].per_part_misfit)
    }) {
        let chosen = candidates.remove(best);
        candidates.insert(0, chosen);
    }
    candidates
}

/// The point in `[lo, hi]` (both > 0) where `past(x)` turns from false to true, by bisection
/// on ln x to a relative step of 10⁻⁴.
fn bisect_log(lo: f64, hi: f64, past: impl Fn(f64) -> bool) -> f64 {
    let (mut lo, mut hi) = (lo.ln(), hi.ln());
    while hi - lo > 1e-4 {
        let mid = 0.5 * (lo + hi);
        if past(mid.exp()) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    (0.5 * (lo + hi)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part_symmetries() -> Vec<Symmetry> {
        Part::ALL.iter().map(|p| p.symmetry()).collect()
    }

    #[test]
    fn initial_poses_respect_the_acceptance_test_and_the_spread() {
        let noise = InitialPoseNoise::with_shape(3e-3, 5.0 / 3.0, 5f64.to_radians());
        let gt = Isometry3::translation(0.0, 0.0, 0.5);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        let n = 4000;
        let mut sum_sq = Vector3::zeros();
        for _ in 0..n {
            let p = noise.draw(&gt, &Symmetry::none(), &mut rng);
            let e = pose_deviation(&p, &gt, &Symmetry::none());
            assert!(e.is_correct(&CorrectThreshold::MM30_DEG30));
            let d = p.translation.vector - gt.translation.vector;
            sum_sq += d.component_mul(&d);
        }
        // Truncation at 30 mm removes almost nothing at σ ≤ 5 mm: per-axis RMS within 5 %
        // (σ of a sample variance estimate with n = 4000 is √(2/n) ≈ 2 %).
        let rms = (sum_sq / n as f64).map(f64::sqrt);
        assert!((rms.x / 3e-3 - 1.0).abs() < 0.05, "{rms:?}");
        assert!((rms.z / 5e-3 - 1.0).abs() < 0.05, "{rms:?}");
    }

    #[test]
    fn the_sample_rates_are_the_rates_of_drawn_poses() {
        // Rates from fixed draws and from draw() agree within their binomial noise.
        let noise = InitialPoseNoise::with_shape(4e-3, 2.0, 3f64.to_radians());
        let symmetry = Part::Gear.symmetry();
        let n = 20_000;
        let from_sample = RateSample::new(std::slice::from_ref(&symmetry), n, 5).rates(&noise)[0];
        let mut rng = rand_pcg::Pcg64::seed_from_u64(6);
        let (mut mm5, mut mm2) = (0, 0);
        for _ in 0..n {
            let q: [f64; 4] = std::array::from_fn(|_| rng.sample(StandardNormal));
            let gt = Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 0.6),
                UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3])),
            );
            let d = pose_deviation(&noise.draw(&gt, &symmetry, &mut rng), &gt, &symmetry);
            mm5 += d.is_correct(&CorrectThreshold::MM5_DEG5) as usize;
            mm2 += d.is_correct(&CorrectThreshold::MM2_DEG2) as usize;
        }
        for (a, b) in [
            (from_sample.mm5_deg5, mm5 as f64 / n as f64),
            (from_sample.mm2_deg2, mm2 as f64 / n as f64),
        ] {
            // Two independent binomial estimates: their difference has σ = √(2p(1−p)/n).
            let sigma = (2.0 * a * (1.0 - a) / n as f64).sqrt();
            assert!((a - b).abs() < 4.0 * sigma + 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn the_fit_recovers_a_distribution_from_its_own_rates() {
        // Rates made by a known distribution are reached again by the fit, on the same draws:
        // the bisections stop at a relative step of 1e-4, and the rates are step functions of
        // the σs over 4 000 draws per part, so the recovered σs sit within a few per cent.
        let sample = RateSample::new(&part_symmetries(), 4000, 9);
        let truth = InitialPoseNoise::with_shape(4.5e-3, 2.5, 1.5f64.to_radians());
        let target = sample.mean_rates(&truth);
        let fitted =
            fit_initial_pose_noise(&sample, target, 2.5).expect("reachable by construction");
        let reached = sample.mean_rates(&fitted);
        assert!(
            (reached.mm5_deg5 - target.mm5_deg5).abs() < 1e-3,
            "{reached:?} vs {target:?}"
        );
        assert!(
            (reached.mm2_deg2 - target.mm2_deg2).abs() < 1e-3,
            "{reached:?} vs {target:?}"
        );
        assert!(
            (fitted.lateral_sigma_m / truth.lateral_sigma_m - 1.0).abs() < 0.05,
            "{fitted:?}"
        );
        assert!(
            (fitted.rotation_sigma_rad / truth.rotation_sigma_rad - 1.0).abs() < 0.15,
            "{fitted:?}"
        );
    }

    #[test]
    fn unreachable_and_malformed_targets_are_errors() {
        let sample = RateSample::new(&part_symmetries(), 500, 2);
        let bad = InitialRates {
            mm5_deg5: 0.1,
            mm2_deg2: 0.2,
        };
        assert!(matches!(
            fit_initial_pose_noise(&sample, bad, 2.0),
            Err(InitialPoseFitError::BadTarget { .. })
        ));
        // 2/2 nearly as likely as 5/5: no Gaussian spread is that concentrated.
        let concentrated = InitialRates {
            mm5_deg5: 0.2,
            mm2_deg2: 0.19,
        };
        assert!(matches!(
            fit_initial_pose_noise(&sample, concentrated, 2.0),
            Err(InitialPoseFitError::Unreachable { .. })
        ));
    }

    #[test]
    fn the_default_has_the_papers_initial_rates() {
        // On draws the fit never saw (another seed): within 4 σ of the binomial noise of a
        // mean over five parts of 20 000 draws each, plus the fit's own sampling noise.
        let sample = RateSample::new(&part_symmetries(), 20_000, 1601);
        let rates = sample.mean_rates(&InitialPoseNoise::default());
        for (got, want) in [
            (rates.mm5_deg5, PAPER_INITIAL_RATES_ALL.mm5_deg5),
            (rates.mm2_deg2, PAPER_INITIAL_RATES_ALL.mm2_deg2),
        ] {
            let sigma = (want * (1.0 - want) / 100_000.0).sqrt();
            assert!(
                (got - want).abs() < 4.0 * sigma * 2f64.sqrt(),
                "{got} vs {want}"
            );
        }
    }
}
