//! The Zigzag: a sheet-metal strip bent into a Z, three straight legs joined by two rounded
//! bends that turn by the same angle in opposite senses.
//!
//! One closed shell: the strip's outline in the xy-plane (the bent centre line thickened by
//! the sheet thickness), extruded along z by the strip's width. Object frame: the Z lies in
//! the xy-plane with its end legs along x, the origin is the middle of the middle leg and of
//! the width. Point-symmetric in the plane, so the half turn about z maps it onto itself,
//! exactly: the sampling of the centre line is point-symmetric too.

use nalgebra::{Point3, Vector2};

use super::builder::MeshBuilder;
use crate::mesh::TriMesh;
use crate::symmetry::{Axis, Symmetry};

/// Thickness of the sheet, mm.
const SHEET_THICKNESS_MM: f64 = 1.5;
/// Width of the strip (its extent along z), mm.
const STRIP_WIDTH_MM: f64 = 10.0;
/// Straight length of each end leg, mm.
const END_LEG_LENGTH_MM: f64 = 12.0;
/// Straight length of the middle (diagonal) leg, mm.
const MIDDLE_LEG_LENGTH_MM: f64 = 16.0;
/// Angle each bend turns the strip by, degrees (the legs meet the diagonal at 60°).
const BEND_ANGLE_DEG: f64 = 120.0;
/// Inside radius of each bend, mm (one sheet thickness).
const BEND_INNER_RADIUS_MM: f64 = 1.5;

/// Segments of each bend.
const BEND_STEPS: usize = 24;
/// Largest spacing of the samples along a straight leg, mm.
const LEG_STEP_MM: f64 = 1.0;

/// Radius of the bends' centre line, mm.
const BEND_CENTRE_RADIUS_MM: f64 = BEND_INNER_RADIUS_MM + SHEET_THICKNESS_MM / 2.0;

/// Unit vector at `heading_rad` from +x.
fn direction(heading_rad: f64) -> Vector2<f64> {
    Vector2::new(heading_rad.cos(), heading_rad.sin())
}

/// Unit vector a quarter turn counter-clockwise from [`direction`]`(heading_rad)`.
fn left_normal(heading_rad: f64) -> Vector2<f64> {
    Vector2::new(-heading_rad.sin(), heading_rad.cos())
}

/// A walk along the strip's centre line, recording `(position, heading)` samples (mm, rad).
struct CentreLine {
    samples: Vec<(Vector2<f64>, f64)>,
}

impl CentreLine {
    fn starting_at(position: Vector2<f64>, heading_rad: f64) -> Self {
        Self {
            samples: vec![(position, heading_rad)],
        }
    }

    fn end(&self) -> (Vector2<f64>, f64) {
        self.samples
            .last()
            .copied()
            .unwrap_or((Vector2::zeros(), 0.0))
    }

    /// Goes straight on for `length_mm`.
    fn straight(&mut self, length_mm: f64) {
        let (start, heading) = self.end();
        let steps = (length_mm / LEG_STEP_MM).ceil().max(1.0) as usize;
        self.samples.extend((1..=steps).map(|i| {
            (
                start + direction(heading) * (length_mm * i as f64 / steps as f64),
                heading,
            )
        }));
    }

    /// Bends by `turn_rad` (positive: to the left) on the bends' centre-line radius.
    fn bend(&mut self, turn_rad: f64) {
        let (start, heading) = self.end();
        let side = turn_rad.signum();
        let centre = start + left_normal(heading) * (side * BEND_CENTRE_RADIUS_MM);
        self.samples.extend((1..=BEND_STEPS).map(|i| {
            let h = heading + turn_rad * i as f64 / BEND_STEPS as f64;
            (centre - left_normal(h) * (side * BEND_CENTRE_RADIUS_MM), h)
        }));
    }
}

/// The centre line of the Z, centred on the origin: end leg along +x, bend right, middle leg,
/// bend left, end leg along +x.
fn centre_line() -> Vec<(Vector2<f64>, f64)> {
    let bend = BEND_ANGLE_DEG.to_radians();
    let mut line = CentreLine::starting_at(Vector2::zeros(), 0.0);
    line.straight(END_LEG_LENGTH_MM);
    line.bend(-bend);
    let (middle_start, middle_heading) = line.end();
    line.straight(MIDDLE_LEG_LENGTH_MM);
    line.bend(bend);
    line.straight(END_LEG_LENGTH_MM);
    let middle = middle_start + direction(middle_heading) * (MIDDLE_LEG_LENGTH_MM / 2.0);
    line.samples
        .into_iter()
        .map(|(p, heading)| (p - middle, heading))
        .collect()
}

/// The zigzag's mesh, metres.
pub(super) fn mesh() -> TriMesh {
    let mut builder = MeshBuilder::new();
    let half_thickness = SHEET_THICKNESS_MM / 2.0;
    let centre = centre_line();
    // The outline, counter-clockwise seen from +z: along the right edge, back along the left.
    let right = centre
        .iter()
        .map(|&(p, h)| p - left_normal(h) * half_thickness);
    let left = centre
        .iter()
        .rev()
        .map(|&(p, h)| p + left_normal(h) * half_thickness);
    let outline: Vec<Vector2<f64>> = right.chain(left).collect();

    let mut layer = |z: f64| -> Vec<u32> {
        outline
            .iter()
            .map(|p| builder.vertex(Point3::new(p.x, p.y, z)))
            .collect()
    };
    let bottom = layer(-STRIP_WIDTH_MM / 2.0);
    let top = layer(STRIP_WIDTH_MM / 2.0);

    let count = outline.len();
    for i in 0..count {
        let next = (i + 1) % count;
        builder.quad(bottom[i], bottom[next], top[next], top[i]);
    }
    // Right-edge vertex i faces left-edge vertex count − 1 − i across the sheet.
    let across = |i: usize| count - 1 - i;
    for i in 0..centre.len() - 1 {
        builder.quad(top[i], top[i + 1], top[across(i + 1)], top[across(i)]);
        builder.quad(
            bottom[i],
            bottom[across(i)],
            bottom[across(i + 1)],
            bottom[i + 1],
        );
    }

    builder.into_mesh()
}

/// The half turn about z, exact.
pub(super) fn symmetry() -> Symmetry {
    Symmetry::cyclic(Axis::Z, 2)
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::parts::Part;
    use crate::parts::builder::METRES_PER_MM;
    use crate::parts::test_support::{
        assert_flat_face_faces, assert_symmetry_holds, clean_report, extent_mm,
    };

    #[test]
    fn is_one_closed_clean_shell_of_strip_size() {
        let report = clean_report(&mesh());
        assert_eq!(report.components, 1);
        let (min, max) = extent_mm(&report);
        let bend = BEND_ANGLE_DEG.to_radians();
        // End legs: y = ± (half the diagonal's rise + the bend's drop), plus half the sheet;
        // their outer ends at x = ∓ (leg + the bend's run − half the diagonal's run).
        let leg_y =
            MIDDLE_LEG_LENGTH_MM / 2.0 * bend.sin() + BEND_CENTRE_RADIUS_MM * (1.0 - bend.cos());
        let leg_end_x = END_LEG_LENGTH_MM
            + BEND_CENTRE_RADIUS_MM * bend.sin()
            + MIDDLE_LEG_LENGTH_MM / 2.0 * bend.cos();
        let expected = Vector3::new(
            leg_end_x,
            leg_y + SHEET_THICKNESS_MM / 2.0,
            STRIP_WIDTH_MM / 2.0,
        );
        for axis in 0..3 {
            assert!(
                (max[axis] - expected[axis]).abs() < 1e-3,
                "{max:?} vs {expected:?}"
            );
            assert!(
                (min[axis] + expected[axis]).abs() < 1e-3,
                "{min:?} vs {expected:?}"
            );
        }
    }

    #[test]
    fn no_face_triangle_is_folded_over() {
        let mesh = mesh();
        let half_width_m = (STRIP_WIDTH_MM / 2.0 * METRES_PER_MM) as f32;
        assert_flat_face_faces(&mesh, half_width_m, true);
        assert_flat_face_faces(&mesh, -half_width_m, false);
    }

    #[test]
    fn volume_is_thickness_times_width_times_centre_line_length() {
        let volume_mm3 = clean_report(&mesh()).signed_volume_m3 * 1e9;
        let length_mm = 2.0 * END_LEG_LENGTH_MM
            + MIDDLE_LEG_LENGTH_MM
            + 2.0 * BEND_CENTRE_RADIUS_MM * BEND_ANGLE_DEG.to_radians();
        let expected_mm3 = SHEET_THICKNESS_MM * STRIP_WIDTH_MM * length_mm;
        // Polygonal bends of 5° steps hold sin x / x ≈ 1 − x²/6 of the bends' area (x = 5°).
        assert!(
            (volume_mm3 - expected_mm3).abs() < 1e-3 * expected_mm3,
            "{volume_mm3} vs {expected_mm3}"
        );
    }

    #[test]
    fn the_half_turn_about_z_is_an_exact_symmetry() {
        // The centre line's samples are point-symmetric, so the outline's vertices are too.
        assert_symmetry_holds(Part::Zigzag, 0.0);
    }
}
