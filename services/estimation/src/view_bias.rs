//! A pose error shared by every point of one view, and the information of a multi-view pose
//! that survives it.
//!
//! [`crate::correlated_error`] caps what one cell of neighbouring pixels adds; the covariance
//! left is still far too sure (Table I's NEES) because a view's depth can be wrong as a whole —
//! a mirror image of the floor on a shiny face, a matching bias along one edge — and that moves
//! the optimum of the view's own points, not just their scatter. Model: the pose view v's points
//! alone would give is off by `β_v ~ N(0, B)`, independent between views, with B expressed in
//! the *view frame*: the camera's axes through the object's origin (z along the optical axis),
//! so that a rotation bias turns the part about its own origin rather than about the camera's
//! (which would lend every rotation a lever arm of the working distance). The refiner weighs
//! the views by their information `I_v` (eq 18–19, or the correlated model's), so its estimate
//! is `ξ̂ ≈ I⁻¹ Σ_v I_v ξ_v` with `I = Σ_v I_v`, and its covariance is the sandwich
//!
//! `Σ_ξ = I⁻¹ (I + Σ_v I_v B_v I_v) I⁻¹`, `B_v = Ad_v B Ad_vᵀ`, `Ad_v = diag(R_o_c,v, R_o_c,v)`,
//!
//! whose information is `I M⁻¹ I`, `M = I + Σ_v I_v B_v I_v`. One view adds at most about
//! `B_v⁻¹` however many pixels it holds, so n views reach about n·B⁻¹, not n times eq 18's.
//! `B = 0` gives `I` exactly.
//!
//! B describes the camera on one part, not a result: [`measure_view_bias`] takes it from
//! single-view refinements at known poses (tuning scenes, never an evaluation's) by maximum
//! likelihood, each error `δ ~ N(0, I⁻¹ + B_v)` with the information the refiner reported for
//! it, by expectation–maximisation (directions a view does not observe — a continuous
//! symmetry's spin — carry no weight).

use glint_geometry::se3;
use nalgebra::{Isometry3, Matrix6, Rotation3, Vector6};

/// A pose bias shared by all of one view's points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewPoseBias {
    /// B: the bias's covariance in the view frame (the camera's axes through the object's
    /// origin), translation in metres first, then rotation in radians.
    pub covariance_v: Matrix6<f64>,
}

impl ViewPoseBias {
    /// No shared pose error: the views' information adds up as eq 19 has it.
    pub fn none() -> Self {
        Self {
            covariance_v: Matrix6::zeros(),
        }
    }

    /// The bias's standard deviations along the view frame's axes: translation (metres) and
    /// rotation (radians), x, y, z each (z along the optical axis).
    pub fn sigmas(&self) -> ([f64; 3], [f64; 3]) {
        let s = |i: usize| self.covariance_v[(i, i)].max(0.0).sqrt();
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
                let ad = view_to_object(&v.r_o_c);
                v.information * (ad * self.covariance_v * ad.transpose()) * v.information
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
    /// The view's camera axes in the object frame at the refined pose.
    pub r_o_c: Rotation3<f64>,
}

/// One single-view refinement at a known pose: what [`measure_view_bias`] learns from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SingleViewError {
    /// `δ = log(t_o_w,est · t_o_w,true⁻¹)`, the refiner's left perturbation (object frame),
    /// against the closest symmetric truth.
    pub error_o: Vector6<f64>,
    /// The information the refiner reported for it (object frame).
    pub information: Matrix6<f64>,
    /// The view's camera axes in the object frame.
    pub r_o_c: Rotation3<f64>,
}

/// What [`measure_view_bias`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewBiasFit {
    /// The maximum-likelihood bias.
    pub bias: ViewPoseBias,
    /// The mean of `δ_v δ_vᵀ` over the samples (view frame): the errors' own spread, noise and
    /// bias together, where they were observed or not.
    pub second_moment_v: Matrix6<f64>,
    /// How many refinements it was measured on.
    pub samples: usize,
    /// EM iterations run (at most [`EM_MAX_ITERATIONS`]).
    pub iterations: usize,
}

/// The most EM steps [`measure_view_bias`] takes.
pub const EM_MAX_ITERATIONS: usize = 2000;

/// EM stops when no entry of B moves by more than this share of B's largest diagonal entry.
const EM_TOLERANCE: f64 = 1e-9;

/// `diag(R_o_c, R_o_c)`: a twist in the view frame as the same twist in the object frame.
fn view_to_object(r_o_c: &Rotation3<f64>) -> Matrix6<f64> {
    se3::adjoint(&Isometry3::from_parts(
        nalgebra::Translation3::identity(),
        (*r_o_c).into(),
    ))
}

/// Measures a [`ViewPoseBias`] from single-view refinements at known poses: the B that
/// maximises the likelihood of their errors under `δ ~ N(0, I⁻¹ + Ad B Adᵀ)`, by
/// expectation–maximisation on the per-view biases β (E: β's posterior mean `m` and covariance
/// `C` given δ; M: `B = mean(m mᵀ + C)`), started at the errors' second moment. The posterior
/// is written with the information, `K = (1 + I A)⁻¹ I = (I⁻¹ + A)⁻¹`, so a singular I (an
/// unobserved spin) needs no inverse and gives that direction no weight. `None` without
/// samples.
pub fn measure_view_bias(samples: &[SingleViewError]) -> Option<ViewBiasFit> {
    if samples.is_empty() {
        return None;
    }
    let n = samples.len() as f64;
    let frames: Vec<(Matrix6<f64>, Vector6<f64>)> = samples
        .iter()
        .map(|s| {
            let ad = view_to_object(&s.r_o_c);
            (ad, ad.transpose() * s.error_o)
        })
        .collect();
    let second_moment_v: Matrix6<f64> = frames
        .iter()
        .map(|(_, e)| e * e.transpose())
        .sum::<Matrix6<f64>>()
        / n;
    let mut b = second_moment_v;
    let mut iterations = 0;
    while iterations < EM_MAX_ITERATIONS {
        iterations += 1;
        let mut next = Matrix6::zeros();
        for (s, (ad, _)) in samples.iter().zip(&frames) {
            let a = ad * b * ad.transpose();
            // A failed inverse (not expected: I·A has no negative eigenvalue) drops the sample
            // to the prior, m = 0 and C = B.
            let k = (Matrix6::identity() + s.information * a)
                .try_inverse()
                .map_or_else(Matrix6::zeros, |m| m * s.information);
            let gain = b * ad.transpose() * k;
            let mean = gain * s.error_o;
            next += mean * mean.transpose() + b - gain * ad * b;
        }
        let next = symmetrise(&(next / n));
        let scale = (0..6).map(|i| next[(i, i)]).fold(0.0, f64::max);
        let moved = (next - b).amax();
        b = next;
        if moved <= EM_TOLERANCE * scale {
            break;
        }
    }
    Some(ViewBiasFit {
        bias: ViewPoseBias {
            covariance_v: clip_psd(&b),
        },
        second_moment_v,
        samples: samples.len(),
        iterations,
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

    fn random_rotation(rng: &mut rand_pcg::Pcg64) -> Rotation3<f64> {
        Rotation3::from_scaled_axis(nalgebra::Vector3::from_fn(|_, _| normal(rng)))
    }

    /// A random SPD matrix `A Aᵀ + ½·1`, scaled per axis like a pose information (metres and
    /// radians).
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

    fn bias_v() -> Matrix6<f64> {
        // 0.3 mm laterally, 0.8 mm along the optical axis, 0.2–0.5° of rotation; correlated
        // depth and tilt.
        let d = Vector6::new(0.3e-3, 0.3e-3, 0.8e-3, 0.004, 0.004, 0.009);
        let mut b = Matrix6::from_diagonal(&d.component_mul(&d));
        b[(2, 3)] = 0.5 * d[2] * d[3];
        b[(3, 2)] = b[(2, 3)];
        b
    }

    fn no_zero(m: Option<Matrix6<f64>>) -> Matrix6<f64> {
        m.unwrap_or_else(Matrix6::zeros)
    }

    #[test]
    fn without_a_bias_the_views_information_adds_up() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        let views: Vec<ViewInformation> = (0..3)
            .map(|_| ViewInformation {
                information: random_information(&mut rng, 1.0),
                r_o_c: random_rotation(&mut rng),
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
            r_o_c: random_rotation(&mut rng),
        };
        let bias = ViewPoseBias {
            covariance_v: bias_v(),
        };
        let ad = view_to_object(&view.r_o_c);
        let expected = no_zero(
            (no_zero(view.information.try_inverse()) + ad * bias.covariance_v * ad.transpose())
                .try_inverse(),
        );
        let ours = bias.information(&[view]);
        assert!((ours - expected).norm() <= 1e-6 * expected.norm());
    }

    #[test]
    fn n_equal_views_reach_n_over_the_bias_however_many_pixels_they_hold() {
        // I_v = k·1 and B = b·1: the information is n·k/(1 + k·b), → n/b as k grows.
        let (k, b, n) = (1e9, 1e-6, 4);
        let views = vec![
            ViewInformation {
                information: Matrix6::identity() * k,
                r_o_c: Rotation3::identity(),
            };
            n
        ];
        let bias = ViewPoseBias {
            covariance_v: Matrix6::identity() * b,
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
            covariance_v: bias_v(),
        };
        let views: Vec<ViewInformation> = (0..3)
            .map(|i| ViewInformation {
                information: random_information(&mut rng, [1.0, 0.05, 3.0][i]),
                r_o_c: random_rotation(&mut rng),
            })
            .collect();
        let total: Matrix6<f64> = views.iter().map(|v| v.information).sum();
        let total_inv = no_zero(total.try_inverse());
        let information = bias.information(&views);
        let trials = 4000;
        let mut sum = 0.0;
        for _ in 0..trials {
            let weighted: Vector6<f64> = views
                .iter()
                .map(|v| {
                    let beta = view_to_object(&v.r_o_c) * draw(&mut rng, &bias.covariance_v);
                    let noise = draw(&mut rng, &no_zero(v.information.try_inverse()));
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
        let eq19 = (total * no_zero(information.try_inverse())).trace();
        assert!(eq19 - 6.0 > half, "eq 19's mean NEES {eq19}");
    }

    #[test]
    fn the_measured_bias_is_the_likelihoods_and_ignores_unobserved_directions() {
        // Errors δ = Ad β + n, β ~ N(0, B) in each view frame, n ~ N(0, I⁻¹); a quarter of the
        // views do not observe the spin about the object's z (zero information there) and err
        // along it by far more than B. EM recovers B within 5 standard errors of a second
        // moment over the full-rank views (var of an entry: (B+P)_ii (B+P)_jj + (B+P)_ij² / N),
        // where the second moment alone is swamped by the spin.
        let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
        let b = bias_v();
        let n = 8000;
        let mut p_diag = Vector6::zeros();
        let samples: Vec<SingleViewError> = (0..n)
            .map(|i| {
                let r_o_c = random_rotation(&mut rng);
                let mut information = random_information(&mut rng, 30.0);
                let p_o = no_zero(information.try_inverse());
                let mut error_o =
                    view_to_object(&r_o_c) * draw(&mut rng, &b) + draw(&mut rng, &p_o);
                if i % 4 == 0 {
                    for k in 0..6 {
                        information[(5, k)] = 0.0;
                        information[(k, 5)] = 0.0;
                    }
                    error_o[5] += 0.2 * normal(&mut rng);
                } else {
                    let ad_t = view_to_object(&r_o_c).transpose();
                    p_diag += (ad_t * p_o * ad_t.transpose()).diagonal() / (0.75 * n as f64);
                }
                SingleViewError {
                    error_o,
                    information,
                    r_o_c,
                }
            })
            .collect();
        let fit = measure_view_bias(&samples).unwrap_or_else(|| panic!("no fit"));
        assert_eq!(fit.samples, n);
        assert!(fit.iterations < EM_MAX_ITERATIONS, "EM did not settle");
        let n_full = 0.75 * n as f64;
        for i in 0..6 {
            for j in 0..6 {
                let c = |a: usize, d: usize| b[(a, d)].abs() + (p_diag[a] * p_diag[d]).sqrt();
                let tolerance = 5.0 * ((c(i, i) * c(j, j) + c(i, j).powi(2)) / n_full).sqrt();
                let got = fit.bias.covariance_v[(i, j)];
                assert!(
                    (got - b[(i, j)]).abs() < tolerance,
                    "B[{i},{j}] {got} vs {} ± {tolerance}",
                    b[(i, j)]
                );
            }
        }
        // The spin's errors reach the second moment's rotation block.
        assert!(fit.second_moment_v[(5, 5)] > 10.0 * b[(5, 5)]);
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
            r_o_c: random_rotation(&mut rng),
        };
        let ours = ViewPoseBias {
            covariance_v: bias_v(),
        }
        .information(&[view, view]);
        assert!(ours.iter().all(|v| v.is_finite()));
        assert!(ours.column(5).norm() <= 1e-9 * ours.norm());
        assert!(ours[(0, 0)] > 0.0 && ours[(0, 0)] < 2.0 * information[(0, 0)]);
    }
}
