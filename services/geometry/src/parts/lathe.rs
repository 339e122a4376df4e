//! Surfaces around the z axis built from rings of vertices: a lathe whose radius may vary with
//! the angle (hexagons, gear outlines) and whose rings may have different vertex counts.
//!
//! A part's profile is a sequence of rings running counter-clockwise in the (r, z) half-plane
//! (up the outside, inwards over the top, down a bore, outwards under the bottom). Stitching
//! ring `from` to ring `to` in that order, with angles increasing counter-clockwise about +z,
//! gives outward faces: the outward normal is ∂p/∂θ × ∂p/∂(profile).

use std::f64::consts::TAU;

use nalgebra::Point3;

use super::builder::MeshBuilder;

/// A closed loop of vertices around the z axis, in increasing polar angle from 0 (inclusive)
/// to 2π (exclusive).
#[derive(Clone, Debug)]
pub(super) struct Ring {
    vertices: Vec<u32>,
    angles_rad: Vec<f64>,
}

impl Ring {
    /// A ring from vertices already in the builder and their polar angles (radians, starting
    /// at 0 and increasing below 2π).
    pub(super) fn from_parts(vertices: Vec<u32>, angles_rad: Vec<f64>) -> Self {
        debug_assert_eq!(vertices.len(), angles_rad.len());
        Self {
            vertices,
            angles_rad,
        }
    }

    /// Number of vertices.
    pub(super) fn len(&self) -> usize {
        self.vertices.len()
    }

    /// Vertex `i`, wrapping around the ring.
    pub(super) fn vertex(&self, i: usize) -> u32 {
        self.vertices[i % self.vertices.len()]
    }

    /// Polar angle of vertex `i`, unwrapped: vertex `len()` is vertex 0 at 2π.
    fn unwrapped_angle_rad(&self, i: usize) -> f64 {
        let n = self.angles_rad.len();
        self.angles_rad[i % n] + TAU * (i / n) as f64
    }
}

/// Polar angles of `count` evenly spaced samples, the first at 0.
pub(super) fn even_angles_rad(count: usize) -> Vec<f64> {
    (0..count).map(|j| TAU * j as f64 / count as f64).collect()
}

impl MeshBuilder {
    /// A ring through the points `(r(θ), θ, z(θ))` (millimetres) for the given polar angles.
    pub(super) fn polar_ring(
        &mut self,
        angles_rad: &[f64],
        radius_and_height_mm: impl Fn(f64) -> (f64, f64),
    ) -> Ring {
        let vertices = angles_rad
            .iter()
            .map(|&theta| {
                let (r, z) = radius_and_height_mm(theta);
                self.vertex(Point3::new(r * theta.cos(), r * theta.sin(), z))
            })
            .collect();
        Ring::from_parts(vertices, angles_rad.to_vec())
    }

    /// A ring in the plane `z = z_mm` through the points `(angle, radius)` (radians,
    /// millimetres) of a star-shaped outline, given in increasing angle from 0.
    pub(super) fn outline_ring(&mut self, outline: &[(f64, f64)], z_mm: f64) -> Ring {
        let vertices = outline
            .iter()
            .map(|&(theta, r)| self.vertex(Point3::new(r * theta.cos(), r * theta.sin(), z_mm)))
            .collect();
        Ring::from_parts(vertices, outline.iter().map(|&(theta, _)| theta).collect())
    }

    /// A circle of radius `radius_mm` at height `z_mm` through the given polar angles.
    pub(super) fn circle(&mut self, angles_rad: &[f64], radius_mm: f64, z_mm: f64) -> Ring {
        self.polar_ring(angles_rad, |_| (radius_mm, z_mm))
    }

    /// Joins two rings with the same vertex count, vertex `j` to vertex `j`, the profile
    /// running from `from` to `to`.
    pub(super) fn stitch(&mut self, from: &Ring, to: &Ring) {
        debug_assert_eq!(from.len(), to.len());
        for j in 0..from.len() {
            self.quad(
                from.vertex(j),
                from.vertex(j + 1),
                to.vertex(j + 1),
                to.vertex(j),
            );
        }
    }

    /// Stitches each ring to the next, the profile running along the slice.
    pub(super) fn stitch_chain(&mut self, rings: &[&Ring]) {
        for pair in rings.windows(2) {
            self.stitch(pair[0], pair[1]);
        }
    }

    /// Stitches each ring to the next and the last back to the first: a closed profile, so a
    /// surface with a hole through it (a bored part, a torus).
    pub(super) fn stitch_loop(&mut self, rings: &[&Ring]) {
        self.stitch_chain(rings);
        if let [first, .., last] = rings {
            self.stitch(last, first);
        }
    }

    /// Joins two rings of any vertex counts in a band of triangles, advancing around both in
    /// order of polar angle; the profile runs from `from` to `to`. The band is a valid surface
    /// when each ring sees the other within the band, e.g. two convex rings in one plane.
    pub(super) fn zip(&mut self, from: &Ring, to: &Ring) {
        let (n_from, n_to) = (from.len(), to.len());
        let (mut i, mut k) = (0, 0);
        while i < n_from || k < n_to {
            let advance_from = k == n_to
                || (i < n_from && from.unwrapped_angle_rad(i + 1) <= to.unwrapped_angle_rad(k + 1));
            if advance_from {
                self.triangle(from.vertex(i), from.vertex(i + 1), to.vertex(k));
                i += 1;
            } else {
                self.triangle(from.vertex(i), to.vertex(k + 1), to.vertex(k));
                k += 1;
            }
        }
    }

    /// Closes the start of a profile with a fan from `pole_mm` (on the axis) to `ring`.
    pub(super) fn cap_start(&mut self, pole_mm: Point3<f64>, ring: &Ring) {
        let pole = self.vertex(pole_mm);
        for j in 0..ring.len() {
            self.triangle(pole, ring.vertex(j + 1), ring.vertex(j));
        }
    }

    /// Closes the end of a profile with a fan from `ring` to `pole_mm` (on the axis).
    pub(super) fn cap_end(&mut self, ring: &Ring, pole_mm: Point3<f64>) {
        let pole = self.vertex(pole_mm);
        for j in 0..ring.len() {
            self.triangle(ring.vertex(j), ring.vertex(j + 1), pole);
        }
    }
}
