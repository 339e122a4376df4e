//! The Tube Fitting: a hex body with a short tube on one side, a longer one on the other and a
//! bore through all three, along z.
//!
//! One closed shell with a hole through it (a revolved closed profile). Object frame: z is
//! the bore's axis pointing from the short tube to the long one, the hexagon has corners on
//! the ±x axis, the origin is the middle of the fitting's length. Six-fold about z, exactly:
//! the hexagon's corners fall on vertex columns.

use std::f64::consts::FRAC_PI_6;

use super::builder::MeshBuilder;
use super::lathe::{Ring, even_angles_rad};
use crate::mesh::TriMesh;
use crate::symmetry::{Axis, Symmetry};

/// Distance across the hexagon's flats, mm.
const HEX_ACROSS_FLATS_MM: f64 = 16.0;
/// Length of the hex body along z, mm.
const HEX_LENGTH_MM: f64 = 10.0;
/// Size of the 45° bevel on the hex body's edges at both ends, mm.
const HEX_BEVEL_MM: f64 = 0.5;
/// Outer radius of both tubes, mm (10 mm tube).
const TUBE_OUTER_RADIUS_MM: f64 = 5.0;
/// Length of the short tube, from its end to the hex body, mm.
const SHORT_TUBE_LENGTH_MM: f64 = 7.0;
/// Length of the long tube, from the hex body to its end, mm.
const LONG_TUBE_LENGTH_MM: f64 = 13.0;
/// Radius of the through bore, mm (6 mm bore).
const BORE_RADIUS_MM: f64 = 3.0;
/// Size of the 45° chamfers on the tube ends, outside and in the bore, mm.
const END_CHAMFER_MM: f64 = 0.5;

/// Vertex columns around the axis: a multiple of 6 so the hexagon's corners are vertices.
const ANGULAR_STEPS: usize = 180;

/// Radius, mm, of the hexagon with the given apothem (corners at 0°, 60°, …) at polar angle
/// `theta_rad`.
fn hexagon_radius_mm(apothem_mm: f64, theta_rad: f64) -> f64 {
    let from_flat_centre = theta_rad.rem_euclid(2.0 * FRAC_PI_6) - FRAC_PI_6;
    apothem_mm / from_flat_centre.cos()
}

/// The fitting's mesh, metres.
pub(super) fn mesh() -> TriMesh {
    let mut builder = MeshBuilder::new();
    let angles = even_angles_rad(ANGULAR_STEPS);
    let apothem = HEX_ACROSS_FLATS_MM / 2.0;
    let (c, r_tube, r_bore) = (END_CHAMFER_MM, TUBE_OUTER_RADIUS_MM, BORE_RADIUS_MM);
    // Built from the short tube's end at z = 0, then centred.
    let z_hex_start = SHORT_TUBE_LENGTH_MM;
    let z_hex_end = z_hex_start + HEX_LENGTH_MM;
    let z_end = z_hex_end + LONG_TUBE_LENGTH_MM;

    let mut circle = |r: f64, z: f64| builder.circle(&angles, r, z);
    let short_tube = [
        circle(r_bore + c, 0.0),
        circle(r_tube - c, 0.0),
        circle(r_tube, c),
        circle(r_tube, z_hex_start),
    ];
    let mut hexagon = |apothem_mm: f64, z: f64| {
        builder.polar_ring(&angles, |theta| (hexagon_radius_mm(apothem_mm, theta), z))
    };
    let hex_body = [
        hexagon(apothem - HEX_BEVEL_MM, z_hex_start),
        hexagon(apothem, z_hex_start + HEX_BEVEL_MM),
        hexagon(apothem, z_hex_end - HEX_BEVEL_MM),
        hexagon(apothem - HEX_BEVEL_MM, z_hex_end),
    ];
    let mut circle = |r: f64, z: f64| builder.circle(&angles, r, z);
    let long_tube_and_bore = [
        circle(r_tube, z_hex_end),
        circle(r_tube, z_end - c),
        circle(r_tube - c, z_end),
        circle(r_bore + c, z_end),
        circle(r_bore, z_end - c),
        circle(r_bore, c),
    ];
    let profile: Vec<&Ring> = short_tube
        .iter()
        .chain(&hex_body)
        .chain(&long_tube_and_bore)
        .collect();
    builder.stitch_loop(&profile);

    builder.centre_along_z();
    builder.into_mesh()
}

/// Six-fold about z, exact.
pub(super) fn symmetry() -> Symmetry {
    Symmetry::cyclic(Axis::Z, 6)
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;
    use crate::parts::Part;
    use crate::parts::test_support::{assert_symmetry_holds, clean_report, extent_mm};

    /// Volume, mm³, of a frustum of similar cross-sections with areas `a` and `b`.
    fn frustum_mm3(height_mm: f64, a: f64, b: f64) -> f64 {
        height_mm / 3.0 * (a + b + (a * b).sqrt())
    }

    #[test]
    fn is_one_closed_clean_shell_of_fitting_size() {
        let report = clean_report(&mesh());
        assert_eq!(report.components, 1);
        let (min, max) = extent_mm(&report);
        let corner_mm = HEX_ACROSS_FLATS_MM / 3f64.sqrt();
        assert!((max.x - corner_mm).abs() < 1e-3 && (min.x + corner_mm).abs() < 1e-3);
        let flat_mm = HEX_ACROSS_FLATS_MM / 2.0;
        assert!((max.y - flat_mm).abs() < 1e-3 && (min.y + flat_mm).abs() < 1e-3);
        let length_mm = SHORT_TUBE_LENGTH_MM + HEX_LENGTH_MM + LONG_TUBE_LENGTH_MM;
        assert!((max.z - length_mm / 2.0).abs() < 1e-3 && (min.z + length_mm / 2.0).abs() < 1e-3);
    }

    #[test]
    fn volume_matches_the_drawing() {
        let volume_mm3 = clean_report(&mesh()).signed_volume_m3 * 1e9;
        let hexagon_area = |apothem: f64| 2.0 * 3f64.sqrt() * apothem * apothem;
        let disc_area = |r: f64| PI * r * r;
        let (c, apothem) = (END_CHAMFER_MM, HEX_ACROSS_FLATS_MM / 2.0);
        let hex_mm3 = hexagon_area(apothem) * (HEX_LENGTH_MM - 2.0 * HEX_BEVEL_MM)
            + 2.0
                * frustum_mm3(
                    HEX_BEVEL_MM,
                    hexagon_area(apothem),
                    hexagon_area(apothem - HEX_BEVEL_MM),
                );
        let tube_end_mm3 = frustum_mm3(
            c,
            disc_area(TUBE_OUTER_RADIUS_MM),
            disc_area(TUBE_OUTER_RADIUS_MM - c),
        );
        let tubes_mm3 = disc_area(TUBE_OUTER_RADIUS_MM)
            * (SHORT_TUBE_LENGTH_MM + LONG_TUBE_LENGTH_MM - 2.0 * c)
            + 2.0 * tube_end_mm3;
        let length_mm = SHORT_TUBE_LENGTH_MM + HEX_LENGTH_MM + LONG_TUBE_LENGTH_MM;
        let bore_mm3 = disc_area(BORE_RADIUS_MM) * (length_mm - 2.0 * c)
            + 2.0 * frustum_mm3(c, disc_area(BORE_RADIUS_MM), disc_area(BORE_RADIUS_MM + c));
        let expected_mm3 = hex_mm3 + tubes_mm3 - bore_mm3;
        // The 180-gons hold sin x / x ≈ 1 − x²/6 (x = 2°) of their circles' areas: 0.02 %.
        assert!(
            (volume_mm3 - expected_mm3).abs() < 1e-3 * expected_mm3,
            "{volume_mm3} vs {expected_mm3}"
        );
    }

    #[test]
    fn the_sixth_turn_about_z_is_an_exact_symmetry() {
        // Columns every 2°, corners on columns: a sixth turn maps vertices onto vertices.
        assert_symmetry_holds(Part::TubeFitting, 0.0);
    }
}
