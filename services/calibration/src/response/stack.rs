//! Exposure stacks: several images of one static scene, each with its exposure time Δt, in
//! digital numbers (DN) as the camera reads them out (eq 12: I = g(E·Δt)).
//!
//! On disk a stack is a directory holding `stack.json`,
//! `{"pattern": "white", "camera": "left", "bit_depth": 8,
//!   "images": [{"exposure_s": 0.00025, "file": "dt_000.png"}, …]}`,
//! and grayscale PNGs of DN beside it (8-bit if `bit_depth` ≤ 8, else 16-bit).

use std::path::{Path, PathBuf};

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

    /// Loads `dir/stack.json` and the PNGs it names.
    pub fn load(dir: &Path) -> Result<Self, ResponseError> {
        let json_path = dir.join("stack.json");
        let text = std::fs::read_to_string(&json_path).map_err(|e| ResponseError::File {
            path: json_path.clone(),
            message: e.to_string(),
        })?;
        let file: StackFile = serde_json::from_str(&text).map_err(|e| ResponseError::File {
            path: json_path.clone(),
            message: e.to_string(),
        })?;
        let mut images = Vec::with_capacity(file.images.len());
        let mut exposures = Vec::with_capacity(file.images.len());
        for entry in &file.images {
            images.push(read_dn_png(&dir.join(&entry.file), file.bit_depth)?);
            exposures.push(entry.exposure_s);
        }
        Self::new(images, exposures, file.bit_depth).map_err(|e| ResponseError::File {
            path: json_path,
            message: e.to_string(),
        })
    }

    /// Writes the stack as `dir/stack.json` + `dt_NNN.png` (each file atomically).
    pub fn save(&self, dir: &Path, pattern: &str, camera: &str) -> Result<(), ResponseError> {
        let mut entries = Vec::new();
        for (i, (img, &dt)) in self.images.iter().zip(&self.exposures_s).enumerate() {
            let file = format!("dt_{i:03}.png");
            write_dn_png(&dir.join(&file), img, self.bit_depth)?;
            entries.push(StackEntry {
                exposure_s: dt,
                file,
            });
        }
        let json = serde_json::to_vec_pretty(&StackFile {
            pattern: pattern.to_owned(),
            camera: camera.to_owned(),
            bit_depth: self.bit_depth,
            images: entries,
        })
        .expect("plain data serialises");
        write_file(&dir.join("stack.json"), &json)
    }

    /// The images, by ascending exposure time.
    pub fn images(&self) -> &[Image<u16>] {
        &self.images
    }
    /// Exposure times Δt, seconds, ascending.
    pub fn exposures_s(&self) -> &[f64] {
        &self.exposures_s
    }
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

#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StackFile {
    pattern: String,
    camera: String,
    bit_depth: u8,
    images: Vec<StackEntry>,
}

#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StackEntry {
    exposure_s: f64,
    file: String,
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

/// Reads a grayscale PNG of DN: 8-bit for `bit_depth` ≤ 8, else 16-bit.
fn read_dn_png(path: &Path, bit_depth: u8) -> Result<Image<u16>, ResponseError> {
    let img = image::open(path).map_err(|e| file_error(path, e))?;
    let (w, h) = (img.width(), img.height());
    let data: Vec<u16> = match (img, bit_depth <= 8) {
        (image::DynamicImage::ImageLuma8(g), true) => {
            g.into_raw().into_iter().map(u16::from).collect()
        }
        (image::DynamicImage::ImageLuma16(g), false) => g.into_raw(),
        (other, _) => {
            return Err(file_error(
                path,
                format!(
                    "is {:?}, but bit_depth {bit_depth} needs a {}-bit grayscale PNG",
                    other.color(),
                    if bit_depth <= 8 { 8 } else { 16 }
                ),
            ));
        }
    };
    Image::new(w, h, data).map_err(|e| file_error(path, e))
}

fn write_dn_png(path: &Path, img: &Image<u16>, bit_depth: u8) -> Result<(), ResponseError> {
    use image::ImageEncoder;
    let mut png = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new(&mut png);
    let result = if bit_depth <= 8 {
        let bytes: Vec<u8> = img.data().iter().map(|&d| d.min(255) as u8).collect();
        encoder.write_image(
            &bytes,
            img.width(),
            img.height(),
            image::ExtendedColorType::L8,
        )
    } else {
        // The image crate takes 16-bit samples in native byte order (PNG's big-endian is its job).
        let bytes: Vec<u8> = img.data().iter().flat_map(|d| d.to_ne_bytes()).collect();
        encoder.write_image(
            &bytes,
            img.width(),
            img.height(),
            image::ExtendedColorType::L16,
        )
    };
    result.map_err(|e| file_error(path, e))?;
    write_file(path, &png)
}

/// The path of a stack's JSON inside its directory.
pub fn stack_json(dir: &Path) -> PathBuf {
    dir.join("stack.json")
}
