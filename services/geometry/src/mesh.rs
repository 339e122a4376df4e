//! Indexed triangle meshes, their validation and topology.
//!
//! Vertices are `f32` metres in the mesh (object) frame; triangles are counter-clockwise seen
//! from outside, so face normals point out of the solid.

use std::collections::HashMap;
use std::fmt;
use std::str::FromStr;

use nalgebra::{Isometry3, Point3, Vector3};

/// The length unit a mesh file is written in. Inside Glint everything is metres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum LengthUnit {
    /// Millimetres: BOP models, most CAD exports.
    Millimetre,
    /// Metres.
    Metre,
}

impl LengthUnit {
    /// Metres in one unit.
    pub fn metres_per_unit(self) -> f64 {
        match self {
            LengthUnit::Millimetre => 1e-3,
            LengthUnit::Metre => 1.0,
        }
    }
}

impl FromStr for LengthUnit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "mm" => Ok(LengthUnit::Millimetre),
            "m" => Ok(LengthUnit::Metre),
            other => Err(format!(
                "unknown length unit {other:?}: expected \"mm\" or \"m\""
            )),
        }
    }
}

impl fmt::Display for LengthUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            LengthUnit::Millimetre => "mm",
            LengthUnit::Metre => "m",
        })
    }
}

/// A mesh that cannot be used at all.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshError {
    /// The mesh has no vertices or no triangles; check that the file holds faces.
    #[error("the mesh is empty ({vertices} vertices, {triangles} triangles)")]
    Empty {
        /// Number of vertices.
        vertices: usize,
        /// Number of triangles.
        triangles: usize,
    },
    /// A vertex has a NaN or infinite coordinate; the file or the code that built the mesh is
    /// corrupt.
    #[error("vertex {index} is not finite: ({x}, {y}, {z})")]
    NonFiniteVertex {
        /// 0-based index of the first such vertex.
        index: usize,
        /// Its x coordinate, metres.
        x: f32,
        /// Its y coordinate, metres.
        y: f32,
        /// Its z coordinate, metres.
        z: f32,
    },
    /// A triangle refers to a vertex the mesh does not have.
    #[error(
        "triangle {triangle} refers to vertex {vertex}, but the mesh has only {vertex_count} vertices"
    )]
    IndexOutOfRange {
        /// 0-based index of the first such triangle.
        triangle: usize,
        /// The vertex index it holds.
        vertex: u32,
        /// Number of vertices in the mesh.
        vertex_count: usize,
    },
    /// Every triangle repeats a vertex or has (relative) zero area, so the mesh has no surface;
    /// check the file's unit and contents.
    #[error("all {triangles} triangles are degenerate (repeated vertices or zero area)")]
    AllDegenerate {
        /// Number of triangles, all degenerate.
        triangles: usize,
    },
    /// The use named by `purpose` needs a closed, consistently oriented surface and the mesh is
    /// not one; repair the mesh (close holes, fix flipped faces) first.
    #[error(
        "the mesh is not watertight ({open_edges} open edges, {non_manifold_edges} non-manifold \
         edges, {inconsistent_edges} edges with flipped neighbours): {purpose} needs a closed, \
         consistently oriented surface"
    )]
    NotWatertight {
        /// Edges used by exactly one triangle.
        open_edges: usize,
        /// Edges used by three or more triangles.
        non_manifold_edges: usize,
        /// Edges whose two triangles traverse them in the same direction.
        inconsistent_edges: usize,
        /// What needed the watertight mesh.
        purpose: &'static str,
    },
}

/// What [`TriMesh::validate`] found in a usable mesh. Problems that do not stop every use of
/// the mesh (open edges, say) are counted here; [`MeshReport::warnings`] words them for a user.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshReport {
    /// Number of vertices.
    pub vertices: usize,
    /// Number of triangles, degenerate ones included.
    pub triangles: usize,
    /// Triangles with a repeated vertex or (relative) zero area.
    pub degenerate_triangles: usize,
    /// Edges used by exactly one triangle.
    pub open_edges: usize,
    /// Edges used by three or more triangles.
    pub non_manifold_edges: usize,
    /// Edges whose two triangles traverse them in the same direction (flipped orientation).
    pub inconsistent_edges: usize,
    /// Edge-connected components.
    pub components: usize,
    /// Signed enclosed volume, m³; negative when the faces point inwards.
    pub signed_volume_m3: f64,
    /// Axis-aligned bounds, metres: the minimum corner.
    pub aabb_min: Point3<f32>,
    /// Axis-aligned bounds, metres: the maximum corner.
    pub aabb_max: Point3<f32>,
}

impl MeshReport {
    /// Closed, 2-manifold and consistently oriented.
    pub fn is_watertight(&self) -> bool {
        self.open_edges == 0 && self.non_manifold_edges == 0 && self.inconsistent_edges == 0
    }

    /// Human-readable warnings; empty for a clean closed mesh.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if self.degenerate_triangles > 0 {
            w.push(format!(
                "{} degenerate triangles (repeated vertices or zero area)",
                self.degenerate_triangles
            ));
        }
        if self.open_edges > 0 {
            w.push(format!(
                "{} open edges: the mesh is not watertight",
                self.open_edges
            ));
        }
        if self.non_manifold_edges > 0 {
            w.push(format!(
                "{} non-manifold edges (3+ faces)",
                self.non_manifold_edges
            ));
        }
        if self.inconsistent_edges > 0 {
            w.push(format!(
                "{} edges whose faces are oriented inconsistently",
                self.inconsistent_edges
            ));
        }
        if self.is_watertight() && self.signed_volume_m3 < 0.0 {
            w.push("faces point inwards (negative enclosed volume)".to_owned());
        }
        w
    }

    /// Fails unless the mesh is watertight; `purpose` says what needed it.
    pub fn require_watertight(&self, purpose: &'static str) -> Result<(), MeshError> {
        if self.is_watertight() {
            Ok(())
        } else {
            Err(MeshError::NotWatertight {
                open_edges: self.open_edges,
                non_manifold_edges: self.non_manifold_edges,
                inconsistent_edges: self.inconsistent_edges,
                purpose,
            })
        }
    }
}

/// An indexed triangle mesh, vertices in metres.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions in the mesh frame, metres.
    pub vertices: Vec<Point3<f32>>,
    /// Triangles as indices into `vertices`, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

/// Relative area below which a triangle counts as degenerate: area < this × (longest edge)².
const DEGENERATE_RELATIVE_AREA: f32 = 1e-9;

impl TriMesh {
    /// A mesh of `vertices` (metres) and `triangles` (indices into `vertices`), unvalidated:
    /// see [`TriMesh::validate`].
    pub fn new(vertices: Vec<Point3<f32>>, triangles: Vec<[u32; 3]>) -> Self {
        Self {
            vertices,
            triangles,
        }
    }

    /// A UV sphere of radius `r` (metres) centred at the origin, with `n` segments around the z
    /// axis (at least 4) and `n/2` rings: outward-facing, closed. Flat facets, so it doubles as a
    /// test object with a dense, known spread of normals.
    pub fn uv_sphere(r: f32, n: u32) -> Self {
        let n = n.max(4);
        let rings = n / 2;
        let mut vertices = vec![Point3::new(0.0, 0.0, r)];
        for k in 1..rings {
            let theta = std::f32::consts::PI * k as f32 / rings as f32;
            for i in 0..n {
                let phi = std::f32::consts::TAU * i as f32 / n as f32;
                vertices.push(Point3::new(
                    r * theta.sin() * phi.cos(),
                    r * theta.sin() * phi.sin(),
                    r * theta.cos(),
                ));
            }
        }
        vertices.push(Point3::new(0.0, 0.0, -r));
        let south = vertices.len() as u32 - 1;
        let ring = |k: u32, i: u32| 1 + (k - 1) * n + i % n;
        let mut triangles = Vec::new();
        for i in 0..n {
            triangles.push([0, ring(1, i), ring(1, i + 1)]);
            triangles.push([south, ring(rings - 1, i + 1), ring(rings - 1, i)]);
        }
        for k in 1..rings - 1 {
            for i in 0..n {
                triangles.push([ring(k, i), ring(k + 1, i), ring(k + 1, i + 1)]);
                triangles.push([ring(k, i), ring(k + 1, i + 1), ring(k, i + 1)]);
            }
        }
        Self::new(vertices, triangles)
    }

    /// An axis-aligned closed box around `centre` with `half_extents`, metres, faces outward.
    pub fn cuboid(centre: [f64; 3], half_extents: [f64; 3]) -> Self {
        let v = |x: f64, y: f64, z: f64| {
            Point3::new(
                (centre[0] + x * half_extents[0]) as f32,
                (centre[1] + y * half_extents[1]) as f32,
                (centre[2] + z * half_extents[2]) as f32,
            )
        };
        Self::new(
            vec![
                v(-1., -1., -1.),
                v(1., -1., -1.),
                v(1., 1., -1.),
                v(-1., 1., -1.),
                v(-1., -1., 1.),
                v(1., -1., 1.),
                v(1., 1., 1.),
                v(-1., 1., 1.),
            ],
            vec![
                [0, 2, 1],
                [0, 3, 2],
                [4, 5, 6],
                [4, 6, 7],
                [0, 1, 5],
                [0, 5, 4],
                [2, 3, 7],
                [2, 7, 6],
                [1, 2, 6],
                [1, 6, 5],
                [0, 4, 7],
                [0, 7, 3],
            ],
        )
    }

    /// The mesh's canonical encoding: the vertex and triangle counts (u64 little-endian),
    /// every vertex's x, y, z (f32 LE), every triangle's indices (u32 LE). Exact: it reads
    /// back bit for bit ([`Self::from_canonical_bytes`]).
    pub fn canonical_bytes(&self) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(16 + 12 * (self.vertices.len() + self.triangles.len()));
        bytes.extend_from_slice(&(self.vertices.len() as u64).to_le_bytes());
        bytes.extend_from_slice(&(self.triangles.len() as u64).to_le_bytes());
        for v in &self.vertices {
            for c in [v.x, v.y, v.z] {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        for t in &self.triangles {
            for i in t {
                bytes.extend_from_slice(&i.to_le_bytes());
            }
        }
        bytes
    }

    /// The mesh of a [`Self::canonical_bytes`] encoding; `None` when the bytes are not one
    /// (wrong length, an index out of range). Vertices are not validated beyond that.
    pub fn from_canonical_bytes(bytes: &[u8]) -> Option<Self> {
        let count = |at: usize| -> Option<usize> {
            usize::try_from(u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?)).ok()
        };
        let (n_vertices, n_triangles) = (count(0)?, count(8)?);
        let expected = n_vertices
            .checked_add(n_triangles)?
            .checked_mul(12)?
            .checked_add(16)?;
        if bytes.len() != expected {
            return None;
        }
        let word = |i: usize| -> [u8; 4] {
            let at = 16 + 4 * i;
            [bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]
        };
        let vertices = (0..n_vertices)
            .map(|v| {
                let c = |k: usize| f32::from_le_bytes(word(3 * v + k));
                Point3::new(c(0), c(1), c(2))
            })
            .collect();
        let triangles: Vec<[u32; 3]> = (0..n_triangles)
            .map(|t| {
                let i = |k: usize| u32::from_le_bytes(word(3 * n_vertices + 3 * t + k));
                [i(0), i(1), i(2)]
            })
            .collect();
        if triangles
            .iter()
            .flatten()
            .any(|&i| i as usize >= n_vertices)
        {
            return None;
        }
        Some(Self::new(vertices, triangles))
    }

    /// SHA-256 of [`Self::canonical_bytes`], lowercase hex. Equal meshes hash equal whatever
    /// file they came from: the key under which stages cache a part.
    pub fn content_sha256_hex(&self) -> String {
        crate::sha256_hex(&self.canonical_bytes())
    }

    /// The corners of triangle `i`.
    #[inline]
    pub fn triangle(&self, i: usize) -> [Point3<f32>; 3] {
        let [a, b, c] = self.triangles[i];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// Area-weighted normal of triangle `i` (length = 2 × area).
    #[inline]
    pub fn triangle_cross(&self, i: usize) -> Vector3<f32> {
        let [a, b, c] = self.triangle(i);
        (b - a).cross(&(c - a))
    }

    /// Unit outward normal of triangle `i`, or zero for a degenerate one.
    pub fn face_normal(&self, i: usize) -> Vector3<f32> {
        self.triangle_cross(i)
            .try_normalize(0.0)
            .unwrap_or_else(Vector3::zeros)
    }

    /// Whether triangle `i` has a repeated vertex or a negligible area.
    pub fn is_degenerate(&self, i: usize) -> bool {
        let [a, b, c] = self.triangles[i];
        if a == b || b == c || a == c {
            return true;
        }
        let [pa, pb, pc] = self.triangle(i);
        let longest = (pb - pa)
            .norm_squared()
            .max((pc - pb).norm_squared())
            .max((pa - pc).norm_squared());
        let twice_area = self.triangle_cross(i).norm();
        longest == 0.0 || 0.5 * twice_area < DEGENERATE_RELATIVE_AREA * longest
    }

    /// Total surface area, m².
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|i| 0.5 * self.triangle_cross(i).norm() as f64)
            .sum()
    }

    /// Signed enclosed volume by the divergence theorem, m³ (exact for a closed mesh).
    pub fn signed_volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|i| {
                let [a, b, c] = self.triangle(i).map(|p| p.coords.cast::<f64>());
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Axis-aligned bounds, or `None` for a mesh without vertices.
    pub fn aabb(&self) -> Option<(Point3<f32>, Point3<f32>)> {
        let first = *self.vertices.first()?;
        Some(
            self.vertices
                .iter()
                .fold((first, first), |(lo, hi), p| (lo.inf(p), hi.sup(p))),
        )
    }

    /// This mesh with every vertex scaled by `factor` (e.g. millimetres → metres).
    pub fn scaled(&self, factor: f32) -> Self {
        Self {
            vertices: self
                .vertices
                .iter()
                .map(|p| Point3::from(p.coords * factor))
                .collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// This mesh with every vertex mapped by `t_a_b` (the mesh is in frame b, the result in a).
    pub fn transformed(&self, t_a_b: &Isometry3<f32>) -> Self {
        Self {
            vertices: self.vertices.iter().map(|p| t_a_b * p).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// Appends `other`, re-indexing its triangles.
    pub fn append(&mut self, other: &TriMesh) {
        let offset = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&other.vertices);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + offset)));
    }

    /// Merges vertices with bit-identical positions (STL stores every triangle's corners
    /// separately) and drops triangles that became degenerate. Returns the number dropped.
    pub fn weld_identical_vertices(&mut self) -> usize {
        let mut index_of: HashMap<[u32; 3], u32> = HashMap::with_capacity(self.vertices.len());
        let mut vertices = Vec::with_capacity(self.vertices.len() / 2);
        let remap: Vec<u32> = self
            .vertices
            .iter()
            .map(|p| {
                // +0.0 folds -0.0 onto 0.0 so both weld.
                let key = [p.x + 0.0, p.y + 0.0, p.z + 0.0].map(f32::to_bits);
                *index_of.entry(key).or_insert_with(|| {
                    vertices.push(*p);
                    (vertices.len() - 1) as u32
                })
            })
            .collect();
        self.vertices = vertices;
        for t in &mut self.triangles {
            *t = t.map(|i| remap[i as usize]);
        }
        self.remove_degenerate_triangles()
    }

    /// Drops triangles with a repeated vertex or zero area; returns how many.
    pub fn remove_degenerate_triangles(&mut self) -> usize {
        let keep: Vec<bool> = (0..self.triangles.len())
            .map(|i| !self.is_degenerate(i))
            .collect();
        let before = self.triangles.len();
        let mut k = keep.iter();
        self.triangles.retain(|_| *k.next().unwrap_or(&true));
        before - self.triangles.len()
    }

    /// Checks what makes a mesh unusable (returned as an error) and counts what only limits
    /// its use (in the report). Never panics, whatever the input.
    pub fn validate(&self) -> Result<MeshReport, MeshError> {
        if self.vertices.is_empty() || self.triangles.is_empty() {
            return Err(MeshError::Empty {
                vertices: self.vertices.len(),
                triangles: self.triangles.len(),
            });
        }
        if let Some((index, p)) = self
            .vertices
            .iter()
            .enumerate()
            .find(|(_, p)| !p.coords.iter().all(|c| c.is_finite()))
        {
            return Err(MeshError::NonFiniteVertex {
                index,
                x: p.x,
                y: p.y,
                z: p.z,
            });
        }
        let n = self.vertices.len();
        for (triangle, t) in self.triangles.iter().enumerate() {
            if let Some(&vertex) = t.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::IndexOutOfRange {
                    triangle,
                    vertex,
                    vertex_count: n,
                });
            }
        }
        let degenerate_triangles = (0..self.triangles.len())
            .filter(|&i| self.is_degenerate(i))
            .count();
        if degenerate_triangles == self.triangles.len() {
            return Err(MeshError::AllDegenerate {
                triangles: degenerate_triangles,
            });
        }
        let topology = EdgeTopology::of(self);
        let Some((aabb_min, aabb_max)) = self.aabb() else {
            return Err(MeshError::Empty {
                vertices: n,
                triangles: self.triangles.len(),
            });
        };
        Ok(MeshReport {
            vertices: n,
            triangles: self.triangles.len(),
            degenerate_triangles,
            open_edges: topology.open_edges,
            non_manifold_edges: topology.non_manifold_edges,
            inconsistent_edges: topology.inconsistent_edges,
            components: self.connected_components().len(),
            signed_volume_m3: self.signed_volume(),
            aabb_min,
            aabb_max,
        })
    }

    /// Triangle indices of each edge-connected component (sharing a vertex suffices).
    pub fn connected_components(&self) -> Vec<Vec<u32>> {
        let mut parent: Vec<u32> = (0..self.vertices.len() as u32).collect();
        fn find(parent: &mut [u32], mut x: u32) -> u32 {
            while parent[x as usize] != x {
                parent[x as usize] = parent[parent[x as usize] as usize];
                x = parent[x as usize];
            }
            x
        }
        for t in &self.triangles {
            if t.iter().any(|&i| i as usize >= parent.len()) {
                continue;
            }
            let r0 = find(&mut parent, t[0]);
            for &v in &t[1..] {
                let r = find(&mut parent, v);
                parent[r as usize] = r0;
            }
        }
        let mut by_root: HashMap<u32, Vec<u32>> = HashMap::new();
        let mut order = Vec::new();
        for (i, t) in self.triangles.iter().enumerate() {
            if t.iter().any(|&v| v as usize >= parent.len()) {
                continue;
            }
            let root = find(&mut parent, t[0]);
            by_root
                .entry(root)
                .or_insert_with(|| {
                    order.push(root);
                    Vec::new()
                })
                .push(i as u32);
        }
        order
            .into_iter()
            .map(|r| by_root.remove(&r).unwrap_or_default())
            .collect()
    }

    /// The sub-mesh made of the given triangles, with only the vertices they use.
    pub fn submesh(&self, triangles: &[u32]) -> TriMesh {
        let mut remap: HashMap<u32, u32> = HashMap::new();
        let mut out = TriMesh::default();
        for &ti in triangles {
            let t = self.triangles[ti as usize].map(|v| {
                *remap.entry(v).or_insert_with(|| {
                    out.vertices.push(self.vertices[v as usize]);
                    (out.vertices.len() - 1) as u32
                })
            });
            out.triangles.push(t);
        }
        out
    }
}

/// Edge use counts: the basis of the watertightness test.
struct EdgeTopology {
    open_edges: usize,
    non_manifold_edges: usize,
    inconsistent_edges: usize,
}

impl EdgeTopology {
    fn of(mesh: &TriMesh) -> Self {
        // Per undirected edge: (uses in direction lo→hi, uses in direction hi→lo).
        let mut uses: HashMap<(u32, u32), (u32, u32)> =
            HashMap::with_capacity(mesh.triangles.len() * 3 / 2);
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if a == b {
                    continue;
                }
                let e = uses.entry((a.min(b), a.max(b))).or_insert((0, 0));
                if a < b { e.0 += 1 } else { e.1 += 1 }
            }
        }
        let mut topology = Self {
            open_edges: 0,
            non_manifold_edges: 0,
            inconsistent_edges: 0,
        };
        for &(forward, backward) in uses.values() {
            match forward + backward {
                1 => topology.open_edges += 1,
                2 if forward != 1 => topology.inconsistent_edges += 1,
                2 => {}
                _ => topology.non_manifold_edges += 1,
            }
        }
        topology
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit-ish tetrahedron with outward faces.
    fn tetrahedron() -> TriMesh {
        TriMesh::new(
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
                Point3::new(0.0, 0.0, 1.0),
            ],
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        )
    }

    #[test]
    fn tetrahedron_is_watertight_with_exact_volume() {
        let report = tetrahedron().validate().unwrap();
        assert!(report.is_watertight(), "{report:?}");
        assert!(report.warnings().is_empty());
        // Volume of the corner tetrahedron is 1/6.
        assert!((report.signed_volume_m3 - 1.0 / 6.0).abs() < 1e-12);
        assert_eq!(report.components, 1);
    }

    #[test]
    fn open_and_flipped_meshes_are_reported() {
        let mut open = tetrahedron();
        open.triangles.pop();
        let r = open.validate().unwrap();
        assert_eq!(r.open_edges, 3);
        assert!(r.require_watertight("test").is_err());

        let mut flipped = tetrahedron();
        flipped.triangles[3] = [1, 3, 2];
        let r = flipped.validate().unwrap();
        assert_eq!(r.inconsistent_edges, 3);
        assert!(!r.warnings().is_empty());
    }

    #[test]
    fn unusable_meshes_are_errors_not_panics() {
        assert!(matches!(
            TriMesh::default().validate(),
            Err(MeshError::Empty { .. })
        ));
        let mut nan = tetrahedron();
        nan.vertices[2].y = f32::NAN;
        assert!(matches!(
            nan.validate(),
            Err(MeshError::NonFiniteVertex { index: 2, .. })
        ));
        let mut bad_index = tetrahedron();
        bad_index.triangles[1][2] = 9;
        assert_eq!(
            bad_index.validate(),
            Err(MeshError::IndexOutOfRange {
                triangle: 1,
                vertex: 9,
                vertex_count: 4
            })
        );
        let all_degenerate = TriMesh::new(tetrahedron().vertices, vec![[0, 0, 1], [1, 2, 2]]);
        assert!(matches!(
            all_degenerate.validate(),
            Err(MeshError::AllDegenerate { .. })
        ));
        // Out-of-range indices must not panic the component search either.
        assert_eq!(bad_index.connected_components().len(), 1);
    }

    #[test]
    fn welding_joins_triangle_soup() {
        let tet = tetrahedron();
        let mut soup = TriMesh::default();
        for i in 0..tet.triangles.len() {
            let corners = tet.triangle(i);
            soup.append(&TriMesh::new(corners.to_vec(), vec![[0, 1, 2]]));
        }
        assert_eq!(soup.vertices.len(), 12);
        assert_eq!(soup.weld_identical_vertices(), 0);
        assert_eq!(soup.vertices.len(), 4);
        assert!(soup.validate().unwrap().is_watertight());
    }
}
