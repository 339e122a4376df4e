//! [`match_stereo`]: validation, planning, the parallel band sweep and the speckle pass.

use super::band::{BandOutput, BandParams, match_band};
use super::plan::{MatchPlan, Patches};
use super::select::SelectParams;
use super::speckle::remove_speckles;
use super::{MatchStatus, PixelRect, StereoError, StereoMatcherConfig, StereoResult};
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
    config.validate()?;
    let (width, height) = (left.width(), left.height());
    if (right.width(), right.height()) != (width, height) {
        return Err(StereoError::SizeMismatch {
            left_width: width,
            left_height: height,
            right_width: right.width(),
            right_height: right.height(),
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

    if let Some(filter) = &config.speckle {
        remove_speckles(disparity_px.data_mut(), status.data_mut(), w, &roi, filter);
    }
    Ok(StereoResult {
        disparity_px,
        status,
        correlation,
        roi,
        disparity_range: config.disparity_range,
    })
}
