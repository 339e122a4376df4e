//! A helical screw thread on a cylinder along +z, meshed on a grid that follows the helix.
//!
//! The thread is single-start and right-handed with a symmetric triangular profile: at polar
//! angle θ and height z its radius is `r_minor + depth · tri(z/pitch − θ/2π) · runout(z)`,
//! where `tri` is 1 on the crest and 0 at the root. Vertex lines run along the helix, so crest
//! and root are meshed exactly with only two lines per pitch; away from the run-outs the only
//! discretisation error is the chord sag between the evenly spaced columns of angles.
//!
//! The section ends in flat rings at the minor radius: the thread depth runs out linearly over
//! the second pitch from each end, and the first pitch from each end is plain cylinder, which
//! holds the wedges that square the helical grid off to the two planes. Every vertex lies
//! between the minor and the major radius and the section is a radial graph over its
//! cylinder, so turning it about z moves its surface by at most the thread depth.

use nalgebra::Point3;

use super::builder::MeshBuilder;
use super::lathe::{Ring, even_angles_rad};

/// Vertex lines per pitch: the crest and the root, the corners of the triangular profile.
const LINES_PER_PITCH: usize = 2;

/// A threaded cylinder section.
#[derive(Clone, Copy, Debug)]
pub(super) struct Thread {
    /// Radius of the thread crest, millimetres.
    pub(super) major_radius_mm: f64,
    /// Radial depth from crest to root, millimetres.
    pub(super) depth_mm: f64,
    /// Axial advance per turn, millimetres.
    pub(super) pitch_mm: f64,
    /// Turns of the helix; the section is `turns + 1` pitches long (≥ 3 for a full-depth
    /// stretch between the run-outs).
    pub(super) turns: usize,
}

impl Thread {
    /// Radius of the thread root, millimetres.
    pub(super) fn minor_radius_mm(&self) -> f64 {
        self.major_radius_mm - self.depth_mm
    }

    /// Axial length of the section, millimetres.
    pub(super) fn length_mm(&self) -> f64 {
        (self.turns + 1) as f64 * self.pitch_mm
    }

    /// Fraction of the full depth at `height_mm` above the section's start: 0 on the first and
    /// last pitch, rising linearly to 1 over the next pitch inwards.
    fn runout(&self, height_mm: f64) -> f64 {
        let rise = ((height_mm - self.pitch_mm) / self.pitch_mm).clamp(0.0, 1.0);
        let fall = ((self.length_mm() - self.pitch_mm - height_mm) / self.pitch_mm).clamp(0.0, 1.0);
        rise * fall
    }

    /// Adds the section from `z_start_mm` up with `angular_steps` columns (at least 3) and
    /// returns its bottom and top rings: circles of the minor radius at evenly spaced angles,
    /// ready to be stitched to the rest of the part.
    pub(super) fn add_section(
        &self,
        builder: &mut MeshBuilder,
        z_start_mm: f64,
        angular_steps: usize,
    ) -> (Ring, Ring) {
        let n = angular_steps.max(3);
        let m = LINES_PER_PITCH;
        // Index of the last helix line; line k + m is line k one turn higher.
        let last = m * self.turns.max(1);
        let angles = even_angles_rad(n);
        let r_minor = self.minor_radius_mm();
        let z_end_mm = z_start_mm + self.length_mm();
        let on_cylinder =
            |r: f64, theta: f64, z: f64| Point3::new(r * theta.cos(), r * theta.sin(), z);
        let height_mm = |k: usize, j: usize| {
            z_start_mm + (k as f64 / m as f64 + j as f64 / n as f64) * self.pitch_mm
        };

        // Helix line k at column j: constant profile phase k/m along the line.
        let lines: Vec<Vec<u32>> = (0..=last)
            .map(|k| {
                let phase = (k % m) as f64 / m as f64;
                let crest_fraction = 1.0 - 2.0 * phase.min(1.0 - phase);
                (0..n)
                    .map(|j| {
                        let z = height_mm(k, j);
                        let r =
                            r_minor + self.depth_mm * crest_fraction * self.runout(z - z_start_mm);
                        builder.vertex(on_cylinder(r, angles[j], z))
                    })
                    .collect()
            })
            .collect();
        // The lines' ends after a full turn: the start of the line one turn up, or, for the
        // top turn, new vertices on the seam (in the run-out, so at the minor radius).
        let seam_ends: Vec<u32> = (last + 1 - m..=last)
            .map(|k| builder.vertex(on_cylinder(r_minor, 0.0, height_mm(k, n))))
            .collect();
        let line_end = |k: usize| {
            if k + m <= last {
                lines[k + m][0]
            } else {
                seam_ends[k + m - 1 - last]
            }
        };
        let at = |k: usize, j: usize| if j < n { lines[k][j] } else { line_end(k) };

        for k in 0..last {
            for j in 0..n {
                builder.quad(at(k, j), at(k, j + 1), at(k + 1, j + 1), at(k + 1, j));
            }
        }

        // Bottom wedge, between the flat bottom ring and the first helix line.
        let bottom: Vec<u32> = std::iter::once(lines[0][0])
            .chain((1..n).map(|j| builder.vertex(on_cylinder(r_minor, angles[j], z_start_mm))))
            .collect();
        builder.triangle(bottom[0], bottom[1], lines[0][1]);
        for j in 1..n - 1 {
            builder.quad(bottom[j], bottom[j + 1], lines[0][j + 1], lines[0][j]);
        }
        // The last column closes against the seam, where lines 0..=m start.
        for k in 0..m {
            builder.triangle(bottom[n - 1], lines[k][0], lines[k + 1][0]);
        }
        builder.triangle(bottom[n - 1], lines[m][0], lines[0][n - 1]);

        // Top wedge, between the last helix line and the flat top ring: the bottom wedge
        // turned upside down.
        let top: Vec<u32> = std::iter::once(line_end(last))
            .chain((1..n).map(|j| builder.vertex(on_cylinder(r_minor, angles[j], z_end_mm))))
            .collect();
        for j in 1..n - 1 {
            builder.quad(lines[last][j], lines[last][j + 1], top[j + 1], top[j]);
        }
        builder.triangle(lines[last][n - 1], line_end(last), top[n - 1]);
        // The first column closes against the seam, where the top turn's lines end.
        builder.triangle(lines[last][1], top[1], top[0]);
        for k in (last + 1 - m..=last).rev() {
            builder.triangle(lines[last][1], line_end(k), line_end(k - 1));
        }

        (
            Ring::from_parts(bottom, angles.clone()),
            Ring::from_parts(top, angles),
        )
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::{PI, TAU};

    use super::*;

    const THREAD: Thread = Thread {
        major_radius_mm: 4.0,
        depth_mm: 0.77,
        pitch_mm: 1.25,
        turns: 5,
    };
    const STEPS: usize = 24;

    #[test]
    fn section_is_a_radial_graph_between_minor_and_major_radius() {
        let mut builder = MeshBuilder::new();
        let z_start = -2.0;
        let (bottom, top) = THREAD.add_section(&mut builder, z_start, STEPS);
        assert_eq!((bottom.len(), top.len()), (STEPS, STEPS));
        let mesh = builder.into_mesh();
        let mm = |p: &Point3<f32>| p.coords.cast::<f64>() * 1e3;
        // The mesh is stored in f32 metres: 10 nm of rounding.
        let eps_mm = 1e-5;

        let z_end = z_start + THREAD.length_mm();
        for p in mesh.vertices.iter().map(mm) {
            let r = p.xy().norm();
            assert!(
                r > THREAD.minor_radius_mm() - eps_mm && r < THREAD.major_radius_mm + eps_mm,
                "{p:?}"
            );
            assert!(p.z > z_start - eps_mm && p.z < z_end + eps_mm, "{p:?}");
        }
        // Unrolled onto (θ, z), every triangle runs counter-clockwise: the section covers its
        // cylinder once, without folds, so it is a radial graph r(θ, z).
        let mut unrolled_area = 0.0;
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mm(&mesh.vertices[i as usize]));
            let theta_a = a.y.atan2(a.x);
            let unrolled = |p: nalgebra::Vector3<f64>| {
                let d = (p.y.atan2(p.x) - theta_a + PI).rem_euclid(TAU) - PI;
                (d, p.z)
            };
            let ((ua, za), (ub, zb), (uc, zc)) = (unrolled(a), unrolled(b), unrolled(c));
            let area = 0.5 * ((ub - ua) * (zc - za) - (uc - ua) * (zb - za));
            assert!(area > 0.0, "triangle {t:?} is folded over");
            unrolled_area += area;
        }
        let cylinder = TAU * THREAD.length_mm();
        assert!(
            (unrolled_area - cylinder).abs() < 1e-6 * cylinder,
            "{unrolled_area} vs {cylinder}"
        );
    }

    #[test]
    fn the_thread_reaches_full_depth_between_the_run_outs() {
        let mut builder = MeshBuilder::new();
        THREAD.add_section(&mut builder, 0.0, STEPS);
        let largest_r_mm = builder
            .into_mesh()
            .vertices
            .iter()
            .map(|p| f64::from(p.xy().coords.norm()) * 1e3)
            .fold(0.0, f64::max);
        assert!(
            (largest_r_mm - THREAD.major_radius_mm).abs() < 1e-4,
            "{largest_r_mm}"
        );
    }
}
