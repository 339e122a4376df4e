//! SE(3) on the left: exponential and logarithm maps, left perturbation and the point Jacobian.
//!
//! A twist is `ξ = (ρ, φ) ∈ ℝ⁶`, translation first, and perturbs a pose on the left:
//! `T ← exp(ξ)·T`. This module is the only owner of that convention.

use nalgebra::{
    Isometry3, Matrix3, Matrix3x6, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6,
};

/// `[v]×`, the cross-product matrix: `[v]× w = v × w`.
#[inline]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The left Jacobian of SO(3), `V(φ) = I + (1−cos θ)/θ² [φ]× + (θ−sin θ)/θ³ [φ]×²`, which maps
/// ρ to the translation of `exp(ξ)`. Taylor-expanded near θ = 0.
fn so3_left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let k = skew(phi);
    let (a, b) = if theta2 < 1e-10 {
        (0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0)
    } else {
        let theta = theta2.sqrt();
        (
            (1.0 - theta.cos()) / theta2,
            (theta - theta.sin()) / (theta2 * theta),
        )
    };
    Matrix3::identity() + k * a + k * k * b
}

/// The exponential map `exp: se(3) → SE(3)` for `ξ = (ρ, φ)`.
pub fn exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let rho = xi.fixed_rows::<3>(0).into_owned();
    let phi = xi.fixed_rows::<3>(3).into_owned();
    let rotation = UnitQuaternion::from_scaled_axis(phi);
    Isometry3::from_parts(Translation3::from(so3_left_jacobian(&phi) * rho), rotation)
}

/// The logarithm map `log: SE(3) → se(3)`, inverse of [`exp`] for rotation angles below π.
pub fn log(t: &Isometry3<f64>) -> Vector6<f64> {
    let phi = t.rotation.scaled_axis();
    let v = so3_left_jacobian(&phi);
    // V is invertible for θ < 2π; fall back to the translation itself if it is not.
    let rho = v
        .try_inverse()
        .map_or(t.translation.vector, |v_inv| v_inv * t.translation.vector);
    Vector6::new(rho.x, rho.y, rho.z, phi.x, phi.y, phi.z)
}

/// `exp(δ)·T`: the left perturbation used by every optimiser in Glint.
#[inline]
pub fn perturb_left(delta: &Vector6<f64>, t: &Isometry3<f64>) -> Isometry3<f64> {
    exp(delta) * t
}

/// The adjoint of `t = t_a_b` on twists, `Ad(t) = [[R, [t]× R], [0, R]]` (translation first):
/// `exp(Ad(t)·ξ) = t·exp(ξ)·t⁻¹`, so a left perturbation expressed in frame b becomes the same
/// perturbation expressed in frame a; a covariance moves as `Ad Σ Adᵀ`.
pub fn adjoint(t: &Isometry3<f64>) -> Matrix6<f64> {
    let r = t.rotation.to_rotation_matrix().into_inner();
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(skew(&t.translation.vector) * r));
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    ad
}

/// `∂(exp(δ)·p)/∂δ` at δ = 0: `[I | −[p]×]` (used by eq 10).
#[inline]
pub fn point_jacobian_left(p: &Point3<f64>) -> Matrix3x6<f64> {
    let mut j = Matrix3x6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-skew(&p.coords)));
    j
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_adjoint_moves_a_perturbation_between_frames() {
        // exp(Ad(t)·ξ) = t·exp(ξ)·t⁻¹ to rounding, for poses away from the identity.
        let t = exp(&Vector6::new(0.3, -0.2, 0.5, 0.4, -0.7, 1.1));
        for xi in twists()
            .iter()
            .filter(|x| x.fixed_rows::<3>(3).norm() < 2.0)
        {
            let lhs = exp(&(adjoint(&t) * xi));
            let rhs = t * exp(xi) * t.inverse();
            assert!((log(&(lhs * rhs.inverse()))).norm() < 1e-9, "{xi:?}");
        }
    }

    fn twists() -> Vec<Vector6<f64>> {
        vec![
            Vector6::zeros(),
            Vector6::new(0.01, -0.02, 0.3, 0.0, 0.0, 0.0),
            Vector6::new(0.1, 0.2, -0.05, 0.3, -0.2, 0.9),
            Vector6::new(-0.4, 0.0, 0.2, 1e-9, 2e-9, -1e-9),
            Vector6::new(0.0, 0.5, 0.0, 0.0, 3.0, 0.0),
        ]
    }

    #[test]
    fn log_inverts_exp() {
        for xi in twists() {
            let back = log(&exp(&xi));
            assert!((back - xi).norm() < 1e-9, "{xi} → {back}");
        }
    }

    #[test]
    fn exp_of_pure_translation_and_pure_rotation() {
        let t = exp(&Vector6::new(1.0, 2.0, 3.0, 0.0, 0.0, 0.0));
        assert!((t.translation.vector - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-15);
        let r = exp(&Vector6::new(
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            std::f64::consts::FRAC_PI_2,
        ));
        assert!((r * Point3::new(1.0, 0.0, 0.0) - Point3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
    }

    #[test]
    fn point_jacobian_matches_finite_differences() {
        let t = exp(&Vector6::new(0.1, -0.2, 0.5, 0.3, 0.1, -0.7));
        let p = Point3::new(0.02, -0.01, 0.03);
        let analytic = point_jacobian_left(&(t * p));
        let h = 1e-6;
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            let plus = perturb_left(&d, &t) * p;
            d[k] = -h;
            let minus = perturb_left(&d, &t) * p;
            let numeric = (plus - minus) / (2.0 * h);
            // Central differences are O(h²): well below 1e-8 here.
            assert!((numeric - analytic.column(k)).norm() < 1e-8, "column {k}");
        }
    }
}
