//! Row-major image buffers and depth maps.

/// Why an image buffer was rejected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ImageError {
    /// The width or height is zero; an image needs at least one pixel.
    #[error("image size {width}×{height} px must be non-zero")]
    ZeroSize {
        /// The requested width, px.
        width: u32,
        /// The requested height, px.
        height: u32,
    },
    /// The buffer does not hold exactly `width × height` samples; check the size or the data.
    #[error("image of {width}×{height} px needs {expected} samples, got {actual}")]
    LengthMismatch {
        /// The requested width, px.
        width: u32,
        /// The requested height, px.
        height: u32,
        /// Samples needed, `width × height`.
        expected: usize,
        /// Samples supplied.
        actual: usize,
    },
}

/// A row-major single-channel image; pixel `(u, v)` is column u, row v.
#[derive(Clone, Debug, PartialEq)]
pub struct Image<T> {
    width: u32,
    height: u32,
    data: Vec<T>,
}

impl<T: Copy> Image<T> {
    /// An image over `data`, which must hold exactly `width × height` samples.
    pub fn new(width: u32, height: u32, data: Vec<T>) -> Result<Self, ImageError> {
        if width == 0 || height == 0 {
            return Err(ImageError::ZeroSize { width, height });
        }
        let expected = width as usize * height as usize;
        if data.len() != expected {
            return Err(ImageError::LengthMismatch {
                width,
                height,
                expected,
                actual: data.len(),
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// An image over `data` whose length the caller made `width × height` with both non-zero
    /// (e.g. from validated intrinsics).
    pub(crate) fn from_parts(width: u32, height: u32, data: Vec<T>) -> Self {
        debug_assert!(width > 0 && height > 0 && data.len() == width as usize * height as usize);
        Self {
            width,
            height,
            data,
        }
    }

    /// An image with every pixel `value`.
    pub fn filled(width: u32, height: u32, value: T) -> Result<Self, ImageError> {
        Self::new(width, height, vec![value; width as usize * height as usize])
    }

    /// An image of `other`'s size with every pixel `value`: cannot fail, as `other`'s size is
    /// already valid. The blank canvas for a per-pixel result of `other`.
    pub fn filled_like<U>(other: &Image<U>, value: T) -> Self {
        Self {
            width: other.width,
            height: other.height,
            data: vec![value; other.data.len()],
        }
    }

    /// Width, px.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height, px.
    pub fn height(&self) -> u32 {
        self.height
    }
    /// The samples, row-major: pixel `(u, v)` is at `v × width + u`.
    pub fn data(&self) -> &[T] {
        &self.data
    }
    /// The samples, row-major, mutably.
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }
    /// The row-major sample buffer, consuming the image.
    pub fn into_data(self) -> Vec<T> {
        self.data
    }

    /// The pixel at column `u`, row `v`, or `None` outside the image.
    #[inline]
    pub fn get(&self, u: u32, v: u32) -> Option<T> {
        (u < self.width && v < self.height)
            .then(|| self.data[v as usize * self.width as usize + u as usize])
    }

    /// Sets the pixel at `(u, v)`; ignored outside the image.
    #[inline]
    pub fn set(&mut self, u: u32, v: u32, value: T) {
        if u < self.width && v < self.height {
            self.data[v as usize * self.width as usize + u as usize] = value;
        }
    }

    /// One row.
    #[inline]
    pub fn row(&self, v: u32) -> &[T] {
        let w = self.width as usize;
        &self.data[v as usize * w..(v as usize + 1) * w]
    }

    /// The image of `f` applied to every pixel: same size, so it cannot fail.
    pub fn map<U: Copy>(&self, f: impl FnMut(T) -> U) -> Image<U> {
        Image {
            width: self.width,
            height: self.height,
            data: self.data.iter().copied().map(f).collect(),
        }
    }

    /// The pixels of `rect` as an image of their own, or `None` when `rect` is empty or does
    /// not fit inside this image.
    pub fn cropped(&self, rect: &PixelRect) -> Option<Image<T>> {
        if rect.is_empty() || !rect.fits_in(self.width, self.height) {
            return None;
        }
        let w = self.width as usize;
        let data = (rect.v_min..rect.v_min + rect.height)
            .flat_map(|v| {
                let start = v as usize * w + rect.u_min as usize;
                self.data[start..start + rect.width as usize]
                    .iter()
                    .copied()
            })
            .collect();
        Some(Image {
            width: rect.width,
            height: rect.height,
            data,
        })
    }

    /// The pixel-wise `f(a, b)` of two images, or `None` when their sizes differ.
    pub fn zip_map<U: Copy, V: Copy>(
        &self,
        other: &Image<U>,
        mut f: impl FnMut(T, U) -> V,
    ) -> Option<Image<V>> {
        ((self.width, self.height) == (other.width, other.height)).then(|| Image {
            width: self.width,
            height: self.height,
            data: self
                .data
                .iter()
                .zip(&other.data)
                .map(|(&a, &b)| f(a, b))
                .collect(),
        })
    }
}

/// Digital numbers as intensities normalised to full scale, `dn / max_dn` in [0, 1]: the
/// units the stereo matcher and the depth-uncertainty model (eq 1–5) work in.
pub fn normalised_intensity(dn: &Image<u16>, max_dn: u16) -> Image<f32> {
    let scale = 1.0 / max_dn.max(1) as f32;
    Image {
        width: dn.width,
        height: dn.height,
        data: dn.data.iter().map(|&d| d as f32 * scale).collect(),
    }
}

/// A summed-area table of a `width × height` buffer: the sum over any pixel rectangle in O(1).
/// Sums are `f64` so long rows of small values keep their precision.
#[derive(Clone, Debug)]
pub struct SummedAreaTable {
    width: usize,
    height: usize,
    /// `(width + 1) × (height + 1)`, zero first row and column.
    table: Vec<f64>,
}

impl SummedAreaTable {
    /// The table of `value(u, v)` over a `width × height` grid.
    pub fn from_fn(
        width: usize,
        height: usize,
        mut value: impl FnMut(usize, usize) -> f64,
    ) -> Self {
        let stride = width + 1;
        let mut table = vec![0.0f64; stride * (height + 1)];
        for v in 0..height {
            let mut row = 0.0f64;
            for u in 0..width {
                row += value(u, v);
                let i = (v + 1) * stride + u + 1;
                table[i] = table[i - stride] + row;
            }
        }
        Self {
            width,
            height,
            table,
        }
    }

    /// Σ over columns `u0..u1`, rows `v0..v1` (half-open), clipped to the grid.
    #[inline]
    pub fn sum(&self, u0: usize, v0: usize, u1: usize, v1: usize) -> f64 {
        let (u1, v1) = (u1.min(self.width), v1.min(self.height));
        if u0 >= u1 || v0 >= v1 {
            return 0.0;
        }
        let s = self.width + 1;
        self.table[v1 * s + u1] - self.table[v0 * s + u1] - self.table[v1 * s + u0]
            + self.table[v0 * s + u0]
    }
}

/// A depth map in metres along the optical axis (z, not ray length); NaN where depth is missing.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    /// Depth per pixel, metres; NaN or non-positive where missing.
    pub depth_m: Image<f32>,
}

impl DepthMap {
    /// A depth map over `depth_m` (metres, NaN where missing).
    pub fn new(depth_m: Image<f32>) -> Self {
        Self { depth_m }
    }

    /// Depth at `(u, v)` in metres, `None` where missing or outside.
    pub fn get(&self, u: u32, v: u32) -> Option<f32> {
        self.depth_m.get(u, v).filter(|z| z.is_finite() && *z > 0.0)
    }

    /// Fraction of pixels with a valid depth.
    pub fn coverage(&self) -> f64 {
        let valid = self
            .depth_m
            .data()
            .iter()
            .filter(|z| z.is_finite() && **z > 0.0)
            .count();
        valid as f64 / self.depth_m.data().len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_and_zip_map_keep_the_size() {
        let a = Image::new(2, 1, vec![1u16, 2]).unwrap();
        let doubled = a.map(|x| x as f32 * 2.0);
        assert_eq!((doubled.width(), doubled.height()), (2, 1));
        assert_eq!(doubled.data(), &[2.0, 4.0]);
        let sum = a.zip_map(&doubled, |x, y| x as f32 + y).unwrap();
        assert_eq!(sum.data(), &[3.0, 6.0]);
        assert!(
            a.zip_map(&Image::filled(1, 1, 0u8).unwrap(), |x, _| x)
                .is_none()
        );
    }

    #[test]
    fn buffers_are_checked() {
        assert_eq!(
            Image::<u8>::new(0, 3, vec![]),
            Err(ImageError::ZeroSize {
                width: 0,
                height: 3
            })
        );
        assert_eq!(
            Image::new(2, 3, vec![0u16; 5]),
            Err(ImageError::LengthMismatch {
                width: 2,
                height: 3,
                expected: 6,
                actual: 5
            })
        );
        let mut img = Image::filled(4, 2, 0.0f32).unwrap();
        img.set(3, 1, 2.5);
        assert_eq!(img.get(3, 1), Some(2.5));
        assert_eq!(img.get(4, 1), None);
        assert_eq!(img.row(1), &[0.0, 0.0, 0.0, 2.5]);
    }

    #[test]
    fn summed_area_table_sums_rectangles() {
        let sat = SummedAreaTable::from_fn(5, 4, |u, v| (u + 10 * v) as f64);
        let brute = |u0: usize, v0: usize, u1: usize, v1: usize| -> f64 {
            (v0..v1)
                .flat_map(|v| (u0..u1).map(move |u| (u + 10 * v) as f64))
                .sum()
        };
        assert_eq!(sat.sum(0, 0, 5, 4), brute(0, 0, 5, 4));
        assert_eq!(sat.sum(1, 2, 4, 3), brute(1, 2, 4, 3));
        assert_eq!(sat.sum(3, 1, 9, 9), brute(3, 1, 5, 4)); // clipped
        assert_eq!(sat.sum(2, 2, 2, 4), 0.0);
        let dn = Image::new(2, 1, vec![0u16, 255]).unwrap();
        assert_eq!(normalised_intensity(&dn, 255).data(), &[0.0, 1.0]);
    }

    #[test]
    fn depth_coverage_counts_valid_pixels() {
        let depth = DepthMap::new(Image::new(2, 2, vec![0.5, f32::NAN, 0.0, 0.7]).unwrap());
        assert_eq!(depth.coverage(), 0.5);
        assert_eq!(depth.get(1, 0), None);
        assert_eq!(depth.get(1, 1), Some(0.7));
    }
}

/// A rectangle of whole pixels: columns `u_min..u_min + width`, rows `v_min..v_min + height`.
///
/// Pixel `(u, v)` covers the continuous square `[u, u+1) × [v, v+1)` (its centre is at
/// `(u + 0.5, v + 0.5)`), so the rectangle covers `[u_min, u_end) × [v_min, v_end)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PixelRect {
    /// First column.
    pub u_min: u32,
    /// First row.
    pub v_min: u32,
    /// Number of columns.
    pub width: u32,
    /// Number of rows.
    pub height: u32,
}

impl PixelRect {
    /// The rectangle of `width × height` pixels whose top-left pixel is `(u_min, v_min)`.
    pub const fn new(u_min: u32, v_min: u32, width: u32, height: u32) -> Self {
        Self {
            u_min,
            v_min,
            width,
            height,
        }
    }

    /// The whole of a `width × height` image.
    pub const fn full(width: u32, height: u32) -> Self {
        Self {
            u_min: 0,
            v_min: 0,
            width,
            height,
        }
    }

    /// One past the last column.
    #[inline]
    pub const fn u_end(&self) -> u64 {
        self.u_min as u64 + self.width as u64
    }

    /// One past the last row.
    #[inline]
    pub const fn v_end(&self) -> u64 {
        self.v_min as u64 + self.height as u64
    }

    /// Whether the rectangle holds no pixel (zero width or height).
    pub const fn is_empty(&self) -> bool {
        self.width == 0 || self.height == 0
    }

    /// Number of pixels.
    pub const fn area(&self) -> u64 {
        self.width as u64 * self.height as u64
    }

    /// Whether pixel `(u, v)` lies inside.
    #[inline]
    pub const fn contains(&self, u: u32, v: u32) -> bool {
        u >= self.u_min && (u as u64) < self.u_end() && v >= self.v_min && (v as u64) < self.v_end()
    }

    /// Whether the rectangle lies inside a `width × height` image.
    pub const fn fits_in(&self, width: u32, height: u32) -> bool {
        self.u_end() <= width as u64 && self.v_end() <= height as u64
    }

    /// The part inside a `width × height` image, or `None` if nothing is left.
    pub fn clipped_to(&self, width: u32, height: u32) -> Option<Self> {
        let u_end = self.u_end().min(width as u64) as u32;
        let v_end = self.v_end().min(height as u64) as u32;
        (self.u_min < u_end && self.v_min < v_end).then(|| Self {
            u_min: self.u_min,
            v_min: self.v_min,
            width: u_end - self.u_min,
            height: v_end - self.v_min,
        })
    }

    /// The smallest rectangle holding every continuous point of `[u0, u1] × [v0, v1]` (in
    /// pixel coordinates, e.g. a projected bounding box), clipped to a `width × height` image.
    pub fn covering(u0: f64, v0: f64, u1: f64, v1: f64, width: u32, height: u32) -> Option<Self> {
        if !(u0.is_finite() && v0.is_finite() && u1.is_finite() && v1.is_finite()) {
            return None;
        }
        let lo_u = u0.min(u1).floor().clamp(0.0, width as f64) as u32;
        let lo_v = v0.min(v1).floor().clamp(0.0, height as f64) as u32;
        let hi_u = (u0.max(u1).floor() + 1.0).clamp(0.0, width as f64) as u32;
        let hi_v = (v0.max(v1).floor() + 1.0).clamp(0.0, height as f64) as u32;
        (lo_u < hi_u && lo_v < hi_v).then(|| Self::new(lo_u, lo_v, hi_u - lo_u, hi_v - lo_v))
    }
}

impl std::fmt::Display for PixelRect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "[{}, {}) × [{}, {})",
            self.u_min,
            self.u_end(),
            self.v_min,
            self.v_end()
        )
    }
}

#[cfg(test)]
mod rect_tests {
    use super::*;

    #[test]
    fn clipping_and_covering() {
        let r = PixelRect::new(10, 20, 30, 40);
        assert_eq!((r.u_end(), r.v_end(), r.area()), (40, 60, 1200));
        assert!(r.contains(10, 20) && r.contains(39, 59) && !r.contains(40, 20));
        assert!(r.fits_in(40, 60) && !r.fits_in(39, 60));
        assert_eq!(r.clipped_to(25, 100), Some(PixelRect::new(10, 20, 15, 40)));
        assert_eq!(r.clipped_to(10, 100), None);
        // [3.2, 7.9] covers pixels 3..=7.
        assert_eq!(
            PixelRect::covering(7.9, 1.0, 3.2, 2.5, 100, 100),
            Some(PixelRect::new(3, 1, 5, 2))
        );
        assert_eq!(
            PixelRect::covering(-5.0, -5.0, 2.0, 2.0, 100, 100),
            Some(PixelRect::new(0, 0, 3, 3))
        );
        assert_eq!(PixelRect::covering(120.0, 0.0, 130.0, 1.0, 100, 100), None);
        assert_eq!(PixelRect::covering(f64::NAN, 0.0, 1.0, 1.0, 100, 100), None);
        assert!(PixelRect::new(0, 0, 0, 5).is_empty());
    }
}
