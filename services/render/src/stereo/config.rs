//! Matcher parameters and the disparity search range.

use super::StereoError;
use glint_geometry::camera::StereoRig;

/// The integer disparities searched, `min_px..=max_px` (d = u_L − u_R, pixels).
///
/// A best match on either end of the range is rejected ([`super::MatchStatus::RangeLimit`]):
/// the true disparity may lie outside, and the subpixel fit needs a neighbour on each side.
/// [`DisparityRange::from_depth_range`] therefore pads the range by one pixel each way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DisparityRange {
    min_px: u32,
    max_px: u32,
}

impl DisparityRange {
    /// The disparities `min_px..=max_px`; needs `min_px ≤ max_px ≤ 65535`.
    pub fn new(min_px: u32, max_px: u32) -> Result<Self, StereoError> {
        if min_px > max_px || max_px > u16::MAX as u32 {
            return Err(StereoError::BadDisparityRange { min_px, max_px });
        }
        Ok(Self { min_px, max_px })
    }

    /// The disparities that see depths `near_m..=far_m` (metres along the optical axis) with
    /// `rig`, padded by one pixel each way so that depths at both ends still get an interior
    /// cost minimum: `min = ⌊f·b/far⌋ − 1`, `max = ⌈f·b/near⌉ + 1`.
    pub fn from_depth_range(rig: &StereoRig, near_m: f64, far_m: f64) -> Result<Self, StereoError> {
        if !(near_m.is_finite() && far_m.is_finite() && near_m > 0.0 && near_m < far_m) {
            return Err(StereoError::BadDepthRange { near_m, far_m });
        }
        let d_far = rig.disparity_from_depth(far_m);
        let d_near = rig.disparity_from_depth(near_m);
        if !(d_near.is_finite() && d_near < u16::MAX as f64 - 1.0) {
            return Err(StereoError::BadDepthRange { near_m, far_m });
        }
        let min_px = (d_far.floor() - 1.0).max(0.0) as u32;
        let max_px = d_near.ceil() as u32 + 1;
        Self::new(min_px, max_px)
    }

    /// Smallest disparity searched, px.
    pub const fn min_px(&self) -> u32 {
        self.min_px
    }
    /// Largest disparity searched, px.
    pub const fn max_px(&self) -> u32 {
        self.max_px
    }
    /// Number of disparities searched, D.
    pub const fn count(&self) -> u32 {
        self.max_px - self.min_px + 1
    }
}

/// How the disparity is refined between integer candidates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SubpixelFit {
    /// Integer disparities only.
    None,
    /// Vertex of the parabola through the scores at k−1, k, k+1.
    Parabola,
    /// Apex of the symmetric "V" through the three scores (Shimizu & Okutomi's equiangular line
    /// fit), meant for L1-like costs.
    Equiangular,
}

/// Removal of small isolated disparity regions (OpenCV's `filterSpeckles`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeckleFilter {
    /// Regions of fewer valid pixels than this are removed.
    pub min_region_px: u32,
    /// 4-neighbours whose disparities differ by at most this (px) belong to one region.
    pub max_step_px: f32,
}

/// Parameters of [`super::match_stereo`]. Intensities are in the images' own units with 1.0 the
/// sensor's full scale (saturation); thresholds below assume that scale.
///
/// The defaults were chosen by measurement (`stereo::tests::parameter_sweep`) on synthetic
/// pairs at N35 geometry: fronto-parallel and 35°/20°-slanted planes at 0.6 m, a square 0.3 m in
/// front of a wall, a low-SNR plane (read noise 0.02 under a pattern spread of ≈ 0.035) and pure
/// noise, each with the texture of Glint's projector (random binary cells of ≈ 2.2 px) and with
/// sparse Gaussian dots. Each field says what the measurement showed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StereoMatcherConfig {
    /// Integer disparities searched. Default: the N35 at 0.4–1.2 m, 90..=275 px.
    pub disparity_range: DisparityRange,
    /// The matching window is `(2r + 1)²` pixels; the cost does not depend on it (running box
    /// sums). Default 5 (11×11): r = 4 leaves a few gross errors at depth edges and loses
    /// coverage at low SNR; r ≥ 6 lowers plane RMSE by < 0.003 px but raises it on slanted
    /// planes (window foreshortening). Measured RMSE at r = 5: 0.031 px fronto-parallel,
    /// 0.096 px slanted, 0.17 px at low SNR.
    pub window_radius_px: u32,
    /// Texture check: a left window whose intensity standard deviation is below this is
    /// [`super::MatchStatus::NoTexture`]; right windows below it score 0. Default 0.01 of full
    /// scale, ≈ 2.5 × the read noise of an 8-bit sensor (1 DN), well under the ≈ 0.2 spread of
    /// a lit pattern window: flat saturated patches (spread 0) and dark windows where only read
    /// noise is left fall below it.
    pub min_window_std: f32,
    /// A best zero-mean normalised cross-correlation below this is
    /// [`super::MatchStatus::LowCorrelation`]. Default 0.5: on pure noise (which passes the
    /// texture check once noise > `min_window_std`) 2 % of pixels survive the other checks
    /// without it and none from 0.4 up, while 0.6–0.7 start to drop true low-SNR matches
    /// (coverage 99.97 % → 99.4 % → 61 %).
    pub min_correlation: f32,
    /// Uniqueness check, on costs `c = 1 − ZNCC`: the best match must satisfy
    /// `c_best ≤ (1 − margin) · c_second`, with `c_second` the best cost more than one pixel
    /// away from the winner. Default 0.15 (OpenCV's `uniquenessRatio` = 15); 0–0.25 changed
    /// nothing measurable behind the other checks, it guards repetitive texture.
    pub uniqueness_margin: f32,
    /// Edge-aware windows: besides the window centred on the pixel, the eight windows shifted
    /// by r along rows, columns and diagonals (each still holding the pixel on its border) are
    /// scored, and a shifted one decides the disparity when its best ZNCC beats the centred
    /// window's by more than this gain. At a depth edge the centred window mixes two surfaces and
    /// its peak drops towards the larger surface's share, while a window shifted onto the
    /// pixel's own surface still scores ≈ 1; inside smooth or slanted surfaces all nine peak
    /// alike and the centred one keeps its unbiased estimate. When contending windows disagree
    /// (one on each side of the edge), the one whose match is left-right consistent wins. The
    /// right-to-left matches of the left-right check use the same rule.
    ///
    /// Default 0.1: in the occlusion scene, matches off by > 2 px fall from 171 (17 of them more
    /// than 2 px from the edge) to 0, and wrongly valid occluded pixels from 159 to 38 (all
    /// within 1 px of the truth), for a slanted-plane RMSE of 0.096 instead of 0.087 px (0.05
    /// would double it: a shifted window on a slant is biased by gradient × r). `None`: centred
    /// windows only, ≈ 20 % faster.
    pub shifted_window_min_gain: Option<f32>,
    /// Subpixel refinement. Default [`SubpixelFit::Parabola`]: ZNCC is quadratic at its peak;
    /// 0.031 px RMSE against 0.051 px for the equiangular fit on the projector texture.
    pub subpixel: SubpixelFit,
    /// Left-right consistency: with `Some(t)`, the right pixel holding the match,
    /// `⌊u + 0.5 − d⌋`, must in turn match back within `t` pixels, `|d_LR − d_RL| ≤ t`.
    /// Default 1 px (OpenCV's `disp12MaxDiff`). `None` skips it, which also spares the `D − 1`
    /// extra columns a region of interest needs on each side for it.
    pub left_right_max_diff_px: Option<f32>,
    /// Small windows at depth edges: see [`EdgeWindows`]. Default
    /// `Some(EdgeWindows { window_radius_px: 3, step_px: 2.0 })`; `None` keeps one window size
    /// everywhere (and halves the time on edge-rich images).
    pub edge_windows: Option<EdgeWindows>,
    /// Default: regions under 25 px (at 1280×1024) with 1 px steps are removed.
    pub speckle: Option<SpeckleFilter>,
}

/// A second, smaller-window match where the first one found a depth edge.
///
/// On parts only 15–40 px wide, the `(2r+1)²` window of a pixel within r of the part's
/// outline holds mostly background texture, and no window shifted onto the part (which is
/// curved, foreshortened and dimmer) scores clearly better, so the pixel takes the
/// background's disparity: on the diffuse twin of a Chrome Screw bin, 13 % of the part pixels
/// with depth were > 5 mm off, 97 % of those within 2 px of the outline
/// (`examples/edge_sweep.rs` in glint-camera). A smaller window straddles less; everywhere
/// else the large window's lower noise is kept.
///
/// After the first pass, every ROI pixel within `window_radius_px` of the large window (L∞)
/// of an edge — 4-neighbours with valid disparities more than `step_px` apart, or a valid
/// pixel next to a missing one — takes the result (disparity or failure status) of a full
/// second match with radius `window_radius_px` here; the speckle pass runs after both.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeWindows {
    /// Radius of the edge windows, smaller than the main window's. Default 3 (7×7): on the
    /// screw's diffuse twin it cut the > 5 mm share from 13.8 % to 5.9 % of matched part
    /// pixels for a coverage of 76 % instead of 81 %; radius 2 cut it to 1.7 % but left a
    /// coverage of 37 % (a 5×5 window holds too few ≈ 2.2 px dots to be unique), radius 4
    /// left 9.3 % at 82 %.
    pub window_radius_px: u32,
    /// Disparity step (px) between 4-neighbours taken for a depth edge. Default 2: at the
    /// N35's f·b = 109.6 px·m a 5 mm step at 0.5 m is 2.2 px, while a surface slanted by 60°
    /// changes disparity by < 0.4 px per pixel at that distance.
    pub step_px: f32,
}

impl StereoMatcherConfig {
    /// The default parameters with the disparity range of `rig` at `near_m..=far_m`.
    pub fn for_depth_range(rig: &StereoRig, near_m: f64, far_m: f64) -> Result<Self, StereoError> {
        Ok(Self {
            disparity_range: DisparityRange::from_depth_range(rig, near_m, far_m)?,
            ..Self::default()
        })
    }

    /// Window side length, `2r + 1`.
    pub const fn window_side_px(&self) -> u32 {
        2 * self.window_radius_px + 1
    }

    /// Checks every parameter's range.
    pub fn validate(&self) -> Result<(), StereoError> {
        let bad = |field, value: f64, valid| {
            Err(StereoError::BadParameter {
                field,
                value,
                valid,
            })
        };
        let range = self.disparity_range;
        if range.min_px > range.max_px || range.max_px > u16::MAX as u32 {
            return Err(StereoError::BadDisparityRange {
                min_px: range.min_px,
                max_px: range.max_px,
            });
        }
        if !(1..=32).contains(&self.window_radius_px) {
            return bad("window_radius_px", self.window_radius_px as f64, "1..=32");
        }
        if !(self.min_window_std.is_finite() && self.min_window_std >= 0.0) {
            return bad("min_window_std", self.min_window_std as f64, "finite, ≥ 0");
        }
        if !(-1.0..=1.0).contains(&self.min_correlation) {
            return bad("min_correlation", self.min_correlation as f64, "[-1, 1]");
        }
        if !(0.0..1.0).contains(&self.uniqueness_margin) {
            return bad("uniqueness_margin", self.uniqueness_margin as f64, "[0, 1)");
        }
        if let Some(g) = self.shifted_window_min_gain
            && !(g.is_finite() && g >= 0.0)
        {
            return bad("shifted_window_min_gain", g as f64, "finite, ≥ 0");
        }
        if let Some(t) = self.left_right_max_diff_px
            && !(t.is_finite() && t >= 0.0)
        {
            return bad("left_right_max_diff_px", t as f64, "finite, ≥ 0");
        }
        if let Some(e) = self.edge_windows {
            if !(1..self.window_radius_px).contains(&e.window_radius_px) {
                return bad(
                    "edge_windows.window_radius_px",
                    e.window_radius_px as f64,
                    "1 ..< window_radius_px",
                );
            }
            if !(e.step_px.is_finite() && e.step_px > 0.0) {
                return bad("edge_windows.step_px", e.step_px as f64, "finite, > 0");
            }
        }
        if let Some(s) = self.speckle
            && !(s.max_step_px.is_finite() && s.max_step_px >= 0.0)
        {
            return bad("speckle.max_step_px", s.max_step_px as f64, "finite, ≥ 0");
        }
        Ok(())
    }
}

impl Default for StereoMatcherConfig {
    fn default() -> Self {
        // The N35 at 0.4–1.2 m: f·b = 109.59 px·m → 91.3..274.0 px, padded to 90..=275.
        let disparity_range = DisparityRange::from_depth_range(&StereoRig::ensenso_n35(), 0.4, 1.2)
            .unwrap_or(DisparityRange {
                min_px: 90,
                max_px: 275,
            });
        Self {
            disparity_range,
            window_radius_px: 5,
            min_window_std: 0.01,
            min_correlation: 0.5,
            uniqueness_margin: 0.15,
            shifted_window_min_gain: Some(0.1),
            subpixel: SubpixelFit::Parabola,
            left_right_max_diff_px: Some(1.0),
            edge_windows: Some(EdgeWindows {
                window_radius_px: 3,
                step_px: 2.0,
            }),
            speckle: Some(SpeckleFilter {
                min_region_px: 25,
                max_step_px: 1.0,
            }),
        }
    }
}
