//! Image files of datasets: decoding (PNG, BMP; the format comes from the contents), PNG
//! encoding in memory and atomic writes, and the 16-bit depth encoding.
//!
//! Depth files store `round(z_mm / depth_unit_mm)` as `u16`, with 0 for "no depth" (BOP and
//! ROBI alike); Glint's [`DepthMap`] is metres with NaN for "no depth".

use std::io::Cursor;
use std::path::Path;

use glint_geometry::image::{DepthMap, Image};
use glint_geometry::io::write_file_atomically;
use image::{DynamicImage, ImageBuffer, ImageFormat, ImageReader, Luma, Primitive};

use super::error::{DatasetError, read_file};
use super::transforms::MM_PER_M;

/// One camera of a rectified stereo pair: the left one is the reference (DESIGN.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum StereoSide {
    /// The left camera, whose frame depth and poses refer to.
    Left,
    /// The right camera, offset by the baseline along the left camera's +x.
    Right,
}

impl StereoSide {
    /// `"left"` or `"right"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Left => "left",
            Self::Right => "right",
        }
    }
}

/// A single-channel pattern image as the camera delivers it: 8-bit, or 16-bit for sensors
/// with a deeper ADC. What the values mean (linear or response-encoded) is the writer's
/// business; the file keeps the integers exactly.
#[derive(Clone, Debug, PartialEq)]
pub enum PatternImage {
    /// 8-bit digital numbers.
    Bits8(Image<u8>),
    /// 16-bit digital numbers.
    Bits16(Image<u16>),
}

impl PatternImage {
    /// `(width, height)` in pixels.
    pub fn size(&self) -> (u32, u32) {
        match self {
            Self::Bits8(image) => (image.width(), image.height()),
            Self::Bits16(image) => (image.width(), image.height()),
        }
    }
}

/// Decodes an image file; the format comes from its contents, not its extension.
pub(crate) fn decode_image(path: &Path) -> Result<DynamicImage, DatasetError> {
    let bytes = read_file(path)?;
    let decode_error = |source: image::ImageError| match source {
        image::ImageError::Unsupported(_) => DatasetError::ImageContent {
            path: path.to_owned(),
            problem: format!(
                "{source}; Glint decodes PNG and BMP images (ITODD's TIFF files need the \
                 `tiff` feature of the image crate)"
            ),
        },
        source => DatasetError::ImageDecode {
            path: path.to_owned(),
            source,
        },
    };
    ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|source| DatasetError::Read {
            path: path.to_owned(),
            source,
        })?
        .decode()
        .map_err(decode_error)
}

/// The `(width, height)` of an image file, from its header only.
pub(crate) fn image_dimensions(path: &Path) -> Result<(u32, u32), DatasetError> {
    let reader = ImageReader::open(path)
        .and_then(|reader| reader.with_guessed_format())
        .map_err(|source| DatasetError::Read {
            path: path.to_owned(),
            source,
        })?;
    reader
        .into_dimensions()
        .map_err(|source| DatasetError::ImageDecode {
            path: path.to_owned(),
            source,
        })
}

/// An 8-bit single-channel image. 8-bit colour converts to luma (Rec. 709 weights, alpha
/// dropped); 16-bit images are refused rather than silently cut to 8 bits.
pub(crate) fn gray8_from(path: &Path, image: DynamicImage) -> Result<Image<u8>, DatasetError> {
    let (width, height) = (image.width(), image.height());
    let data = match image {
        DynamicImage::ImageLuma8(gray) => gray.into_raw(),
        image @ (DynamicImage::ImageLumaA8(_)
        | DynamicImage::ImageRgb8(_)
        | DynamicImage::ImageRgba8(_)) => image.to_luma8().into_raw(),
        other => {
            return Err(DatasetError::ImageContent {
                path: path.to_owned(),
                problem: format!(
                    "expected an 8-bit gray or colour image, found {:?}",
                    other.color()
                ),
            });
        }
    };
    into_image(path, width, height, data)
}

/// A 16-bit single-channel image (depth). Anything else is refused: an 8-bit depth file
/// would silently mean something else.
pub(crate) fn gray16_from(path: &Path, image: DynamicImage) -> Result<Image<u16>, DatasetError> {
    let (width, height) = (image.width(), image.height());
    match image {
        DynamicImage::ImageLuma16(gray) => into_image(path, width, height, gray.into_raw()),
        other => Err(DatasetError::ImageContent {
            path: path.to_owned(),
            problem: format!(
                "expected a 16-bit single-channel image, found {:?}",
                other.color()
            ),
        }),
    }
}

/// An 8- or 16-bit single-channel image, kept at its bit depth.
pub(crate) fn pattern_from(path: &Path, image: DynamicImage) -> Result<PatternImage, DatasetError> {
    match image {
        DynamicImage::ImageLuma16(_) => gray16_from(path, image).map(PatternImage::Bits16),
        other => gray8_from(path, other).map(PatternImage::Bits8),
    }
}

fn into_image<T: Copy>(
    path: &Path,
    width: u32,
    height: u32,
    data: Vec<T>,
) -> Result<Image<T>, DatasetError> {
    Image::new(width, height, data).map_err(|error| DatasetError::ImageContent {
        path: path.to_owned(),
        problem: error.to_string(),
    })
}

/// `image` as the `image` crate's gray buffer of the same size.
fn gray_buffer<T: Primitive>(image: &Image<T>) -> ImageBuffer<Luma<T>, Vec<T>> {
    let mut buffer = ImageBuffer::new(image.width(), image.height());
    // Both are row-major with width × height samples.
    for (pixel, &value) in buffer.pixels_mut().zip(image.data()) {
        *pixel = Luma([value]);
    }
    buffer
}

/// The bytes of `image` as a PNG for the file at `path` (named in errors).
fn encode_png(path: &Path, image: DynamicImage) -> Result<Vec<u8>, DatasetError> {
    let mut bytes = Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, ImageFormat::Png)
        .map_err(|source| DatasetError::ImageEncode {
            path: path.to_owned(),
            source,
        })?;
    Ok(bytes.into_inner())
}

/// Writes an 8-bit gray PNG atomically.
pub fn write_png_u8(path: &Path, image: &Image<u8>) -> Result<(), DatasetError> {
    let bytes = encode_png(path, DynamicImage::ImageLuma8(gray_buffer(image)))?;
    Ok(write_file_atomically(path, &bytes)?)
}

/// Writes a 16-bit gray PNG atomically.
pub(crate) fn write_png_u16(path: &Path, image: &Image<u16>) -> Result<(), DatasetError> {
    let bytes = encode_png(path, DynamicImage::ImageLuma16(gray_buffer(image)))?;
    Ok(write_file_atomically(path, &bytes)?)
}

/// Encodes a depth map (metres, NaN or 0 where missing) as 16-bit depth units of
/// `depth_unit_mm` millimetres: `round(z · 1000 / depth_unit_mm)`, 0 for missing. `path` is
/// the file the result is for, named in errors. A depth that does not fit in 16 bits
/// (`z ≥ 65535.5 · depth_unit`), is negative or infinite, or is positive but rounds to 0 (and
/// would read back as missing) is an error naming the pixel.
pub fn depth_to_units(
    depth: &DepthMap,
    depth_unit_mm: f64,
    path: &Path,
) -> Result<Image<u16>, DatasetError> {
    if !(depth_unit_mm.is_finite() && depth_unit_mm > 0.0) {
        return Err(DatasetError::Invalid {
            path: path.to_owned(),
            problem: format!("depth unit {depth_unit_mm} mm must be finite and positive"),
        });
    }
    let image = &depth.depth_m;
    let units_per_m = MM_PER_M / depth_unit_mm;
    let mut units = Image::filled_like(image, 0u16);
    for (index, (&z_m, unit)) in image.data().iter().zip(units.data_mut()).enumerate() {
        let pixel_error = |problem: String| DatasetError::Pixel {
            path: path.to_owned(),
            u: (index % image.width() as usize) as u32,
            v: (index / image.width() as usize) as u32,
            problem,
        };
        if z_m.is_nan() || z_m == 0.0 {
            continue; // stays 0, "missing"
        }
        let value = (z_m as f64 * units_per_m).round();
        if z_m < 0.0 || value > u16::MAX as f64 {
            return Err(pixel_error(format!(
                "depth {z_m} m does not fit a 16-bit depth file with {depth_unit_mm} mm units \
                 (0 to {:.4} m)",
                u16::MAX as f64 / units_per_m
            )));
        }
        if value < 1.0 {
            return Err(pixel_error(format!(
                "depth {z_m} m rounds to 0 units of {depth_unit_mm} mm, which means \"missing\""
            )));
        }
        *unit = value as u16;
    }
    Ok(units)
}

/// Decodes 16-bit depth units of `depth_unit_mm` millimetres into a depth map in metres, NaN
/// where the file has 0.
pub fn depth_from_units(units: &Image<u16>, depth_unit_mm: f64) -> DepthMap {
    let m_per_unit = depth_unit_mm / MM_PER_M;
    DepthMap::new(units.map(|unit| {
        if unit == 0 {
            f32::NAN
        } else {
            (unit as f64 * m_per_unit) as f32
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_round_trips_within_half_a_unit() {
        let z = vec![0.6, f32::NAN, 0.0, 1.23456, 6.5535, 1e-4];
        let depth = DepthMap::new(Image::new(3, 2, z.clone()).unwrap());
        let units = depth_to_units(&depth, 0.1, Path::new("d.png")).unwrap();
        assert_eq!(units.data(), &[6000, 0, 0, 12346, 65535, 1]);
        let back = depth_from_units(&units, 0.1);
        for (a, b) in z.iter().zip(back.depth_m.data()) {
            if *a == 0.0 || a.is_nan() {
                assert!(b.is_nan());
            } else {
                assert!((*a as f64 - *b as f64).abs() <= 0.5e-4 + 1e-7, "{a} {b}");
            }
        }
    }

    #[test]
    fn unstorable_depths_name_the_pixel() {
        for bad in [6.5536f32, -0.5, f32::INFINITY, 1e-6] {
            let depth = DepthMap::new(Image::new(2, 2, vec![0.5, 0.5, 0.5, bad]).unwrap());
            let err = depth_to_units(&depth, 0.1, Path::new("depth/000003.png")).unwrap_err();
            assert!(
                matches!(err, DatasetError::Pixel { u: 1, v: 1, .. }),
                "{bad}: {err:?}"
            );
            assert!(err.to_string().contains("depth/000003.png"), "{err}");
        }
        let depth = DepthMap::new(Image::filled(1, 1, 0.5f32).unwrap());
        assert!(depth_to_units(&depth, 0.0, Path::new("d.png")).is_err());
    }

    #[test]
    fn pngs_round_trip_bit_exactly() {
        let gray = Image::new(3, 2, vec![0u8, 1, 2, 127, 254, 255]).unwrap();
        let deep = Image::new(2, 2, vec![0u16, 1, 4095, 65535]).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
        write_png_u8(&a, &gray).unwrap();
        write_png_u16(&b, &deep).unwrap();
        assert_eq!(image_dimensions(&a).unwrap(), (3, 2));
        assert_eq!(gray8_from(&a, decode_image(&a).unwrap()).unwrap(), gray);
        assert_eq!(gray16_from(&b, decode_image(&b).unwrap()).unwrap(), deep);
        assert_eq!(
            pattern_from(&b, decode_image(&b).unwrap()).unwrap(),
            PatternImage::Bits16(deep.clone())
        );
        // Bit depths are not silently converted.
        assert!(gray16_from(&a, decode_image(&a).unwrap()).is_err());
        assert!(gray8_from(&b, decode_image(&b).unwrap()).is_err());
        // ITODD's TIFFs are recognised, and refused with a hint.
        let tiff = dir.path().join("000000.tif");
        std::fs::write(&tiff, b"II*\0\x08\0\0\0\0\0").unwrap();
        let message = decode_image(&tiff).unwrap_err().to_string();
        assert!(
            message.contains("000000.tif") && message.contains("`tiff` feature"),
            "{message}"
        );
        // Garbage is an error naming the file.
        let junk = dir.path().join("junk.png");
        std::fs::write(&junk, b"\x89PNG\r\n\x1a\nnot really").unwrap();
        let err = decode_image(&junk).unwrap_err();
        assert!(err.to_string().contains("junk.png"), "{err}");
    }
}
