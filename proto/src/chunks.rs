//! Large arrays (images, depth maps) streamed as declared [`v1::ArrayHeader`]s followed by
//! [`v1::BytesChunk`]s of at most [`CHUNK_BYTES`], so every gRPC message stays under the 4 MiB
//! default receive limit.
//!
//! A sender turns its arrays into headers and chunks with [`OutgoingArray`] and [`chunks`]; a
//! receiver feeds what arrives to an [`ArrayAssembler`], which rejects — with a
//! [`ConversionError`] naming the field — duplicate names, sizes that disagree with the layout,
//! streams over [`MAX_STREAM_BYTES`], chunks out of order, overlapping or past the end, and a
//! stream that ends before every array is complete.

use crate::convert::ConversionError;
use crate::v1;

/// Bytes per chunk a sender uses: 1 MiB, a quarter of gRPC's default receive limit.
pub const CHUNK_BYTES: usize = 1 << 20;

/// The most bytes one stream may declare: 256 MiB, e.g. 12 full-resolution (1280×1024) float32
/// arrays with room to spare. More is refused before anything is allocated.
pub const MAX_STREAM_BYTES: u64 = 256 << 20;

/// An array to send: its header (layout with empty `data`) and its bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct OutgoingArray {
    pub header: v1::ArrayHeader,
    pub bytes: Vec<u8>,
}

impl OutgoingArray {
    /// An image named `name`; its bytes move out of the message.
    pub fn image(name: &str, mut image: v1::Image) -> Self {
        let bytes = std::mem::take(&mut image.data);
        Self {
            header: v1::ArrayHeader {
                name: name.into(),
                size_bytes: bytes.len() as u64,
                layout: Some(v1::array_header::Layout::Image(image)),
            },
            bytes,
        }
    }

    /// A depth map named `name`; its bytes move out of the message.
    pub fn depth(name: &str, mut depth: v1::DepthMap) -> Self {
        let bytes = std::mem::take(&mut depth.data);
        Self {
            header: v1::ArrayHeader {
                name: name.into(),
                size_bytes: bytes.len() as u64,
                layout: Some(v1::array_header::Layout::Depth(depth)),
            },
            bytes,
        }
    }
}

/// The chunks of `arrays`, in order: array 0 from offset 0, then array 1, ...
pub fn chunks(arrays: &[OutgoingArray]) -> impl Iterator<Item = v1::BytesChunk> + '_ {
    arrays.iter().enumerate().flat_map(|(index, array)| {
        array
            .bytes
            .chunks(CHUNK_BYTES)
            .enumerate()
            .map(move |(k, data)| v1::BytesChunk {
                array: index as u32,
                offset: (k * CHUNK_BYTES) as u64,
                data: data.to_vec(),
            })
    })
}

/// A received array, complete: the header's layout with its `data` filled in.
#[derive(Clone, Debug, PartialEq)]
pub enum AssembledArray {
    Image(v1::Image),
    Depth(v1::DepthMap),
}

/// Reassembles the arrays a stream declared from its chunks.
#[derive(Debug)]
pub struct ArrayAssembler {
    field: String,
    names: Vec<String>,
    arrays: Vec<AssembledArray>,
    sizes: Vec<u64>,
    /// The array being filled (arrays fill one after another).
    current: usize,
}

fn bytes_per_sample(array: &AssembledArray) -> Option<u64> {
    match array {
        AssembledArray::Image(image) => match v1::ImageEncoding::try_from(image.encoding).ok()? {
            v1::ImageEncoding::Mono8 => Some(1),
            v1::ImageEncoding::Mono16Le => Some(2),
            v1::ImageEncoding::Float32Le => Some(4),
            v1::ImageEncoding::Unspecified => None,
        },
        AssembledArray::Depth(depth) => match v1::DepthEncoding::try_from(depth.encoding).ok()? {
            v1::DepthEncoding::Float32LeM => Some(4),
            v1::DepthEncoding::Uint16LeScaled => Some(2),
            v1::DepthEncoding::Unspecified => None,
        },
    }
}

impl ArrayAssembler {
    /// Checks the declared arrays; `field` names the headers' field in errors (e.g. `arrays`).
    pub fn new(headers: Vec<v1::ArrayHeader>, field: &str) -> Result<Self, ConversionError> {
        let mut names = Vec::with_capacity(headers.len());
        let mut arrays = Vec::with_capacity(headers.len());
        let mut sizes = Vec::with_capacity(headers.len());
        let mut total = 0u64;
        for (i, header) in headers.into_iter().enumerate() {
            let at = format!("{field}[{i}]");
            if header.name.is_empty() || names.contains(&header.name) {
                return Err(ConversionError::new(
                    format!("{at}.name"),
                    format!("{:?} must be a non-empty name not used before", header.name),
                ));
            }
            let (array, width, height) = match header.layout {
                Some(v1::array_header::Layout::Image(mut image)) => {
                    image.data.clear();
                    let (w, h) = (image.width_px, image.height_px);
                    (AssembledArray::Image(image), w, h)
                }
                Some(v1::array_header::Layout::Depth(mut depth)) => {
                    depth.data.clear();
                    let (w, h) = (depth.width_px, depth.height_px);
                    (AssembledArray::Depth(depth), w, h)
                }
                None => return Err(ConversionError::missing(format!("{at}.layout"))),
            };
            let Some(sample) = bytes_per_sample(&array) else {
                return Err(ConversionError::new(
                    format!("{at}.encoding"),
                    "must be a known, specified encoding",
                ));
            };
            let expected = u64::from(width) * u64::from(height) * sample;
            if expected == 0 || header.size_bytes != expected {
                return Err(ConversionError::new(
                    format!("{at}.size_bytes"),
                    format!(
                        "is {}, but a {width}x{height} array of {sample}-byte samples has {expected} bytes",
                        header.size_bytes
                    ),
                ));
            }
            total += expected;
            if total > MAX_STREAM_BYTES {
                return Err(ConversionError::new(
                    format!("{at}.size_bytes"),
                    format!("the stream's arrays exceed {MAX_STREAM_BYTES} bytes"),
                ));
            }
            names.push(header.name);
            arrays.push(array);
            sizes.push(expected);
        }
        Ok(Self {
            field: field.into(),
            names,
            arrays,
            sizes,
            current: 0,
        })
    }

    /// Appends a chunk: it must continue the array being filled exactly where it stopped.
    pub fn push(&mut self, chunk: v1::BytesChunk) -> Result<(), ConversionError> {
        let index = chunk.array as usize;
        if index != self.current || index >= self.arrays.len() {
            return Err(ConversionError::new(
                "chunk.array",
                format!(
                    "is {index}, but the next bytes belong to array {} of {} (chunks arrive in order)",
                    self.current,
                    self.arrays.len()
                ),
            ));
        }
        let data = match &mut self.arrays[index] {
            AssembledArray::Image(image) => &mut image.data,
            AssembledArray::Depth(depth) => &mut depth.data,
        };
        let received = data.len() as u64;
        if chunk.offset != received {
            return Err(ConversionError::new(
                "chunk.offset",
                format!(
                    "is {}, but {received} bytes of array {index} have arrived",
                    chunk.offset
                ),
            ));
        }
        if received + chunk.data.len() as u64 > self.sizes[index] {
            return Err(ConversionError::new(
                "chunk.data",
                format!(
                    "runs past the end of array {index} ({} bytes declared)",
                    self.sizes[index]
                ),
            ));
        }
        data.extend_from_slice(&chunk.data);
        if data.len() as u64 == self.sizes[index] {
            self.current += 1;
        }
        Ok(())
    }

    /// Whether every declared array is complete.
    pub fn is_complete(&self) -> bool {
        self.current == self.arrays.len()
    }

    /// The complete arrays with their names, in declared order; an error if the stream ended
    /// early.
    pub fn finish(self) -> Result<Vec<(String, AssembledArray)>, ConversionError> {
        if !self.is_complete() {
            return Err(ConversionError::new(
                self.field.clone(),
                format!(
                    "the stream ended with array {} ({:?}) incomplete",
                    self.current, self.names[self.current]
                ),
            ));
        }
        Ok(self.names.into_iter().zip(self.arrays).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_geometry::image::{DepthMap, Image};

    /// A full 1280×1024 capture: two 16-bit pattern images and a float32 depth map.
    fn full_capture() -> Vec<OutgoingArray> {
        let (w, h) = (1280u32, 1024u32);
        let pattern = |seed: u16| {
            Image::new(
                w,
                h,
                (0..w * h).map(|i| (i as u16).wrapping_mul(seed)).collect(),
            )
            .unwrap()
        };
        let depth = DepthMap::new(
            Image::new(
                w,
                h,
                (0..w * h)
                    .map(|i| {
                        if i % 7 == 0 {
                            f32::NAN
                        } else {
                            0.5 + i as f32 * 1e-7
                        }
                    })
                    .collect(),
            )
            .unwrap(),
        );
        vec![
            OutgoingArray::image("left", v1::Image::from(&pattern(3))),
            OutgoingArray::image("right", v1::Image::from(&pattern(5))),
            OutgoingArray::depth("depth", v1::DepthMap::from(&depth)),
        ]
    }

    #[test]
    fn a_full_capture_round_trips_in_chunks_under_the_default_limit() {
        let arrays = full_capture();
        let headers: Vec<_> = arrays.iter().map(|a| a.header.clone()).collect();
        let mut assembler = ArrayAssembler::new(headers, "arrays").unwrap();
        let mut count = 0;
        for chunk in chunks(&arrays) {
            // Every message stays well under gRPC's 4 MiB default receive limit.
            assert!(prost::Message::encoded_len(&chunk) < 4 << 20);
            assembler.push(chunk).unwrap();
            count += 1;
        }
        // 2.5 MiB + 2.5 MiB + 5 MiB in 1 MiB chunks: 3 + 3 + 5.
        assert_eq!(count, 11);
        let out = assembler.finish().unwrap();
        assert_eq!(out.len(), 3);
        for ((name, array), sent) in out.iter().zip(&arrays) {
            assert_eq!(name, &sent.header.name);
            let data = match array {
                AssembledArray::Image(i) => &i.data,
                AssembledArray::Depth(d) => &d.data,
            };
            assert_eq!(data, &sent.bytes);
        }
        let AssembledArray::Depth(depth) = &out[2].1 else {
            panic!("depth declared third")
        };
        let back = DepthMap::try_from(depth).unwrap();
        assert_eq!(back.depth_m.width(), 1280);
    }

    #[test]
    fn bad_streams_name_the_field() {
        let arrays = full_capture();
        let headers: Vec<_> = arrays.iter().map(|a| a.header.clone()).collect();
        let mut wrong_size = headers.clone();
        wrong_size[1].size_bytes -= 1;
        let e = ArrayAssembler::new(wrong_size, "arrays").unwrap_err();
        assert_eq!(e.field, "arrays[1].size_bytes", "{e}");
        let mut duplicate = headers.clone();
        duplicate[1].name = "left".into();
        assert_eq!(
            ArrayAssembler::new(duplicate, "arrays").unwrap_err().field,
            "arrays[1].name"
        );
        let mut huge = headers.clone();
        if let Some(v1::array_header::Layout::Image(image)) = &mut huge[0].layout {
            image.width_px = 65535;
            image.height_px = 65535;
        }
        huge[0].size_bytes = 65535 * 65535 * 2;
        assert!(
            ArrayAssembler::new(huge, "arrays")
                .unwrap_err()
                .message
                .contains("exceed")
        );

        let all: Vec<_> = chunks(&arrays).collect();
        // Out of order: the second chunk first.
        let mut a = ArrayAssembler::new(headers.clone(), "arrays").unwrap();
        assert_eq!(a.push(all[1].clone()).unwrap_err().field, "chunk.offset");
        // Another array's bytes before this one is complete.
        let mut a = ArrayAssembler::new(headers.clone(), "arrays").unwrap();
        assert_eq!(a.push(all[4].clone()).unwrap_err().field, "chunk.array");
        // Past the end.
        let mut a = ArrayAssembler::new(headers.clone(), "arrays").unwrap();
        let mut long = all[0].clone();
        long.data = vec![0; 3 << 20];
        assert_eq!(a.push(long).unwrap_err().field, "chunk.data");
        // Ending early.
        let mut a = ArrayAssembler::new(headers, "arrays").unwrap();
        a.push(all[0].clone()).unwrap();
        let e = a.finish().unwrap_err();
        assert!(e.message.contains("\"left\"") && e.field == "arrays", "{e}");
    }
}
