//! A triangle-mesh builder that works in millimetres and `f64`, the units the part drawings are
//! written in, and hands out a [`TriMesh`] in metres.
//!
//! Triangles are added counter-clockwise seen from outside the solid (outward normals).

use nalgebra::{Isometry3, Point3, Vector3};

use crate::mesh::TriMesh;

/// Metres per millimetre.
pub(super) const METRES_PER_MM: f64 = 1e-3;

/// Vertices (millimetres) and triangles of a part under construction.
#[derive(Debug, Default)]
pub(super) struct MeshBuilder {
    vertices_mm: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
}

impl MeshBuilder {
    pub(super) fn new() -> Self {
        Self::default()
    }

    /// Adds a vertex (millimetres) and returns its index.
    pub(super) fn vertex(&mut self, position_mm: Point3<f64>) -> u32 {
        self.vertices_mm.push(position_mm);
        // The parts have at most tens of thousands of vertices, far below `u32::MAX`.
        (self.vertices_mm.len() - 1) as u32
    }

    /// Adds a triangle whose corners are counter-clockwise seen from outside.
    pub(super) fn triangle(&mut self, a: u32, b: u32, c: u32) {
        self.triangles.push([a, b, c]);
    }

    /// Adds the quad `a b c d` (counter-clockwise seen from outside) as two triangles split
    /// along the diagonal `a c`.
    pub(super) fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.triangle(a, b, c);
        self.triangle(a, c, d);
    }

    /// Maps every vertex built so far by `t_a_b` (a rigid motion keeps the faces outward).
    pub(super) fn transform(&mut self, t_a_b: &Isometry3<f64>) {
        for p in &mut self.vertices_mm {
            *p = t_a_b * *p;
        }
    }

    /// Moves the part along z so that its extent along z is centred on the origin; x and y are
    /// untouched, so a symmetry axis through the origin stays there.
    pub(super) fn centre_along_z(&mut self) {
        let (lowest, highest) = self
            .vertices_mm
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.z), hi.max(p.z))
            });
        if lowest.is_finite() && highest.is_finite() {
            let shift = Vector3::new(0.0, 0.0, -0.5 * (lowest + highest));
            self.transform(&Isometry3::translation(shift.x, shift.y, shift.z));
        }
    }

    /// Adds another builder's vertices and triangles, re-indexed.
    pub(super) fn append(&mut self, other: MeshBuilder) {
        let offset = self.vertices_mm.len() as u32;
        self.vertices_mm.extend(other.vertices_mm);
        self.triangles
            .extend(other.triangles.into_iter().map(|t| t.map(|i| i + offset)));
    }

    /// The finished mesh, vertices converted to metres.
    pub(super) fn into_mesh(self) -> TriMesh {
        let vertices = self
            .vertices_mm
            .iter()
            .map(|p| Point3::from(p.coords * METRES_PER_MM).cast::<f32>())
            .collect();
        TriMesh::new(vertices, self.triangles)
    }
}
