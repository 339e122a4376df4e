//! Aligning a detector's pose with the depth image along the viewing ray, before refinement.
//!
//! A template detector places a part well across the image and worst in depth (Glint's fit
//! to the paper's detector: σ 0.53 mm across, 16.9 mm in depth), while the depth image measures
//! exactly that axis. A one-dimensional search along the mean viewing direction of the points,
//! counting the points that lie on the model's surface at each offset, moves the hypothesis
//! into the refiner's basin without touching the axes the detector got right.

use glint_geometry::sdf::SdfGrid;
use nalgebra::{Isometry3, Translation3, Vector3};

use crate::points::DepthPoint;
use crate::refine::{depth_gain, faces_away};

/// How [`align_depth`] searches. Lengths in metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthAlignmentConfig {
    /// Offsets `−range_m ..= range_m` along the viewing direction are tried.
    pub range_m: f64,
    /// Spacing of the offsets tried.
    pub step_m: f64,
    /// A point scores `1 − |SDF| / inlier_m` at an offset where `|SDF| < inlier_m` (a
    /// triangular kernel: a plateau of offsets that all keep the points within reach still has
    /// one peak, where they lie on the surface).
    pub inlier_m: f64,
    /// At most this many points (evenly strided) are scored.
    pub max_points: usize,
    /// Points on a model face turned away from their camera score nothing, as in the refiner
    /// ([`crate::refine::SdfRefineConfig::back_facing_cos`]): a thin sheet's back face would
    /// otherwise score as well as its front.
    pub back_facing_cos: f64,
}

impl Default for DepthAlignmentConfig {
    /// ±30 mm (the acceptance test on initial poses) in 0.5 mm steps, inliers within 2 mm,
    /// 2000 points, the refiner's back-face test. The step is a third of the thinnest wall (the
    /// Zigzag's 1.5 mm sheet): from a 1 mm grid the start could land mid-sheet, where the SDF
    /// has a ridge and the refiner feels no pull to either face.
    fn default() -> Self {
        Self {
            range_m: 30e-3,
            step_m: 0.5e-3,
            inlier_m: 2e-3,
            max_points: 2000,
            back_facing_cos: crate::refine::SdfRefineConfig::default().back_facing_cos,
        }
    }
}

/// The outcome of [`align_depth`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthAlignment {
    /// The aligned pose, world → object.
    pub t_o_w: Isometry3<f64>,
    /// The offset applied along `direction_w`, metres (positive: away from the camera).
    pub offset_m: f64,
    /// The unit viewing direction searched along, world frame.
    pub direction_w: Vector3<f64>,
    /// Points scored at the chosen offset within the inlier distance.
    pub inliers: usize,
    /// Points scored.
    pub scored: usize,
}

/// Moves `t_o_w` (world → object) along the points' mean viewing direction (the mean of
/// their unit `dp_dz_w`) to the offset of highest score: points within
/// [`DepthAlignmentConfig::inlier_m`] of the model's surface, each weighted by how close it
/// lies; ties go to the smallest offset, so a hypothesis already in place stays. `None` without
/// points, without a usable direction, or with a step, range or inlier distance that is not a
/// finite positive length (the range may be 0).
pub fn align_depth(
    sdf: &SdfGrid,
    points: &[DepthPoint],
    t_o_w: &Isometry3<f64>,
    config: &DepthAlignmentConfig,
) -> Option<DepthAlignment> {
    let direction_w = points
        .iter()
        .filter_map(|p| p.dp_dz_w.try_normalize(1e-12))
        .sum::<Vector3<f64>>();
    align_depth_along(sdf, points, t_o_w, &direction_w, config)
}

/// [`align_depth`] along a given world direction `direction_w` (any length but zero; unit
/// in the result) instead of the points' own: the viewing ray of the camera a detector looked
/// from, when the points come from another view. `None` as [`align_depth`], or for a
/// direction of zero length.
pub fn align_depth_along(
    sdf: &SdfGrid,
    points: &[DepthPoint],
    t_o_w: &Isometry3<f64>,
    direction_w: &Vector3<f64>,
    config: &DepthAlignmentConfig,
) -> Option<DepthAlignment> {
    let direction_w = direction_w.try_normalize(1e-12)?;
    let usable = config.step_m.is_finite()
        && config.step_m > 0.0
        && config.range_m.is_finite()
        && config.range_m >= 0.0
        && config.inlier_m > 0.0;
    let stride = points.len().div_ceil(config.max_points.max(1)).max(1);
    let scored: Vec<&DepthPoint> = points.iter().step_by(stride).collect();
    let rot_o_w = t_o_w.rotation.to_rotation_matrix().into_inner();
    if scored.is_empty() || !usable {
        return None;
    }
    let steps = (config.range_m / config.step_m).floor() as i64;
    let at = |offset_m: f64| {
        // Moving the object by offset·d in the world: t_o_w · T(−offset·d).
        t_o_w * Translation3::from(-offset_m * direction_w)
    };
    // (score, inliers) at an offset.
    let score = |offset_m: f64| {
        let pose = at(offset_m);
        scored.iter().fold((0.0, 0usize), |(sum, n), p| {
            let s = sdf.sample(&(pose * p.p_w));
            let d = s.distance_m.abs();
            if s.inside_grid
                && d <= config.inlier_m
                && !faces_away(
                    depth_gain(&s.gradient, p, &rot_o_w),
                    p,
                    config.back_facing_cos,
                )
            {
                (sum + 1.0 - d / config.inlier_m, n + 1)
            } else {
                (sum, n)
            }
        })
    };
    // Offsets in order of |offset| (0, +1, −1, +2, …): a strict improvement is needed to move
    // further out, so ties keep the smaller offset.
    let (mut best_offset, mut best) = (0.0, score(0.0));
    for k in 1..=steps {
        for offset in [k as f64 * config.step_m, -(k as f64) * config.step_m] {
            let s = score(offset);
            if s.0 > best.0 {
                (best_offset, best) = (offset, s);
            }
        }
    }
    Some(DepthAlignment {
        t_o_w: at(best_offset),
        offset_m: best_offset,
        direction_w,
        inliers: best.1,
        scored: scored.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_geometry::parts::Part;
    use glint_geometry::sdf::SdfConfig;
    use nalgebra::{Point3, UnitQuaternion};

    /// The centroids of the part's triangles that face `eye` (on its surface), placed at
    /// `t_w_o`, each with the unit ray from `eye` as its depth direction.
    fn surface_points(part: Part, t_w_o: &Isometry3<f64>, eye: &Point3<f64>) -> Vec<DepthPoint> {
        let mesh = part.mesh();
        mesh.triangles
            .iter()
            .filter_map(|t| {
                let [a, b, c] = t.map(|i| mesh.vertices[i as usize].cast::<f64>());
                let centre = Point3::from((a.coords + b.coords + c.coords) / 3.0);
                let p_w = t_w_o * centre;
                let ray = (p_w - eye).normalize();
                let normal_w = t_w_o.rotation * (b - a).cross(&(c - a));
                (normal_w.dot(&ray) < 0.0).then_some(DepthPoint {
                    p_w,
                    dp_dz_w: ray,
                    sigma_z_m: 1e-4,
                })
            })
            .collect()
    }

    /// The Gear's SDF on a 1 mm grid.
    fn gear_sdf() -> SdfGrid {
        let config = SdfConfig {
            voxel_size_m: 1e-3,
            padding_m: 30e-3,
        };
        SdfGrid::build(&Part::Gear.mesh(), &config).unwrap()
    }

    #[test]
    fn a_pose_off_in_depth_is_moved_back_onto_the_points() {
        let part = Part::Gear;
        let sdf = gear_sdf();
        let t_w_o = Isometry3::from_parts(
            Translation3::new(0.01, -0.02, 0.0),
            UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0),
        );
        let eye = Point3::new(0.0, 0.0, 0.6);
        let points = surface_points(part, &t_w_o, &eye);
        let config = DepthAlignmentConfig::default();
        // The truth stays where it is: ties and maxima at offset 0.
        let kept = align_depth(&sdf, &points, &t_w_o.inverse(), &config).unwrap();
        assert_eq!(kept.offset_m, 0.0, "{kept:?}");
        assert_eq!(kept.inliers, kept.scored);
        // 17 mm too far along the view and 0.5 mm across: moved back to within a step.
        let view = kept.direction_w;
        let across = view.cross(&Vector3::x()).normalize();
        for shift_mm in [17.0, -12.0, 25.0] {
            let t_w_o_off = Translation3::from(view * shift_mm * 1e-3 + across * 0.5e-3) * t_w_o;
            let aligned = align_depth(&sdf, &points, &t_w_o_off.inverse(), &config).unwrap();
            assert!(
                (aligned.offset_m * 1e3 + shift_mm).abs() <= 1.0,
                "{shift_mm} mm: {aligned:?}"
            );
            // What is left is the lateral error and under a step along the view.
            let left =
                (aligned.t_o_w.inverse().translation.vector - t_w_o.translation.vector).norm();
            assert!(left < 0.5e-3 + 1e-3, "{shift_mm} mm: {left} m left");
        }
    }

    #[test]
    fn along_another_cameras_ray_the_detectors_depth_error_is_removed() {
        // Points seen from a camera 40° off the detector's axis; the detector erred 15 mm
        // along its own ray. Searching along the points' mean ray moves the pose along the
        // wrong axis; along the detector's ray it lands within a step of the truth.
        let part = Part::Gear;
        let sdf = gear_sdf();
        let t_w_o = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.02),
            UnitQuaternion::from_euler_angles(0.2, 0.1, 0.4),
        );
        let angle = 40f64.to_radians();
        let eye = Point3::new(0.6 * angle.sin(), 0.0, 0.6 * angle.cos());
        let points = surface_points(part, &t_w_o, &eye);
        let detector_ray = Vector3::new(0.0, 0.0, -1.0);
        let off = Translation3::from(detector_ray * 15e-3) * t_w_o;
        let config = DepthAlignmentConfig::default();
        let aligned = align_depth_along(
            &sdf,
            &points,
            &off.inverse(),
            &(detector_ray * 3.0),
            &config,
        )
        .unwrap();
        assert!((aligned.direction_w - detector_ray).norm() < 1e-12);
        let left = (aligned.t_o_w.inverse().translation.vector - t_w_o.translation.vector).norm();
        assert!(left <= config.step_m + 1e-9, "{left} m left: {aligned:?}");
        assert!(
            align_depth_along(&sdf, &points, &off.inverse(), &Vector3::zeros(), &config).is_none()
        );
    }

    #[test]
    fn no_points_or_no_direction_is_none() {
        let sdf = SdfGrid::build(&Part::Zigzag.mesh(), &SdfConfig::default()).unwrap();
        let config = DepthAlignmentConfig::default();
        assert!(align_depth(&sdf, &[], &Isometry3::identity(), &config).is_none());
        let still = DepthPoint {
            p_w: Point3::origin(),
            dp_dz_w: Vector3::zeros(),
            sigma_z_m: 1e-4,
        };
        assert!(align_depth(&sdf, &[still], &Isometry3::identity(), &config).is_none());
    }
}
