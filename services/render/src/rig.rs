//! The structured-light camera as hardware: a rectified stereo pair with the projector between
//! the two cameras.
//!
//! The rig frame is the left camera's (x right, y down, z forward). The right camera sits at
//! `+baseline` along x; the projector halfway, looking the same way.

use glint_geometry::camera::{CameraError, PinholeIntrinsics, StereoRig};
use nalgebra::Isometry3;

use crate::integrator::Camera;
use crate::projector::{Pattern, Projector};

/// An SLI stereo camera with its projector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SliRig {
    /// The two cameras: shared intrinsics and the baseline, metres, of the right camera along
    /// +x of the left.
    pub stereo: StereoRig,
    /// Projector → left camera.
    pub t_left_projector: Isometry3<f64>,
    /// The projector's optics; its image is where patterns live.
    pub projector_intrinsics: PinholeIntrinsics,
    /// Radiant intensity of a fully lit pattern pixel, W/sr.
    pub projector_intensity_w_per_sr: f32,
}

impl SliRig {
    /// The Ensenso N35 of ROBI: 1280×1024, fx = fy = 1083.1 px, baseline 101.18 mm; a projector
    /// halfway between the cameras with a 10 % wider field of view (so it lights everything
    /// both cameras see at working distance) and half their resolution (dots of ~2 px).
    pub fn ensenso_n35() -> Self {
        let stereo = StereoRig::ensenso_n35();
        let k = stereo.intrinsics;
        let projector_intrinsics = PinholeIntrinsics {
            width_px: k.width_px / 2,
            height_px: k.height_px / 2,
            fx_px: k.fx_px / 2.0 / 1.1,
            fy_px: k.fy_px / 2.0 / 1.1,
            cx_px: k.cx_px / 2.0,
            cy_px: k.cy_px / 2.0,
        };
        Self {
            stereo,
            t_left_projector: Isometry3::translation(stereo.baseline_m / 2.0, 0.0, 0.0),
            projector_intrinsics,
            projector_intensity_w_per_sr: 1.0,
        }
    }

    /// The same rig with cameras (and projector) sampled at another resolution, same fields of view.
    pub fn resized(&self, width_px: u32, height_px: u32) -> Result<Self, CameraError> {
        let sx = width_px as f64 / self.stereo.intrinsics.width_px as f64;
        let sy = height_px as f64 / self.stereo.intrinsics.height_px as f64;
        let p = &self.projector_intrinsics;
        let projector_w = ((p.width_px as f64 * sx).round() as u32).max(1);
        let projector_h = ((p.height_px as f64 * sy).round() as u32).max(1);
        Ok(Self {
            stereo: StereoRig::new(
                self.stereo.intrinsics.resized(width_px, height_px)?,
                self.stereo.baseline_m,
            )?,
            projector_intrinsics: p.resized(projector_w, projector_h)?,
            ..*self
        })
    }

    /// Left and right cameras for a rig pose `t_w_left` (left camera → world).
    pub fn cameras(&self, t_w_left: &Isometry3<f64>) -> [Camera; 2] {
        let t_left_right = Isometry3::translation(self.stereo.baseline_m, 0.0, 0.0);
        [
            Camera {
                intrinsics: self.stereo.intrinsics,
                t_w_c: *t_w_left,
            },
            Camera {
                intrinsics: self.stereo.intrinsics,
                t_w_c: t_w_left * t_left_right,
            },
        ]
    }

    /// The projector showing `pattern`, for a rig pose `t_w_left`.
    pub fn projector(&self, t_w_left: &Isometry3<f64>, pattern: Pattern) -> Projector {
        Projector {
            t_w_p: t_w_left * self.t_left_projector,
            intrinsics: self.projector_intrinsics,
            pattern,
            intensity_w_per_sr: self.projector_intensity_w_per_sr,
        }
    }
}
