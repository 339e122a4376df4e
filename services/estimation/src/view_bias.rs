//! A pose error shared by every point of one view, and the information of a multi-view pose
//! that survives it.
//!
//! [`crate::correlated_error`] caps what one cell of neighbouring pixels adds; the covariance
//! left is still far too sure (Table I's NEES) because a view's depth can be wrong as a whole —
//! a mirror image of the floor on a shiny face, a matching bias along one edge — and that moves
//! the optimum of the view's own points, not just their scatter. Model: the pose view v's points
//! alone would give is off by `β_v ~ N(0, B)`, B expressed in the view's camera frame (a left
//! perturbation of `t_c_o`, translation first), independent between views. The refiner weighs
//! the views by their information `I_v` (eq 18–19, or the correlated model's), so its estimate
//! is `ξ̂ ≈ I⁻¹ Σ_v I_v ξ_v` with `I = Σ_v I_v`, and its covariance is the sandwich
//!
//! `Σ_ξ = I⁻¹ (I + Σ_v I_v B_v I_v) I⁻¹`, `B_v = Ad(t_o_c,v) B Ad(t_o_c,v)ᵀ`,
//!
//! whose information is `I M⁻¹ I`, `M = I + Σ_v I_v B_v I_v`. One view adds at most about
//! `B_v⁻¹` however many pixels it holds, so n views reach about n·B⁻¹, not n times eq 18's.
//! `B = 0` gives `I` exactly.
//!
//! B describes the camera on one part, not a result: [`measure_view_bias`] takes it from
//! single-view refinements at known poses (tuning scenes, never an evaluation's) as the second
//! moment of their camera-frame errors minus the covariance the refiner predicted for them.

use glint_geometry::se3;
use nalgebra::{Isometry3, Matrix6, Vector6};

/// A pose bias shared by all of one view's points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewPoseBias {
    /// B: the bias's covariance in the view's camera frame, as a left perturbation of `t_c_o`
    /// (translation in metres first, then rotation in radians).
    pub covariance_c: Matrix6<f64>,
}

impl ViewPoseBias {
    /// No shared pose error: the views' information adds up as eq 19 has it.
    pub fn none() -> Self {
        Self {
            covariance_c: Matrix6::zeros(),
        }
    }

    /// The bias's standard deviations along the camera axes: translation (metres) and
    /// rotation (radians), x, y, z each (z along the optical axis).
    pub fn sigmas(&self) -> ([f64; 3], [f64; 3]) {
        let s = |i: usize| self.covariance_c[(i, i)].max(0.0).sqrt();
        ([s(0), s(1), s(2)], [s(3), s(4), s(5)])
    }

    /// The information of a pose refined on `views` when each view carries this bias (module
    /// doc: `I M⁻¹ I`), in the refiner's δ coordinates (the object frame, translation first).
    /// With no views it is zero; with [`Self::none`] it is `Σ_v I_v`.
    pub fn information(&self, views: &[ViewInformation]) -> Matrix6<f64> {
        let total: Matrix6<f64> = views.iter().map(|v| v.information).sum();
        let shared: Matrix6<f64> = views
            .iter()
            .map(|v| {
                let ad = se3::adjoint(&v.t_o_c);
                v.information * (ad * self.covariance_c * ad.transpose()) * v.information
            })
            .sum();
        let m = total + shared;
        symmetrise(&(total * pinv_psd(&m) * total))
    }
}

/// One view's share of a refinement: its information and where its camera was.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewInformation {
    /// The view's information alone, in the refiner's δ coordinates (object frame).
    pub information: Matrix6<f64>,
    /// The view's camera in the object frame at the refined pose.
    pub t_o_c: Isometry3<f64>,
}

/// One single-view refinement at a known pose: what [`measure_view_bias`] learns from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SingleViewError {
    /// `δ = log(t_o_w,est · t_o_w,true⁻¹)`, the refiner's left perturbation (object frame),
    /// against the closest symmetric truth.
    pub error_o: Vector6<f64>,
    /// The information the refiner reported for it (object frame).
    pub information: Matrix6<f64>,
    /// The view's camera in the object frame.
    pub t_o_c: Isometry3<f64>,
}

/// What [`measure_view_bias`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewBiasFit {
    /// The measured bias, `B = S − P` made positive semi-definite.
    pub bias: ViewPoseBias,
    /// S: the mean of `δ_c δ_cᵀ` over the samples, camera frame.
    pub second_moment_c: Matrix6<f64>,
    /// P: the mean covariance the refiner predicted (its information's pseudo-inverse), camera
    /// frame.
    pub predicted_c: Matrix6<f64>,
    /// How many refinements it was measured on.
    pub samples: usize,
}

/// Measures a [`ViewPoseBias`] from single-view refinements at known poses: the camera-frame
/// errors' second moment minus the predicted covariance, negative eigenvalues set to zero.
/// `None` without samples.
pub fn measure_view_bias(samples: &[SingleViewError]) -> Option<ViewBiasFit> {
    if samples.is_empty() {
        return None;
    }
    let n = samples.len() as f64;
    let (mut second_moment_c, mut predicted_c) = (Matrix6::zeros(), Matrix6::zeros());
    for s in samples {
        // δ_c = Ad(t_c_o) δ_o: the same error as a left perturbation of t_c_o (up to sign).
        let ad = se3::adjoint(&s.t_o_c.inverse());
        let e = ad * s.error_o;
        second_moment_c += e * e.transpose() / n;
        predicted_c += ad * pinv_psd(&s.information) * ad.transpose() / n;
    }
    let bias = ViewPoseBias {
        covariance_c: clip_psd(&(second_moment_c - predicted_c)),
    };
    Some(ViewBiasFit {
        bias,
        second_moment_c,
        predicted_c,
        samples: samples.len(),
    })
}

fn symmetrise(m: &Matrix6<f64>) -> Matrix6<f64> {
    (m + m.transpose()) * 0.5
}

/// Relative eigenvalue below which a direction counts as unobserved (a continuous symmetry's
/// spin), after Jacobi scaling makes the matrix unit-free.
const RANK_TOLERANCE: f64 = 1e-12;

/// The pseudo-inverse of a symmetric positive semi-definite matrix of mixed units: scaled to a
/// unit diagonal first, so the rank decision does not depend on metres against radians.
fn pinv_psd(m: &Matrix6<f64>) -> Matrix6<f64> {
    let m = symmetrise(m);
    let d = Vector6::from_fn(|i, _| {
        let v = m[(i, i)];
        if v > 0.0 { 1.0 / v.sqrt() } else { 0.0 }
    });
    let scaled = Matrix6::from_fn(|i, j| d[i] * m[(i, j)] * d[j]);
    let eig = scaled.symmetric_eigen();
    let top = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let mut inv = Matrix6::zeros();
    for (k, &lambda) in eig.eigenvalues.iter().enumerate() {
        if lambda > RANK_TOLERANCE * top {
            let u = eig.eigenvectors.column(k);
            inv += u * u.transpose() / lambda;
        }
    }
    Matrix6::from_fn(|i, j| d[i] * inv[(i, j)] * d[j])
}

/// The nearest positive semi-definite matrix in the Frobenius norm: negative eigenvalues to 0.
fn clip_psd(m: &Matrix6<f64>) -> Matrix6<f64> {
    let eig = symmetrise(m).symmetric_eigen();
    let mut out = Matrix6::zeros();
    for (k, &lambda) in eig.eigenvalues.iter().enumerate() {
        if lambda > 0.0 {
            let u = eig.eigenvectors.column(k);
            out += u * u.transpose() * lambda;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    fn normal(rng: &mut rand_pcg::Pcg64) -> f64 {
        StandardNormal.sample(rng)
    }

    fn random_pose(rng: &mut rand_pcg::Pcg64) -> Isometry3<f64> {
        let xi = Vector6::from_fn(|_, _| 0.5 * normal(rng));
        se3::exp(&xi)
    }

    /// A random SPD matrix `A Aᵀ + ε·diag`, scaled per axis like a pose information (metres
    /// and radians).
    fn random_information(rng: &mut rand_pcg::Pcg64, scale: f64) -> Matrix6<f64> {
        let a = Matrix6::from_fn(|_, _| normal(rng));
        let units = Matrix6::from_diagonal(&Vector6::new(1e3, 1e3, 1e3, 30.0, 30.0, 30.0));
        units * (a * a.transpose() + Matrix6::identity() * 0.5) * units * scale
    }

    /// A Gaussian draw with covariance `c` (Cholesky of c plus a negligible jitter).
    fn draw(rng: &mut rand_pcg::Pcg64, c: &Matrix6<f64>) -> Vector6<f64> {
        let l = (c + Matrix6::identity() * 1e-30)
            .cholesky()
            .map(|ch| ch.l())
            .unwrap_or_else(Matrix6::zeros);
        l * Vector6::from_fn(|_, _| normal(rng))
    }

    fn bias_c() -> Matrix6<f64> {
        // 0.3 mm laterally, 0.8 mm along the optical axis, 0.2–0.5° of rotation.
        let d = Vector6::new(0.3e-3, 0.3e-3, 0.8e-3, 0.004, 0.004, 0.009);
        Matrix6::from_diagonal(&d.component_mul(&d))
    }

    #[test]
    fn without_a_bias_the_views_information_adds_up() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        let views: Vec<ViewInformation> = (0..3)
            .map(|_| ViewInformation {
                information: random_information(&mut rng, 1.0),
                t_o_c: random_pose(&mut rng),
            })
            .collect();
        let sum: Matrix6<f64> = views.iter().map(|v| v.information).sum();
        let ours = ViewPoseBias::none().information(&views);
        assert!((ours - sum).norm() <= 1e-9 * sum.norm());
    }

    #[test]
    fn one_view_gets_the_inverse_of_its_covariance_plus_the_bias() {
        // (I⁻¹ + B_o)⁻¹ for an invertible I.
        let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
        let view = ViewInformation {
            information: random_information(&mut rng, 1.0),
            t_o_c: random_pose(&mut rng),
        };
        let bias = ViewPoseBias {
            covariance_c: bias_c(),
        };
        let ad = se3::adjoint(&view.t_o_c);
        let expected = (view
            .information
            .try_inverse()
            .unwrap_or_else(Matrix6::zeros)
            + ad * bias.covariance_c * ad.transpose())
        .try_inverse()
        .unwrap_or_else(Matrix6::zeros);
        let ours = bias.information(&[view]);
        assert!((ours - expected).norm() <= 1e-6 * expected.norm());
    }

    #[test]
    fn n_equal_views_reach_n_over_the_bias_however_many_pixels_they_hold() {
        // I_v = k·1 and B_o = b·1: the information is n·k/(1 + k·b), → n/b as k grows.
        let (k, b, n) = (1e9, 1e-6, 4);
        let views = vec![
            ViewInformation {
                information: Matrix6::identity() * k,
                t_o_c: Isometry3::identity(),
            };
            n
        ];
        let bias = ViewPoseBias {
            covariance_c: Matrix6::identity() * b,
        };
        let expected = n as f64 * k / (1.0 + k * b);
        let ours = bias.information(&views);
        assert!((ours - Matrix6::identity() * expected).norm() <= 1e-9 * expected);
    }

    #[test]
    fn the_sandwich_is_the_covariance_of_the_weighted_estimate() {
        // Monte Carlo: views with their own information and a bias each, the estimate weighed
        // as the refiner weighs it; the mean NEES under the sandwich's information must be 6
        // within 4 standard errors of a mean of χ²₆ draws (√(12/N)).
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let bias = ViewPoseBias {
            covariance_c: bias_c(),
        };
        let views: Vec<ViewInformation> = (0..3)
            .map(|i| ViewInformation {
                information: random_information(&mut rng, [1.0, 0.05, 3.0][i]),
                t_o_c: random_pose(&mut rng),
            })
            .collect();
        let total: Matrix6<f64> = views.iter().map(|v| v.information).sum();
        let total_inv = total.try_inverse().unwrap_or_else(Matrix6::zeros);
        let information = bias.information(&views);
        let trials = 4000;
        let mut sum = 0.0;
        for _ in 0..trials {
            let weighted: Vector6<f64> = views
                .iter()
                .map(|v| {
                    let ad = se3::adjoint(&v.t_o_c);
                    let beta = ad * draw(&mut rng, &bias.covariance_c);
                    let noise = draw(
                        &mut rng,
                        &v.information.try_inverse().unwrap_or_else(Matrix6::zeros),
                    );
                    v.information * (beta + noise)
                })
                .sum();
            let e = total_inv * weighted;
            sum += (e.transpose() * information * e)[(0, 0)];
        }
        let mean = sum / trials as f64;
        let half = 4.0 * (12.0 / trials as f64).sqrt();
        assert!((mean - 6.0).abs() < half, "mean NEES {mean}");
        // Eq 19 alone is overconfident on the same draws: E[eᵀ I e] = tr(I Σ_ξ).
        let eq19 = (total * information.try_inverse().unwrap_or_else(Matrix6::zeros)).trace();
        assert!(eq19 - 6.0 > half, "eq 19's mean NEES {eq19}");
    }

    #[test]
    fn the_measured_bias_is_the_error_second_moment_less_the_predicted_covariance() {
        // Errors drawn as N(0, P + B) in each camera frame with P the refiner's predicted
        // covariance: S − P recovers B within the estimate's sampling error (var of a second
        // moment entry: B_ii B_jj + B_ij² over N; 5 standard errors).
        let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
        let b = bias_c();
        let n = 20_000;
        let samples: Vec<SingleViewError> = (0..n)
            .map(|_| {
                let t_o_c = random_pose(&mut rng);
                let information = random_information(&mut rng, 2.0);
                let p_o = information.try_inverse().unwrap_or_else(Matrix6::zeros);
                let ad_o_c = se3::adjoint(&t_o_c);
                let error_o = ad_o_c * draw(&mut rng, &b) + draw(&mut rng, &p_o);
                SingleViewError {
                    error_o,
                    information,
                    t_o_c,
                }
            })
            .collect();
        let fit = measure_view_bias(&samples).unwrap_or_else(|| panic!("no fit"));
        assert_eq!(fit.samples, n);
        for i in 0..6 {
            for j in 0..6 {
                // The predicted covariance adds its own spread to S; bound it by P's scale.
                let p = fit.predicted_c[(i, i)].sqrt() * fit.predicted_c[(j, j)].sqrt();
                let spread = (b[(i, i)] + p) * (b[(j, j)] + p) + (b[(i, j)] + p).powi(2);
                let tolerance = 5.0 * (spread / n as f64).sqrt();
                let got = fit.bias.covariance_c[(i, j)];
                assert!(
                    (got - b[(i, j)]).abs() < tolerance,
                    "B[{i},{j}] {got} vs {}",
                    b[(i, j)]
                );
            }
        }
        assert!(measure_view_bias(&[]).is_none());
    }

    #[test]
    fn an_unobserved_spin_stays_unobserved() {
        // A continuous symmetry: no information about rotation about the object's z; the
        // bias must not invent any.
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let mut information = random_information(&mut rng, 1.0);
        for k in 0..6 {
            information[(5, k)] = 0.0;
            information[(k, 5)] = 0.0;
        }
        let view = ViewInformation {
            information,
            t_o_c: random_pose(&mut rng),
        };
        let ours = ViewPoseBias {
            covariance_c: bias_c(),
        }
        .information(&[view, view]);
        assert!(ours.iter().all(|v| v.is_finite()));
        assert!(ours.column(5).norm() <= 1e-9 * ours.norm());
        assert!(ours[(0, 0)] > 0.0 && ours[(0, 0)] < 2.0 * information[(0, 0)]);
    }
}
