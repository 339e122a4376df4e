//! Candidate viewpoints: a spherical cap of rig poses above the bin, all looking at its centre,
//! like ROBI's robot-arm views.

use nalgebra::{Isometry3, Point3, Vector3};

/// `count` poses of the left camera (`t_w_c`, camera → world) spread evenly (Fibonacci
/// spiral) over the cap of polar angle ≤ `max_polar_deg` around world +z, at `distance_m` from
/// `target`. The rig's midpoint (the projector) looks at `target`; `baseline_m` shifts the
/// left camera half a baseline to the left of it.
pub fn spherical_cap(
    count: usize,
    distance_m: f64,
    max_polar_deg: f64,
    target: Point3<f64>,
    baseline_m: f64,
) -> Vec<Isometry3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let cos_max = max_polar_deg.to_radians().cos();
    (0..count)
        .map(|i| {
            // Equal-area rings: cos θ uniform in [cos_max, 1].
            let cos_polar = 1.0 - (1.0 - cos_max) * (i as f64 + 0.5) / count as f64;
            let sin_polar = (1.0 - cos_polar * cos_polar).max(0.0).sqrt();
            let azimuth = golden * i as f64;
            let eye = target
                + Vector3::new(
                    sin_polar * azimuth.cos(),
                    sin_polar * azimuth.sin(),
                    cos_polar,
                ) * distance_m;
            // Optical axis towards the target; image y along world +y (never parallel to the axis
            // inside a cap narrower than 90°).
            let hint = Vector3::y();
            let t_w_mid = Isometry3::face_towards(&eye, &target, &hint);
            t_w_mid * Isometry3::translation(-baseline_m / 2.0, 0.0, 0.0)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cap_views_look_at_the_target_from_the_right_distance() {
        let target = Point3::new(0.0, 0.0, 0.02);
        let views = spherical_cap(60, 0.6, 35.0, target, 0.1);
        assert_eq!(views.len(), 60);
        for t_w_c in &views {
            let mid = t_w_c * Point3::new(0.05, 0.0, 0.0);
            assert!(((mid - target).norm() - 0.6).abs() < 1e-9);
            // The optical axis through the rig's midpoint hits the target.
            let target_c = t_w_c.inverse_transform_point(&target);
            assert!(
                (target_c.x - 0.05).abs() < 1e-9 && target_c.y.abs() < 1e-9 && target_c.z > 0.0
            );
            let polar = (mid - target).normalize().z.acos().to_degrees();
            assert!(polar <= 35.0 + 1e-9);
        }
    }
}
