//! Pinhole cameras and the rectified stereo rig of a structured-light camera.
//!
//! Image coordinates are continuous pixels: pixel `(u, v)` (column, row) covers
//! `[u, u+1) × [v, v+1)` and has its centre at `(u + 0.5, v + 0.5)`. The camera frame is
//! x right, y down, z forward (OpenCV/BOP).

use nalgebra::{Matrix3, Point2, Point3};

/// Why camera parameters were rejected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CameraError {
    /// The image width or height is zero or above 65535 px; pass a size within `1..=65535`.
    #[error("image size {width}×{height} px must be non-zero and at most 65535 on each side")]
    BadSize {
        /// The rejected width, px.
        width: u32,
        /// The rejected height, px.
        height: u32,
    },
    /// A focal length or the stereo baseline is zero, negative, NaN or infinite; it must be a
    /// finite positive number.
    #[error("{field} = {value} must be finite and positive")]
    NotPositive {
        /// Name of the offending parameter (`fx_px`, `fy_px` or `baseline_m`).
        field: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// A principal-point coordinate is NaN or infinite; it must be a finite number.
    #[error("{field} = {value} must be finite")]
    NotFinite {
        /// Name of the offending parameter (`cx_px` or `cy_px`).
        field: &'static str,
        /// The rejected value.
        value: f64,
    },
}

/// Pinhole intrinsics, in pixels.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PinholeIntrinsics {
    /// Image width, px.
    pub width_px: u32,
    /// Image height, px.
    pub height_px: u32,
    /// Focal length along x (columns), px.
    pub fx_px: f64,
    /// Focal length along y (rows), px.
    pub fy_px: f64,
    /// Principal point in continuous pixel coordinates (the image centre is `width/2`).
    pub cx_px: f64,
    /// Principal point's row coordinate, continuous px (the image centre is `height/2`).
    pub cy_px: f64,
}

impl PinholeIntrinsics {
    /// Validated intrinsics.
    pub fn new(
        width_px: u32,
        height_px: u32,
        fx_px: f64,
        fy_px: f64,
        cx_px: f64,
        cy_px: f64,
    ) -> Result<Self, CameraError> {
        if width_px == 0 || height_px == 0 || width_px > 65535 || height_px > 65535 {
            return Err(CameraError::BadSize {
                width: width_px,
                height: height_px,
            });
        }
        for (field, value) in [("fx_px", fx_px), ("fy_px", fy_px)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(CameraError::NotPositive { field, value });
            }
        }
        for (field, value) in [("cx_px", cx_px), ("cy_px", cy_px)] {
            if !value.is_finite() {
                return Err(CameraError::NotFinite { field, value });
            }
        }
        Ok(Self {
            width_px,
            height_px,
            fx_px,
            fy_px,
            cx_px,
            cy_px,
        })
    }

    /// The Ensenso N35 cameras that captured ROBI: 1280×1024, fx = fy = 1083.1 px.
    pub fn ensenso_n35() -> Self {
        Self {
            width_px: 1280,
            height_px: 1024,
            fx_px: 1083.1,
            fy_px: 1083.1,
            cx_px: 640.0,
            cy_px: 512.0,
        }
    }

    /// The same camera sampled at another resolution (same field of view).
    pub fn resized(&self, width_px: u32, height_px: u32) -> Result<Self, CameraError> {
        let sx = width_px as f64 / self.width_px as f64;
        let sy = height_px as f64 / self.height_px as f64;
        Self::new(
            width_px,
            height_px,
            self.fx_px * sx,
            self.fy_px * sy,
            self.cx_px * sx,
            self.cy_px * sy,
        )
    }

    /// The calibration matrix K.
    pub fn k(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.fx_px, 0.0, self.cx_px, 0.0, self.fy_px, self.cy_px, 0.0, 0.0, 1.0,
        )
    }

    /// Projects a camera-frame point (metres) to continuous pixel coordinates; `None` behind
    /// the camera.
    #[inline]
    pub fn project(&self, p_c: &Point3<f64>) -> Option<Point2<f64>> {
        (p_c.z > 0.0).then(|| {
            Point2::new(
                self.fx_px * p_c.x / p_c.z + self.cx_px,
                self.fy_px * p_c.y / p_c.z + self.cy_px,
            )
        })
    }

    /// The camera that sees only the pixels of `rect` (its pixel (0, 0) is `rect`'s top-left):
    /// the principal point shifts, the focal lengths stay. `None` when `rect` is empty or does
    /// not fit inside the image.
    pub fn cropped(&self, rect: &crate::image::PixelRect) -> Option<Self> {
        if rect.is_empty() || !rect.fits_in(self.width_px, self.height_px) {
            return None;
        }
        Some(Self {
            width_px: rect.width,
            height_px: rect.height,
            cx_px: self.cx_px - rect.u_min as f64,
            cy_px: self.cy_px - rect.v_min as f64,
            ..*self
        })
    }

    /// The camera-frame point at depth `z_m` (along the optical axis) seen at continuous pixel
    /// coordinates `uv`: `z K⁻¹ (u, v, 1)ᵀ` (eq 6).
    #[inline]
    pub fn unproject(&self, uv: &Point2<f64>, z_m: f64) -> Point3<f64> {
        Point3::new(
            (uv.x - self.cx_px) / self.fx_px * z_m,
            (uv.y - self.cy_px) / self.fy_px * z_m,
            z_m,
        )
    }

    /// The continuous coordinates of pixel `(u, v)`'s centre.
    #[inline]
    pub fn pixel_centre(u: u32, v: u32) -> Point2<f64> {
        Point2::new(u as f64 + 0.5, v as f64 + 0.5)
    }
}

/// A rectified stereo pair: both cameras share `intrinsics`; the right camera sits
/// `baseline_m` along +x of the left one, so disparity `d = u_L − u_R` and `z = f·b/d`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StereoRig {
    /// Intrinsics shared by the left and right cameras.
    pub intrinsics: PinholeIntrinsics,
    /// Distance from the left to the right camera centre along the left camera's +x, metres.
    pub baseline_m: f64,
}

impl StereoRig {
    /// A validated rig; fails with [`CameraError::NotPositive`] unless `baseline_m` is finite
    /// and positive.
    pub fn new(intrinsics: PinholeIntrinsics, baseline_m: f64) -> Result<Self, CameraError> {
        if !(baseline_m.is_finite() && baseline_m > 0.0) {
            return Err(CameraError::NotPositive {
                field: "baseline_m",
                value: baseline_m,
            });
        }
        Ok(Self {
            intrinsics,
            baseline_m,
        })
    }

    /// The Ensenso N35 of ROBI: baseline 101.18 mm.
    pub fn ensenso_n35() -> Self {
        Self {
            intrinsics: PinholeIntrinsics::ensenso_n35(),
            baseline_m: 0.10118,
        }
    }

    /// Depth (m) of a disparity (px): `z = f·b/d`.
    #[inline]
    pub fn depth_from_disparity(&self, disparity_px: f64) -> f64 {
        self.intrinsics.fx_px * self.baseline_m / disparity_px
    }

    /// Disparity (px) of a depth (m).
    #[inline]
    pub fn disparity_from_depth(&self, z_m: f64) -> f64 {
        self.intrinsics.fx_px * self.baseline_m / z_m
    }

    /// `F = ∂z/∂d = −f·b/d²`, m/px (eq 4).
    #[inline]
    pub fn depth_per_disparity(&self, disparity_px: f64) -> f64 {
        -self.intrinsics.fx_px * self.baseline_m / (disparity_px * disparity_px)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cropped_camera_sees_the_same_rays() {
        use crate::image::{Image, PixelRect};
        let k = PinholeIntrinsics::ensenso_n35();
        let rect = PixelRect::new(100, 40, 300, 200);
        let c = k.cropped(&rect).unwrap();
        let p = Point3::new(0.01, -0.02, 0.5);
        let (full, crop) = (k.project(&p).unwrap(), c.project(&p).unwrap());
        assert!((full.x - crop.x - 100.0).abs() < 1e-9 && (full.y - crop.y - 40.0).abs() < 1e-9);
        assert!(
            k.cropped(&PixelRect::new(k.width_px - 1, 0, 2, 1))
                .is_none()
        );
        let image = Image::new(4, 3, (0..12).collect::<Vec<u32>>()).unwrap();
        let sub = image.cropped(&PixelRect::new(1, 1, 2, 2)).unwrap();
        assert_eq!(sub.data(), &[5, 6, 9, 10]);
        assert!(image.cropped(&PixelRect::new(3, 0, 2, 1)).is_none());
    }

    #[test]
    fn project_inverts_unproject() {
        let k = PinholeIntrinsics::ensenso_n35();
        let p = Point3::new(0.031, -0.017, 0.62);
        let uv = k.project(&p).unwrap();
        assert!((k.unproject(&uv, p.z) - p).norm() < 1e-12);
        assert!(k.project(&Point3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn bad_intrinsics_are_rejected() {
        assert!(PinholeIntrinsics::new(0, 10, 1.0, 1.0, 0.0, 0.0).is_err());
        assert!(PinholeIntrinsics::new(10, 10, f64::NAN, 1.0, 0.0, 0.0).is_err());
        assert!(PinholeIntrinsics::new(10, 10, 1.0, -1.0, 0.0, 0.0).is_err());
        assert!(PinholeIntrinsics::new(10, 10, 1.0, 1.0, f64::INFINITY, 0.0).is_err());
        assert!(StereoRig::new(PinholeIntrinsics::ensenso_n35(), 0.0).is_err());
    }

    #[test]
    fn disparity_jacobian_matches_finite_difference() {
        let rig = StereoRig::ensenso_n35();
        let d = rig.disparity_from_depth(0.6);
        // At 0.6 m the N35 sees 182.6 px of disparity.
        assert!((d - 1083.1 * 0.10118 / 0.6).abs() < 1e-9);
        let h = 1e-4;
        let numeric =
            (rig.depth_from_disparity(d + h) - rig.depth_from_disparity(d - h)) / (2.0 * h);
        assert!((numeric - rig.depth_per_disparity(d)).abs() < 1e-9);
    }
}
