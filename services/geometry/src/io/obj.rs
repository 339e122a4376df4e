//! Wavefront OBJ, geometry only: `v` and `f` statements.
//!
//! A `v` line's first three numbers are the position; an optional `w` and vertex colours after
//! them are ignored. An `f` corner is `i`, `i/t`, `i//n` or `i/t/n`, of which only the vertex
//! index `i` matters: 1-based, or negative to count back from the latest vertex (`-1`).
//! Polygons are fan-triangulated. Every other statement (`vt`, `vn`, `o`, `g`, `s`, `usemtl`,
//! `mtllib`, `l`, `p`, ...) and everything after a `#` is ignored.

use nalgebra::Point3;

use super::text::{self, Lines};
use super::{Location, MeshIoError, ParsedMesh};
use crate::mesh::TriMesh;

/// Statements that open OBJ files, for sniffing.
const OBJ_KEYWORDS: [&[u8]; 12] = [
    b"v", b"vt", b"vn", b"vp", b"f", b"o", b"g", b"s", b"l", b"p", b"mtllib", b"usemtl",
];

/// How many lines sniffing looks through for the first statement.
const SNIFF_LINES: usize = 64;

/// Whether the first statement (past blank and comment lines) is an OBJ one.
pub(super) fn looks_like_obj(bytes: &[u8]) -> bool {
    Lines::numbered_from(bytes, 1)
        .take(SNIFF_LINES)
        .find_map(|(_, line)| text::tokens(strip_comment(line)).next())
        .is_some_and(|keyword| OBJ_KEYWORDS.contains(&keyword))
}

/// Reads an OBJ file; coordinates are multiplied by `metres_per_unit`.
pub(super) fn read(
    bytes: &[u8],
    metres_per_unit: f64,
    file: &str,
) -> Result<ParsedMesh, MeshIoError> {
    let parse_error = |line: usize, expected: &str, found: String| MeshIoError::Parse {
        file: file.to_owned(),
        at: Location::Line(line),
        expected: expected.to_owned(),
        found,
    };
    let mut mesh = TriMesh::default();
    let mut polygon: Vec<u32> = Vec::new();
    let mut short_faces = 0;
    // Positive indices may point past the vertices read so far (nothing forbids a face before
    // its vertices), so they are checked at the end; this is the largest and where it was.
    let mut largest_index: Option<(u32, i64, usize)> = None;
    for (number, line) in Lines::numbered_from(bytes, 1) {
        let mut words = text::tokens(strip_comment(line));
        match words.next() {
            Some(b"v") => {
                let mut xyz = [0.0f64; 3];
                for (axis, c) in xyz.iter_mut().enumerate() {
                    let token = words.next();
                    *c = token.and_then(text::parse_f64).ok_or_else(|| {
                        parse_error(
                            number,
                            &format!(
                                "coordinate {} of a vertex (`v x y z`)",
                                ["x", "y", "z"][axis]
                            ),
                            token.map_or_else(|| "the end of the line".to_owned(), text::quote),
                        )
                    })?;
                }
                mesh.vertices
                    .push(Point3::from(xyz.map(|c| (c * metres_per_unit) as f32)));
            }
            Some(b"f") => {
                polygon.clear();
                for corner in words {
                    let vertex_token = corner.split(|&b| b == b'/').next().unwrap_or(corner);
                    let written = text::parse_i64(vertex_token).filter(|&i| i != 0).ok_or_else(|| {
                        parse_error(
                            number,
                            "a face corner `i`, `i/t`, `i//n` or `i/t/n` with a non-zero vertex index i",
                            text::quote(corner),
                        )
                    })?;
                    let vertices_so_far = mesh.vertices.len() as i64;
                    let resolved = if written > 0 {
                        written - 1
                    } else {
                        vertices_so_far + written
                    };
                    let out_of_range = || MeshIoError::IndexOutOfRange {
                        file: file.to_owned(),
                        at: Location::Line(number),
                        index: written,
                        vertex_count: mesh.vertices.len(),
                    };
                    let vertex = u32::try_from(resolved).map_err(|_| out_of_range())?;
                    if largest_index.is_none_or(|(largest, ..)| vertex > largest) {
                        largest_index = Some((vertex, written, number));
                    }
                    polygon.push(vertex);
                }
                match polygon.as_slice() {
                    [first, rest @ ..] if rest.len() >= 2 => {
                        mesh.triangles
                            .extend(rest.windows(2).map(|pair| [*first, pair[0], pair[1]]));
                    }
                    _ => short_faces += 1,
                }
            }
            _ => {}
        }
    }
    if let Some((vertex, written, line)) = largest_index
        && vertex as usize >= mesh.vertices.len()
    {
        return Err(MeshIoError::IndexOutOfRange {
            file: file.to_owned(),
            at: Location::Line(line),
            index: written,
            vertex_count: mesh.vertices.len(),
        });
    }
    let mut warnings = Vec::new();
    if short_faces > 0 {
        warnings.push(format!(
            "ignored {short_faces} faces with fewer than 3 vertices"
        ));
    }
    Ok(ParsedMesh {
        mesh,
        warnings,
        triangle_soup: false,
    })
}

/// The part of a line before a `#`.
fn strip_comment(line: &[u8]) -> &[u8] {
    line.split(|&b| b == b'#').next().unwrap_or(line)
}

#[cfg(test)]
mod tests {
    use super::super::test_meshes::{
        BOX_VOLUME_MM3, assert_same_vertices, box_quads_mm, obj_with_every_face_form,
    };
    use super::super::{LoadedMesh, MeshFormat, read_mesh_from_bytes};
    use super::*;
    use crate::mesh::LengthUnit;

    fn read_obj(bytes: &[u8], unit: LengthUnit) -> Result<LoadedMesh, MeshIoError> {
        read_mesh_from_bytes(bytes, MeshFormat::Obj, unit, "test.obj")
    }

    #[test]
    fn every_face_form_and_negative_indices_give_the_closed_box() {
        let bytes = obj_with_every_face_form();
        let text = String::from_utf8(bytes.clone()).unwrap();
        for form in [
            "f 1 3/2 4//1 2/4/1",
            "f -4/1 -3//1 -1/3/1 -2",
            "f -6/1/1 -2 -1/3 -5//1",
        ] {
            assert!(text.contains(form), "the fixture lacks {form:?}:\n{text}");
        }
        let (vertices_mm, _) = box_quads_mm();
        for (unit, metres_per_unit) in [(LengthUnit::Millimetre, 1e-3), (LengthUnit::Metre, 1.0)] {
            let loaded = read_obj(&bytes, unit).unwrap();
            let expected: Vec<_> = vertices_mm
                .iter()
                .map(|p| p.map(|c| (f64::from(c) * metres_per_unit) as f32))
                .collect();
            assert_same_vertices(&loaded.mesh.vertices, &expected);
            assert_eq!(loaded.mesh.triangles.len(), 12);
            assert!(loaded.report.is_watertight(), "{:?}", loaded.report);
            assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
            let volume = BOX_VOLUME_MM3 * metres_per_unit.powi(3);
            assert!((loaded.report.signed_volume_m3 / volume - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn polygons_are_fans_and_faces_may_precede_their_vertices() {
        // A hexagon written before its vertices, with a comment after the face.
        let mut text = String::from("f 1 2 3 4 5 6 # a hexagon\n");
        for k in 0..6 {
            let angle = std::f64::consts::TAU * f64::from(k) / 6.0;
            text += &format!("v {} {} 0\n", angle.cos(), angle.sin());
        }
        let loaded = read_obj(text.as_bytes(), LengthUnit::Metre).unwrap();
        assert_eq!(
            loaded.mesh.triangles,
            vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]
        );
        let area = 3.0 * 3f64.sqrt() / 2.0;
        assert!((loaded.mesh.area() / area - 1.0).abs() < 1e-6);
        assert_eq!(loaded.report.open_edges, 6);
    }

    #[test]
    fn non_utf8_outside_the_numbers_is_harmless() {
        let bytes = b"# caf\xe9\no pi\xe8ce\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        assert_eq!(
            read_obj(bytes, LengthUnit::Metre)
                .unwrap()
                .mesh
                .triangles
                .len(),
            1
        );
    }

    #[test]
    fn bad_statements_and_indices_are_located() {
        let vertices = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        let cases = [
            (format!("{vertices}f 1 2 4\n"), 4, 4, 3),
            (format!("{vertices}f 1 2 3\nf -4 1 2\n"), 5, -4, 3),
            // Out of range only because the file ends: reported where it was written.
            (format!("f 1 2 9\n{vertices}"), 1, 9, 3),
            (
                format!("{vertices}f 1 2 99999999999\n"),
                4,
                99_999_999_999,
                3,
            ),
        ];
        for (text, line, index, vertex_count) in cases {
            let err = read_obj(text.as_bytes(), LengthUnit::Metre).unwrap_err();
            match &err {
                MeshIoError::IndexOutOfRange {
                    file,
                    at,
                    index: i,
                    vertex_count: n,
                } => {
                    assert_eq!(
                        (file.as_str(), at, *i, *n),
                        ("test.obj", &Location::Line(line), index, vertex_count)
                    );
                }
                other => panic!("{text:?}: {other:?}"),
            }
            assert!(
                err.to_string()
                    .starts_with(&format!("test.obj: at line {line}: vertex index {index}"))
            );
        }
        let cases = [
            (format!("{vertices}f 1 0 2\n"), 4, "`0`"),
            (format!("{vertices}f 1 a/1 2\n"), 4, "`a/1`"),
            (format!("{vertices}f 1 /1 2\n"), 4, "`/1`"),
            ("v 0 0 0\nv 1 0\n".to_owned(), 2, "the end of the line"),
            ("v 0 0 0\nv 1 0 zero\n".to_owned(), 2, "`zero`"),
        ];
        for (text, line, found_expected) in cases {
            match read_obj(text.as_bytes(), LengthUnit::Metre).unwrap_err() {
                MeshIoError::Parse { at, found, .. } => {
                    assert_eq!(
                        (at, found.as_str()),
                        (Location::Line(line), found_expected),
                        "{text:?}"
                    );
                }
                other => panic!("{text:?}: {other:?}"),
            }
        }
    }
}
