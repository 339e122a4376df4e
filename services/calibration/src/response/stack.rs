//! Exposure stacks: several images of one static scene, each with its exposure time Δt, in
//! digital numbers (DN) as the camera reads them out (eq 12: I = g(E·Δt)).
//!
//! On disk a stack is the folder format of `glint_camera::dataset::exposure_stack`
//! (`stack.json` + grayscale PNGs of DN), read there; this crate takes the images.

use std::path::Path;

use glint_geometry::image::Image;

use super::ResponseError;

/// An exposure stack in memory, validated: ≥ 2 images of one size, finite Δt > 0 each,
/// every DN ≤ the bit depth's maximum.
#[derive(Clone, Debug)]
pub struct ExposureStack {
    images: Vec<Image<u16>>,
    exposures_s: Vec<f64>,
    bit_depth: u8,
}

impl ExposureStack {
    /// Validates and sorts the images by exposure time (ascending).
    pub fn new(
        images: Vec<Image<u16>>,
        exposures_s: Vec<f64>,
        bit_depth: u8,
    ) -> Result<Self, ResponseError> {
        if !(1..=16).contains(&bit_depth) {
            return Err(ResponseError::Input(format!(
                "bit_depth is {bit_depth}, but must be 1 … 16"
            )));
        }
        if images.len() != exposures_s.len() {
            return Err(ResponseError::Input(format!(
                "{} images but {} exposure times",
                images.len(),
                exposures_s.len()
            )));
        }
        if images.len() < 2 {
            return Err(ResponseError::Input(format!(
                "an exposure stack needs at least 2 exposures (5 or more recommended), got {}",
                images.len()
            )));
        }
        let max_dn = max_dn(bit_depth);
        let (w, h) = (images[0].width(), images[0].height());
        for (i, (img, &dt)) in images.iter().zip(&exposures_s).enumerate() {
            if !(dt.is_finite() && dt > 0.0) {
                return Err(ResponseError::Input(format!(
                    "images[{i}].exposure_s is {dt}, but must be a finite time > 0 s"
                )));
            }
            if (img.width(), img.height()) != (w, h) {
                return Err(ResponseError::Input(format!(
                    "images[{i}] is {}×{} px but images[0] is {w}×{h} px",
                    img.width(),
                    img.height()
                )));
            }
            if let Some(&dn) = img.data().iter().find(|&&d| d > max_dn) {
                return Err(ResponseError::Input(format!(
                    "images[{i}] has DN {dn}, above {max_dn} for bit_depth {bit_depth}"
                )));
            }
        }
        let mut order: Vec<usize> = (0..images.len()).collect();
        order.sort_by(|&a, &b| exposures_s[a].total_cmp(&exposures_s[b]));
        for pair in order.windows(2) {
            if exposures_s[pair[0]] == exposures_s[pair[1]] {
                return Err(ResponseError::Input(format!(
                    "images[{}] and images[{}] have the same exposure_s {}: exposures must differ",
                    pair[0], pair[1], exposures_s[pair[0]]
                )));
            }
        }
        Ok(Self {
            images: order.iter().map(|&i| images[i].clone()).collect(),
            exposures_s: order.iter().map(|&i| exposures_s[i]).collect(),
            bit_depth,
        })
    }

    /// A synthetic stack: `radiance` read out by `sensor` at each of `exposures_s` (seeded shot
    /// and read noise, exposure j with seed `seed + j`). For tests and simulated captures.
    pub fn read_out(
        sensor: &glint_render::sensor::Sensor,
        radiance: &Image<f32>,
        exposures_s: &[f64],
        seed: u64,
    ) -> Result<Self, ResponseError> {
        let images = exposures_s
            .iter()
            .enumerate()
            .map(|(j, &dt)| {
                glint_render::sensor::Sensor {
                    exposure_s: dt as f32,
                    ..sensor.clone()
                }
                .read_out(radiance, seed.wrapping_add(j as u64))
            })
            .collect();
        Self::new(images, exposures_s.to_vec(), sensor.bit_depth)
    }

    /// The images, by ascending exposure time.
    pub fn images(&self) -> &[Image<u16>] {
        &self.images
    }
    /// Exposure times Δt, seconds, ascending.
    pub fn exposures_s(&self) -> &[f64] {
        &self.exposures_s
    }
    /// Bits per pixel of the readout, 1 … 16.
    pub fn bit_depth(&self) -> u8 {
        self.bit_depth
    }
    /// Largest DN.
    pub fn max_dn(&self) -> u16 {
        max_dn(self.bit_depth)
    }
    /// (width, height) in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.images[0].width(), self.images[0].height())
    }
}

/// Largest DN of `bit_depth` bits (1 … 16).
pub fn max_dn(bit_depth: u8) -> u16 {
    ((1u32 << bit_depth.clamp(1, 16)) - 1) as u16
}

fn file_error(path: &Path, message: impl ToString) -> ResponseError {
    ResponseError::File {
        path: path.to_owned(),
        message: message.to_string(),
    }
}

pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ResponseError> {
    glint_geometry::io::write_file_atomically(path, bytes).map_err(|e| file_error(path, e))
}
