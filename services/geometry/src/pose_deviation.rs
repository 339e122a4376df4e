//! Pose errors that respect a part's symmetry, and the paper's correct-detection test.

use nalgebra::{Isometry3, UnitQuaternion};

use crate::symmetry::Symmetry;

/// Translation and rotation error of an estimated pose against ground truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseDeviation {
    /// Distance between the estimated and true object origins, metres.
    pub translation_m: f64,
    /// Smallest rotation angle between the estimate and any symmetric equivalent of the truth,
    /// radians, in [0, π].
    pub rotation_rad: f64,
}

impl PoseDeviation {
    /// The translation error in millimetres.
    pub fn translation_mm(&self) -> f64 {
        self.translation_m * 1e3
    }
    /// The rotation error in degrees, in [0, 180].
    pub fn rotation_deg(&self) -> f64 {
        self.rotation_rad.to_degrees()
    }
    /// The paper's correct-detection test: both errors strictly below the threshold.
    pub fn is_correct(&self, threshold: &CorrectThreshold) -> bool {
        self.translation_m < threshold.translation_m && self.rotation_rad < threshold.rotation_rad
    }
}

/// A correct-detection threshold: a pose is correct within `translation_m` and `rotation_rad`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrectThreshold {
    /// Translation threshold, metres; the error must be strictly below it.
    pub translation_m: f64,
    /// Rotation threshold, radians; the error must be strictly below it.
    pub rotation_rad: f64,
    /// Short label, e.g. "5mm5deg".
    pub label: &'static str,
}

impl CorrectThreshold {
    /// 5 mm / 5°, the paper's main metric.
    pub const MM5_DEG5: Self = Self {
        translation_m: 5e-3,
        rotation_rad: 5.0 * std::f64::consts::PI / 180.0,
        label: "5mm5deg",
    };
    /// 2 mm / 2°, the strict metric.
    pub const MM2_DEG2: Self = Self {
        translation_m: 2e-3,
        rotation_rad: 2.0 * std::f64::consts::PI / 180.0,
        label: "2mm2deg",
    };
    /// 30 mm / 30°: the gate on initial poses.
    pub const MM30_DEG30: Self = Self {
        translation_m: 30e-3,
        rotation_rad: 30.0 * std::f64::consts::PI / 180.0,
        label: "30mm30deg",
    };
}

/// The error of `t_c_o_est` against `t_c_o_gt` (object → any common frame), minimised over
/// the symmetry group. Symmetry elements are rotations about the object origin, so the
/// translation error does not depend on them.
///
/// For a finite group the rotation error is `min_S ∠(R_estᵀ R_gt S)`. With a continuous axis
/// `a`, the minimum over all `Rot(a, θ)` of `∠(M Rot(a, θ))` is the angle between `a` and `M a`
/// (every rotation taking `a` to `M a` turns by at least that angle, and one turns by exactly
/// that), so no sampling is needed.
pub fn pose_deviation(
    t_c_o_est: &Isometry3<f64>,
    t_c_o_gt: &Isometry3<f64>,
    symmetry: &Symmetry,
) -> PoseDeviation {
    let translation_m = (t_c_o_est.translation.vector - t_c_o_gt.translation.vector).norm();
    let r_est_inv_gt: UnitQuaternion<f64> = t_c_o_est.rotation.inverse() * t_c_o_gt.rotation;
    let rotation_rad = symmetry
        .discrete_rotations()
        .iter()
        .map(|s| {
            let m = r_est_inv_gt * s;
            match symmetry.continuous_axis() {
                Some(a) => a.angle(&(m * a)),
                None => m.angle(),
            }
        })
        .fold(f64::INFINITY, f64::min);
    PoseDeviation {
        translation_m,
        rotation_rad,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::symmetry::Axis;
    use nalgebra::{Translation3, Vector3};
    use std::f64::consts::PI;

    fn pose(axis: Vector3<f64>, angle: f64, t: [f64; 3]) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle),
        )
    }

    #[test]
    fn asymmetric_error_is_the_relative_rotation() {
        let gt = pose(Vector3::new(1.0, 2.0, 3.0), 0.7, [0.1, 0.0, 0.6]);
        let est = pose(Vector3::x(), 0.03, [0.0, 0.0, 0.0]) * gt;
        let est = Isometry3::from_parts(Translation3::new(0.1036, 0.0048, 0.6), est.rotation);
        let e = pose_deviation(&est, &gt, &Symmetry::none());
        assert!((e.rotation_rad - 0.03).abs() < 1e-12);
        assert!((e.translation_m - 0.006).abs() < 1e-12);
        assert!(!e.is_correct(&CorrectThreshold::MM5_DEG5)); // 6 mm is over 5 mm
        assert!(e.is_correct(&CorrectThreshold::MM30_DEG30));
    }

    #[test]
    fn discrete_symmetry_forgives_its_rotations_only() {
        let gt = pose(Vector3::new(0.3, -1.0, 0.2), 1.1, [0.0, 0.0, 0.5]);
        let sixfold = Symmetry::cyclic(Axis::Z, 6);
        // The truth turned by 60° about its own z plus a 1° wobble: 1° off under 6-fold symmetry.
        let est = gt
            * pose(Vector3::z(), PI / 3.0, [0.0; 3])
            * pose(Vector3::x(), 1f64.to_radians(), [0.0; 3]);
        let e = pose_deviation(&est, &gt, &sixfold);
        assert!(
            (e.rotation_deg() - 1.0).abs() < 1e-9,
            "{}",
            e.rotation_deg()
        );
        // Without the symmetry the same estimate is ~60° off.
        assert!(pose_deviation(&est, &gt, &Symmetry::none()).rotation_deg() > 59.0);
        // 30° about z is as far from 6-fold symmetric as it gets.
        let half = gt * pose(Vector3::z(), PI / 6.0, [0.0; 3]);
        assert!((pose_deviation(&half, &gt, &sixfold).rotation_deg() - 30.0).abs() < 1e-9);
    }

    #[test]
    fn continuous_symmetry_ignores_spin_about_the_axis() {
        let gt = pose(Vector3::new(1.0, 1.0, 0.0), 0.4, [0.0, 0.0, 0.5]);
        let spin = Symmetry::continuous(Axis::Z);
        let est = gt * pose(Vector3::z(), 2.3, [0.0; 3]);
        assert!(pose_deviation(&est, &gt, &spin).rotation_rad < 1e-9);
        // A 3° tilt of the axis stays 3° whatever the spin.
        let tilted = gt
            * pose(Vector3::z(), 1.2, [0.0; 3])
            * pose(Vector3::y(), 3f64.to_radians(), [0.0; 3]);
        assert!((pose_deviation(&tilted, &gt, &spin).rotation_deg() - 3.0).abs() < 1e-9);
    }
}
