//! Per-window mean and spread of an image, from a summed-area table: O(1) per window whatever
//! its size.

/// Sums over the `(2r + 1)²` window centred on each pixel of a `width × height` buffer, over
/// all of its K shots (planes stacked one after another in `data`): a space-time window of
/// `n = (2r + 1)² · K` values.
///
/// For centres whose window fits in the buffer: `sum[i] = Σ x` and `inv_norm[i] = 1/√(Σ (x − x̄)²)`
/// (the ZNCC denominator's factor, x̄ the space-time mean), or 0 when the window's standard
/// deviation is below `min_std` (too little texture to match). Both are 0 where the window does
/// not fit.
pub(super) struct WindowStats {
    pub sum: Vec<f32>,
    pub inv_norm: Vec<f32>,
}

impl WindowStats {
    pub fn compute(data: &[f32], width: usize, height: usize, radius: usize, min_std: f32) -> Self {
        let plane = width * height;
        let shots = data.len().checked_div(plane).unwrap_or(1);
        debug_assert_eq!(data.len(), plane * shots);
        let mut sum = vec![0.0f32; width * height];
        let mut inv_norm = vec![0.0f32; width * height];
        let side = 2 * radius + 1;
        if width < side || height < side {
            return Self { sum, inv_norm };
        }
        // Summed-area tables of x and x² in f64: (width + 1) × (height + 1), zero first row/column.
        let stride = width + 1;
        let mut s1 = vec![0.0f64; stride * (height + 1)];
        let mut s2 = vec![0.0f64; stride * (height + 1)];
        for y in 0..height {
            let (mut row1, mut row2) = (0.0f64, 0.0f64);
            for x in 0..width {
                // Over the shots; one shot adds exactly x and x².
                let (mut value, mut square) = (0.0f64, 0.0f64);
                for k in 0..shots {
                    let shot = data[k * plane + y * width + x] as f64;
                    value += shot;
                    square += shot * shot;
                }
                row1 += value;
                row2 += square;
                let i = (y + 1) * stride + x + 1;
                s1[i] = s1[i - stride] + row1;
                s2[i] = s2[i - stride] + row2;
            }
        }
        let n = (side * side * shots) as f64;
        let min_norm2 = (min_std as f64).powi(2) * n;
        for y in radius..height - radius {
            let (top, bottom) = ((y - radius) * stride, (y + radius + 1) * stride);
            for x in radius..width - radius {
                let (left, right) = (x - radius, x + radius + 1);
                let box_sum = |s: &[f64]| {
                    s[bottom + right] - s[bottom + left] - s[top + right] + s[top + left]
                };
                let (b1, b2) = (box_sum(&s1), box_sum(&s2));
                // Σ(x − x̄)² = Σx² − (Σx)²/n, clamped against rounding.
                let norm2 = (b2 - b1 * b1 / n).max(0.0);
                let i = y * width + x;
                sum[i] = b1 as f32;
                inv_norm[i] = if norm2 > 0.0 && norm2 >= min_norm2 {
                    (1.0 / norm2.sqrt()) as f32
                } else {
                    0.0
                };
            }
        }
        Self { sum, inv_norm }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_brute_force() {
        let (w, h, r) = (9, 7, 2);
        let data: Vec<f32> = (0..w * h).map(|i| ((i * 37 % 11) as f32) * 0.1).collect();
        let stats = WindowStats::compute(&data, w, h, r, 0.0);
        for y in r..h - r {
            for x in r..w - r {
                let window: Vec<f64> = (y - r..=y + r)
                    .flat_map(|yy| (x - r..=x + r).map(move |xx| (yy, xx)))
                    .map(|(yy, xx)| data[yy * w + xx] as f64)
                    .collect();
                let sum: f64 = window.iter().sum();
                let mean = sum / window.len() as f64;
                let norm2: f64 = window.iter().map(|v| (v - mean).powi(2)).sum();
                assert!((stats.sum[y * w + x] as f64 - sum).abs() < 1e-5);
                assert!((stats.inv_norm[y * w + x] as f64 - 1.0 / norm2.sqrt()).abs() < 1e-5);
            }
        }
        assert_eq!(stats.inv_norm[0], 0.0);
        // A flat window has no texture.
        let flat = WindowStats::compute(&[0.7; 25], 5, 5, 2, 1e-3);
        assert_eq!(flat.inv_norm[12], 0.0);
    }
}
