//! OpenEXR files of float images: radiance, depth (NaN where missing) and masks as named
//! 32-bit float channels of one layer (the `exr` crate, lossless ZIP compression).

use std::io::Cursor;
use std::path::Path;

use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Layer, LayerAttributes, ReadChannels,
    ReadLayers, WritableImage, read,
};
use glint_geometry::image::Image as GlintImage;

/// Why an EXR could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ExrError {
    /// [`write_exr`] was given an empty channel list.
    #[error("{path}: no channels to write")]
    NoChannels {
        /// The file, as displayed.
        path: String,
    },
    /// A channel passed to [`write_exr`] is not the size of the first one.
    #[error(
        "{path}: channel {name:?} is {width}×{height} px but {first:?} is {first_width}×{first_height} px"
    )]
    SizeMismatch {
        /// The file, as displayed.
        path: String,
        /// Name of the mis-sized channel.
        name: String,
        /// Its width, px.
        width: u32,
        /// Its height, px.
        height: u32,
        /// Name of the first channel, whose size all must share.
        first: String,
        /// Width of the first channel, px.
        first_width: u32,
        /// Height of the first channel, px.
        first_height: u32,
    },
    /// A channel name passed to [`write_exr`] is empty or used twice.
    #[error("{path}: channel name {name:?} is empty or repeated")]
    BadName {
        /// The file, as displayed.
        path: String,
        /// The offending name.
        name: String,
    },
    /// The `exr` crate failed to encode or to open and decode the file.
    #[error("{path}: {source}")]
    Exr {
        /// The file, as displayed.
        path: String,
        /// The `exr` crate's error.
        source: exr::error::Error,
    },
    /// The encoded bytes could not be written to the file atomically.
    #[error(transparent)]
    Write(#[from] glint_geometry::io::AtomicWriteError),
    /// A decoded channel could not be turned into an image (e.g. its sample count does not
    /// match the layer size).
    #[error("{path}: {problem}")]
    Read {
        /// The file, as displayed.
        path: String,
        /// What went wrong.
        problem: String,
    },
}

/// Writes `channels` (name, image), all the same size, to `path` atomically.
pub fn write_exr(path: &Path, channels: &[(&str, &GlintImage<f32>)]) -> Result<(), ExrError> {
    let shown = path.display().to_string();
    let Some((first, first_image)) = channels.first() else {
        return Err(ExrError::NoChannels { path: shown });
    };
    let (width, height) = (first_image.width(), first_image.height());
    let mut list = Vec::with_capacity(channels.len());
    for (i, (name, image)) in channels.iter().enumerate() {
        if name.is_empty() || channels[..i].iter().any(|(other, _)| other == name) {
            return Err(ExrError::BadName {
                path: shown,
                name: name.to_string(),
            });
        }
        if (image.width(), image.height()) != (width, height) {
            return Err(ExrError::SizeMismatch {
                path: shown,
                name: name.to_string(),
                width: image.width(),
                height: image.height(),
                first: first.to_string(),
                first_width: width,
                first_height: height,
            });
        }
        list.push(AnyChannel::new(
            *name,
            FlatSamples::F32(image.data().to_vec()),
        ));
    }
    let layer = Layer::new(
        (width as usize, height as usize),
        LayerAttributes::named("glint"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list.into()),
    );
    let mut bytes = Vec::new();
    exr::prelude::Image::from_layer(layer)
        .write()
        .to_buffered(Cursor::new(&mut bytes))
        .map_err(|source| ExrError::Exr {
            path: shown.clone(),
            source,
        })?;
    glint_geometry::io::write_file_atomically(path, &bytes)?;
    Ok(())
}

/// Reads every channel of the first layer of `path` as f32 images, in the file's (sorted) order.
pub fn read_exr(path: &Path) -> Result<Vec<(String, GlintImage<f32>)>, ExrError> {
    let shown = path.display().to_string();
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|source| ExrError::Exr {
            path: shown.clone(),
            source,
        })?;
    let size = image.layer_data.size;
    image
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|channel| {
            let data: Vec<f32> = channel.sample_data.values_as_f32().collect();
            GlintImage::new(size.0 as u32, size.1 as u32, data)
                .map(|img| (channel.name.to_string(), img))
                .map_err(|e| ExrError::Read {
                    path: shown.clone(),
                    problem: e.to_string(),
                })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_round_trip_bit_exact_with_nan() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("capture.exr");
        let radiance = GlintImage::new(3, 2, vec![0.0, 1.5, 1e-7, 3.25, 1e6, 0.5]).unwrap();
        let depth = GlintImage::new(3, 2, vec![0.6, f32::NAN, 0.61, 0.62, f32::NAN, 0.7]).unwrap();
        write_exr(&path, &[("radiance", &radiance), ("depth_m", &depth)]).unwrap();
        let back = read_exr(&path).unwrap();
        let find = |n: &str| back.iter().find(|(name, _)| name == n).unwrap().1.clone();
        assert_eq!(find("radiance"), radiance);
        let d = find("depth_m");
        for (a, b) in d.data().iter().zip(depth.data()) {
            assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
        }
    }

    #[test]
    fn bad_channel_sets_are_errors_and_write_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.exr");
        let a = GlintImage::filled(3, 2, 0.0f32).unwrap();
        let b = GlintImage::filled(2, 2, 0.0f32).unwrap();
        assert!(matches!(
            write_exr(&path, &[]),
            Err(ExrError::NoChannels { .. })
        ));
        assert!(matches!(
            write_exr(&path, &[("a", &a), ("b", &b)]),
            Err(ExrError::SizeMismatch { .. })
        ));
        assert!(matches!(
            write_exr(&path, &[("a", &a), ("a", &a)]),
            Err(ExrError::BadName { .. })
        ));
        assert!(!path.exists());
        std::fs::write(&path, b"not an exr").unwrap();
        assert!(matches!(read_exr(&path), Err(ExrError::Exr { .. })));
    }
}
