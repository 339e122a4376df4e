//! Removal of small isolated disparity regions: flood fill over 4-neighbours whose disparities
//! differ by at most a step, O(pixels).

use super::{MatchStatus, PixelRect, SpeckleFilter};

/// Marks valid pixels of `roi` that belong to regions of fewer than `filter.min_region_px`
/// pixels as [`MatchStatus::Speckle`] and clears their disparity. Returns how many were removed.
pub(super) fn remove_speckles(
    disparity_px: &mut [f32],
    status: &mut [MatchStatus],
    width: usize,
    roi: &PixelRect,
    filter: &SpeckleFilter,
) -> usize {
    let (u0, v0) = (roi.u_min as usize, roi.v_min as usize);
    let (w, h) = (roi.width as usize, roi.height as usize);
    let index = |x: usize, y: usize| (v0 + y) * width + u0 + x;
    let mut visited = vec![false; w * h];
    let mut stack: Vec<(u32, u32)> = Vec::new();
    let mut region: Vec<(u32, u32)> = Vec::new();
    let mut removed = 0;
    for y0 in 0..h {
        for x0 in 0..w {
            if visited[y0 * w + x0] || !status[index(x0, y0)].is_valid() {
                continue;
            }
            visited[y0 * w + x0] = true;
            stack.push((x0 as u32, y0 as u32));
            region.clear();
            while let Some((x, y)) = stack.pop() {
                let (x, y) = (x as usize, y as usize);
                region.push((x as u32, y as u32));
                let d = disparity_px[index(x, y)];
                let neighbours = [
                    (x.wrapping_sub(1), y),
                    (x + 1, y),
                    (x, y.wrapping_sub(1)),
                    (x, y + 1),
                ];
                for (nx, ny) in neighbours {
                    if nx >= w || ny >= h || visited[ny * w + nx] {
                        continue;
                    }
                    let i = index(nx, ny);
                    if status[i].is_valid() && (disparity_px[i] - d).abs() <= filter.max_step_px {
                        visited[ny * w + nx] = true;
                        stack.push((nx as u32, ny as u32));
                    }
                }
            }
            if region.len() < filter.min_region_px as usize {
                for &(x, y) in &region {
                    let i = index(x as usize, y as usize);
                    status[i] = MatchStatus::Speckle;
                    disparity_px[i] = f32::NAN;
                }
                removed += region.len();
            }
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_islands_go_large_regions_stay() {
        let (w, h) = (8, 6);
        let mut disparity = vec![10.0f32; w * h];
        let mut status = vec![MatchStatus::Valid; w * h];
        // A 2-pixel island at a different disparity, and one invalid pixel.
        disparity[2 * w + 3] = 20.0;
        disparity[2 * w + 4] = 20.5;
        status[5 * w + 7] = MatchStatus::NoTexture;
        disparity[5 * w + 7] = f32::NAN;
        let filter = SpeckleFilter {
            min_region_px: 3,
            max_step_px: 1.0,
        };
        let removed = remove_speckles(
            &mut disparity,
            &mut status,
            w,
            &PixelRect::full(w as u32, h as u32),
            &filter,
        );
        assert_eq!(removed, 2);
        assert_eq!(status[2 * w + 3], MatchStatus::Speckle);
        assert!(disparity[2 * w + 4].is_nan());
        assert_eq!(status[0], MatchStatus::Valid);
        assert_eq!(status[5 * w + 7], MatchStatus::NoTexture);
    }
}
