//! Which pixels of each image a match reads and writes, and the working copies it matches on.

use super::window_stats::WindowStats;
use super::{PixelRect, Side, StereoError, StereoMatcherConfig};
use glint_geometry::image::Image;
use std::ops::Range;

/// The pixel ranges one match touches (all in image coordinates, half-open).
///
/// With window radius r, window shift s (0 or r, see [`super::band`]) and disparities
/// `d_min..=d_max` (D of them):
/// - `out_cols × out_rows`: ROI pixels whose window fits in the left image and that have at
///   least one candidate — the ones the kernel gives a status;
/// - `score_cols × score_rows`: pixels whose score curves are computed: `out_*` widened by s
///   (shifted windows are other pixels' centred windows) and, for columns, by `D − 1` more each
///   way when the left-right check is on, so that every right pixel a ROI pixel can match (and
///   its shifted windows) has all its candidates scored;
/// - `left_cols`, `right_cols`, `patch_rows`: what is read from each image. A left column x at
///   disparity d reads right column x − d, so `right_cols` spans `left_cols` shifted by
///   `−d_max..=−d_min`.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct MatchPlan {
    pub width: usize,
    pub radius: usize,
    pub shift: usize,
    pub d_min: usize,
    pub d_count: usize,
    pub out_rows: Range<usize>,
    pub out_cols: Range<usize>,
    pub score_rows: Range<usize>,
    pub score_cols: Range<usize>,
    pub left_cols: Range<usize>,
    pub right_cols: Range<usize>,
    pub patch_rows: Range<usize>,
}

impl MatchPlan {
    /// The plan for `roi` of a `width × height` pair, or `None` when no ROI pixel can be matched
    /// at all (every window leaves the image or no disparity fits).
    pub fn new(
        width: usize,
        height: usize,
        roi: &PixelRect,
        config: &StereoMatcherConfig,
    ) -> Option<Self> {
        let r = config.window_radius_px as usize;
        let shift = if config.shifted_window_min_gain.is_some() {
            r
        } else {
            0
        };
        let d_min = config.disparity_range.min_px() as usize;
        let d_max = config.disparity_range.max_px() as usize;
        let d_count = d_max - d_min + 1;
        let fits = |lo: usize, hi: usize, n: usize| lo.max(r)..hi.min(n.saturating_sub(r));
        // A left pixel u has a candidate iff its right window fits at d_min: u − d_min ≥ r.
        let has_candidate = |cols: Range<usize>| cols.start.max(r + d_min)..cols.end;
        let out_rows = fits(roi.v_min as usize, roi.v_end() as usize, height);
        let out_cols = has_candidate(fits(roi.u_min as usize, roi.u_end() as usize, width));
        if out_rows.is_empty() || out_cols.is_empty() {
            return None;
        }
        let widen = if config.left_right_max_diff_px.is_some() {
            d_count - 1
        } else {
            0
        } + shift;
        let score_cols = has_candidate(fits(
            out_cols.start.saturating_sub(widen),
            out_cols.end + widen,
            width,
        ));
        let score_rows = fits(
            out_rows.start.saturating_sub(shift),
            out_rows.end + shift,
            height,
        );
        let left_cols = score_cols.start - r..score_cols.end + r;
        let right_cols = left_cols.start.saturating_sub(d_max)..left_cols.end - d_min;
        let patch_rows = score_rows.start - r..score_rows.end + r;
        Some(Self {
            width,
            radius: r,
            shift,
            d_min,
            d_count,
            out_rows,
            out_cols,
            score_rows,
            score_cols,
            left_cols,
            right_cols,
            patch_rows,
        })
    }

    /// Number of disparities a left pixel `u` can be scored at: those whose right window fits,
    /// `u − d − r ≥ 0`.
    #[inline]
    pub fn candidate_count(&self, u: usize) -> usize {
        (u + 1)
            .saturating_sub(self.radius + self.d_min)
            .min(self.d_count)
    }

    /// Index base of the mirrored right buffers: right column `c = u − d_min − k` is stored at
    /// `mirror_base() − u + k`, so one left pixel's candidates are contiguous and ascending in k.
    #[inline]
    pub fn mirror_base(&self) -> usize {
        self.right_cols.end - 1 + self.d_min
    }
}

/// The image sequences as the kernel reads them: the planned regions of every shot copied out,
/// each side centred on its mean over all shots (space-time ZNCC is invariant to one offset per
/// side, and it keeps the running sums small and exact-ish in f32), the right one mirrored
/// left-right per row, with their space-time window statistics. Shot k's plane follows shot
/// k − 1's.
pub(super) struct Patches {
    /// Shots K ≥ 1.
    pub shots: usize,
    /// `K × patch_rows × left_cols`.
    pub left: Vec<f32>,
    /// `K × patch_rows × right_cols`, row-mirrored: right column c at index
    /// `right_cols.end − 1 − c`.
    pub right_mirrored: Vec<f32>,
    /// Window sum Σl and 1/‖l − l̄‖ (0: no texture), `patch_rows × left_cols`.
    pub left_stats: WindowStats,
    /// Window mean r̄ and 1/‖r − r̄‖, `patch_rows × right_cols`, row-mirrored.
    pub right_mean_mirrored: Vec<f32>,
    pub right_inv_norm_mirrored: Vec<f32>,
}

impl Patches {
    /// `left` and `right` are the K shots of each side (same length ≥ 1, equal sizes: the
    /// caller checks).
    pub fn new(
        plan: &MatchPlan,
        left: &[&Image<f32>],
        right: &[&Image<f32>],
        min_window_std: f32,
    ) -> Result<Self, StereoError> {
        let r = plan.radius;
        let shots = left.len();
        let n = ((2 * r + 1) * (2 * r + 1) * shots) as f32;
        let (nl, nr) = (plan.left_cols.len(), plan.right_cols.len());
        let left = copy_centred(left, Side::Left, &plan.left_cols, &plan.patch_rows)?;
        let right = copy_centred(right, Side::Right, &plan.right_cols, &plan.patch_rows)?;
        let left_stats = WindowStats::compute(&left, nl, plan.patch_rows.len(), r, min_window_std);
        let right_stats =
            WindowStats::compute(&right, nr, plan.patch_rows.len(), r, min_window_std);
        let mut right_mean_mirrored: Vec<f32> = right_stats.sum.iter().map(|s| s / n).collect();
        let mut right_inv_norm_mirrored = right_stats.inv_norm;
        let mut right_mirrored = right;
        for buffer in [
            &mut right_mirrored,
            &mut right_mean_mirrored,
            &mut right_inv_norm_mirrored,
        ] {
            buffer.chunks_exact_mut(nr).for_each(|row| row.reverse());
        }
        Ok(Self {
            shots,
            left,
            right_mirrored,
            left_stats,
            right_mean_mirrored,
            right_inv_norm_mirrored,
        })
    }
}

/// Copies `cols × rows` of every shot of `images` (one plane after another), checking every
/// value is finite, minus their common mean.
fn copy_centred(
    images: &[&Image<f32>],
    side: Side,
    cols: &Range<usize>,
    rows: &Range<usize>,
) -> Result<Vec<f32>, StereoError> {
    let mut out = Vec::with_capacity(cols.len() * rows.len() * images.len());
    let mut total = 0.0f64;
    for image in images {
        for v in rows.clone() {
            let row = &image.row(v as u32)[cols.clone()];
            if let Some(i) = row.iter().position(|x| !x.is_finite()) {
                return Err(StereoError::NonFinite {
                    side,
                    u: (cols.start + i) as u32,
                    v: v as u32,
                    value: row[i],
                });
            }
            total += row.iter().map(|&x| x as f64).sum::<f64>();
            out.extend_from_slice(row);
        }
    }
    let mean = (total / out.len().max(1) as f64) as f32;
    out.iter_mut().for_each(|x| *x -= mean);
    Ok(out)
}
