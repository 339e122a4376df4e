//! Exposure stacks on disk, for the camera-response calibration:
//! `<scene_dir>/glint/exposure_stack/<im_id:06>/` holds
//!
//! - `stack.json`: `{"pattern": "white", "camera": "left", "bit_depth": 8, "images":
//!   [{"exposure_s": 0.001, "file": "dt_000.png"}, ...]}`, images sorted by increasing
//!   exposure (seconds);
//! - the images, gray PNGs of the sensor's digital numbers: 8-bit when `bit_depth` ≤ 8,
//!   16-bit otherwise (values as read out, not rescaled).
//!
//! `glint capture --exposure-stack` also writes `gt_left_radiance.exr` there: the simulator's
//! radiance, for evaluating a calibration only (the reader ignores it).
//!
//! The view's camera pose, object poses and masks are the BOP scene's usual files for the
//! same `im_id`; the rig is `glint/rig.json` ([`super::rig_file`]).

use std::path::{Path, PathBuf};

use glint_geometry::image::Image;
use serde_json::json;

use super::error::{DatasetError, create_directory};
use super::image_files::{decode_image, gray8_from, gray16_from, write_png_u8, write_png_u16};
use super::json::{JsonNode, read_json_file, write_pretty_json};
use crate::exposure::ExposureStack;

/// The stack's description file inside its directory.
pub const STACK_JSON: &str = "stack.json";

/// An exposure stack read back from its directory.
#[derive(Clone, Debug, PartialEq)]
pub struct ExposureStackFiles {
    /// The directory read.
    pub dir: PathBuf,
    /// What the projector showed (`"white"` for Glint's stacks).
    pub pattern: String,
    /// Which camera took it (`"left"`).
    pub camera: String,
    /// Bits of the digital numbers.
    pub bit_depth: u8,
    /// Exposure times, seconds, strictly increasing.
    pub exposures_s: Vec<f64>,
    /// The images, same order, as digital numbers (8-bit files widened to u16).
    pub images: Vec<Image<u16>>,
}

/// Writes `stack` into `dir` (created if missing): the images first, then `stack.json`, each
/// atomically. An older `stack.json` is removed before any image is replaced, so an
/// interrupted write never leaves a description that points at mixed images.
pub fn write_exposure_stack(dir: &Path, stack: &ExposureStack) -> Result<(), DatasetError> {
    let json_path = dir.join(STACK_JSON);
    if !(1..=16).contains(&stack.bit_depth) {
        return Err(DatasetError::Invalid {
            path: json_path,
            problem: format!("bit depth {} must be 1 to 16", stack.bit_depth),
        });
    }
    if stack.left.len() != stack.exposures_s.len() {
        return Err(DatasetError::Invalid {
            path: json_path,
            problem: format!(
                "{} images for {} exposure times",
                stack.left.len(),
                stack.exposures_s.len()
            ),
        });
    }
    create_directory(dir)?;
    if json_path.exists() {
        std::fs::remove_file(&json_path).map_err(|source| DatasetError::Read {
            path: json_path.clone(),
            source,
        })?;
    }
    let mut entries = Vec::with_capacity(stack.left.len());
    for (k, (image, &dt)) in stack.left.iter().zip(&stack.exposures_s).enumerate() {
        let file = format!("dt_{k:03}.png");
        let path = dir.join(&file);
        if stack.bit_depth <= 8 {
            write_png_u8(&path, &image.map(|d| d.min(255) as u8))?;
        } else {
            write_png_u16(&path, image)?;
        }
        entries.push(json!({"exposure_s": dt, "file": file}));
    }
    let value = json!({
        "pattern": "white",
        "camera": "left",
        "bit_depth": stack.bit_depth,
        "images": entries,
    });
    write_pretty_json(&json_path, &value)
}

impl ExposureStackFiles {
    /// Reads the stack in `dir`. Errors name the file and, for `stack.json`, the key: a
    /// missing or non-positive exposure, exposures not strictly increasing, a file outside
    /// `dir`, an image whose bit depth or size disagrees, a value above `2^bit_depth − 1`.
    pub fn read(dir: impl Into<PathBuf>) -> Result<Self, DatasetError> {
        let dir = dir.into();
        let json_path = dir.join(STACK_JSON);
        let value = read_json_file(&json_path)?;
        let root = JsonNode::root(&json_path, &value);
        let pattern = root.field("pattern")?.str()?.to_owned();
        let camera = root.field("camera")?.str()?.to_owned();
        let bits_node = root.field("bit_depth")?;
        let bit_depth = bits_node.integer::<u8>()?;
        if !(1..=16).contains(&bit_depth) {
            return Err(bits_node.error(format!("{bit_depth} bits: must be 1 to 16")));
        }
        let max_dn = ((1u32 << bit_depth) - 1) as u16;
        let images_node = root.field("images")?;
        let items = images_node.items()?;
        if items.len() < 2 {
            return Err(
                images_node.error(format!("{} image(s); a stack has at least 2", items.len()))
            );
        }
        let mut exposures_s = Vec::with_capacity(items.len());
        let mut images: Vec<Image<u16>> = Vec::with_capacity(items.len());
        for item in &items {
            let dt_node = item.field("exposure_s")?;
            let dt = dt_node.f64()?;
            if dt <= 0.0 {
                return Err(dt_node.error(format!("{dt} s must be positive")));
            }
            if let Some(&previous) = exposures_s.last()
                && dt <= previous
            {
                return Err(dt_node.error(format!(
                    "{dt} s after {previous} s: exposures must increase strictly"
                )));
            }
            let file_node = item.field("file")?;
            let file = file_node.str()?;
            let relative = Path::new(file);
            if relative.components().count() != 1 || relative.is_absolute() || file == ".." {
                return Err(file_node.error(format!(
                    "{file:?} must be a plain file name inside {}",
                    dir.display()
                )));
            }
            let path = dir.join(relative);
            let decoded = decode_image(&path)?;
            let image = if bit_depth <= 8 {
                gray8_from(&path, decoded)?.map(u16::from)
            } else {
                gray16_from(&path, decoded)?
            };
            if let Some(first) = images.first()
                && (first.width(), first.height()) != (image.width(), image.height())
            {
                return Err(DatasetError::ImageContent {
                    path,
                    problem: format!(
                        "{}×{} px, but the stack's first image is {}×{} px",
                        image.width(),
                        image.height(),
                        first.width(),
                        first.height()
                    ),
                });
            }
            if let Some(k) = image.data().iter().position(|&d| d > max_dn) {
                let w = image.width() as usize;
                return Err(DatasetError::Pixel {
                    path,
                    u: (k % w) as u32,
                    v: (k / w) as u32,
                    problem: format!(
                        "value {} exceeds {max_dn}, the largest of {bit_depth} bits",
                        image.data()[k]
                    ),
                });
            }
            exposures_s.push(dt);
            images.push(image);
        }
        Ok(Self {
            dir,
            pattern,
            camera,
            bit_depth,
            exposures_s,
            images,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;

    fn stack(bit_depth: u8) -> ExposureStack {
        let max = (1u32 << bit_depth) - 1;
        let image = |k: u32| {
            let data = (0..12u32)
                .map(|i| ((i * 37 + k * 11) % (max + 1)) as u16)
                .collect();
            Image::new(4, 3, data).unwrap()
        };
        ExposureStack {
            t_w_c: Isometry3::identity(),
            exposures_s: vec![2.5e-4, 1e-3, 8e-3],
            left: (0..3).map(image).collect(),
            bit_depth,
        }
    }

    #[test]
    fn stacks_round_trip_at_8_and_12_bits() {
        for bits in [8, 12] {
            let dir = tempfile::tempdir().unwrap();
            let s = stack(bits);
            write_exposure_stack(dir.path(), &s).unwrap();
            let back = ExposureStackFiles::read(dir.path()).unwrap();
            assert_eq!(back.exposures_s, s.exposures_s);
            assert_eq!(back.images, s.left);
            assert_eq!((back.bit_depth, back.pattern.as_str()), (bits, "white"));
            assert_eq!(back.camera, "left");
            let decoded = image::open(dir.path().join("dt_001.png")).unwrap();
            let expected = if bits <= 8 {
                image::ColorType::L8
            } else {
                image::ColorType::L16
            };
            assert_eq!(decoded.color(), expected);
        }
    }

    #[test]
    fn bad_stacks_name_file_and_key() {
        let dir = tempfile::tempdir().unwrap();
        write_exposure_stack(dir.path(), &stack(8)).unwrap();
        let json_path = dir.path().join(STACK_JSON);
        let good: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&json_path).unwrap()).unwrap();
        let cases: [(&str, serde_json::Value); 4] = [
            ("/images/1/exposure_s", json!(1e-4)),
            ("/images/0/exposure_s", json!(-1.0)),
            ("/images/2/file", json!("../x.png")),
            ("/bit_depth", json!(17)),
        ];
        for (key, bad) in cases {
            let mut value = good.clone();
            *value.pointer_mut(key).unwrap() = bad;
            std::fs::write(&json_path, value.to_string()).unwrap();
            let err = ExposureStackFiles::read(dir.path()).unwrap_err();
            assert_eq!(err.key(), Some(key), "{err}");
            assert!(err.to_string().contains("stack.json"), "{err}");
        }
        // A value the declared bit depth cannot hold, found in the image file.
        let mut value = good.clone();
        value["bit_depth"] = json!(4);
        std::fs::write(&json_path, value.to_string()).unwrap();
        let err = ExposureStackFiles::read(dir.path())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("dt_000.png") && err.contains("exceeds 15"),
            "{err}"
        );
        // A missing image names its file.
        std::fs::write(&json_path, good.to_string()).unwrap();
        std::fs::remove_file(dir.path().join("dt_002.png")).unwrap();
        let err = ExposureStackFiles::read(dir.path())
            .unwrap_err()
            .to_string();
        assert!(err.contains("dt_002.png"), "{err}");
    }
}
