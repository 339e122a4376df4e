//! Evaluation arithmetic: symmetry-aware NEES and its χ² band. Evaluation only: these read
//! ground truth.

use glint_geometry::Symmetry;
use glint_geometry::se3;
use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector6};

/// The ground-truth `t_o_w` equivalent under `symmetry` that is closest to `t_o_w_est`:
/// `S⁻¹ · t_o_w_gt` over the discrete elements S, and for a continuous axis `a` the spin
/// `Rot(a, θ)` about it that best aligns the two, in closed form: with `M = R_est R_base⁻¹ =
/// (w, v)` as a quaternion, `∠(M · Rot(a, φ))` is smallest where the product's scalar part
/// `w cos(φ/2) − (v·a) sin(φ/2)` is largest in magnitude, at `φ = 2 atan2(−v·a, w)`; then
/// `θ = −φ`. (The angle alone is [`glint_geometry::pose_deviation::pose_deviation`]'s; the NEES
/// needs the whole pose.)
pub fn closest_symmetric_gt(
    t_o_w_est: &Isometry3<f64>,
    t_o_w_gt: &Isometry3<f64>,
    symmetry: &Symmetry,
) -> Isometry3<f64> {
    let mut best = *t_o_w_gt;
    let mut best_angle = f64::INFINITY;
    for s in symmetry.discrete_rotations() {
        let base = Isometry3::from_parts(Translation3::identity(), s.inverse()) * t_o_w_gt;
        let candidate = match symmetry.continuous_axis() {
            Some(axis) => {
                let m = (t_o_w_est.rotation * base.rotation.inverse()).into_inner();
                let phi = 2.0 * (-m.imag().dot(&axis.into_inner())).atan2(m.w);
                let spin = UnitQuaternion::from_axis_angle(&axis, -phi);
                Isometry3::from_parts(Translation3::identity(), spin) * base
            }
            None => base,
        };
        let angle = (t_o_w_est.rotation * candidate.rotation.inverse()).angle();
        if angle < best_angle {
            (best, best_angle) = (candidate, angle);
        }
    }
    best
}

/// The error of `t_o_w_est` as the refiner's left perturbation, `δ = log(T_est · T_gt⁻¹)`
/// (object frame, translation first), against the closest symmetric truth.
pub fn symmetric_error(
    t_o_w_est: &Isometry3<f64>,
    t_o_w_gt: &Isometry3<f64>,
    symmetry: &Symmetry,
) -> Vector6<f64> {
    let gt = closest_symmetric_gt(t_o_w_est, t_o_w_gt, symmetry);
    se3::log(&(t_o_w_est * gt.inverse()))
}

/// Normalised estimation error squared of a refined `t_o_w_est` against the truth, with the
/// refiner's Fisher information (eq 18): `δᵀ I δ`, `δ = log(T_est · T_gt⁻¹)` (the left
/// perturbation the information is expressed in) against the closest symmetric truth.
/// Returns the NEES and its degrees of freedom: 6, or 5 with a continuous symmetry (the spin
/// is unobserved and the closest truth removes it).
pub fn nees(
    t_o_w_est: &Isometry3<f64>,
    t_o_w_gt: &Isometry3<f64>,
    information: &Matrix6<f64>,
    symmetry: &Symmetry,
) -> (f64, usize) {
    let delta = symmetric_error(t_o_w_est, t_o_w_gt, symmetry);
    let value = (delta.transpose() * information * delta)[(0, 0)];
    let dof = if symmetry.continuous_axis().is_some() {
        5
    } else {
        6
    };
    (value, dof)
}

/// The two-sided 95 % interval of the mean of `n` χ²_k draws, by the normal approximation of
/// the mean (k ± 1.96 √(2k/n)).
pub fn chi2_mean_band(k: usize, n: usize) -> (f64, f64) {
    let k = k as f64;
    let half = 1.96 * (2.0 * k / n.max(1) as f64).sqrt();
    (k - half, k + half)
}

/// The arithmetic mean of `v`; NaN if `v` is empty.
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// The median of `v` (the mean of the middle two for an even count); NaN if `v` is empty.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => v[n / 2],
        _ => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Pearson correlation of two equally long samples (NaN when either has no spread).
pub fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len()) as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    sxy / (sxx * syy).sqrt()
}

/// Spearman rank correlation: Pearson of the ranks (ties broken by order; meant for
/// continuous data).
pub fn spearman(x: &[f64], y: &[f64]) -> f64 {
    let rank = |v: &[f64]| {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
        let mut r = vec![0.0; v.len()];
        for (k, &i) in idx.iter().enumerate() {
            r[i] = k as f64;
        }
        r
    };
    pearson(&rank(x), &rank(y))
}

/// McNemar's exact two-sided test of paired binary outcomes: with `b` pairs where only the
/// first method is right and `c` where only the second is, the probability under "both are
/// equally good" (each discordant pair a fair coin) of a split at least as uneven:
/// `min(1, 2 · P(X ≤ min(b, c)))`, `X ~ Binomial(b + c, ½)`. 1 without discordant pairs.
pub fn mcnemar_exact_p(b: usize, c: usize) -> f64 {
    let n = b + c;
    let k = b.min(c);
    // P(X = i) by the recurrence C(n, i + 1) = C(n, i) (n − i) / (i + 1), in logs to stay
    // finite for large n.
    let ln_half_n = n as f64 * 0.5f64.ln();
    let mut ln_term = ln_half_n; // i = 0
    let mut tail = ln_term.exp();
    for i in 0..k {
        ln_term += ((n - i) as f64).ln() - ((i + 1) as f64).ln();
        tail += ln_term.exp();
    }
    (2.0 * tail).min(1.0)
}

/// The paired sign-flip (permutation) test's two-sided p of per-trial differences `d` (one
/// method's score minus another's on the same trials): under "both are equally good" each
/// difference is as likely negated, so p is the share of `resamples` random sign patterns
/// whose |Σ d| is at least the observed one, counting the observed pattern (`(1 + k) / (1 +
/// resamples)`, never 0). On binary outcomes it is McNemar's test by simulation; it also takes
/// scores averaged over draws (a random policy's). 1 when every difference is 0.
pub fn paired_sign_flip_p(d: &[f64], resamples: u32, seed: u64) -> f64 {
    use rand::{Rng, SeedableRng};
    let observed = d.iter().sum::<f64>().abs();
    if observed == 0.0 {
        return 1.0;
    }
    // A relative tolerance so that a pattern summing to the observed value up to rounding
    // counts as "as extreme".
    let tolerance = 1e-12 * d.iter().map(|x| x.abs()).sum::<f64>();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let extreme = (0..resamples)
        .filter(|_| {
            let s: f64 = d
                .iter()
                .map(|&x| if rng.random::<bool>() { x } else { -x })
                .sum();
            s.abs() >= observed - tolerance
        })
        .count();
    (1 + extreme) as f64 / (1 + resamples) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_geometry::symmetry::Axis;
    use rand::{Rng, SeedableRng};

    #[test]
    fn correlations_of_exact_relations() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        let line: Vec<f64> = x.iter().map(|v| 3.0 - 2.0 * v).collect();
        assert!((pearson(&x, &line) + 1.0).abs() < 1e-12);
        // A monotone but curved relation: ranks agree exactly, values do not.
        let cubed: Vec<f64> = x.iter().map(|v| v * v * v).collect();
        assert!((spearman(&x, &cubed) - 1.0).abs() < 1e-12);
        assert!(pearson(&x, &cubed) < 1.0 - 1e-3);
    }

    #[test]
    fn the_sign_flip_test_agrees_with_mcnemar_on_binary_outcomes() {
        // 1 vs 9 discordant pairs (and 20 ties, which flip to themselves): McNemar's exact p is
        // 22/1024 ≈ 0.0215; 20 000 resamples estimate it within ±3σ ≈ 0.0031.
        let mut d = vec![0.0; 20];
        d.extend(std::iter::repeat_n(1.0, 9));
        d.push(-1.0);
        let p = paired_sign_flip_p(&d, 20_000, 7);
        let exact = mcnemar_exact_p(1, 9);
        let sigma = (exact * (1.0 - exact) / 20_000.0).sqrt();
        assert!((p - exact).abs() < 3.0 * sigma, "{p} vs {exact}");
        assert_eq!(paired_sign_flip_p(&[0.0, 0.0], 100, 1), 1.0);
        // Never 0: with every sign pattern less extreme, one resample in 1 + N.
        let all_right = vec![1.0; 40];
        assert!((paired_sign_flip_p(&all_right, 999, 1) - 1e-3).abs() < 1e-12);
    }

    #[test]
    fn mcnemar_matches_the_binomial_by_hand() {
        // No discordant pairs, or an even split: no evidence either way.
        assert_eq!(mcnemar_exact_p(0, 0), 1.0);
        assert_eq!(mcnemar_exact_p(5, 5), 1.0);
        // 1 vs 9: 2 · (C(10,0) + C(10,1)) / 2¹⁰ = 22 / 1024.
        assert!((mcnemar_exact_p(1, 9) - 22.0 / 1024.0).abs() < 1e-12);
        assert_eq!(mcnemar_exact_p(9, 1), mcnemar_exact_p(1, 9));
        // 0 vs 10: 2 / 1024.
        assert!((mcnemar_exact_p(0, 10) - 2.0 / 1024.0).abs() < 1e-12);
        // Large n stays finite and tiny: 0 vs 2000 is 2 · 2⁻²⁰⁰⁰, below f64's range → 0.
        assert!(mcnemar_exact_p(0, 2000) < 1e-300);
        assert!(mcnemar_exact_p(1000, 1100) > 0.01);
    }

    #[test]
    fn the_closed_form_spin_is_no_worse_than_a_fine_search() {
        let continuous = Symmetry::continuous(Axis::Z);
        let axis = Axis::Z.unit();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        for _ in 0..50 {
            let mut angle = || rng.random_range(-3.0..3.0);
            let gt = Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 0.5),
                UnitQuaternion::from_euler_angles(angle(), angle(), angle()),
            );
            let est = Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 0.5),
                UnitQuaternion::from_euler_angles(angle(), angle(), angle()),
            );
            let closest = closest_symmetric_gt(&est, &gt, &continuous);
            let closed = (est.rotation * closest.rotation.inverse()).angle();
            // A grid of 0.1° spins: the optimum lies within 0.05° of a sample, so the search
            // can beat the closed form by at most ~0.05° (the angle is 1-Lipschitz in the spin).
            let searched = (0..3600)
                .map(|k| {
                    let spin =
                        UnitQuaternion::from_axis_angle(&axis, k as f64 * 0.1f64.to_radians());
                    (est.rotation * (spin * gt.rotation).inverse()).angle()
                })
                .fold(f64::INFINITY, f64::min);
            assert!(closed <= searched + 1e-9, "{closed} > {searched}");
            assert!(searched - closed <= 0.05f64.to_radians() + 1e-9);
        }
    }

    #[test]
    fn closest_symmetric_truth_removes_symmetric_rotations() {
        let gt = Isometry3::from_parts(
            Translation3::new(0.01, 0.02, 0.5),
            UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0),
        );
        // An estimate a sixth of a turn about the object's z from the truth, plus 1° about x.
        let spin = UnitQuaternion::from_axis_angle(&Axis::Z.unit(), std::f64::consts::PI / 3.0);
        let small = UnitQuaternion::from_axis_angle(&Axis::X.unit(), 1f64.to_radians());
        let est = Isometry3::from_parts(Translation3::identity(), small * spin) * gt;
        let six = Symmetry::cyclic(Axis::Z, 6);
        let closest = closest_symmetric_gt(&est, &gt, &six);
        let residual = (est.rotation * closest.rotation.inverse())
            .angle()
            .to_degrees();
        assert!((residual - 1.0).abs() < 1e-9, "{residual}");
        let continuous = Symmetry::continuous(Axis::Z);
        let spin = UnitQuaternion::from_axis_angle(&Axis::Z.unit(), 0.777);
        let est = Isometry3::from_parts(Translation3::identity(), small * spin) * gt;
        let closest = closest_symmetric_gt(&est, &gt, &continuous);
        let residual = (est.rotation * closest.rotation.inverse())
            .angle()
            .to_degrees();
        assert!((residual - 1.0).abs() < 1e-6, "{residual}");
        // The NEES of a pure symmetric offset is zero.
        let exact = Isometry3::from_parts(Translation3::identity(), spin) * gt;
        let (value, dof) = nees(&exact, &gt, &Matrix6::identity(), &continuous);
        assert!(value < 1e-12 && dof == 5, "{value}");
    }
}
