//! The ZNCC kernel: one band of rows, streaming, O(W·D) work per row whatever the window size.
//!
//! For a left pixel u and disparity d (right pixel c = u − d), with sums over the `(2r+1)²`
//! window and all K shots of the sequence (space-time ZNCC; K = 1 is the single-shot case):
//!
//! ```text
//! ZNCC(u, d) = (Σ l·r − Σl · r̄) / (‖l − l̄‖ · ‖r − r̄‖)
//! ```
//!
//! `Σl`, `r̄` and the norms come from summed-area tables ([`super::window_stats`]). The cross
//! term Σ l·r is kept as running sums: per window column x and candidate k = d − d_min,
//! `column[x][k] = Σ_rows l(x)·r(x − d)` is updated as the window slides down one row (add the
//! entering row's products of every shot, subtract the leaving row's), and the window sum is a running sum of
//! 2r+1 columns as u slides right. Each row costs ~2 multiply-adds per (x, k) for the columns
//! and one add, one subtract and the ZNCC per (u, k).
//!
//! Scored rows go into a ring of the last 2s+1 rows (s = r with shifted windows, else 0): a
//! pixel's shifted windows are the centred windows of the pixels s away, so they cost no extra
//! scoring, and row v is decided once row v + s is scored. The right-to-left winners are
//! gathered while scoring, so the left-right check needs no second pass.

use super::MatchStatus;
use super::plan::{MatchPlan, Patches};
use super::select::{SelectParams, max_score, select};
use std::ops::Range;

/// Rows of the three output images, full width, row-major.
pub(super) struct BandOutput<'a> {
    pub disparity_px: &'a mut [f32],
    pub status: &'a mut [MatchStatus],
    pub correlation: &'a mut [f32],
}

/// What the kernel decides with, besides the per-pixel [`SelectParams`].
#[derive(Clone, Copy, Debug)]
pub(super) struct BandParams {
    pub select: SelectParams,
    pub left_right_max_diff_px: Option<f32>,
    pub shifted_window_min_gain: Option<f32>,
}

/// The last `slots` scored rows: score curves, their peaks and the right-to-left winners.
struct ScoreRing {
    slots: usize,
    /// `slots × score_cols × D`; a pixel's curve holds its candidate count of entries.
    curves: Vec<f32>,
    /// Best score of each curve, `slots × score_cols`.
    peaks: Vec<f32>,
    /// Best score and candidate index of each right pixel's best left match (row-mirrored),
    /// `slots × right_cols`; index `NO_MATCH` where no left pixel was scored against it.
    right_best_score: Vec<f32>,
    right_best_index: Vec<u32>,
}

const NO_MATCH: u32 = u32::MAX;

/// Matches output rows `rows` (a sub-range of `plan.out_rows`) into `out`, whose rows start at
/// `rows.start`.
pub(super) fn match_band(
    plan: &MatchPlan,
    patches: &Patches,
    params: &BandParams,
    rows: Range<usize>,
    out: BandOutput<'_>,
) {
    let (r, s, d_count) = (plan.radius, plan.shift, plan.d_count);
    let (nl, nr, ns) = (
        plan.left_cols.len(),
        plan.right_cols.len(),
        plan.score_cols.len(),
    );
    let slots = 2 * s + 1;
    let mut ring = ScoreRing {
        slots,
        curves: vec![0.0; slots * ns * d_count],
        peaks: vec![f32::NEG_INFINITY; slots * ns],
        right_best_score: vec![f32::NEG_INFINITY; slots * nr],
        right_best_index: vec![NO_MATCH; slots * nr],
    };
    let mut column_sums = vec![0.0f32; nl * d_count];
    let mut window_sums = vec![0.0f32; d_count];
    // Per window column: candidates whose right column lies in the patch, and where they start
    // in a mirrored right row.
    let first_right = plan.right_cols.start + plan.d_min;
    let columns: Vec<(usize, usize)> = plan
        .left_cols
        .clone()
        .map(|x| {
            let count = if x >= first_right {
                (x - first_right + 1).min(d_count)
            } else {
                0
            };
            (count, if count > 0 { plan.mirror_base() - x } else { 0 })
        })
        .collect();
    // Row v of shot k.
    let rows_per_shot = plan.patch_rows.len();
    let left_row = |v: usize, k: usize| {
        &patches.left[(k * rows_per_shot + v - plan.patch_rows.start) * nl..][..nl]
    };
    let right_row = |v: usize, k: usize| {
        &patches.right_mirrored[(k * rows_per_shot + v - plan.patch_rows.start) * nr..][..nr]
    };
    let shots = patches.shots;

    let scored = rows.start.saturating_sub(s).max(plan.score_rows.start)
        ..(rows.end + s).min(plan.score_rows.end);
    for v in scored.start - r..=scored.start + r {
        for k in 0..shots {
            add_row_products(
                &mut column_sums,
                d_count,
                &columns,
                left_row(v, k),
                right_row(v, k),
            );
        }
    }
    let mut next = scored.start;
    for v in rows.clone() {
        while next < (v + s + 1).min(scored.end) {
            if next > scored.start {
                for k in 0..shots {
                    slide_row_products(
                        &mut column_sums,
                        d_count,
                        &columns,
                        (left_row(next + r, k), right_row(next + r, k)),
                        (left_row(next - r - 1, k), right_row(next - r - 1, k)),
                    );
                }
            }
            score_row(
                plan,
                patches,
                next,
                &column_sums,
                &mut window_sums,
                &mut ring,
            );
            next += 1;
        }
        let offset = (v - rows.start) * plan.width;
        let out_row = BandOutput {
            disparity_px: &mut out.disparity_px[offset..offset + plan.width],
            status: &mut out.status[offset..offset + plan.width],
            correlation: &mut out.correlation[offset..offset + plan.width],
        };
        decide_row(plan, patches, params, v, &ring, out_row);
    }
}

/// `column[x][k] += l(x) · r(x − d_min − k)` for one row.
fn add_row_products(
    column_sums: &mut [f32],
    d_count: usize,
    columns: &[(usize, usize)],
    left: &[f32],
    right: &[f32],
) {
    for (x, &(count, start)) in columns.iter().enumerate() {
        let l = left[x];
        let sums = &mut column_sums[x * d_count..x * d_count + count];
        for (sum, &r) in sums.iter_mut().zip(&right[start..start + count]) {
            *sum += l * r;
        }
    }
}

/// Slides every column's window down one row: adds the entering row's products and subtracts
/// the leaving row's.
fn slide_row_products(
    column_sums: &mut [f32],
    d_count: usize,
    columns: &[(usize, usize)],
    (left_in, right_in): (&[f32], &[f32]),
    (left_out, right_out): (&[f32], &[f32]),
) {
    for (x, &(count, start)) in columns.iter().enumerate() {
        let (l_in, l_out) = (left_in[x], left_out[x]);
        let sums = &mut column_sums[x * d_count..x * d_count + count];
        let r_in = &right_in[start..start + count];
        let r_out = &right_out[start..start + count];
        for ((sum, &a), &b) in sums.iter_mut().zip(r_in).zip(r_out) {
            *sum += l_in * a - l_out * b;
        }
    }
}

/// Scores every pixel of `plan.score_cols` in row `v` (whose column sums are current) into its
/// ring slot, with curve peaks and the right-to-left winners.
fn score_row(
    plan: &MatchPlan,
    patches: &Patches,
    v: usize,
    column_sums: &[f32],
    window_sums: &mut [f32],
    ring: &mut ScoreRing,
) {
    let (r, d_count) = (plan.radius, plan.d_count);
    let (nl, nr, ns) = (
        plan.left_cols.len(),
        plan.right_cols.len(),
        plan.score_cols.len(),
    );
    let patch_row = v - plan.patch_rows.start;
    let left_sum = &patches.left_stats.sum[patch_row * nl..][..nl];
    let left_inv_norm = &patches.left_stats.inv_norm[patch_row * nl..][..nl];
    let right_mean = &patches.right_mean_mirrored[patch_row * nr..][..nr];
    let right_inv_norm = &patches.right_inv_norm_mirrored[patch_row * nr..][..nr];
    let slot = v % ring.slots;
    let curves = &mut ring.curves[slot * ns * d_count..][..ns * d_count];
    let peaks = &mut ring.peaks[slot * ns..][..ns];
    let right_best_score = &mut ring.right_best_score[slot * nr..][..nr];
    let right_best_index = &mut ring.right_best_index[slot * nr..][..nr];
    right_best_score.fill(f32::NEG_INFINITY);
    right_best_index.fill(NO_MATCH);
    let column = |x: usize| &column_sums[x * d_count..(x + 1) * d_count];

    // Window sums for the first scored pixel: patch columns 0..=2r.
    window_sums.fill(0.0);
    for x in 0..2 * r {
        window_sums
            .iter_mut()
            .zip(column(x))
            .for_each(|(w, c)| *w += c);
    }
    for (iu, u) in plan.score_cols.clone().enumerate() {
        // Patch column of u's window centre; its window spans patch columns x − r..=x + r.
        let x = u - plan.left_cols.start;
        let entering = column(x + r);
        if x > r {
            let leaving = column(x - r - 1);
            for ((w, &a), &b) in window_sums.iter_mut().zip(entering).zip(leaving) {
                *w += a - b;
            }
        } else {
            window_sums
                .iter_mut()
                .zip(entering)
                .for_each(|(w, c)| *w += c);
        }

        let count = plan.candidate_count(u);
        let start = plan.mirror_base() - u;
        let (sum_l, inv_norm_l) = (left_sum[x], left_inv_norm[x]);
        let scores = &mut curves[iu * d_count..iu * d_count + count];
        let means = &right_mean[start..start + count];
        let inv_norms = &right_inv_norm[start..start + count];
        for (((score, &w), &mean_r), &inv_r) in scores
            .iter_mut()
            .zip(window_sums.iter())
            .zip(means)
            .zip(inv_norms)
        {
            *score = (w - sum_l * mean_r) * inv_norm_l * inv_r;
        }
        peaks[iu] = max_score(scores);
        // Right-to-left winners: right pixel c = u − d_min − k sits at mirrored index start + k.
        let best_scores = &mut right_best_score[start..start + count];
        let best_indices = &mut right_best_index[start..start + count];
        for (k, ((best, index), &score)) in best_scores
            .iter_mut()
            .zip(best_indices.iter_mut())
            .zip(scores.iter())
            .enumerate()
        {
            let better = score > *best;
            *best = if better { score } else { *best };
            *index = if better { k as u32 } else { *index };
        }
    }
}

/// A window that may decide a pixel: where it is centred and its best score.
#[derive(Clone, Copy, Debug)]
struct WindowPeak {
    row: usize,
    col: usize,
    peak: f32,
}

/// The window that decides a pixel (at row `v`, column `u` of its own image): the centred one,
/// unless some of the eight shifted by s along rows, columns and diagonals (each still holding
/// the pixel) beat its peak by more than `min_gain`. Among those, the best-peaked wins when they
/// agree on the disparity (±1 px). When they disagree — windows on both sides of a depth edge
/// fit well — `acceptable(index)` breaks the tie: the best-peaked of the windows whose winner
/// it accepts, if any. `peak(row, col)` is `None` where no window was scored; `index(row, col)`
/// is the candidate index of a scored window's peak (looked up only for contenders).
#[inline]
fn choose_window(
    v: usize,
    u: usize,
    s: usize,
    min_gain: f32,
    peak: impl Fn(usize, usize) -> Option<WindowPeak>,
    index: impl Fn(usize, usize) -> usize,
    acceptable: impl Fn(usize) -> bool,
) -> (usize, usize) {
    let Some(centre) = peak(v, u) else {
        return (v, u);
    };
    let mut qualifying = [centre; 8];
    let mut count = 0;
    let rows = [v.checked_sub(s), Some(v), Some(v + s)];
    let cols = [u.checked_sub(s), Some(u), Some(u + s)];
    for row in rows.into_iter().flatten() {
        for col in cols.into_iter().flatten() {
            if let Some(w) = peak(row, col)
                && (row, col) != (v, u)
                && w.peak > centre.peak + min_gain
            {
                qualifying[count] = w;
                count += 1;
            }
        }
    }
    let qualifying = &qualifying[..count];
    let Some(best) = qualifying
        .iter()
        .copied()
        .max_by(|a, b| a.peak.total_cmp(&b.peak))
    else {
        return (v, u);
    };
    let best_index = index(best.row, best.col);
    if qualifying
        .iter()
        .all(|w| index(w.row, w.col).abs_diff(best_index) <= 1)
    {
        return (best.row, best.col);
    }
    let accepted = qualifying
        .iter()
        .filter(|w| acceptable(index(w.row, w.col)))
        .max_by(|a, b| a.peak.total_cmp(&b.peak));
    accepted.map_or((best.row, best.col), |w| (w.row, w.col))
}

/// Decides every ROI pixel of row `v`: window choice, checks, subpixel fit, left-right check.
fn decide_row(
    plan: &MatchPlan,
    patches: &Patches,
    params: &BandParams,
    v: usize,
    ring: &ScoreRing,
    out: BandOutput<'_>,
) {
    let (s, d_count) = (plan.shift, plan.d_count);
    let (nl, nr, ns) = (
        plan.left_cols.len(),
        plan.right_cols.len(),
        plan.score_cols.len(),
    );
    let left_inv_norm = &patches.left_stats.inv_norm[(v - plan.patch_rows.start) * nl..][..nl];
    let slot_of = |row: usize| row % ring.slots;
    let scored_row = |row: usize| row.abs_diff(v) <= s && plan.score_rows.contains(&row);
    let curve = |row: usize, col: usize| {
        let start = (slot_of(row) * ns + col - plan.score_cols.start) * d_count;
        &ring.curves[start..start + plan.candidate_count(col)]
    };
    // Left windows by (row, image column).
    let left_peak = |row: usize, col: usize| {
        (scored_row(row) && plan.score_cols.contains(&col)).then(|| {
            let peak = ring.peaks[slot_of(row) * ns + col - plan.score_cols.start];
            WindowPeak { row, col, peak }
        })
    };
    let left_index = |row: usize, col: usize| {
        let peak = ring.peaks[slot_of(row) * ns + col - plan.score_cols.start];
        curve(row, col).iter().position(|&x| x == peak).unwrap_or(0)
    };
    // Right windows by (row, mirrored index j = right_cols.end − 1 − c).
    let right_peak = |row: usize, j: usize| {
        let at = slot_of(row) * nr + j;
        (scored_row(row) && j < nr && ring.right_best_index[at] != NO_MATCH).then(|| WindowPeak {
            row,
            col: j,
            peak: ring.right_best_score[at],
        })
    };
    let right_index = |row: usize, j: usize| ring.right_best_index[slot_of(row) * nr + j] as usize;
    // The best left match of right column c (candidate index, or NO_MATCH), by the same
    // window rule without a tie-break.
    let right_match = |c: usize| {
        if c < plan.radius || c >= plan.right_cols.end || c < plan.right_cols.start {
            return NO_MATCH;
        }
        let j = plan.right_cols.end - 1 - c;
        let (row, j) = match params.shifted_window_min_gain {
            Some(min_gain) if s > 0 => {
                choose_window(v, j, s, min_gain, right_peak, right_index, |_| false)
            }
            _ => (v, j),
        };
        ring.right_best_index[slot_of(row) * nr + j]
    };

    for u in plan.out_cols.clone() {
        if left_inv_norm[u - plan.left_cols.start] == 0.0 {
            out.status[u] = MatchStatus::NoTexture;
            continue;
        }
        let (row, col) = match params.shifted_window_min_gain {
            Some(min_gain) if s > 0 => {
                // Disagreeing windows: prefer a disparity whose right pixel u − d_min − k
                // matches back within a pixel (the far side of an edge often does not).
                let consistent = |k: usize| {
                    k < plan.candidate_count(u) && {
                        let back = right_match(u - plan.d_min - k);
                        back != NO_MATCH && (back as usize).abs_diff(k) <= 1
                    }
                };
                choose_window(v, u, s, min_gain, left_peak, left_index, consistent)
            }
            _ => (v, u),
        };
        let choice = select(curve(row, col), &params.select);
        out.correlation[u] = choice.best_score;
        out.status[u] = choice.status;
        if choice.status != MatchStatus::Valid {
            continue;
        }
        let disparity = (plan.d_min + choice.best_index) as f32 + choice.offset;
        out.disparity_px[u] = disparity;
        if let Some(max_diff) = params.left_right_max_diff_px {
            // The right pixel holding this one's subpixel match, c = ⌊u + 0.5 − d⌋, and its own
            // best left match.
            let c = (u as f32 + 0.5 - disparity).floor();
            let back = if c >= 0.0 {
                right_match(c as usize)
            } else {
                NO_MATCH
            };
            let consistent = back != NO_MATCH
                && (disparity - (plan.d_min + back as usize) as f32).abs() <= max_diff;
            if !consistent {
                out.status[u] = MatchStatus::LeftRightInconsistent;
                out.disparity_px[u] = f32::NAN;
            }
        }
    }
}
