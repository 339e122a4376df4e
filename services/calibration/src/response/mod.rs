//! The camera response g of eq 12–13 (I = g(E·Δt)) recovered from an exposure stack, its
//! inverse, and the radiance map E = g⁻¹(I)/Δt.

mod debevec;
mod plot;
mod stack;

pub use debevec::{DebevecConfig, MAX_LEVELS, SamplePixel, SolveInfo, calibrate, select_samples};
pub use plot::response_png;
pub use stack::{ExposureStack, max_dn};

use std::path::{Path, PathBuf};

use glint_geometry::image::Image;
use glint_render::sensor::ResponseCurve;

use debevec::Levels;

/// Why a response calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum ResponseError {
    /// The stack, a setting or a table does not meet its stated requirements; the message
    /// names the field and the requirement.
    #[error("{0}")]
    Input(String),
    /// A response file could not be read, parsed, checked or written.
    #[error("{}: {message}", path.display())]
    File {
        /// The file, or where the text came from.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// Fewer than two sample pixels are usable: re-capture with exposure times that read the
    /// scene well (not all saturated, not all black) in at least two exposures.
    #[error(
        "only {found} pixel(s) are well exposed (0 < DN < max) in at least two exposures: \
         the stack is all saturated or all dark; change the exposure times"
    )]
    NoUsablePixels {
        /// The usable sample pixels found.
        found: usize,
    },
    /// The SVD least-squares solve failed or gave a non-finite response.
    #[error("least-squares solve failed: {0}")]
    Solve(String),
}

/// Format tag of the response JSON.
pub const RESPONSE_FORMAT: &str = "glint-response/1";

/// A recovered response: g⁻¹ per DN level (in ln units) and g sampled over ln exposure.
///
/// Exposure X = E·Δt is in *relative* units: Debevec–Malik fixes the scale only up to a
/// factor, here X = 1 at the middle level (g⁻¹(z_mid) = 1). Radiances from
/// [`ResponseTable::radiance_map`] are in those units per second.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResponseTable {
    /// The file format, [`RESPONSE_FORMAT`].
    pub format: String,
    /// Bits per pixel of the camera's readout, 1 … 16.
    pub bit_depth: u8,
    /// Largest DN, 2^`bit_depth` − 1 (saturation).
    pub max_dn: u16,
    /// g⁻¹: per level, the level's centre DN and ln X.
    pub inverse: InverseTable,
    /// g: intensity (DN / max DN, in [0, 1]) over a uniform grid of ln X spanning the inner
    /// levels; from the inverse made monotone (running maximum).
    pub forward: ForwardTable,
    /// How g was solved (settings, stack, residual).
    pub solve: SolveInfo,
}

/// g⁻¹ (eq 13) tabulated per level of the Debevec–Malik solve: one level per DN, binned to
/// at most [`MAX_LEVELS`] for deep sensors.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InverseTable {
    /// Each level's centre DN, ascending from 0 to `max_dn`.
    pub dn: Vec<f64>,
    /// Each level's ln X = ln g⁻¹, X in relative exposure units (X = 1 at the middle level).
    pub ln_exposure: Vec<f64>,
}

/// g (eq 13) tabulated over a uniform grid of ln exposure, as [`ResponseTable::intensity`]
/// reads it ([`check_forward`] states the requirements).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForwardTable {
    /// The grid: ln X, X in relative exposure units, uniform and increasing.
    pub ln_exposure: Vec<f64>,
    /// The intensity g reads at each grid point: DN / max DN, in [0, 1].
    pub intensity: Vec<f64>,
}

/// Recovered vs true response over a range of intensities.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ResponseComparison {
    /// max |Δ ln g⁻¹| over the levels in range, after removing the best constant offset (the
    /// unit of exposure is arbitrary).
    pub max_abs_ln_error: f64,
    /// RMS of Δ ln g⁻¹ over the same levels, after removing the same offset.
    pub rms_ln_error: f64,
    /// The removed offset: ln(recovered unit / true unit).
    pub ln_offset: f64,
    /// Levels compared.
    pub levels: usize,
}

/// Levels of g⁻¹ of a response with `max_dn` full scale (one per DN, binned to at most
/// [`MAX_LEVELS`]).
pub fn debevec_levels(max_dn: u16) -> usize {
    Levels::for_max_dn(max_dn).count
}

/// Points of the forward table.
const FORWARD_POINTS: usize = 256;

impl ResponseTable {
    fn new(
        bit_depth: u8,
        dn: Vec<f64>,
        ln_exposure: Vec<f64>,
        solve: SolveInfo,
    ) -> Result<Self, ResponseError> {
        let max_dn = max_dn(bit_depth);
        if ln_exposure.iter().any(|x| !x.is_finite()) {
            return Err(ResponseError::Solve("the solution is not finite".into()));
        }
        let forward = forward_table(&dn, &ln_exposure, max_dn);
        Ok(Self {
            format: RESPONSE_FORMAT.to_owned(),
            bit_depth,
            max_dn,
            inverse: InverseTable { dn, ln_exposure },
            forward,
            solve,
        })
    }

    fn levels(&self) -> Levels {
        Levels::for_max_dn(self.max_dn)
    }

    /// ln g⁻¹(dn): ln of the relative exposure that reads `dn`.
    pub fn ln_exposure(&self, dn: u16) -> f64 {
        self.inverse.ln_exposure[self.levels().of(dn)]
    }

    /// g (eq 12): the intensity (DN / max DN, in [0, 1]) a relative exposure `exp(ln_x)`
    /// reads, interpolated in the forward table. Below the table the response is taken as
    /// linear through black (I ∝ X), above it the sensor is saturated at the last level.
    pub fn intensity(&self, ln_x: f64) -> f64 {
        let ForwardTable {
            ln_exposure: grid,
            intensity,
        } = &self.forward;
        let (Some(&lo), Some(&hi)) = (grid.first(), grid.last()) else {
            return 0.0;
        };
        if ln_x.is_nan() {
            return 0.0;
        }
        if ln_x <= lo {
            return intensity[0] * (ln_x - lo).exp();
        }
        if ln_x >= hi || grid.len() < 2 {
            return intensity[intensity.len() - 1];
        }
        let x = (ln_x - lo) / (hi - lo) * (grid.len() - 1) as f64;
        let k = (x.floor() as usize).min(grid.len() - 2);
        let t = x - k as f64;
        intensity[k] * (1.0 - t) + intensity[k + 1] * t
    }

    /// The hat weight of `dn` (0 for black and saturated readings).
    pub fn weight(&self, dn: u16) -> f64 {
        let levels = self.levels();
        levels.weight(levels.of(dn))
    }

    /// The radiance map E = g⁻¹(I)/Δt (eq 13), the hat-weighted mean over the stack in ln units
    /// (Debevec's eq 6): ln E = Σ_j w(z_j) (ln g⁻¹(z_j) − ln Δt_j) / Σ_j w(z_j). Relative
    /// exposure units per second; NaN where no exposure is well exposed (all black or all
    /// saturated).
    pub fn radiance_map(&self, stack: &ExposureStack) -> Result<Image<f32>, ResponseError> {
        if stack.bit_depth() != self.bit_depth {
            return Err(ResponseError::Input(format!(
                "the stack has bit_depth {} but the response was calibrated for {}",
                stack.bit_depth(),
                self.bit_depth
            )));
        }
        let (w, h) = stack.size();
        let ln_dt: Vec<f64> = stack.exposures_s().iter().map(|t| t.ln()).collect();
        let data = (0..(w * h) as usize)
            .map(|i| {
                let (mut num, mut den) = (0.0, 0.0);
                for (img, ln_t) in stack.images().iter().zip(&ln_dt) {
                    let dn = img.data()[i];
                    let wt = self.weight(dn);
                    num += wt * (self.ln_exposure(dn) - ln_t);
                    den += wt;
                }
                if den > 0.0 {
                    (num / den).exp() as f32
                } else {
                    f32::NAN
                }
            })
            .collect();
        Image::new(w, h, data).map_err(|e| ResponseError::Input(e.to_string()))
    }

    /// Compares with a known response `truth` (normalised exposure → normalised intensity) over
    /// the levels whose intensity DN / max DN lies in `intensity_range`.
    pub fn compare_with(
        &self,
        truth: &ResponseCurve,
        intensity_range: (f64, f64),
    ) -> ResponseComparison {
        let pairs: Vec<(f64, f64)> = self
            .inverse
            .dn
            .iter()
            .zip(&self.inverse.ln_exposure)
            .filter_map(|(&dn, &ln_x)| {
                let i = dn / self.max_dn as f64;
                (i >= intensity_range.0 && i <= intensity_range.1)
                    .then(|| (ln_x, (truth.invert(i as f32) as f64).ln()))
            })
            .collect();
        let n = pairs.len().max(1) as f64;
        let offset = pairs.iter().map(|(r, t)| r - t).sum::<f64>() / n;
        let errors: Vec<f64> = pairs.iter().map(|(r, t)| r - t - offset).collect();
        ResponseComparison {
            max_abs_ln_error: errors.iter().fold(0.0, |m, e| m.max(e.abs())),
            rms_ln_error: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
            ln_offset: offset,
            levels: pairs.len(),
        }
    }

    /// Writes the table as pretty JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<(), ResponseError> {
        let json = serde_json::to_vec_pretty(self).map_err(|e| ResponseError::File {
            path: path.into(),
            message: e.to_string(),
        })?;
        stack::write_file(path, &json)
    }

    /// Reads and checks a table written by [`ResponseTable::save`].
    pub fn load(path: &Path) -> Result<Self, ResponseError> {
        let text = std::fs::read_to_string(path).map_err(|e| ResponseError::File {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        Self::parse(&text, path)
    }

    /// Checks and reads the JSON text of a table; `origin` names where it came from in errors
    /// (a file, or an embedded default).
    pub fn parse(text: &str, origin: &Path) -> Result<Self, ResponseError> {
        let path = origin;
        let fail = |message: String| ResponseError::File {
            path: path.to_owned(),
            message,
        };
        let table: Self = serde_json::from_str(text).map_err(|e| fail(e.to_string()))?;
        if table.format != RESPONSE_FORMAT {
            return Err(fail(format!(
                "format is {:?}, expected {RESPONSE_FORMAT:?}",
                table.format
            )));
        }
        let levels = Levels::for_max_dn(max_dn(table.bit_depth));
        if table.max_dn != max_dn(table.bit_depth)
            || table.inverse.ln_exposure.len() != levels.count
            || table.inverse.dn.len() != levels.count
        {
            return Err(fail(format!(
                "inverse has {} levels and max_dn {}, but bit_depth {} needs {} levels and max_dn {}",
                table.inverse.ln_exposure.len(),
                table.max_dn,
                table.bit_depth,
                levels.count,
                max_dn(table.bit_depth)
            )));
        }
        if table.inverse.ln_exposure.iter().any(|x| !x.is_finite()) {
            return Err(fail("inverse.ln_exposure has a non-finite value".into()));
        }
        check_forward(&table.forward)
            .map_err(|(field, problem)| fail(format!("forward.{field}: {problem}")))?;
        Ok(table)
    }
}

/// Checks that g's table is one [`ResponseTable::intensity`] can read: at least 2 points, as
/// many intensities as grid points, all finite, ln X a uniform increasing grid, intensities in
/// [0, 1]. On failure: the field (`ln_exposure` or `intensity`) and the problem.
pub fn check_forward(forward: &ForwardTable) -> Result<(), (&'static str, String)> {
    let (grid, intensity) = (&forward.ln_exposure, &forward.intensity);
    if grid.len() < 2 {
        return Err(("ln_exposure", "needs at least 2 values".into()));
    }
    if intensity.len() != grid.len() {
        return Err((
            "intensity",
            format!(
                "has {} values but ln_exposure has {}",
                intensity.len(),
                grid.len()
            ),
        ));
    }
    for (field, values) in [("ln_exposure", grid), ("intensity", intensity)] {
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err((field, format!("value {i} is {}, not finite", values[i])));
        }
    }
    let step = (grid[grid.len() - 1] - grid[0]) / (grid.len() - 1) as f64;
    if step <= 0.0
        || grid
            .iter()
            .enumerate()
            .any(|(k, x)| (x - (grid[0] + step * k as f64)).abs() > 1e-6 * step)
    {
        return Err((
            "ln_exposure",
            "must be a uniform, increasing grid of ln X".into(),
        ));
    }
    if let Some(i) = intensity.iter().position(|v| !(0.0..=1.0).contains(v)) {
        return Err((
            "intensity",
            format!("value {i} is {}, outside [0, 1]", intensity[i]),
        ));
    }
    Ok(())
}

/// g from g⁻¹: ln X uniform over the inner levels' range, intensity by linear interpolation of
/// the running-maximum (monotone) inverse.
fn forward_table(dn: &[f64], ln_exposure: &[f64], max_dn: u16) -> ForwardTable {
    let n = ln_exposure.len();
    let inner = if n > 2 { 1..n - 1 } else { 0..n };
    let mut monotone: Vec<(f64, f64)> = Vec::new();
    for z in inner {
        let x = monotone
            .last()
            .map_or(ln_exposure[z], |&(last, _)| ln_exposure[z].max(last));
        monotone.push((x, dn[z] / max_dn as f64));
    }
    let (lo, hi) = (monotone[0].0, monotone[monotone.len() - 1].0);
    let mut ln_grid = Vec::with_capacity(FORWARD_POINTS);
    let mut intensity = Vec::with_capacity(FORWARD_POINTS);
    let mut j = 0;
    for k in 0..FORWARD_POINTS {
        let x = lo + (hi - lo) * k as f64 / (FORWARD_POINTS - 1) as f64;
        while j + 1 < monotone.len() && monotone[j + 1].0 < x {
            j += 1;
        }
        let (x0, i0) = monotone[j];
        let i = match monotone.get(j + 1) {
            Some(&(x1, i1)) if x1 > x0 => i0 + (i1 - i0) * ((x - x0) / (x1 - x0)).clamp(0.0, 1.0),
            _ => i0,
        };
        ln_grid.push(x);
        intensity.push(i);
    }
    ForwardTable {
        ln_exposure: ln_grid,
        intensity,
    }
}

#[cfg(test)]
mod tests;
