//! Mesh files: PLY (ascii, binary), OBJ and STL (ascii, binary) in; PLY out.
//!
//! Files store lengths in a unit the caller names ([`LengthUnit`]: BOP models are millimetres);
//! a [`TriMesh`] is always metres. Readers scale while parsing (in `f64`, so a coordinate is
//! rounded to `f32` once), drop degenerate triangles, weld STL's triangle soup and validate the
//! result: a [`LoadedMesh`] is usable, and what only limits its use (open edges, say) is in its
//! warnings.
//!
//! Readers take any bytes: a truncated, corrupt or hostile file gives a [`MeshIoError`] that names
//! the file and where in it the problem is, never a panic, and never an allocation larger than
//! the file itself can fill. Writers go through [`write_atomically`], which never leaves a
//! half-written file behind.

mod atomic;
mod obj;
mod ply;
mod stl;
#[cfg(test)]
mod test_meshes;
mod text;

use std::fmt;
use std::path::Path;

pub use atomic::{AtomicWriteError, write_atomically, write_file_atomically};
pub use ply::{PlyEncoding, write_ply_points_to, write_ply_to};

use nalgebra::Point3;

use crate::mesh::{LengthUnit, MeshError, MeshReport, TriMesh};

/// A mesh file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MeshFormat {
    /// Stanford PLY: ascii, binary little- or big-endian.
    Ply,
    /// Wavefront OBJ (geometry only).
    Obj,
    /// STL, ascii or binary: a triangle soup, welded on reading.
    Stl,
}

impl MeshFormat {
    /// The format a file extension (without the dot, any case) stands for.
    pub fn from_extension(extension: &str) -> Option<Self> {
        match extension.to_ascii_lowercase().as_str() {
            "ply" => Some(Self::Ply),
            "obj" => Some(Self::Obj),
            "stl" => Some(Self::Stl),
            _ => None,
        }
    }

    /// The format a path's extension stands for.
    pub fn from_path(path: &Path) -> Option<Self> {
        path.extension()?.to_str().and_then(Self::from_extension)
    }

    /// Guesses the format from a file's first bytes: the PLY magic line, binary STL's size
    /// equation or ascii STL's `solid`, or an OBJ statement on the first line that is not a
    /// comment.
    pub fn sniff(bytes: &[u8]) -> Option<Self> {
        if ply::looks_like_ply(bytes) {
            Some(Self::Ply)
        } else if stl::looks_like_stl(bytes) {
            Some(Self::Stl)
        } else if obj::looks_like_obj(bytes) {
            Some(Self::Obj)
        } else {
            None
        }
    }
}

impl fmt::Display for MeshFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Ply => "PLY",
            Self::Obj => "OBJ",
            Self::Stl => "STL",
        })
    }
}

/// Where in a file a problem is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Location {
    /// A 1-based line of a text file or of a PLY header.
    Line(usize),
    /// A 0-based byte offset.
    Byte(u64),
    /// Entry `index` (0-based) of a PLY element such as `vertex` or `face`, in a text body.
    ElementAtLine {
        /// Name of the element, as declared in the header.
        element: String,
        /// 0-based index of the entry within the element.
        index: usize,
        /// 1-based line of the file where the entry is.
        line: usize,
    },
    /// Entry `index` (0-based) of a PLY element, in a binary body; `byte` is where it starts.
    ElementAtByte {
        /// Name of the element, as declared in the header.
        element: String,
        /// 0-based index of the entry within the element.
        index: usize,
        /// 0-based byte offset in the file where the entry starts.
        byte: u64,
    },
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Line(line) => write!(f, "line {line}"),
            Self::Byte(byte) => write!(f, "byte {byte}"),
            Self::ElementAtLine {
                element,
                index,
                line,
            } => write!(f, "{element} {index} (line {line})"),
            Self::ElementAtByte {
                element,
                index,
                byte,
            } => write!(f, "{element} {index} (byte {byte})"),
        }
    }
}

/// Why a mesh file could not be read or written. Every message names the file.
#[derive(Debug, thiserror::Error)]
pub enum MeshIoError {
    /// The file could not be read at all (missing, no permission, ...).
    #[error("cannot read {file}")]
    Read {
        /// The file's path, or the name given for in-memory data.
        file: String,
        /// The I/O error from the operating system.
        #[source]
        source: std::io::Error,
    },
    /// Neither the extension nor the contents tell the format.
    #[error("{file}: unknown mesh format: {detail}; Glint reads .ply, .obj and .stl files")]
    UnknownFormat {
        /// The file's path, or the name given for in-memory data.
        file: String,
        /// Why neither told it: the unrecognised extension, or that there is none.
        detail: String,
    },
    /// The PLY header is malformed or declares something this reader cannot use.
    #[error("{file}: bad PLY header at {at}: expected {expected}, found {found}")]
    BadHeader {
        /// The file's path, or the name given for in-memory data.
        file: String,
        /// Where in the header.
        at: Location,
        /// What the reader expected there.
        expected: String,
        /// What the header holds there.
        found: String,
    },
    /// A value or keyword in the body is not what the format requires there.
    #[error("{file}: at {at}: expected {expected}, found {found}")]
    Parse {
        /// The file's path, or the name given for in-memory data.
        file: String,
        /// Where in the file.
        at: Location,
        /// What the format requires there.
        expected: String,
        /// What the file holds there.
        found: String,
    },
    /// The data ends before everything the file declares or began.
    #[error("{file}: the data ends early, at {at}: expected {expected}")]
    Truncated {
        /// The file's path, or the name given for in-memory data.
        file: String,
        /// Where the data ends.
        at: Location,
        /// What was still to come.
        expected: String,
    },
    /// A face refers to a vertex the file does not have. `index` is as written in the file
    /// (0-based for PLY, 1-based or negative for OBJ).
    #[error(
        "{file}: at {at}: vertex index {index} is out of range: the file has {vertex_count} vertices"
    )]
    IndexOutOfRange {
        /// The file's path, or the name given for in-memory data.
        file: String,
        /// Where the face is.
        at: Location,
        /// The vertex index as written in the file.
        index: i64,
        /// Number of vertices the file has.
        vertex_count: usize,
    },
    /// The file parsed, but the mesh in it is unusable (empty, a non-finite vertex, ...).
    #[error("{file}: unusable mesh")]
    InvalidMesh {
        /// The file's path, or the name given for in-memory data.
        file: String,
        /// What is wrong with the mesh.
        #[source]
        source: MeshError,
    },
    /// An output file could not be written; the message names it.
    #[error(transparent)]
    Write(#[from] AtomicWriteError),
}

/// A mesh read from a file: in metres, validated.
#[derive(Clone, Debug)]
pub struct LoadedMesh {
    /// The mesh, in metres.
    pub mesh: TriMesh,
    /// What [`TriMesh::validate`] found in `mesh`.
    pub report: MeshReport,
    /// Problems that did not stop loading, worded for a user: dropped degenerate triangles,
    /// open edges, ignored parts of the file.
    pub warnings: Vec<String>,
}

/// Reads a mesh file written in `unit` (millimetres or metres) and returns it in metres,
/// validated. The format comes from the extension, or from the contents when the extension is
/// not `.ply`, `.obj` or `.stl`.
pub fn read_mesh(path: &Path, unit: LengthUnit) -> Result<LoadedMesh, MeshIoError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| MeshIoError::Read {
        file: file.clone(),
        source,
    })?;
    let format = match MeshFormat::from_path(path) {
        Some(format) => format,
        None => MeshFormat::sniff(&bytes).ok_or_else(|| MeshIoError::UnknownFormat {
            file: file.clone(),
            detail: match path.extension() {
                Some(extension) => format!(
                    "the extension `.{}` is none of Glint's and the contents are not recognisable",
                    extension.to_string_lossy()
                ),
                None => "no file extension, and the contents are not recognisable".to_owned(),
            },
        })?,
    };
    read_mesh_from_bytes(&bytes, format, unit, &file)
}

/// Reads a mesh in `format` from memory; `unit` is the file's length unit, and
/// `name_for_errors` is how error messages name the data (a path, say).
pub fn read_mesh_from_bytes(
    bytes: &[u8],
    format: MeshFormat,
    unit: LengthUnit,
    name_for_errors: &str,
) -> Result<LoadedMesh, MeshIoError> {
    let metres_per_unit = unit.metres_per_unit();
    let parsed = match format {
        MeshFormat::Ply => ply::read(bytes, metres_per_unit, name_for_errors)?,
        MeshFormat::Obj => obj::read(bytes, metres_per_unit, name_for_errors)?,
        MeshFormat::Stl => stl::read(bytes, metres_per_unit, name_for_errors)?,
    };
    finish(parsed, name_for_errors)
}

/// Writes `mesh` (metres) as PLY with vertices in `unit`, atomically: on any error the file at
/// `path` is unchanged and no temporary file is left.
pub fn write_ply(
    path: &Path,
    mesh: &TriMesh,
    unit: LengthUnit,
    encoding: PlyEncoding,
) -> Result<(), MeshIoError> {
    write_atomically(path, |w| write_ply_to(w, mesh, unit, encoding))?;
    Ok(())
}

/// `mesh` (metres) as the bytes of a PLY file with vertices in `unit`.
pub fn write_ply_to_vec(mesh: &TriMesh, unit: LengthUnit, encoding: PlyEncoding) -> Vec<u8> {
    // Header plus 12 bytes a vertex and 13 a triangle in binary; ascii is about twice that.
    let mut bytes = Vec::with_capacity(256 + 12 * mesh.vertices.len() + 13 * mesh.triangles.len());
    // Writing into a Vec<u8> cannot fail: its io::Write never errs.
    let _ = write_ply_to(&mut bytes, mesh, unit, encoding);
    bytes
}

/// Reads the vertices of a PLY point cloud written in `unit`, in metres: a file with a
/// `vertex` element and no faces (other vertex properties, such as normals, are skipped). Errors
/// name the file; a cloud without points or with a non-finite point is
/// [`MeshIoError::InvalidMesh`].
pub fn read_ply_points(path: &Path, unit: LengthUnit) -> Result<Vec<Point3<f32>>, MeshIoError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| MeshIoError::Read {
        file: file.clone(),
        source,
    })?;
    let parsed = ply::read(&bytes, unit.metres_per_unit(), &file)?;
    let vertices = parsed.mesh.vertices;
    let invalid = |source: MeshError| MeshIoError::InvalidMesh {
        file: file.clone(),
        source,
    };
    if vertices.is_empty() {
        return Err(invalid(MeshError::Empty {
            vertices: 0,
            triangles: parsed.mesh.triangles.len(),
        }));
    }
    if let Some((index, p)) = vertices
        .iter()
        .enumerate()
        .find(|(_, p)| !p.coords.iter().all(|c| c.is_finite()))
    {
        return Err(invalid(MeshError::NonFiniteVertex {
            index,
            x: p.x,
            y: p.y,
            z: p.z,
        }));
    }
    Ok(vertices)
}

/// Writes a point cloud (metres) as binary little-endian PLY in metres, with `nx ny nz` when
/// `normals` is given (one per point), atomically.
pub fn write_ply_points(
    path: &Path,
    points: &[Point3<f64>],
    normals: Option<&[nalgebra::Vector3<f64>]>,
) -> Result<(), MeshIoError> {
    write_atomically(path, |w| write_ply_points_to(w, points, normals))?;
    Ok(())
}

/// What a format's parser hands on: vertices already in metres, every index in range.
struct ParsedMesh {
    mesh: TriMesh,
    /// Things the parser skipped or repaired.
    warnings: Vec<String>,
    /// Each triangle has its own three vertices (STL) and shared corners must be welded.
    triangle_soup: bool,
}

/// The steps every format shares after parsing: weld a soup, drop degenerate triangles,
/// validate.
fn finish(parsed: ParsedMesh, file: &str) -> Result<LoadedMesh, MeshIoError> {
    let ParsedMesh {
        mut mesh,
        mut warnings,
        triangle_soup,
    } = parsed;
    let invalid = |source: MeshError| MeshIoError::InvalidMesh {
        file: file.to_owned(),
        source,
    };
    // Parsers check indices where they can say which line is at fault; this repeats the check
    // because welding and the degeneracy test index the vertices and would panic.
    let vertex_count = mesh.vertices.len();
    for (triangle, corners) in mesh.triangles.iter().enumerate() {
        if let Some(&vertex) = corners.iter().find(|&&v| v as usize >= vertex_count) {
            return Err(invalid(MeshError::IndexOutOfRange {
                triangle,
                vertex,
                vertex_count,
            }));
        }
    }
    let triangles_read = mesh.triangles.len();
    let degenerate = if triangle_soup {
        mesh.weld_identical_vertices()
    } else {
        mesh.remove_degenerate_triangles()
    };
    if degenerate > 0 {
        if degenerate == triangles_read {
            return Err(invalid(MeshError::AllDegenerate {
                triangles: degenerate,
            }));
        }
        warnings.push(format!(
            "removed {degenerate} of {triangles_read} triangles as degenerate (repeated vertices or zero area)"
        ));
    }
    let report = mesh.validate().map_err(invalid)?;
    warnings.extend(report.warnings());
    Ok(LoadedMesh {
        mesh,
        report,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::test_meshes::{
        BOX_VOLUME_MM3, ascii_stl, binary_stl, bop_like_ply, box_mesh_mm, mm_to_m,
        obj_with_every_face_form,
    };
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn point_clouds_round_trip_with_and_without_normals() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let points = vec![
            Point3::new(0.001, -0.02, 0.3),
            Point3::new(0.5, 0.25, -0.125),
        ];
        let normals = [nalgebra::Vector3::z(), nalgebra::Vector3::x()];
        for (name, n) in [("n.ply", Some(&normals[..])), ("p.ply", None)] {
            let path = dir.join(name);
            write_ply_points(&path, &points, n).unwrap();
            let read = read_ply_points(&path, LengthUnit::Metre).unwrap();
            assert_eq!(read.len(), 2);
            for (a, b) in read.iter().zip(&points) {
                // f32 storage: relative rounding 2⁻²⁴.
                assert!((a.cast::<f64>() - b).norm() < 1e-7, "{a} vs {b}");
            }
        }
        assert!(write_ply_points(&dir.join("bad.ply"), &points, Some(&normals[..1])).is_err());
        assert!(!dir.join("bad.ply").exists());
        write_ply_points(&dir.join("empty.ply"), &[], None).unwrap();
        assert!(matches!(
            read_ply_points(&dir.join("empty.ply"), LengthUnit::Metre),
            Err(MeshIoError::InvalidMesh { .. })
        ));
    }

    #[test]
    fn formats_come_from_extensions_in_any_case() {
        assert_eq!(
            MeshFormat::from_path(Path::new("models/obj_000001.PLY")),
            Some(MeshFormat::Ply)
        );
        assert_eq!(
            MeshFormat::from_path(Path::new("a.Obj")),
            Some(MeshFormat::Obj)
        );
        assert_eq!(
            MeshFormat::from_path(Path::new("a.stl")),
            Some(MeshFormat::Stl)
        );
        assert_eq!(MeshFormat::from_path(Path::new("a.off")), None);
        assert_eq!(MeshFormat::from_path(Path::new("noextension")), None);
    }

    #[test]
    fn formats_are_sniffed_from_contents() {
        let mesh = mm_to_m(&box_mesh_mm());
        let ply = write_ply_to_vec(&mesh, LengthUnit::Metre, PlyEncoding::BinaryLittleEndian);
        assert_eq!(MeshFormat::sniff(&ply), Some(MeshFormat::Ply));
        assert_eq!(
            MeshFormat::sniff(&binary_stl(&mesh, b"solid but binary")),
            Some(MeshFormat::Stl)
        );
        assert_eq!(
            MeshFormat::sniff(b"solid cube\n facet normal 0 0 1\n"),
            Some(MeshFormat::Stl)
        );
        assert_eq!(
            MeshFormat::sniff(b"# exported\n\nmtllib a.mtl\nv 0 0 0\n"),
            Some(MeshFormat::Obj)
        );
        assert_eq!(MeshFormat::sniff(b"OFF\n8 12 0\n"), None);
        assert_eq!(MeshFormat::sniff(b""), None);
    }

    #[test]
    fn read_mesh_uses_the_extension_or_sniffs() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = mm_to_m(&box_mesh_mm());
        let path = dir.path().join("box.mesh");
        write_ply(&path, &mesh, LengthUnit::Millimetre, PlyEncoding::Ascii).unwrap();
        let loaded = read_mesh(&path, LengthUnit::Millimetre).unwrap();
        assert_eq!(loaded.report.triangles, 12);
        assert!((loaded.report.signed_volume_m3 / (BOX_VOLUME_MM3 * 1e-9) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn unknown_and_unreadable_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mystery.xyz");
        std::fs::write(&path, b"OFF\n3 1 0\n").unwrap();
        let err = read_mesh(&path, LengthUnit::Metre).unwrap_err();
        assert!(matches!(err, MeshIoError::UnknownFormat { .. }), "{err:?}");
        assert!(
            err.to_string().contains("mystery.xyz") && err.to_string().contains(".xyz"),
            "{err}"
        );

        let missing = dir.path().join("missing.ply");
        let err = read_mesh(&missing, LengthUnit::Metre).unwrap_err();
        assert!(
            matches!(&err, MeshIoError::Read { source, .. } if source.kind() == std::io::ErrorKind::NotFound)
        );
        assert!(err.to_string().contains("missing.ply"), "{err}");
    }

    #[test]
    fn empty_meshes_are_invalid_in_every_format() {
        let empty_ply = b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n\
            property float y\nproperty float z\nelement face 0\n\
            property list uchar int vertex_indices\nend_header\n";
        let empty_files: [(MeshFormat, &[u8]); 4] = [
            (MeshFormat::Ply, empty_ply),
            (MeshFormat::Obj, b"# nothing here\n"),
            (MeshFormat::Stl, b"solid empty\nendsolid empty\n"),
            (MeshFormat::Stl, &[0; 84]),
        ];
        for (format, bytes) in empty_files {
            let err =
                read_mesh_from_bytes(bytes, format, LengthUnit::Metre, "empty.file").unwrap_err();
            assert!(
                matches!(
                    err,
                    MeshIoError::InvalidMesh {
                        source: MeshError::Empty { .. },
                        ..
                    }
                ),
                "{format}: {err:?}"
            );
            assert!(err.to_string().contains("empty.file"), "{err}");
        }
    }

    #[test]
    fn non_finite_vertices_are_invalid() {
        let obj = b"v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n";
        let err =
            read_mesh_from_bytes(obj, MeshFormat::Obj, LengthUnit::Metre, "nan.obj").unwrap_err();
        assert!(
            matches!(
                err,
                MeshIoError::InvalidMesh {
                    source: MeshError::NonFiniteVertex { index: 2, .. },
                    ..
                }
            ),
            "{err:?}"
        );
        assert!(err.to_string().contains("nan.obj"));
        // Finite in a file's double, infinite once narrowed to f32 metres.
        let obj = b"v 0 0 0\nv 1e300 0 0\nv 0 1 0\nf 1 2 3\n";
        let err =
            read_mesh_from_bytes(obj, MeshFormat::Obj, LengthUnit::Metre, "huge.obj").unwrap_err();
        assert!(matches!(
            err,
            MeshIoError::InvalidMesh {
                source: MeshError::NonFiniteVertex { index: 1, .. },
                ..
            }
        ));
    }

    #[test]
    fn degenerate_triangles_are_dropped_with_a_warning() {
        let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 2\n";
        let loaded =
            read_mesh_from_bytes(obj, MeshFormat::Obj, LengthUnit::Metre, "flat.obj").unwrap();
        assert_eq!(loaded.mesh.triangles, vec![[0, 1, 2]]);
        assert!(
            loaded
                .warnings
                .iter()
                .any(|w| w.contains("removed 2 of 3 triangles")),
            "{:?}",
            loaded.warnings
        );
        assert!(
            loaded.warnings.iter().any(|w| w.contains("open edges")),
            "{:?}",
            loaded.warnings
        );

        let all_flat = b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n";
        let err = read_mesh_from_bytes(all_flat, MeshFormat::Obj, LengthUnit::Metre, "flat.obj")
            .unwrap_err();
        assert!(matches!(
            err,
            MeshIoError::InvalidMesh {
                source: MeshError::AllDegenerate { triangles: 1 },
                ..
            }
        ));
    }

    #[test]
    fn write_ply_into_a_missing_directory_fails_cleanly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("absent").join("box.ply");
        let err = write_ply(
            &path,
            &mm_to_m(&box_mesh_mm()),
            LengthUnit::Millimetre,
            PlyEncoding::default(),
        )
        .unwrap_err();
        assert!(matches!(err, MeshIoError::Write(_)), "{err:?}");
        assert!(
            err.to_string().contains("box.ply") && err.to_string().contains("does not exist"),
            "{err}"
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    /// Valid files of every format and encoding, truncated and corrupted: each read must end in
    /// `Ok` or `Err`, never a panic (overflow checks are on in tests, so arithmetic counts too).
    #[test]
    fn mutated_files_never_panic() {
        let mesh = mm_to_m(&box_mesh_mm());
        let files: Vec<(MeshFormat, Vec<u8>)> = vec![
            (
                MeshFormat::Ply,
                write_ply_to_vec(
                    &mesh,
                    LengthUnit::Millimetre,
                    PlyEncoding::BinaryLittleEndian,
                ),
            ),
            (
                MeshFormat::Ply,
                write_ply_to_vec(&mesh, LengthUnit::Millimetre, PlyEncoding::Ascii),
            ),
            (MeshFormat::Ply, bop_like_ply(&box_mesh_mm(), true)),
            (MeshFormat::Obj, obj_with_every_face_form()),
            (MeshFormat::Stl, ascii_stl(&box_mesh_mm())),
            (
                MeshFormat::Stl,
                binary_stl(&box_mesh_mm(), b"solid binary header"),
            ),
        ];
        let mut rng = rand_pcg::Pcg64::seed_from_u64(0x6c69_6e74);
        let mut reads = 0;
        for (format, original) in &files {
            let mut read = |bytes: &[u8]| {
                reads += 1;
                let _ = read_mesh_from_bytes(bytes, *format, LengthUnit::Millimetre, "mutant");
            };
            // Every prefix for the small headers, then every 7th.
            for end in (0..original.len()).filter(|&end| end < 400 || end % 7 == 0) {
                read(&original[..end]);
            }
            for _ in 0..300 {
                let mut mutant = original.clone();
                for _ in 0..rng.random_range(1..=3) {
                    let at = rng.random_range(0..mutant.len());
                    mutant[at] ^= rng.random_range(1..=255u8);
                }
                read(&mutant);
                // Hostile values where they hurt most: counts, lengths and indices.
                let at = rng.random_range(0..mutant.len());
                mutant[at] =
                    [0x00, 0xff, 0x7f, 0x80, b'9', b'-', b'\n', b' '][rng.random_range(0..8)];
                read(&mutant);
                read(&mutant[..rng.random_range(0..mutant.len())]);
            }
            // The same bytes in the other formats.
            for other in [MeshFormat::Ply, MeshFormat::Obj, MeshFormat::Stl] {
                let _ = read_mesh_from_bytes(original, other, LengthUnit::Metre, "mutant");
            }
        }
        assert!(reads > 5000, "{reads}");
    }
}
