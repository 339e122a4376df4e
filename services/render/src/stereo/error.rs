//! Why a stereo match was refused.

use super::PixelRect;
use glint_geometry::image::ImageError;

/// Which image of the pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The left camera's image.
    Left,
    /// The right camera's image.
    Right,
}

impl std::fmt::Display for Side {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Side::Left => "left",
            Side::Right => "right",
        })
    }
}

/// Invalid stereo input or configuration. Matching never panics on bad input: it returns one
/// of these.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum StereoError {
    /// The left and right images are not the same size.
    #[error(
        "left image is {left_width}×{left_height} px but right is {right_width}×{right_height} px"
    )]
    SizeMismatch {
        /// Width of the left image, px.
        left_width: u32,
        /// Height of the left image, px.
        left_height: u32,
        /// Width of the right image, px.
        right_width: u32,
        /// Height of the right image, px.
        right_height: u32,
    },
    /// An image has a NaN or infinite value in the pixels the match reads.
    #[error("{side} image has a non-finite value {value} at pixel ({u}, {v})")]
    NonFinite {
        /// The image it is in.
        side: Side,
        /// Its column, px.
        u: u32,
        /// Its row, px.
        v: u32,
        /// The value found.
        value: f32,
    },
    /// The region of interest has no pixel.
    #[error("region of interest {roi} is empty")]
    EmptyRoi {
        /// The region asked for.
        roi: PixelRect,
    },
    /// The region of interest reaches beyond the image.
    #[error("region of interest {roi} exceeds the {width}×{height} px image")]
    RoiOutsideImage {
        /// The region asked for.
        roi: PixelRect,
        /// Image width, px.
        width: u32,
        /// Image height, px.
        height: u32,
    },
    /// A depth range is not finite with 0 < near < far, or its near end needs a disparity
    /// above 65535 px.
    #[error("depth range [{near_m} m, {far_m} m] must be finite with 0 < near < far")]
    BadDepthRange {
        /// Near end, metres along the optical axis.
        near_m: f64,
        /// Far end, metres along the optical axis.
        far_m: f64,
    },
    /// A disparity range has min > max or max > 65535.
    #[error("disparity range [{min_px}, {max_px}] px must have min ≤ max ≤ 65535")]
    BadDisparityRange {
        /// Smallest disparity searched, px.
        min_px: u32,
        /// Largest disparity searched, px.
        max_px: u32,
    },
    /// The largest disparity is at least the image width, so no column can be matched.
    #[error("maximum disparity {max_px} px leaves no column to match in an image {width} px wide")]
    DisparityRangeTooWide {
        /// Largest disparity searched, px.
        max_px: u32,
        /// Image width, px.
        width: u32,
    },
    /// A side of a shot sequence is empty, or the two sides differ in length.
    #[error(
        "a sequence needs at least one shot and as many right as left shots; got {left} left \
         and {right} right"
    )]
    ShotCount {
        /// Number of left shots given.
        left: usize,
        /// Number of right shots given.
        right: usize,
    },
    /// A matcher parameter is outside its valid range.
    #[error("{field} = {value} is out of its valid range ({valid})")]
    BadParameter {
        /// Name of the parameter, as a path into the config.
        field: &'static str,
        /// Its value.
        value: f64,
        /// Its valid range, in words.
        valid: &'static str,
    },
    /// An image could not be made: zero size (an empty input) or the wrong sample count.
    #[error(transparent)]
    Image(#[from] ImageError),
}
