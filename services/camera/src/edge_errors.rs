//! Where a capture's depth errors are, relative to depth edges (evaluation only: it reads the
//! ground-truth depth). Block matching fattens foreground across depth discontinuities: a
//! window that straddles an edge is matched by the texture of whichever side dominates it, so
//! a pixel within the window radius r of an edge can get the other side's depth. Binning the
//! errors by each pixel's distance to the nearest edge shows whether that is what happens.
//!
//! Distances are chessboard (L∞) distances in pixels, the metric of a square window: the
//! `(2r+1)²` window centred on a pixel holds an edge pixel iff the distance is ≤ r.

use glint_geometry::image::Image;

use crate::capture::{CaptureTruth, StereoCapture};

/// A true-depth step between 4-neighbours above this, metres, makes both pixels edge pixels
/// (5 mm: far above the depth change across one pixel of any surface of the scene but
/// grazing ones, well below the part-to-floor steps).
pub const EDGE_STEP_M: f32 = 5e-3;

/// The errors of one range of distances to the nearest depth edge.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EdgeBin {
    /// Distances `min_px..=max_px` (L∞ px).
    pub min_px: u32,
    /// Upper end of the distances, inclusive (L∞ px); `u32::MAX` for the last bin.
    pub max_px: u32,
    /// Part pixels at these distances, with matched depth.
    pub valid: usize,
    /// Of those, more than 5 mm farther than the truth.
    pub farther_5mm: usize,
    /// Of those, more than 5 mm nearer than the truth.
    pub nearer_5mm: usize,
}

/// Per pixel, the L∞ distance (px) to the nearest pixel on a depth edge of `gt_depth_m`
/// (a step > [`EDGE_STEP_M`] to a 4-neighbour, or a surface next to nothing), `u32::MAX`
/// when the image has no edge. Two-pass chamfer transform, exact for L∞.
pub fn distance_to_depth_edge(gt_depth_m: &Image<f32>) -> Image<u32> {
    let (w, h) = (gt_depth_m.width() as usize, gt_depth_m.height() as usize);
    let z = gt_depth_m.data();
    let step = |a: f32, b: f32| match (a.is_finite(), b.is_finite()) {
        (true, true) => (a - b).abs() > EDGE_STEP_M,
        (false, false) => false,
        _ => true,
    };
    let far = u32::MAX / 2;
    let mut distance = Image::filled_like(gt_depth_m, far);
    let d = distance.data_mut();
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            let edge = (u + 1 < w && step(z[i], z[i + 1]))
                || (u > 0 && step(z[i], z[i - 1]))
                || (v + 1 < h && step(z[i], z[i + w]))
                || (v > 0 && step(z[i], z[i - w]));
            if edge {
                d[i] = 0;
            }
        }
    }
    // Forward pass: neighbours above and to the left; backward: below and to the right.
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            let mut best = d[i];
            if u > 0 {
                best = best.min(d[i - 1] + 1);
            }
            if v > 0 {
                best = best.min(d[i - w] + 1);
                if u > 0 {
                    best = best.min(d[i - w - 1] + 1);
                }
                if u + 1 < w {
                    best = best.min(d[i - w + 1] + 1);
                }
            }
            d[i] = best;
        }
    }
    for v in (0..h).rev() {
        for u in (0..w).rev() {
            let i = v * w + u;
            let mut best = d[i];
            if u + 1 < w {
                best = best.min(d[i + 1] + 1);
            }
            if v + 1 < h {
                best = best.min(d[i + w] + 1);
                if u + 1 < w {
                    best = best.min(d[i + w + 1] + 1);
                }
                if u > 0 {
                    best = best.min(d[i + w - 1] + 1);
                }
            }
            d[i] = best;
        }
    }
    // Still `far` (or more): no edge reached it, so the image has none.
    for x in d.iter_mut().filter(|x| **x >= far) {
        *x = u32::MAX;
    }
    distance
}

/// Bins the matched depth of the part pixels (labels `labels`) of `capture` by distance to
/// the nearest depth edge of its ground truth `truth`: `bounds` are the bins' upper ends
/// (inclusive, increasing), and a last bin takes everything farther.
pub fn errors_by_edge_distance(
    capture: &StereoCapture,
    truth: &CaptureTruth,
    labels: &[u16],
    bounds: &[u32],
) -> Vec<EdgeBin> {
    let distance = distance_to_depth_edge(&truth.depth_m);
    let mut bins: Vec<EdgeBin> = bounds
        .iter()
        .scan(0u32, |lo, &hi| {
            let bin = EdgeBin {
                min_px: *lo,
                max_px: hi,
                ..EdgeBin::default()
            };
            *lo = hi + 1;
            Some(bin)
        })
        .collect();
    bins.push(EdgeBin {
        min_px: bounds.last().map_or(0, |b| b + 1),
        max_px: u32::MAX,
        ..EdgeBin::default()
    });
    let true_depth = truth.depth_m.data();
    let matched = capture.depth.depth_m.data();
    for (i, &label) in truth.label.data().iter().enumerate() {
        if !labels.contains(&label) || !true_depth[i].is_finite() || !matched[i].is_finite() {
            continue;
        }
        let dist = distance.data()[i];
        let Some(bin) = bins.iter_mut().find(|b| dist <= b.max_px) else {
            continue;
        };
        bin.valid += 1;
        let e = matched[i] - true_depth[i];
        if e > 5e-3 {
            bin.farther_5mm += 1;
        } else if e < -5e-3 {
            bin.nearer_5mm += 1;
        }
    }
    bins
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chessboard_distance_to_a_step() {
        // 9×7 at 0.5 m with a 3×3 block 20 mm nearer in the middle: its 9 pixels and the
        // ring around them touch a step.
        let mut z = vec![0.5f32; 63];
        for v in 2..5 {
            for u in 3..6 {
                z[v * 9 + u] = 0.48;
            }
        }
        let d = distance_to_depth_edge(&Image::new(9, 7, z).unwrap());
        assert_eq!(d.get(4, 3), Some(1)); // block centre: the block's border is an edge
        assert_eq!(d.get(3, 2), Some(0));
        assert_eq!(d.get(2, 3), Some(0)); // just outside the block, next to it
        assert_eq!(d.get(1, 3), Some(1));
        assert_eq!(d.get(0, 0), Some(2)); // L∞ to (2, 2), left of the block
        assert_eq!(d.get(8, 6), Some(2));
        let flat = distance_to_depth_edge(&Image::filled(4, 4, 0.5f32).unwrap());
        assert!(flat.data().iter().all(|&x| x == u32::MAX));
    }
}
