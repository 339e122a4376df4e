//! Row-major image buffers and depth maps.

/// Why an image buffer was rejected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ImageError {
    #[error("image size {width}×{height} px must be non-zero")]
    ZeroSize { width: u32, height: u32 },
    #[error("image of {width}×{height} px needs {expected} samples, got {actual}")]
    LengthMismatch {
        width: u32,
        height: u32,
        expected: usize,
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

    /// An image with every pixel `value`.
    pub fn filled(width: u32, height: u32, value: T) -> Result<Self, ImageError> {
        Self::new(width, height, vec![value; width as usize * height as usize])
    }

    pub fn width(&self) -> u32 {
        self.width
    }
    pub fn height(&self) -> u32 {
        self.height
    }
    pub fn data(&self) -> &[T] {
        &self.data
    }
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }
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
}

/// A depth map in metres along the optical axis (z, not ray length); NaN where depth is missing.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    pub depth_m: Image<f32>,
}

impl DepthMap {
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
    fn depth_coverage_counts_valid_pixels() {
        let depth = DepthMap::new(Image::new(2, 2, vec![0.5, f32::NAN, 0.0, 0.7]).unwrap());
        assert_eq!(depth.coverage(), 0.5);
        assert_eq!(depth.get(1, 0), None);
        assert_eq!(depth.get(1, 1), Some(0.7));
    }
}
