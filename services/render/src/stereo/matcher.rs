//! [`match_stereo`]: validation, planning, the parallel band sweep and the speckle pass.

use super::band::{BandOutput, BandParams, match_band};
use super::plan::{MatchPlan, Patches};
use super::select::SelectParams;
use super::speckle::remove_speckles;
use super::{EdgeWindows, MatchStatus, PixelRect, StereoError, StereoMatcherConfig, StereoResult};
use glint_geometry::image::Image;
use rayon::prelude::*;

/// Bands shorter than this waste too much on re-priming the 2r+1 rows of running sums.
const MIN_BAND_ROWS: usize = 16;
/// Bands per worker thread, for load balance.
const BANDS_PER_THREAD: usize = 2;

/// Matches a rectified pair: a disparity `d = u_L − u_R` (px) and a [`MatchStatus`] for every
/// pixel of the left image.
///
/// `left` and `right` must be rectified (epipolar lines are rows; the right camera sits along
/// +x of the left one, so a scene point appears `d ≥ 0` pixels further left in the right image)
/// and equally sized, with values in units where 1.0 is the sensor's full scale. Only the
/// left pixels of `roi` (the whole image when `None`) are matched; others are
/// [`MatchStatus::OutOfRoi`]. The right columns read are those of the ROI shifted by the
/// disparity range (and widened by `D − 1` each way for the left-right check); only values
/// read are checked for finiteness.
///
/// Errors (never panics) on mismatched sizes, non-finite values, an empty ROI or one outside
/// the image, invalid parameters, or a disparity range as wide as the image.
pub fn match_stereo(
    left: &Image<f32>,
    right: &Image<f32>,
    config: &StereoMatcherConfig,
    roi: Option<PixelRect>,
) -> Result<StereoResult, StereoError> {
    match_stereo_sequence(&[left], &[right], config, roi)
}

/// Spatio-temporal matching of a sequence of K rectified pairs taken under K different
/// projector patterns from one static viewpoint (`left[k]`, `right[k]` under pattern k): as
/// [`match_stereo`], with every ZNCC taken over the `(2r+1)²` window × all K shots,
///
/// ```text
/// ZNCC(u, d) = Σ_k Σ_w (l − l̄)(r − r̄) / (‖l − l̄‖ · ‖r − r̄‖),  means and norms over window × shots,
/// ```
///
/// so the texture, uniqueness and left-right checks, window choice and subpixel fit act on
/// space-time windows. A pixel's K values carry K independent pattern samples, so a small
/// window is as unique as a K-times larger single-shot one without mixing depths across it.
/// K = 1 is [`match_stereo`] exactly (same operations in the same order).
///
/// Errors as [`match_stereo`], and [`StereoError::ShotCount`] when a side has no shot or the
/// sides differ in shot count; every image must have the first left image's size.
pub fn match_stereo_sequence(
    left: &[&Image<f32>],
    right: &[&Image<f32>],
    config: &StereoMatcherConfig,
    roi: Option<PixelRect>,
) -> Result<StereoResult, StereoError> {
    config.validate()?;
    let Some(first) = left.first() else {
        return Err(StereoError::ShotCount {
            left: left.len(),
            right: right.len(),
        });
    };
    if right.len() != left.len() {
        return Err(StereoError::ShotCount {
            left: left.len(),
            right: right.len(),
        });
    }
    for other in left.iter().chain(right) {
        if (other.width(), other.height()) != (first.width(), first.height()) {
            return Err(StereoError::SizeMismatch {
                left_width: first.width(),
                left_height: first.height(),
                right_width: other.width(),
                right_height: other.height(),
            });
        }
    }
    let mut result = match_windows(left, right, config, roi)?;
    if let Some(edge) = config.edge_windows {
        rematch_near_edges(left, right, config, &edge, &mut result)?;
    }
    if let Some(filter) = &config.speckle {
        let w = first.width() as usize;
        remove_speckles(
            result.disparity_px.data_mut(),
            result.status.data_mut(),
            w,
            &result.roi,
            filter,
        );
    }
    Ok(result)
}

/// Pixels of the ROI within `radius` (L∞) of a depth edge of `result`: a 4-neighbour pair
/// with both disparities valid and more than `step_px` apart, or with exactly one valid (a
/// hole's border; pixels outside the ROI do not count). Row-major, full image.
pub(super) fn near_depth_edges(result: &StereoResult, step_px: f32, radius: usize) -> Vec<bool> {
    let (w, h) = (
        result.disparity_px.width() as usize,
        result.disparity_px.height() as usize,
    );
    let d = result.disparity_px.data();
    let status = result.status.data();
    let counts = |i: usize| status[i] != MatchStatus::OutOfRoi;
    let mut edge = vec![false; w * h];
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            if !counts(i) {
                continue;
            }
            let right = (u + 1 < w).then_some(i + 1);
            let below = (v + 1 < h).then_some(i + w);
            for j in [right, below].into_iter().flatten().filter(|&j| counts(j)) {
                let jump = match (d[i].is_finite(), d[j].is_finite()) {
                    (true, true) => (d[i] - d[j]).abs() > step_px,
                    (false, false) => false,
                    _ => true,
                };
                if jump {
                    edge[i] = true;
                    edge[j] = true;
                }
            }
        }
    }
    // Separable L∞ dilation by `radius`: rows, then columns, with running counts.
    let dilate =
        |line: &mut dyn FnMut(usize) -> usize, len: usize, src: &[bool], out: &mut [bool]| {
            let mut count = 0usize;
            for k in 0..len + radius {
                if k < len && src[line(k)] {
                    count += 1;
                }
                if k > 2 * radius && src[line(k - 2 * radius - 1)] {
                    count -= 1;
                }
                if k >= radius {
                    out[line(k - radius)] = count > 0;
                }
            }
        };
    let mut rows = vec![false; w * h];
    for v in 0..h {
        dilate(&mut |k| v * w + k, w, &edge, &mut rows);
    }
    let mut near = vec![false; w * h];
    for u in 0..w {
        dilate(&mut |k| k * w + u, h, &rows, &mut near);
    }
    for (n, &s) in near.iter_mut().zip(status) {
        *n &= s != MatchStatus::OutOfRoi;
    }
    near
}

/// Replaces the result near depth edges with a smaller-window match (see
/// [`StereoMatcherConfig::edge_windows`]), matching only the box around those pixels.
fn rematch_near_edges(
    left: &[&Image<f32>],
    right: &[&Image<f32>],
    config: &StereoMatcherConfig,
    edge: &EdgeWindows,
    result: &mut StereoResult,
) -> Result<(), StereoError> {
    let w = result.disparity_px.width() as usize;
    let near = near_depth_edges(result, edge.step_px, config.window_radius_px as usize);
    let (mut u0, mut v0, mut u1, mut v1) = (usize::MAX, usize::MAX, 0, 0);
    for (i, _) in near.iter().enumerate().filter(|(_, n)| **n) {
        let (u, v) = (i % w, i / w);
        (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
    }
    if u0 > u1 {
        return Ok(());
    }
    let small_config = StereoMatcherConfig {
        window_radius_px: edge.window_radius_px,
        edge_windows: None,
        speckle: None,
        ..*config
    };
    let bbox = PixelRect::new(
        u0 as u32,
        v0 as u32,
        (u1 - u0 + 1) as u32,
        (v1 - v0 + 1) as u32,
    );
    let small = match_windows(left, right, &small_config, Some(bbox))?;
    for (i, _) in near.iter().enumerate().filter(|(_, n)| **n) {
        result.disparity_px.data_mut()[i] = small.disparity_px.data()[i];
        result.status.data_mut()[i] = small.status.data()[i];
        result.correlation.data_mut()[i] = small.correlation.data()[i];
    }
    Ok(())
}

/// One window size's matching over `roi`, without the speckle pass; `left` and `right` are
/// equally long (≥ 1) sequences of equally sized images.
fn match_windows(
    left: &[&Image<f32>],
    right: &[&Image<f32>],
    config: &StereoMatcherConfig,
    roi: Option<PixelRect>,
) -> Result<StereoResult, StereoError> {
    let (Some(first_left), Some(first_right)) = (left.first(), right.first()) else {
        return Err(StereoError::ShotCount {
            left: left.len(),
            right: right.len(),
        });
    };
    let (width, height) = (first_left.width(), first_left.height());
    if (first_right.width(), first_right.height()) != (width, height) {
        return Err(StereoError::SizeMismatch {
            left_width: width,
            left_height: height,
            right_width: first_right.width(),
            right_height: first_right.height(),
        });
    }
    let roi = roi.unwrap_or(PixelRect::full(width, height));
    if roi.is_empty() {
        return Err(StereoError::EmptyRoi { roi });
    }
    if !roi.fits_in(width, height) {
        return Err(StereoError::RoiOutsideImage { roi, width, height });
    }
    let max_px = config.disparity_range.max_px();
    if max_px >= width {
        return Err(StereoError::DisparityRangeTooWide { max_px, width });
    }

    let mut disparity_px = Image::filled(width, height, f32::NAN)?;
    let mut status = Image::filled(width, height, MatchStatus::OutOfRoi)?;
    let mut correlation = Image::filled(width, height, f32::NAN)?;
    let w = width as usize;
    for v in roi.v_min as usize..roi.v_end() as usize {
        status.data_mut()[v * w + roi.u_min as usize..v * w + roi.u_end() as usize]
            .fill(MatchStatus::NoCandidate);
    }

    if let Some(plan) = MatchPlan::new(w, height as usize, &roi, config) {
        let patches = Patches::new(&plan, left, right, config.min_window_std)?;
        let params = BandParams {
            select: SelectParams {
                min_correlation: config.min_correlation,
                uniqueness_factor: 1.0 - config.uniqueness_margin,
                subpixel: config.subpixel,
            },
            left_right_max_diff_px: config.left_right_max_diff_px,
            shifted_window_min_gain: config.shifted_window_min_gain,
        };
        let rows = plan.out_rows.clone();
        let bands = BANDS_PER_THREAD * rayon::current_num_threads().max(1);
        let band_rows = rows.len().div_ceil(bands).max(MIN_BAND_ROWS);
        let span = rows.start * w..rows.end * w;
        disparity_px.data_mut()[span.clone()]
            .par_chunks_mut(band_rows * w)
            .zip(status.data_mut()[span.clone()].par_chunks_mut(band_rows * w))
            .zip(correlation.data_mut()[span].par_chunks_mut(band_rows * w))
            .enumerate()
            .for_each(|(band, ((disparity_px, status), correlation))| {
                let first = rows.start + band * band_rows;
                let band_range = first..first + disparity_px.len() / w;
                let out = BandOutput {
                    disparity_px,
                    status,
                    correlation,
                };
                match_band(&plan, &patches, &params, band_range, out);
            });
    }

    Ok(StereoResult {
        disparity_px,
        status,
        correlation,
        roi,
        disparity_range: config.disparity_range,
    })
}
