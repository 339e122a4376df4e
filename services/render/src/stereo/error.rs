//! Why a stereo match was refused.

use super::PixelRect;
use glint_geometry::image::ImageError;

/// Which image of the pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Left,
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
    #[error(
        "left image is {left_width}×{left_height} px but right is {right_width}×{right_height} px"
    )]
    SizeMismatch {
        left_width: u32,
        left_height: u32,
        right_width: u32,
        right_height: u32,
    },
    #[error("{side} image has a non-finite value {value} at pixel ({u}, {v})")]
    NonFinite {
        side: Side,
        u: u32,
        v: u32,
        value: f32,
    },
    #[error("region of interest {roi} is empty")]
    EmptyRoi { roi: PixelRect },
    #[error("region of interest {roi} exceeds the {width}×{height} px image")]
    RoiOutsideImage {
        roi: PixelRect,
        width: u32,
        height: u32,
    },
    #[error("depth range [{near_m} m, {far_m} m] must be finite with 0 < near < far")]
    BadDepthRange { near_m: f64, far_m: f64 },
    #[error("disparity range [{min_px}, {max_px}] px must have min ≤ max ≤ 65535")]
    BadDisparityRange { min_px: u32, max_px: u32 },
    #[error("maximum disparity {max_px} px leaves no column to match in an image {width} px wide")]
    DisparityRangeTooWide { max_px: u32, width: u32 },
    #[error(
        "a sequence needs at least one shot and as many right as left shots; got {left} left \
         and {right} right"
    )]
    ShotCount { left: usize, right: usize },
    #[error("{field} = {value} is out of its valid range ({valid})")]
    BadParameter {
        field: &'static str,
        value: f64,
        valid: &'static str,
    },
    #[error(transparent)]
    Image(#[from] ImageError),
}
