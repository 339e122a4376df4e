//! Depth pixels of an object → world-frame points with their depth uncertainty (eq 6–7).

use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::{DepthMap, Image, SummedAreaTable};
use nalgebra::{Isometry3, Point3, Vector3};

/// One depth measurement of the object, in the world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthPoint {
    /// The back-projected point `T_w_c · z K⁻¹ (u, v, 1)ᵀ`, metres (eq 6–7).
    pub p_w: Point3<f64>,
    /// `∂p_w/∂z = R_w_c K⁻¹ (u, v, 1)ᵀ`: how the point moves with its measured depth, the
    /// factor that carries σ_z into the SDF residual (eq 11's G).
    pub dp_dz_w: Vector3<f64>,
    /// σ_z of the measured depth, metres (eq 1–5), finite and positive.
    pub sigma_z_m: f64,
}

/// Where each point's σ_z comes from.
#[derive(Clone, Copy, Debug)]
pub enum DepthSigma<'a> {
    /// Per pixel, e.g. from [`crate::depth_sigma::depth_sigma`]; pixels with a non-finite or
    /// non-positive σ_z carry no information and are skipped.
    PerPixel(&'a Image<f32>),
    /// The same σ_z (metres) for every pixel: an unweighted refinement.
    Constant(f64),
}

/// Counts of what [`object_points`] kept and dropped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PointCounts {
    /// Pixels of the mask.
    pub masked: usize,
    /// Of those, without depth.
    pub no_depth: usize,
    /// With depth but no usable σ_z.
    pub no_sigma: usize,
    /// Returned.
    pub kept: usize,
}

/// The object's depth points from one view: every pixel `(u, v)` with `mask(u, v)` and a valid
/// depth in `depth` (the camera's, with `intrinsics`), back-projected through the pixel centre
/// and moved to the world by the camera pose `t_w_c` (eq 6–7). Appends to `out`.
pub fn object_points(
    depth: &DepthMap,
    mask: impl Fn(u32, u32) -> bool,
    sigma: DepthSigma<'_>,
    intrinsics: &PinholeIntrinsics,
    t_w_c: &Isometry3<f64>,
    out: &mut Vec<DepthPoint>,
) -> PointCounts {
    let mut counts = PointCounts::default();
    for v in 0..depth.depth_m.height() {
        for u in 0..depth.depth_m.width() {
            if !mask(u, v) {
                continue;
            }
            counts.masked += 1;
            let Some(z) = depth.get(u, v) else {
                counts.no_depth += 1;
                continue;
            };
            let sigma_z_m = match sigma {
                DepthSigma::PerPixel(image) => image.get(u, v).map_or(f64::NAN, f64::from),
                DepthSigma::Constant(s) => s,
            };
            if !(sigma_z_m.is_finite() && sigma_z_m > 0.0) {
                counts.no_sigma += 1;
                continue;
            }
            let ray_c = intrinsics.unproject(&PinholeIntrinsics::pixel_centre(u, v), 1.0);
            out.push(DepthPoint {
                p_w: t_w_c * (ray_c * z as f64),
                dp_dz_w: t_w_c.rotation * ray_c.coords,
                sigma_z_m,
            });
            counts.kept += 1;
        }
    }
    counts
}

/// The pixels of a `width × height` mask whose whole `(2r + 1)²` window lies inside it, `r =
/// radius_px`. A stereo matcher's window that straddles a silhouette mixes the object with
/// whatever is behind it and may report the background's depth for an object pixel ("edge
/// fattening"); the interior's depth comes from the object alone.
///
/// # Panics
/// When `width` or `height` is 0: the size is meant to be an image's, which never is.
pub fn interior_mask(
    width: u32,
    height: u32,
    radius_px: u32,
    mask: impl Fn(u32, u32) -> bool,
) -> Image<bool> {
    let sat = SummedAreaTable::from_fn(width as usize, height as usize, |u, v| {
        f64::from(u8::from(mask(u as u32, v as u32)))
    });
    let r = radius_px as i64;
    let full = ((2 * r + 1) * (2 * r + 1)) as f64;
    let data = (0..height as i64)
        .flat_map(|v| (0..width as i64).map(move |u| (u, v)))
        .map(|(u, v)| {
            u - r >= 0
                && v - r >= 0
                && u + r < width as i64
                && v + r < height as i64
                && sat.sum(
                    (u - r) as usize,
                    (v - r) as usize,
                    (u + r + 1) as usize,
                    (v + r + 1) as usize,
                ) == full
        })
        .collect();
    // `data` has width × height samples by construction, so only a zero side (no image's
    // size, see the doc) can fail; the signature has no error to report it with.
    #[allow(clippy::expect_used)]
    Image::new(width, height, data).expect("interior_mask needs an image's non-zero size")
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn interior_keeps_pixels_whose_window_is_inside() {
        // A 7×5 block at (2, 1) in a 12×8 image; radius 1 leaves its 5×3 interior.
        let inside = |u: u32, v: u32| (2..9).contains(&u) && (1..6).contains(&v);
        let interior = interior_mask(12, 8, 1, inside);
        let kept: Vec<(u32, u32)> = (0..8)
            .flat_map(|v| (0..12).map(move |u| (u, v)))
            .filter(|&(u, v)| interior.get(u, v).unwrap())
            .collect();
        assert_eq!(kept.len(), 15);
        assert!(
            kept.iter()
                .all(|&(u, v)| (3..8).contains(&u) && (2..5).contains(&v))
        );
        // Radius 0 is the mask itself.
        let same = interior_mask(12, 8, 0, inside);
        assert_eq!(same.data().iter().filter(|&&b| b).count(), 35);
    }

    #[test]
    fn points_are_back_projected_into_the_world() {
        let k = PinholeIntrinsics::ensenso_n35().resized(64, 48).unwrap();
        let t_w_c = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.5),
            UnitQuaternion::from_euler_angles(3.0, 0.1, -0.4),
        );
        let mut depth = Image::filled(64, 48, f32::NAN).unwrap();
        depth.set(10, 20, 0.6);
        depth.set(11, 20, 0.7);
        depth.set(30, 5, 0.8);
        let mut sigma = Image::filled(64, 48, 1e-4f32).unwrap();
        sigma.set(11, 20, f32::INFINITY);
        let mut points = Vec::new();
        let counts = object_points(
            &DepthMap::new(depth),
            |u, v| v == 20 && u < 40,
            DepthSigma::PerPixel(&sigma),
            &k,
            &t_w_c,
            &mut points,
        );
        assert_eq!(
            counts,
            PointCounts {
                masked: 40,
                no_depth: 38,
                no_sigma: 1,
                kept: 1
            }
        );
        let p = &points[0];
        // Back in the camera, the point projects to the pixel centre at depth 0.6.
        let p_c = t_w_c.inverse() * p.p_w;
        assert!((p_c.z - 0.6).abs() < 1e-6);
        let uv = k.project(&p_c).unwrap();
        assert!((uv.x - 10.5).abs() < 1e-6 && (uv.y - 20.5).abs() < 1e-6);
        // ∂p/∂z is the ray through the pixel with unit z in the camera.
        let dz = t_w_c.inverse().rotation * p.dp_dz_w;
        assert!((dz.z - 1.0).abs() < 1e-12);
        assert!((p_c.coords - dz * 0.6).norm() < 1e-6);
        assert_eq!(p.sigma_z_m, 1e-4f32 as f64);
    }
}
