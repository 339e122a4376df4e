//! Stereo matching of rectified pattern images: the depth a structured-light camera reports.
//!
//! # Conventions
//! - Rectified pair, baseline b along +x of the left camera: a point at depth z appears at
//!   `u_R = u_L − d` with disparity `d = f·b/z ≥ 0` (DESIGN.md, "Conventions").
//! - Pixel `(u, v)` is column u, row v, with its centre at `(u + 0.5, v + 0.5)`; a disparity
//!   belongs to the left pixel's centre, so `u_R = u + 0.5 − d` in continuous coordinates.
//! - Intensities are in the images' units with 1.0 = sensor full scale (saturation).
//! - Invalid disparity and depth are NaN, with a [`MatchStatus`] saying why.
//!
//! # Algorithm ([`match_stereo`])
//! Local window matching with zero-mean normalised cross-correlation (ZNCC), winner-takes-all.
//! [`match_stereo_sequence`] matches K shots under K patterns at once (space-time windows: the
//! sums below run over the window and the shots); [`match_stereo`] is its K = 1 case.
//! 1. **Cost.** ZNCC over a `(2r+1)²` window for every integer disparity of the
//!    [`DisparityRange`]. It is invariant to gain and offset between the two cameras, which
//!    matters for shiny parts whose radiance differs between viewpoints. Window sums use
//!    summed-area tables (means, norms) and running column/row sums (the cross term), so the
//!    cost is O(W·H·D), independent of the window size; rows are streamed and no W·H·D volume
//!    is stored: memory is O(W·D·(2r+1)) per worker (`band` has the details). The scores agree
//!    with a brute-force f64 ZNCC to 1e-6.
//! 2. **Window choice.** Besides the centred window, the eight windows shifted by r (each still
//!    holding the pixel) may decide, if their best score beats the centred one's by a margin:
//!    this keeps depth edges sharp, where a centred window mixes two surfaces
//!    ([`StereoMatcherConfig::shifted_window_min_gain`]); when windows on both sides of an edge
//!    contend, the left-right consistent one wins. They are other pixels' centred windows, so
//!    they cost memory traffic (a ring of 2r+1 rows of score curves), not scoring.
//! 3. **Edge windows.** Within r of a depth edge of the result (a disparity step > 2 px or a
//!    hole's border), a second match with a smaller window (7×7) decides instead: on parts
//!    only a few windows wide the large window at the outline is mostly background, which
//!    shifted windows do not cure on curved, dim surfaces ([`EdgeWindows`]).
//! 4. **Checks**, in this order, each with its own [`MatchStatus`]: window fits
//!    (`NoCandidate`); texture — the left window's standard deviation ≥ `min_window_std`
//!    (`NoTexture`: flat saturated patches, dark noise); best ZNCC ≥ `min_correlation`
//!    (`LowCorrelation`); winner not on an end of the range (`RangeLimit`); uniqueness against
//!    the best candidate more than 1 px away (`NotUnique`); left-right consistency
//!    (`LeftRightInconsistent`: occlusions); small isolated regions (`Speckle`).
//! 5. **Subpixel**: parabola through the scores at the winner and its two neighbours.
//!
//! Parallelism: bands of rows on rayon, each with its own scratch (no per-pixel allocation).
//! One 1280×1024 match over 186 disparities takes 0.3 s on two idle cores, 0.55 s on the same
//! two cores under load (`stereo::tests::full_resolution_n35`). Depth edges are localised to
//! ±2 px: beyond the two pixels on either side of an edge, no match was off by more than
//! 0.77 px in the occlusion tests.
//!
//! # Not done, and why
//! - Semi-global aggregation: on the projector's dense random texture the local matcher already
//!   reaches 99–100 % coverage and 0.03–0.1 px RMSE on planes (see [`StereoMatcherConfig`]);
//!   SGM's smoothness terms risk fronto-parallel bias on slanted surfaces, and it needs a
//!   W·H·D cost volume (490 MB at u16 for the N35) or tiling. It was not implemented, so it
//!   was not measured either; it may pay off on weakly textured, inter-reflecting scenes.
//! - Census cost: ZNCC already ignores gain and offset, and saturated (clipped) windows are
//!   caught by the texture check, so census's robustness to radiometric change buys little here.

mod band;
mod config;
mod error;
mod matcher;
mod plan;
mod result;
mod select;
mod speckle;
mod window_stats;

#[cfg(test)]
mod synthetic;
#[cfg(test)]
mod tests;

pub use config::{DisparityRange, EdgeWindows, SpeckleFilter, StereoMatcherConfig, SubpixelFit};
pub use error::{Side, StereoError};
pub use glint_geometry::image::PixelRect;
pub use matcher::{match_stereo, match_stereo_sequence};
pub use result::{MatchStatus, StereoResult, disparity_to_depth};
