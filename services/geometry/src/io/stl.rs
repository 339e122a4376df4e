//! STL, binary and ascii: a triangle soup (every triangle with its own three corners), welded
//! into an indexed mesh by [`TriMesh::weld_identical_vertices`] after reading.
//!
//! Binary STL is an 80-byte header, a little-endian `u32` triangle count and 50 bytes a
//! triangle (normal, three corners as `f32`, a 2-byte attribute). Ascii STL is
//! `solid name`, then `facet normal nx ny nz / outer loop / vertex x y z ×3 / endloop /
//! endfacet` per triangle, then `endsolid name`. Stored normals are ignored: the corner order
//! (counter-clockwise seen from outside) orients a triangle.
//!
//! Many binary files begin with `solid` too, so the size equation decides first: a file of
//! exactly 84 + 50 × count bytes is binary. Otherwise a file that starts with `solid` and reads
//! as text is ascii, and anything else is treated as binary (and reported as truncated, or
//! with a warning about trailing bytes).

use nalgebra::Point3;

use super::text::{self, Tokens};
use super::{Location, MeshIoError, ParsedMesh};
use crate::mesh::TriMesh;

/// Bytes before the first binary record: the header and the triangle count.
const BINARY_PREAMBLE_BYTES: usize = 84;
/// Bytes of one binary triangle record.
const BINARY_RECORD_BYTES: usize = 50;
/// How much of a file the text test looks at.
const TEXT_PROBE_BYTES: usize = 1024;

/// Whether `bytes` are an STL file: a binary one of exactly the declared size, or ascii.
pub(super) fn looks_like_stl(bytes: &[u8]) -> bool {
    matches!(
        layout(bytes),
        Layout::Binary { exact_size: true } | Layout::Ascii
    )
}

/// Reads an STL file; coordinates are multiplied by `metres_per_unit`.
pub(super) fn read(
    bytes: &[u8],
    metres_per_unit: f64,
    file: &str,
) -> Result<ParsedMesh, MeshIoError> {
    match layout(bytes) {
        Layout::Ascii => read_ascii(bytes, metres_per_unit, file),
        Layout::Binary { .. } => read_binary(bytes, metres_per_unit, file),
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Layout {
    Binary { exact_size: bool },
    Ascii,
}

fn layout(bytes: &[u8]) -> Layout {
    let exact_size =
        declared_triangles(bytes).is_some_and(|count| binary_size(count) == bytes.len() as u64);
    if exact_size {
        Layout::Binary { exact_size }
    } else if starts_with_solid(bytes) && reads_as_text(bytes) {
        Layout::Ascii
    } else {
        Layout::Binary { exact_size }
    }
}

/// The triangle count of a binary header.
fn declared_triangles(bytes: &[u8]) -> Option<u32> {
    let count = bytes.get(BINARY_PREAMBLE_BYTES - 4..BINARY_PREAMBLE_BYTES)?;
    Some(u32::from_le_bytes([count[0], count[1], count[2], count[3]]))
}

/// Size of a binary file with `triangles` records.
fn binary_size(triangles: u32) -> u64 {
    BINARY_PREAMBLE_BYTES as u64 + BINARY_RECORD_BYTES as u64 * u64::from(triangles)
}

fn starts_with_solid(bytes: &[u8]) -> bool {
    let start = bytes
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(bytes.len());
    bytes[start..]
        .get(..5)
        .is_some_and(|word| text::is_keyword(word, "solid"))
}

/// No control characters but whitespace in the first kilobyte. Binary records nearly always
/// hold a zero byte (in 0.0, 1.0, small counts and header padding); text never does.
fn reads_as_text(bytes: &[u8]) -> bool {
    bytes[..bytes.len().min(TEXT_PROBE_BYTES)]
        .iter()
        .all(|&b| b >= 0x20 || matches!(b, b'\t' | b'\n' | b'\r' | 0x0b | 0x0c))
}

fn read_binary(bytes: &[u8], metres_per_unit: f64, file: &str) -> Result<ParsedMesh, MeshIoError> {
    let Some(declared) = declared_triangles(bytes) else {
        return Err(MeshIoError::Truncated {
            file: file.to_owned(),
            at: Location::Byte(bytes.len() as u64),
            expected: format!(
                "a binary STL header and triangle count ({BINARY_PREAMBLE_BYTES} bytes); nor is this ascii STL, \
                 which starts with `solid`"
            ),
        });
    };
    let expected_size = binary_size(declared);
    if (bytes.len() as u64) < expected_size {
        return Err(MeshIoError::Truncated {
            file: file.to_owned(),
            at: Location::Byte(bytes.len() as u64),
            expected: format!(
                "{expected_size} bytes for the {declared} triangles the header declares \
                 ({BINARY_PREAMBLE_BYTES} + {BINARY_RECORD_BYTES} × {declared})"
            ),
        });
    }
    let mut warnings = Vec::new();
    let extra = bytes.len() as u64 - expected_size;
    if extra > 0 {
        warnings.push(format!(
            "ignored {extra} bytes after the {declared} triangles the header declares"
        ));
    }
    // The size check above bounds these allocations by the file size.
    let mut mesh = TriMesh {
        vertices: Vec::with_capacity(3 * declared as usize),
        triangles: Vec::with_capacity(declared as usize),
    };
    let records = bytes[BINARY_PREAMBLE_BYTES..]
        .chunks_exact(BINARY_RECORD_BYTES)
        .take(declared as usize);
    for record in records {
        // Bytes 0..12 are the normal, 48..50 the attribute.
        let corner = |k: usize| {
            let c = |axis: usize| {
                let at = 12 + 12 * k + 4 * axis;
                let value = f32::from_le_bytes([
                    record[at],
                    record[at + 1],
                    record[at + 2],
                    record[at + 3],
                ]);
                (f64::from(value) * metres_per_unit) as f32
            };
            Point3::new(c(0), c(1), c(2))
        };
        push_triangle(&mut mesh, [corner(0), corner(1), corner(2)]);
    }
    Ok(ParsedMesh {
        mesh,
        warnings,
        triangle_soup: true,
    })
}

fn push_triangle(mesh: &mut TriMesh, corners: [Point3<f32>; 3]) {
    let first = mesh.vertices.len() as u32;
    mesh.vertices.extend_from_slice(&corners);
    mesh.triangles.push([first, first + 1, first + 2]);
}

fn read_ascii(bytes: &[u8], metres_per_unit: f64, file: &str) -> Result<ParsedMesh, MeshIoError> {
    let mut reader = AsciiReader {
        tokens: Tokens::new(bytes),
        file,
    };
    let mut mesh = TriMesh::default();
    let mut warnings = Vec::new();
    let mut polygon: Vec<Point3<f32>> = Vec::new();
    reader.expect("solid", "`solid` at the start of an ascii STL file")?;
    reader.tokens.skip_rest_of_line();
    let mut ended = false;
    while let Some((line, token)) = reader.tokens.next() {
        if text::is_keyword(token, "facet") {
            reader.expect("normal", "`normal` after `facet`")?;
            for _ in 0..3 {
                reader.number("a component of the facet normal")?;
            }
            reader.expect("outer", "`outer loop`")?;
            reader.expect("loop", "`loop` after `outer`")?;
            polygon.clear();
            loop {
                let (_, token) = reader.next("`vertex` or `endloop`")?;
                if text::is_keyword(token, "endloop") {
                    break;
                }
                if !text::is_keyword(token, "vertex") {
                    return Err(reader.parse_error("`vertex` or `endloop`", token));
                }
                let mut xyz = [0.0f64; 3];
                for c in &mut xyz {
                    *c = reader.number("a vertex coordinate")?;
                }
                polygon.push(Point3::from(xyz.map(|c| (c * metres_per_unit) as f32)));
            }
            reader.expect("endfacet", "`endfacet` after `endloop`")?;
            match polygon.as_slice() {
                [first, rest @ ..] if rest.len() >= 2 => {
                    for pair in rest.windows(2) {
                        push_triangle(&mut mesh, [*first, pair[0], pair[1]]);
                    }
                }
                _ => {
                    return Err(MeshIoError::Parse {
                        file: file.to_owned(),
                        at: Location::Line(line),
                        expected: "a facet with at least 3 vertices".to_owned(),
                        found: format!("{} vertices", polygon.len()),
                    });
                }
            }
        } else if text::is_keyword(token, "endsolid") {
            reader.tokens.skip_rest_of_line();
            ended = true;
        } else if ended && text::is_keyword(token, "solid") {
            // Some exporters write one solid per part into the same file.
            reader.tokens.skip_rest_of_line();
            ended = false;
        } else if ended {
            warnings.push(format!("ignored data after `endsolid`, from line {line}"));
            break;
        } else {
            return Err(reader.parse_error("`facet` or `endsolid`", token));
        }
    }
    if !ended {
        warnings.push("no `endsolid` at the end: the file may be truncated".to_owned());
    }
    Ok(ParsedMesh {
        mesh,
        warnings,
        triangle_soup: true,
    })
}

/// Keyword and number reading with errors that say where and what was expected.
struct AsciiReader<'a> {
    tokens: Tokens<'a>,
    file: &'a str,
}

impl<'a> AsciiReader<'a> {
    fn next(&mut self, expected: &str) -> Result<(usize, &'a [u8]), MeshIoError> {
        self.tokens.next().ok_or_else(|| MeshIoError::Truncated {
            file: self.file.to_owned(),
            at: Location::Line(self.tokens.line()),
            expected: expected.to_owned(),
        })
    }

    fn expect(&mut self, keyword: &str, expected: &str) -> Result<(), MeshIoError> {
        let (_, token) = self.next(expected)?;
        if text::is_keyword(token, keyword) {
            Ok(())
        } else {
            Err(self.parse_error(expected, token))
        }
    }

    fn number(&mut self, expected: &str) -> Result<f64, MeshIoError> {
        let (_, token) = self.next(expected)?;
        text::parse_f64(token).ok_or_else(|| self.parse_error(expected, token))
    }

    fn parse_error(&self, expected: &str, found: &[u8]) -> MeshIoError {
        MeshIoError::Parse {
            file: self.file.to_owned(),
            at: Location::Line(self.tokens.line()),
            expected: expected.to_owned(),
            found: text::quote(found),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_meshes::{BOX_VOLUME_MM3, ascii_stl, binary_stl, box_mesh_mm};
    use super::super::{LoadedMesh, MeshFormat, read_mesh_from_bytes};
    use super::*;
    use crate::mesh::LengthUnit;

    fn read_stl(bytes: &[u8], unit: LengthUnit) -> Result<LoadedMesh, MeshIoError> {
        read_mesh_from_bytes(bytes, MeshFormat::Stl, unit, "test.stl")
    }

    fn assert_is_the_welded_box(loaded: &LoadedMesh, metres_per_unit: f64) {
        assert_eq!(loaded.report.vertices, 8);
        assert_eq!(loaded.report.triangles, 12);
        assert!(loaded.report.is_watertight(), "{:?}", loaded.report);
        assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
        let volume = BOX_VOLUME_MM3 * metres_per_unit.powi(3);
        assert!(
            (loaded.report.signed_volume_m3 / volume - 1.0).abs() < 1e-6,
            "{}",
            loaded.report.signed_volume_m3
        );
        let extent = loaded.report.aabb_max - loaded.report.aabb_min;
        assert!((f64::from(extent.y) / (35.0 * metres_per_unit) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn ascii_and_binary_weld_into_the_closed_box() {
        let mesh = box_mesh_mm();
        let files = [
            ascii_stl(&mesh),
            binary_stl(&mesh, b"exported by a CAD tool"),
            // Starts with `solid` but is binary: the size equation decides.
            binary_stl(&mesh, b"solid box, binary nonetheless"),
        ];
        for bytes in &files {
            for (unit, metres_per_unit) in
                [(LengthUnit::Millimetre, 1e-3), (LengthUnit::Metre, 1.0)]
            {
                assert_is_the_welded_box(&read_stl(bytes, unit).unwrap(), metres_per_unit);
            }
        }
        assert_eq!(layout(&files[2]), Layout::Binary { exact_size: true });
        assert_eq!(layout(&files[0]), Layout::Ascii);
    }

    #[test]
    fn binary_sizes_are_checked() {
        let bytes = binary_stl(&box_mesh_mm(), b"solid");
        let err = read_stl(&bytes[..bytes.len() - 1], LengthUnit::Millimetre).unwrap_err();
        match &err {
            MeshIoError::Truncated { file, at, expected } => {
                assert_eq!((file.as_str(), at), ("test.stl", &Location::Byte(683)));
                assert!(
                    expected.starts_with("684 bytes for the 12 triangles"),
                    "{expected}"
                );
            }
            other => panic!("{other:?}"),
        }
        assert!(
            err.to_string()
                .starts_with("test.stl: the data ends early, at byte 683"),
            "{err}"
        );
        // A huge declared count in a small file: no allocation, just the error.
        let mut huge = bytes.clone();
        huge[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            read_stl(&huge, LengthUnit::Metre),
            Err(MeshIoError::Truncated { .. })
        ));
        // Too short for anything, and not text.
        let err = read_stl(&[0xff; 20], LengthUnit::Metre).unwrap_err();
        assert!(
            matches!(
                err,
                MeshIoError::Truncated {
                    at: Location::Byte(20),
                    ..
                }
            ),
            "{err:?}"
        );
        // Bytes after the records are ignored with a warning.
        let mut padded = bytes.clone();
        padded.extend_from_slice(&[0; 7]);
        let loaded = read_stl(&padded, LengthUnit::Millimetre).unwrap();
        assert_eq!(
            loaded.warnings,
            ["ignored 7 bytes after the 12 triangles the header declares"]
        );
        assert_eq!(loaded.report.triangles, 12);
    }

    #[test]
    fn ascii_variants_load() {
        let one = "facet normal 0 0 -1 outer loop vertex 0 0 0 vertex 0 1 0 vertex 1 0 0 endloop endfacet";
        // Shouting, everything on one line, two solids, no final newline.
        let text = format!(
            "SOLID a\n{}\nENDSOLID a\nsolid b\n{one}\nendsolid",
            one.to_uppercase()
        );
        let loaded = read_stl(text.as_bytes(), LengthUnit::Metre).unwrap();
        assert_eq!(loaded.mesh.triangles.len(), 2);
        // A quad facet is a fan; a missing endsolid is only a warning.
        let quad = "solid q\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\n";
        let loaded = read_stl(quad.as_bytes(), LengthUnit::Metre).unwrap();
        assert_eq!(loaded.mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(
            loaded.warnings[0].starts_with("no `endsolid`"),
            "{:?}",
            loaded.warnings
        );
    }

    #[test]
    fn ascii_errors_are_located() {
        let head = "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n";
        let cases = [
            (
                format!("{head}   vertex 0 1\n  endloop\n"),
                7,
                "a vertex coordinate",
                "`endloop`",
            ),
            (
                format!("{head}  endloop\n endfacet\nendsolid t\n"),
                2,
                "a facet with at least 3 vertices",
                "2 vertices",
            ),
            (
                format!("{head}   vertex 0 1 0\n  endloop\n endfacet\n face\n"),
                9,
                "`facet` or `endsolid`",
                "`face`",
            ),
            (
                format!("{head}   vertex 0 1 0\n  endloop\n endloop\n"),
                8,
                "`endfacet` after `endloop`",
                "`endloop`",
            ),
            (
                format!("{head}   vertex 0 1 0\n  endloop\n endfacet\n facet normal 0 0 nope\n"),
                9,
                "a component",
                "`nope`",
            ),
        ];
        for (text, line, expected_start, found_expected) in cases {
            match read_stl(text.as_bytes(), LengthUnit::Metre).unwrap_err() {
                MeshIoError::Parse {
                    file,
                    at,
                    expected,
                    found,
                } => {
                    assert_eq!(file, "test.stl");
                    assert_eq!(
                        (at, found.as_str()),
                        (Location::Line(line), found_expected),
                        "{text:?}"
                    );
                    assert!(expected.starts_with(expected_start), "{expected}");
                }
                other => panic!("{text:?}: {other:?}"),
            }
        }
        let err = read_stl(head.as_bytes(), LengthUnit::Metre).unwrap_err();
        assert!(
            matches!(
                err,
                MeshIoError::Truncated {
                    at: Location::Line(5),
                    ..
                }
            ),
            "{err:?}"
        );
        let err = read_stl(b"solid", LengthUnit::Metre).unwrap_err();
        assert!(matches!(err, MeshIoError::InvalidMesh { .. }), "{err:?}");
    }
}
