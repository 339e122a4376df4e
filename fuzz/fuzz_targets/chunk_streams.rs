//! The reassembly of chunked arrays (captures, exposure stacks, refine views): a header list
//! and a chunk sequence, as any client may send them, must assemble or be refused — never
//! panic, never allocate past the stream limit. Input: a u16 length, that many bytes of an
//! `ExposureStackHeader` (its `arrays`), then length-delimited `BytesChunk`s.
#![no_main]

use glint_proto::chunks::{ArrayAssembler, MAX_STREAM_BYTES};
use glint_proto::v1;
use libfuzzer_sys::fuzz_target;
use prost::Message;

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let n = u16::from_le_bytes([data[0], data[1]]) as usize;
    let Some(header_bytes) = data.get(2..2 + n) else {
        return;
    };
    let Ok(header) = v1::ExposureStackHeader::decode(header_bytes) else {
        return;
    };
    let Ok(mut assembler) = ArrayAssembler::new(header.arrays, "arrays") else {
        return;
    };
    let mut rest = &data[2 + n..];
    while !rest.is_empty() {
        let Ok(chunk) = v1::BytesChunk::decode_length_delimited(&mut rest) else {
            return;
        };
        if assembler.push(chunk).is_err() {
            return;
        }
    }
    if let Ok(arrays) = assembler.finish() {
        let total: usize = arrays
            .iter()
            .map(|(_, a)| match a {
                glint_proto::chunks::AssembledArray::Image(m) => m.data.len(),
                glint_proto::chunks::AssembledArray::Depth(m) => m.data.len(),
            })
            .sum();
        assert!(total as u64 <= MAX_STREAM_BYTES);
        for (_, array) in arrays {
            match array {
                glint_proto::chunks::AssembledArray::Image(m) => {
                    let _ = glint_geometry::image::Image::<u16>::try_from(m);
                }
                glint_proto::chunks::AssembledArray::Depth(m) => {
                    let _ = glint_geometry::image::DepthMap::try_from(m);
                }
            }
        }
    }
});
