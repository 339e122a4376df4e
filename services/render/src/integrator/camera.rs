//! A pinhole camera placed in the world, and its rays.

use glam::Vec3A;
use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::Image;
use nalgebra::{Isometry3, Vector3};

/// A camera placed in the world.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    /// Pinhole intrinsics (focal lengths and principal point in px, image size).
    pub intrinsics: PinholeIntrinsics,
    /// Camera → world.
    pub t_w_c: Isometry3<f64>,
}

impl Camera {
    /// R_w_c and the camera centre in the world, in the renderer's f32.
    pub(super) fn rotation_and_origin(&self) -> (nalgebra::Matrix3<f32>, Vec3A) {
        let rotation = self
            .t_w_c
            .rotation
            .to_rotation_matrix()
            .matrix()
            .cast::<f32>();
        let origin = self.t_w_c.translation.vector.cast::<f32>();
        (rotation, Vec3A::new(origin.x, origin.y, origin.z))
    }
}

/// A blank image of the camera's size, every pixel `value`.
///
/// # Panics
/// When `k` has a zero side, which no constructor of [`PinholeIntrinsics`] (`new`, `resized`,
/// `cropped`) nor Glint's rig and camera readers let through: only a hand-built value can.
pub(super) fn camera_image<T: Copy>(k: &PinholeIntrinsics, value: T) -> Image<T> {
    // A zero side breaks the invariant every `PinholeIntrinsics` constructor checks; a render
    // has no image to return for it (`par_chunks_mut(0)` would panic too).
    #[allow(clippy::expect_used)]
    Image::filled(k.width_px, k.height_px, value).expect("intrinsics have non-zero sides")
}

/// The camera ray through continuous pixel coordinates (u, v) (pixel centres at +0.5): its unit
/// direction in the camera frame and in the world (`rotation` = R_w_c).
#[inline]
pub(super) fn camera_ray(
    k: &PinholeIntrinsics,
    rotation: &nalgebra::Matrix3<f32>,
    u: f32,
    v: f32,
) -> (Vector3<f32>, Vec3A) {
    let x = (u - k.cx_px as f32) / k.fx_px as f32;
    let y = (v - k.cy_px as f32) / k.fy_px as f32;
    let d_c = Vector3::new(x, y, 1.0).normalize();
    let d_w = rotation * d_c;
    (d_c, Vec3A::new(d_w.x, d_w.y, d_w.z))
}

/// The ray of sample `sample` of pixel (u, v): the first (`sample` 0) through the pixel's
/// centre, so that depth and label come from it, the rest jittered uniformly over the pixel by
/// `rng`. As [`camera_ray`]: the direction in the camera frame and in the world.
#[inline]
pub(super) fn pixel_sample_ray(
    k: &PinholeIntrinsics,
    rotation: &nalgebra::Matrix3<f32>,
    (u, v): (u32, u32),
    sample: u32,
    rng: &mut impl rand::Rng,
) -> (Vector3<f32>, Vec3A) {
    let (ju, jv) = if sample == 0 {
        (0.5, 0.5)
    } else {
        (rng.random::<f32>(), rng.random::<f32>())
    };
    camera_ray(k, rotation, u as f32 + ju, v as f32 + jv)
}
