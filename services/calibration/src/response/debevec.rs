//! Debevec–Malik response recovery ("Recovering High Dynamic Range Radiance Maps from
//! Photographs", 1997), the paper's §IV-A calibration of g in eq 12–13.
//!
//! Unknowns: Debevec's g(z) = ln g⁻¹(z) = ln X for every level z (X = E·Δt, the exposure, in
//! relative units), and ln E_i per sample pixel i. Least squares over
//! - data rows      w(z_ij) [g(z_ij) − ln E_i] = w(z_ij) ln Δt_j,
//! - one anchor     g(z_mid) = 0 (fixes the unit of X: X = 1 at the middle level),
//! - smoothness     λ w(z) [g(z−1) − 2 g(z) + g(z+1)] = 0 for the inner levels,
//!
//! with hat weights w(z) = z − z_min below the middle, z_max − z above (0 at both ends, so
//! black and saturated readings carry no data). Solved by SVD (nalgebra).

use glint_geometry::image::Image;
use nalgebra::{DMatrix, DVector};

use super::stack::ExposureStack;
use super::{ResponseError, ResponseTable};

/// At most this many levels enter the solve: stacks deeper than 10 bits are binned down so
/// that the SVD stays ~1000 unknowns.
pub const MAX_LEVELS: usize = 1024;

/// Debevec–Malik settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DebevecConfig {
    /// Smoothness weight λ (Debevec's and OpenCV's usual 10 for 8 bits).
    pub lambda: f64,
    /// Number of sample pixels (≥ 2; Debevec recommends N(P − 1) > z_max − z_min, e.g. 50–70
    /// for 5–6 exposures of 8 bits).
    pub samples: usize,
}

impl Default for DebevecConfig {
    fn default() -> Self {
        Self {
            lambda: 10.0,
            samples: 70,
        }
    }
}

/// How DN map to the solve's levels and their hat weights.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Levels {
    pub count: usize,
    dn_per_level: f64,
}

impl Levels {
    pub fn for_max_dn(max_dn: u16) -> Self {
        let dns = max_dn as usize + 1;
        let count = dns.min(MAX_LEVELS);
        Self {
            count,
            dn_per_level: dns as f64 / count as f64,
        }
    }
    #[inline]
    pub fn of(&self, dn: u16) -> usize {
        ((dn as f64 / self.dn_per_level) as usize).min(self.count - 1)
    }
    /// The DN at the centre of level z.
    pub fn centre_dn(&self, z: usize) -> f64 {
        (z as f64 + 0.5) * self.dn_per_level - 0.5
    }
    /// Hat weight of level z: 0 at both ends, largest in the middle.
    #[inline]
    pub fn weight(&self, z: usize) -> f64 {
        let z_max = self.count - 1;
        if 2 * z <= z_max {
            z as f64
        } else {
            (z_max - z) as f64
        }
    }
    pub fn mid(&self) -> usize {
        self.count / 2
    }
}

/// A chosen sample pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SamplePixel {
    /// Pixel column.
    pub u: u32,
    /// Pixel row.
    pub v: u32,
}

/// Picks up to `count` sample pixels, stratified over intensity.
///
/// Candidates lie on a regular grid (~64 × 64, away from the border). A candidate is kept only
/// if at least two exposures read it well exposed (0 < z < z_max): a pixel seen once only adds
/// an unknown and its own equation, and constrains nothing. Its brightness key is the sum of
/// its DN over the stack (monotone in radiance); the key's range is cut into `count` equal
/// bins and each non-empty bin contributes its flattest candidate (smallest 3 × 3 DN range in
/// the middle exposure: edges are where lens blur and misregistration bite). Deterministic.
pub fn select_samples(stack: &ExposureStack, count: usize) -> Vec<SamplePixel> {
    let (w, h) = stack.size();
    let images = stack.images();
    let levels = Levels::for_max_dn(stack.max_dn());
    let middle = &images[images.len() / 2];
    let step_u = (w / 64).max(1);
    let step_v = (h / 64).max(1);
    struct Candidate {
        pixel: SamplePixel,
        key: u64,
        roughness: u32,
    }
    let mut candidates = Vec::new();
    let mut v = step_v / 2;
    while v < h {
        let mut u = step_u / 2;
        while u < w {
            let well = images
                .iter()
                .filter(|img| {
                    // (u, v) lies inside: the loops stop at the image size.
                    let z = levels.of(img.get(u, v).unwrap_or(0));
                    z > 0 && z < levels.count - 1
                })
                .count();
            if well >= 2 {
                let key = images
                    .iter()
                    .map(|img| img.get(u, v).unwrap_or(0) as u64)
                    .sum();
                candidates.push(Candidate {
                    pixel: SamplePixel { u, v },
                    key,
                    roughness: local_range(middle, u, v),
                });
            }
            u += step_u;
        }
        v += step_v;
    }
    let keys = || candidates.iter().map(|c| c.key);
    let (Some(lo), Some(hi)) = (keys().min(), keys().max()) else {
        return Vec::new();
    };
    if count == 0 {
        return Vec::new();
    }
    let span = (hi - lo + 1) as f64;
    let mut best: Vec<Option<usize>> = vec![None; count];
    for (i, c) in candidates.iter().enumerate() {
        let bin = (((c.key - lo) as f64 / span) * count as f64) as usize;
        let slot = &mut best[bin.min(count - 1)];
        if slot.is_none_or(|j| c.roughness < candidates[j].roughness) {
            *slot = Some(i);
        }
    }
    best.into_iter()
        .flatten()
        .map(|i| candidates[i].pixel)
        .collect()
}

/// max − min of the 3 × 3 neighbourhood (clipped at the border).
fn local_range(img: &Image<u16>, u: u32, v: u32) -> u32 {
    let (mut lo, mut hi) = (u16::MAX, 0u16);
    for dv in -1i64..=1 {
        for du in -1i64..=1 {
            let (x, y) = (u as i64 + du, v as i64 + dv);
            if x >= 0
                && y >= 0
                && let Some(d) = img.get(x as u32, y as u32)
            {
                lo = lo.min(d);
                hi = hi.max(d);
            }
        }
    }
    (hi - lo) as u32
}

/// Recovers the response of `stack`'s camera.
pub fn calibrate(
    stack: &ExposureStack,
    config: &DebevecConfig,
) -> Result<ResponseTable, ResponseError> {
    if !(config.lambda.is_finite() && config.lambda >= 0.0) {
        return Err(ResponseError::Input(format!(
            "lambda is {}, but must be a finite number ≥ 0",
            config.lambda
        )));
    }
    if config.samples < 2 {
        return Err(ResponseError::Input(format!(
            "samples is {}, but at least 2 sample pixels are needed",
            config.samples
        )));
    }
    let samples = select_samples(stack, config.samples);
    if samples.len() < 2 {
        return Err(ResponseError::NoUsablePixels {
            found: samples.len(),
        });
    }
    let levels = Levels::for_max_dn(stack.max_dn());
    let n = levels.count;
    let p = stack.images().len();
    let rows = samples.len() * p + 1 + n.saturating_sub(2);
    let cols = n + samples.len();
    let mut a = DMatrix::<f64>::zeros(rows, cols);
    let mut b = DVector::<f64>::zeros(rows);
    let mut k = 0;
    for (i, s) in samples.iter().enumerate() {
        for (img, &dt) in stack.images().iter().zip(stack.exposures_s()) {
            // Sample pixels were chosen inside the stack's images.
            let z = levels.of(img.get(s.u, s.v).unwrap_or(0));
            let w = levels.weight(z);
            a[(k, z)] = w;
            a[(k, n + i)] = -w;
            b[k] = w * dt.ln();
            k += 1;
        }
    }
    a[(k, levels.mid())] = 1.0;
    k += 1;
    for z in 1..n - 1 {
        let w = config.lambda * levels.weight(z);
        a[(k, z - 1)] = w;
        a[(k, z)] = -2.0 * w;
        a[(k, z + 1)] = w;
        k += 1;
    }
    debug_assert_eq!(k, rows);
    let x = a
        .clone()
        .svd(true, true)
        .solve(&b, 1e-12)
        .map_err(|e| ResponseError::Solve(e.to_string()))?;
    let ln_exposure: Vec<f64> = (0..n).map(|z| x[z]).collect();
    let residual = (&a * &x - &b).norm() / (rows as f64).sqrt();
    ResponseTable::new(
        stack.bit_depth(),
        (0..n).map(|z| levels.centre_dn(z)).collect(),
        ln_exposure,
        SolveInfo {
            lambda: config.lambda,
            samples: samples.len(),
            exposures_s: stack.exposures_s().to_vec(),
            rms_residual: residual,
        },
    )
}

/// How a response was solved, kept in its JSON.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolveInfo {
    /// Smoothness weight λ of the solve ([`DebevecConfig::lambda`]); 0 for a table decoded
    /// from a message, which does not carry the solve.
    pub lambda: f64,
    /// Sample pixels used.
    pub samples: usize,
    /// The stack's exposure times, seconds.
    pub exposures_s: Vec<f64>,
    /// RMS of the weighted least-squares residual (ln units × weight).
    pub rms_residual: f64,
}
