//! Choosing a disparity from one pixel's score curve: winner, checks, subpixel fit.

use super::{MatchStatus, SubpixelFit};

/// The thresholds of the per-pixel checks.
#[derive(Clone, Copy, Debug)]
pub(super) struct SelectParams {
    pub min_correlation: f32,
    /// `1 − uniqueness_margin`.
    pub uniqueness_factor: f32,
    pub subpixel: SubpixelFit,
}

/// The outcome for one pixel: the integer winner, its score, and either a refined disparity
/// offset or the check that failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Selection {
    pub best_index: usize,
    pub best_score: f32,
    /// Subpixel offset in [−0.5, 0.5] added to the winner's disparity.
    pub offset: f32,
    pub status: MatchStatus,
}

/// The largest value of a slice (−∞ when empty), in a form the compiler vectorises.
#[inline]
pub(super) fn max_score(scores: &[f32]) -> f32 {
    const LANES: usize = 8;
    let mut lanes = [f32::NEG_INFINITY; LANES];
    let chunks = scores.chunks_exact(LANES);
    let tail = chunks.remainder();
    for chunk in chunks {
        for (m, &s) in lanes.iter_mut().zip(chunk) {
            *m = if s > *m { s } else { *m };
        }
    }
    lanes
        .into_iter()
        .chain(tail.iter().copied())
        .fold(f32::NEG_INFINITY, |m, s| if s > m { s } else { m })
}

/// Picks the best of `scores` (ZNCC, higher is better; at least one entry, all finite) and runs
/// the correlation, range-limit and uniqueness checks, then the subpixel fit.
#[inline]
pub(super) fn select(scores: &[f32], params: &SelectParams) -> Selection {
    let best_score = max_score(scores);
    let best_index = scores.iter().position(|&s| s == best_score).unwrap_or(0);
    let verdict = |status| Selection {
        best_index,
        best_score,
        offset: 0.0,
        status,
    };
    if best_score < params.min_correlation {
        return verdict(MatchStatus::LowCorrelation);
    }
    if best_index == 0 || best_index + 1 >= scores.len() {
        return verdict(MatchStatus::RangeLimit);
    }
    let second = max_score(&scores[..best_index - 1]).max(max_score(&scores[best_index + 2..]));
    if 1.0 - best_score > params.uniqueness_factor * (1.0 - second) {
        return verdict(MatchStatus::NotUnique);
    }
    let (minus, plus) = (scores[best_index - 1], scores[best_index + 1]);
    let offset = subpixel_offset(params.subpixel, minus, best_score, plus);
    Selection {
        best_index,
        best_score,
        offset,
        status: MatchStatus::Valid,
    }
}

/// Offset in [−0.5, 0.5] of the peak of a score curve sampled at −1, 0, +1, with `centre` the
/// largest of the three.
#[inline]
pub(super) fn subpixel_offset(fit: SubpixelFit, minus: f32, centre: f32, plus: f32) -> f32 {
    let offset = match fit {
        SubpixelFit::None => 0.0,
        SubpixelFit::Parabola => {
            let curvature = minus - 2.0 * centre + plus;
            if curvature < 0.0 {
                0.5 * (minus - plus) / curvature
            } else {
                0.0
            }
        }
        SubpixelFit::Equiangular => {
            let rise = if plus >= minus {
                centre - minus
            } else {
                centre - plus
            };
            if rise > 0.0 {
                0.5 * (plus - minus) / rise
            } else {
                0.0
            }
        }
    };
    offset.clamp(-0.5, 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PARAMS: SelectParams = SelectParams {
        min_correlation: 0.5,
        uniqueness_factor: 0.85,
        subpixel: SubpixelFit::Parabola,
    };

    #[test]
    fn parabola_and_v_fits_recover_their_own_peaks() {
        for true_offset in [-0.4f32, -0.1, 0.0, 0.25, 0.45] {
            let parabola = |x: f32| 1.0 - 0.3 * (x - true_offset).powi(2);
            let fit = subpixel_offset(
                SubpixelFit::Parabola,
                parabola(-1.0),
                parabola(0.0),
                parabola(1.0),
            );
            assert!((fit - true_offset).abs() < 1e-5, "{fit} vs {true_offset}");
            let v = |x: f32| 1.0 - 0.3 * (x - true_offset).abs();
            let fit = subpixel_offset(SubpixelFit::Equiangular, v(-1.0), v(0.0), v(1.0));
            assert!((fit - true_offset).abs() < 1e-5, "{fit} vs {true_offset}");
        }
    }

    #[test]
    fn checks_fire_in_order() {
        let mut curve = vec![0.1f32; 20];
        curve[7] = 0.45;
        assert_eq!(select(&curve, &PARAMS).status, MatchStatus::LowCorrelation);
        curve[7] = 0.95;
        curve[8] = 0.9;
        let s = select(&curve, &PARAMS);
        assert_eq!((s.status, s.best_index), (MatchStatus::Valid, 7));
        assert!(s.offset > 0.0 && s.offset < 0.5);
        // A rival two pixels away breaks uniqueness; one pixel away does not count.
        curve[9] = 0.945;
        assert_eq!(select(&curve, &PARAMS).status, MatchStatus::NotUnique);
        curve[9] = 0.1;
        curve[19] = 0.99;
        assert_eq!(select(&curve, &PARAMS).status, MatchStatus::RangeLimit);
        assert_eq!(max_score(&[]), f32::NEG_INFINITY);
    }
}
