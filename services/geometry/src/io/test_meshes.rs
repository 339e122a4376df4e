//! Test meshes and files written byte by byte, independently of the writers under test.

use nalgebra::Point3;

use crate::mesh::TriMesh;

/// Corners of the test box, millimetres: off-centre and of unequal sides so that a swapped
/// axis or a missed offset changes the numbers.
pub const BOX_MIN_MM: [f32; 3] = [-10.0, -20.0, 5.0];
pub const BOX_MAX_MM: [f32; 3] = [30.0, 15.0, 45.0];
/// 40 × 35 × 40 mm.
pub const BOX_VOLUME_MM3: f64 = 56_000.0;

/// The box's 8 corners, corner `i` at (bit 0 → x, bit 1 → y, bit 2 → z) of `i`, and its 6
/// faces as quads, counter-clockwise seen from outside.
pub fn box_quads_mm() -> (Vec<Point3<f32>>, Vec<[u32; 4]>) {
    let vertices = (0..8)
        .map(|i| {
            let pick = |axis: usize| {
                if i >> axis & 1 == 0 {
                    BOX_MIN_MM[axis]
                } else {
                    BOX_MAX_MM[axis]
                }
            };
            Point3::new(pick(0), pick(1), pick(2))
        })
        .collect();
    let quads = vec![
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    (vertices, quads)
}

/// The box as 12 triangles, coordinates in millimetres.
pub fn box_mesh_mm() -> TriMesh {
    let (vertices, quads) = box_quads_mm();
    let triangles = quads
        .iter()
        .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
        .collect();
    TriMesh::new(vertices, triangles)
}

/// A millimetre mesh converted to metres the way the readers do it (in f64, rounded once).
pub fn mm_to_m(mesh_mm: &TriMesh) -> TriMesh {
    TriMesh::new(
        mesh_mm
            .vertices
            .iter()
            .map(|p| p.map(|c| (f64::from(c) * 1e-3) as f32))
            .collect(),
        mesh_mm.triangles.clone(),
    )
}

/// Asserts equal vertex lists within f32 precision (a few units in the last place).
pub fn assert_same_vertices(actual: &[Point3<f32>], expected: &[Point3<f32>]) {
    assert_eq!(actual.len(), expected.len());
    for (i, (a, e)) in actual.iter().zip(expected).enumerate() {
        for axis in 0..3 {
            let tolerance = 4.0 * f32::EPSILON * e[axis].abs().max(f32::MIN_POSITIVE);
            assert!(
                (a[axis] - e[axis]).abs() <= tolerance,
                "vertex {i}: {a} vs {e}"
            );
        }
    }
}

/// The triangles of `mesh` as binary STL, with `header` at the start of the 80-byte header.
pub fn binary_stl(mesh: &TriMesh, header: &[u8]) -> Vec<u8> {
    let mut bytes = vec![0u8; 80];
    bytes[..header.len()].copy_from_slice(header);
    bytes.extend_from_slice(&(mesh.triangles.len() as u32).to_le_bytes());
    for i in 0..mesh.triangles.len() {
        let normal = mesh.face_normal(i);
        for c in normal
            .iter()
            .chain(mesh.triangle(i).iter().flat_map(|p| p.coords.iter()))
        {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
        bytes.extend_from_slice(&[0, 0]);
    }
    bytes
}

/// The triangles of `mesh` as ascii STL, indented and in mixed styles as exporters write it.
pub fn ascii_stl(mesh: &TriMesh) -> Vec<u8> {
    let mut text = String::from("solid test box (exported by hand)\n");
    for i in 0..mesh.triangles.len() {
        let n = mesh.face_normal(i);
        text += &format!(
            "  facet normal {:e} {:e} {:e}\n    outer loop\n",
            n.x, n.y, n.z
        );
        for p in mesh.triangle(i) {
            text += &format!("      vertex {} {} {}\n", p.x, p.y, p.z);
        }
        text += "    endloop\n  endfacet\n";
    }
    text += "endsolid test box\n";
    text.into_bytes()
}

/// The box (millimetres) as OBJ with quads in every face form (`i`, `i/t`, `i//n`, `i/t/n`),
/// positive and negative indices, and statements a geometry reader must ignore.
pub fn obj_with_every_face_form() -> Vec<u8> {
    let (vertices, quads) = box_quads_mm();
    let mut text = String::from("# box\r\nmtllib box.mtl\no box\n");
    for p in &vertices {
        // The optional w and vertex colours must be ignored.
        text += &format!("v {} {} {} 1.0 0.5 0.5 0.5\n", p.x, p.y, p.z);
    }
    text += "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\ng sides\nusemtl steel\ns off\n";
    let n = vertices.len() as i64;
    for (q, quad) in quads.iter().enumerate() {
        let corners: Vec<String> = quad
            .iter()
            .enumerate()
            .map(|(k, &v)| {
                // Odd faces count back from the end: -1 is the last vertex.
                let index = if q % 2 == 1 {
                    i64::from(v) - n
                } else {
                    i64::from(v) + 1
                };
                match (q + k) % 4 {
                    0 => format!("{index}"),
                    1 => format!("{index}/{}", k + 1),
                    2 => format!("{index}//1"),
                    _ => format!("{index}/{}/1", k + 1),
                }
            })
            .collect();
        text += &format!("f {}\n", corners.join(" "));
    }
    text += "l 1 2\n# end\n";
    text.into_bytes()
}

/// A BOP-style binary PLY of a millimetre mesh: float x y z, normals, uchar colours with
/// alpha, `list uchar int vertex_indices`, and a texture-coordinate list per face.
pub fn bop_like_ply(mesh_mm: &TriMesh, little_endian: bool) -> Vec<u8> {
    let format = if little_endian {
        "binary_little_endian"
    } else {
        "binary_big_endian"
    };
    let mut bytes = format!(
        "ply\nformat {format} 1.0\ncomment Created by BOP-like exporter\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\n\
         property float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
         property uchar alpha\nelement face {}\nproperty list uchar int vertex_indices\n\
         property list uchar float texcoord\nend_header\n",
        mesh_mm.vertices.len(),
        mesh_mm.triangles.len()
    )
    .into_bytes();
    let f32_bytes = |v: f32| {
        if little_endian {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        }
    };
    let i32_bytes = |v: i32| {
        if little_endian {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        }
    };
    for p in &mesh_mm.vertices {
        let normal = p.coords.normalize();
        for c in p.iter().chain(normal.iter()) {
            bytes.extend_from_slice(&f32_bytes(*c));
        }
        bytes.extend_from_slice(&[200, 100, 50, 255]);
    }
    for t in &mesh_mm.triangles {
        bytes.push(3);
        for &v in t {
            bytes.extend_from_slice(&i32_bytes(v as i32));
        }
        bytes.push(6);
        for uv in [0.0f32, 0.0, 1.0, 0.0, 0.0, 1.0] {
            bytes.extend_from_slice(&f32_bytes(uv));
        }
    }
    bytes
}

#[test]
fn the_test_box_is_closed_and_outward() {
    let report = box_mesh_mm().validate().unwrap();
    assert!(report.is_watertight());
    assert_eq!(report.signed_volume_m3, BOX_VOLUME_MM3);
}
