//! What the matcher returns: disparity, per-pixel status, and their conversion to depth.

use super::{DisparityRange, PixelRect};
use glint_geometry::camera::StereoRig;
use glint_geometry::image::{DepthMap, Image};

/// Why a left pixel has, or has no, disparity. Checks run in the order listed; a pixel gets the
/// first that fails.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum MatchStatus {
    /// A disparity passed every check.
    Valid = 0,
    /// Outside the requested region of interest: not computed.
    #[default]
    OutOfRoi = 1,
    /// The matching window does not fit in the left image, or no right window fits for any
    /// searched disparity (the left border band of width `max disparity`).
    NoCandidate = 2,
    /// The left window's intensity spread is below `min_window_std`: flat (e.g. saturated) or
    /// too dark for the pattern to rise above the noise.
    NoTexture = 3,
    /// The best correlation is below `min_correlation`: typically noise-dominated windows.
    LowCorrelation = 4,
    /// The best disparity lies on an end of the searched range (or of the part of it that fits
    /// in the right image): the true one may lie outside.
    RangeLimit = 5,
    /// A candidate more than one pixel away scores nearly as well as the best.
    NotUnique = 6,
    /// The right pixel matched does not match back (occlusions, mismatches).
    LeftRightInconsistent = 7,
    /// Part of a small isolated disparity region.
    Speckle = 8,
}

impl MatchStatus {
    /// Every status, in discriminant order (`ALL[s as usize] == s`).
    pub const ALL: [MatchStatus; 9] = [
        MatchStatus::Valid,
        MatchStatus::OutOfRoi,
        MatchStatus::NoCandidate,
        MatchStatus::NoTexture,
        MatchStatus::LowCorrelation,
        MatchStatus::RangeLimit,
        MatchStatus::NotUnique,
        MatchStatus::LeftRightInconsistent,
        MatchStatus::Speckle,
    ];

    /// Whether this is [`MatchStatus::Valid`].
    #[inline]
    pub const fn is_valid(self) -> bool {
        matches!(self, MatchStatus::Valid)
    }

    /// A short lowercase name for logs and legends.
    pub const fn name(self) -> &'static str {
        match self {
            MatchStatus::Valid => "valid",
            MatchStatus::OutOfRoi => "out of roi",
            MatchStatus::NoCandidate => "no candidate",
            MatchStatus::NoTexture => "no texture",
            MatchStatus::RangeLimit => "range limit",
            MatchStatus::LowCorrelation => "low correlation",
            MatchStatus::NotUnique => "not unique",
            MatchStatus::LeftRightInconsistent => "left-right inconsistent",
            MatchStatus::Speckle => "speckle",
        }
    }
}

/// A disparity map of the left image.
#[derive(Clone, Debug, PartialEq)]
pub struct StereoResult {
    /// Disparity `d = u_L − u_R` (px) of each left pixel's centre; NaN unless `status` is
    /// [`MatchStatus::Valid`].
    pub disparity_px: Image<f32>,
    /// Why each pixel has or lacks a disparity.
    pub status: Image<MatchStatus>,
    /// The ZNCC of the best integer candidate, in [−1, 1]; NaN where no candidate was scored
    /// (outside the ROI, no candidate, no texture).
    pub correlation: Image<f32>,
    /// The region that was matched.
    pub roi: PixelRect,
    /// The disparities that were searched.
    pub disparity_range: DisparityRange,
}

impl StereoResult {
    /// Image width, px.
    pub fn width(&self) -> u32 {
        self.disparity_px.width()
    }
    /// Image height, px.
    pub fn height(&self) -> u32 {
        self.disparity_px.height()
    }

    /// Pixels of each status, indexed by `status as usize` (see [`MatchStatus::ALL`]).
    pub fn status_counts(&self) -> [usize; MatchStatus::ALL.len()] {
        let mut counts = [0; MatchStatus::ALL.len()];
        for s in self.status.data() {
            counts[*s as usize] += 1;
        }
        counts
    }

    /// Fraction of the ROI's pixels with a valid disparity.
    pub fn roi_coverage(&self) -> f64 {
        let valid = self.status_counts()[MatchStatus::Valid as usize];
        valid as f64 / self.roi.area().max(1) as f64
    }
}

/// Depth (m, along the left camera's optical axis) of each left pixel: `z = f·b/d` with the
/// rig's `fx_px` and `baseline_m`; NaN where the disparity is invalid or not positive.
///
/// The rig must describe the rectified images that were matched (same resolution and focal
/// length); the map is in the left camera frame, pixel for pixel with the left image.
pub fn disparity_to_depth(result: &StereoResult, rig: &StereoRig) -> DepthMap {
    let fb = (rig.intrinsics.fx_px * rig.baseline_m) as f32;
    let mut depth_m = result.disparity_px.clone();
    for d in depth_m.data_mut() {
        *d = if *d > 0.0 { fb / *d } else { f32::NAN };
    }
    DepthMap::new(depth_m)
}
