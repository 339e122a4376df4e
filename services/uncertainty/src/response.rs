//! The camera as calibration measured it: the response g (`glint calibrate response`) and the
//! radiometric scale between the renderer's radiance and the response's relative exposure
//! (`glint calibrate bsdf`'s per-view scale), at the exposure time of pattern captures.

use glint_calibration::response::ResponseTable;

/// Radiance → intensity as the calibrated camera reads it: `I = g(E · s · Δt)` (eq 14), with
/// `s` the radiometric scale (relative exposure per second per W·sr⁻¹·m⁻²) and `Δt` seconds.
#[derive(Clone, Debug)]
pub struct CalibratedCamera {
    /// The response g: intensity in [0, 1] of full scale against log relative exposure
    /// (`glint calibrate response`).
    pub response: ResponseTable,
    /// Relative radiance-map units per W·sr⁻¹·m⁻², from the BSDF fit's reference surface.
    pub radiometric_scale: f64,
    /// Exposure time of the camera's pattern captures, seconds.
    pub exposure_s: f64,
}

/// Why a calibration cannot be used.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CalibrationError {
    /// The radiometric scale is zero, negative or not finite: take it from a successful BSDF
    /// fit (`glint calibrate bsdf`).
    #[error("radiometric_scale is {0}; it must be finite and positive")]
    Scale(f64),
    /// The exposure time is zero, negative or not finite: give the pattern captures' exposure
    /// in seconds.
    #[error("exposure_s is {0}; it must be finite and positive (seconds)")]
    Exposure(f64),
}

impl CalibratedCamera {
    /// The camera of `response` at `radiometric_scale` and `exposure_s` seconds, both checked
    /// finite and positive.
    pub fn new(
        response: ResponseTable,
        radiometric_scale: f64,
        exposure_s: f64,
    ) -> Result<Self, CalibrationError> {
        if !(radiometric_scale.is_finite() && radiometric_scale > 0.0) {
            return Err(CalibrationError::Scale(radiometric_scale));
        }
        if !(exposure_s.is_finite() && exposure_s > 0.0) {
            return Err(CalibrationError::Exposure(exposure_s));
        }
        Ok(Self {
            response,
            radiometric_scale,
            exposure_s,
        })
    }

    /// The intensity, in [0, 1] of full scale, of a pixel receiving `radiance` W·sr⁻¹·m⁻².
    #[inline]
    pub fn intensity(&self, radiance: f32) -> f32 {
        if radiance.is_nan() || radiance <= 0.0 {
            return 0.0;
        }
        let ln_x = (radiance as f64 * self.radiometric_scale * self.exposure_s).ln();
        self.response.intensity(ln_x) as f32
    }
}
