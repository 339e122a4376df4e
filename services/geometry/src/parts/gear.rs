//! The Gear: a 20-tooth involute spur gear with a bore, faces at z = ±half its width.
//!
//! One closed shell with a hole through it. Object frame: z is the gear's axis, the origin its
//! centre, a tooth is centred on +x. Dihedral: the 20 turns about z, and the half turn about x
//! (the outline is mirror-symmetric about x and the faces about z = 0); all exact, as the
//! outline is sampled the same way on every tooth and on both flanks.

use std::f64::consts::TAU;

use super::builder::MeshBuilder;
use super::lathe::even_angles_rad;
use crate::mesh::TriMesh;
use crate::symmetry::{Axis, Symmetry};

/// Number of teeth.
const TEETH: usize = 20;
/// Module, mm: pitch diameter per tooth (tip diameter = module × (teeth + 2) = 39.6 mm).
const MODULE_MM: f64 = 1.8;
/// Pressure angle of the involute flanks, degrees.
const PRESSURE_ANGLE_DEG: f64 = 20.0;
/// Tooth height above the pitch circle, mm (1 module).
const ADDENDUM_MM: f64 = MODULE_MM;
/// Tooth depth below the pitch circle, mm (1.25 modules).
const DEDENDUM_MM: f64 = 1.25 * MODULE_MM;
/// Arc length, mm, of the rounded corner between a flank and the root circle.
const ROOT_FILLET_MM: f64 = 0.3 * MODULE_MM;
/// Width of the gear along z, mm.
const FACE_WIDTH_MM: f64 = 8.0;
/// Radius of the bore, mm.
const BORE_RADIUS_MM: f64 = 4.0;
/// Depth below the root circle of the ring of face vertices that follows the outline's angles,
/// mm: it keeps the faces' triangles inside the outline.
const FACE_RING_INSET_MM: f64 = 1.0;

/// Outline samples on half the tooth's tip, from the tooth's centre line to the tip corner.
const TIP_STEPS: usize = 2;
/// Segments of each involute flank.
const FLANK_STEPS: usize = 10;
/// Segments of each root fillet.
const FILLET_STEPS: usize = 4;
/// Segments of half the root arc between two teeth.
const ROOT_STEPS: usize = 3;
/// Vertices around the bore (a multiple of the teeth, for the symmetry).
const BORE_STEPS: usize = 4 * TEETH;

/// Pitch-circle radius, mm.
fn pitch_radius_mm() -> f64 {
    MODULE_MM * TEETH as f64 / 2.0
}

/// The involute function inv α = tan α − α.
fn involute(pressure_angle_rad: f64) -> f64 {
    pressure_angle_rad.tan() - pressure_angle_rad
}

/// The outline as `(angle, radius)` (radians, mm) in increasing angle over [0, 2π), starting
/// at the centre of the tooth on +x.
fn outline() -> Vec<(f64, f64)> {
    let r_pitch = pitch_radius_mm();
    let r_base = r_pitch * PRESSURE_ANGLE_DEG.to_radians().cos();
    let r_tip = r_pitch + ADDENDUM_MM;
    let r_root = r_pitch - DEDENDUM_MM;
    let tooth_period = TAU / TEETH as f64;
    // Half the tooth's angular thickness at radius r ≥ r_base: half a tooth (a quarter
    // period) at the pitch circle, corrected along the involute.
    let half_thickness = |r: f64| {
        let at = |radius: f64| involute((r_base / radius).min(1.0).acos());
        tooth_period / 4.0 + at(r_pitch) - at(r)
    };

    // Half a period: the tip from the centre line, the flank down to the base circle, a fillet
    // into the root circle, the root to the middle of the gap.
    let mut half: Vec<(f64, f64)> = (0..TIP_STEPS)
        .map(|i| (half_thickness(r_tip) * i as f64 / TIP_STEPS as f64, r_tip))
        .collect();
    half.extend((0..=FLANK_STEPS).map(|i| {
        let r = r_tip + (r_base - r_tip) * i as f64 / FLANK_STEPS as f64;
        (half_thickness(r), r)
    }));
    // Quadratic Bézier from the flank's foot, tangent to the radius there, to the root circle.
    let foot_angle = half_thickness(r_base);
    let fillet_end_angle = foot_angle + ROOT_FILLET_MM / r_root;
    let polar = |angle: f64, r: f64| [r * angle.cos(), r * angle.sin()];
    let (p0, p1, p2) = (
        polar(foot_angle, r_base),
        polar(foot_angle, r_root),
        polar(fillet_end_angle, r_root),
    );
    half.extend((1..=FILLET_STEPS).map(|i| {
        let t = i as f64 / FILLET_STEPS as f64;
        let w = [(1.0 - t) * (1.0 - t), 2.0 * t * (1.0 - t), t * t];
        let x = w[0] * p0[0] + w[1] * p1[0] + w[2] * p2[0];
        let y = w[0] * p0[1] + w[1] * p1[1] + w[2] * p2[1];
        (y.atan2(x), x.hypot(y))
    }));
    let gap_middle = tooth_period / 2.0;
    half.extend((1..=ROOT_STEPS).map(|i| {
        let angle =
            fillet_end_angle + (gap_middle - fillet_end_angle) * i as f64 / ROOT_STEPS as f64;
        (angle, r_root)
    }));

    // A period is the half and its mirror image about the middle of the gap.
    let period: Vec<(f64, f64)> = half
        .iter()
        .copied()
        .chain(
            half[1..half.len() - 1]
                .iter()
                .rev()
                .map(|&(angle, r)| (tooth_period - angle, r)),
        )
        .collect();
    (0..TEETH)
        .flat_map(|tooth| {
            let offset = tooth as f64 * tooth_period;
            period.iter().map(move |&(angle, r)| (angle + offset, r))
        })
        .collect()
}

/// The gear's mesh, metres.
pub(super) fn mesh() -> TriMesh {
    let mut builder = MeshBuilder::new();
    let outline = outline();
    let r_face_ring = pitch_radius_mm() - DEDENDUM_MM - FACE_RING_INSET_MM;
    let face_ring: Vec<(f64, f64)> = outline
        .iter()
        .map(|&(angle, _)| (angle, r_face_ring))
        .collect();
    let bore_angles = even_angles_rad(BORE_STEPS);
    let (bottom, top) = (-FACE_WIDTH_MM / 2.0, FACE_WIDTH_MM / 2.0);

    let teeth_bottom = builder.outline_ring(&outline, bottom);
    let teeth_top = builder.outline_ring(&outline, top);
    let face_top = builder.outline_ring(&face_ring, top);
    let bore_top = builder.circle(&bore_angles, BORE_RADIUS_MM, top);
    let bore_bottom = builder.circle(&bore_angles, BORE_RADIUS_MM, bottom);
    let face_bottom = builder.outline_ring(&face_ring, bottom);

    // Up the teeth, in over the top face, down the bore, out under the bottom face.
    builder.stitch_chain(&[&teeth_bottom, &teeth_top, &face_top]);
    builder.zip(&face_top, &bore_top);
    builder.stitch(&bore_top, &bore_bottom);
    builder.zip(&bore_bottom, &face_bottom);
    builder.stitch(&face_bottom, &teeth_bottom);

    builder.into_mesh()
}

/// The 20 turns about z and the half turn about x, exact.
pub(super) fn symmetry() -> Symmetry {
    Symmetry::dihedral(Axis::Z, TEETH as u32, Axis::X)
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;
    use crate::parts::Part;
    use crate::parts::builder::METRES_PER_MM;
    use crate::parts::test_support::{
        assert_flat_face_faces, assert_symmetry_holds, clean_report, extent_mm,
    };

    #[test]
    fn outline_is_star_shaped_in_increasing_angle() {
        let outline = outline();
        assert_eq!(outline[0], (0.0, pitch_radius_mm() + ADDENDUM_MM));
        assert!(
            outline.windows(2).all(|w| w[0].0 < w[1].0),
            "angles must increase"
        );
        assert!(outline.last().is_some_and(|&(angle, _)| angle < TAU));
    }

    #[test]
    fn is_one_closed_clean_shell_of_gear_size() {
        let report = clean_report(&mesh());
        assert_eq!(report.components, 1);
        let (min, max) = extent_mm(&report);
        let r_tip = pitch_radius_mm() + ADDENDUM_MM;
        // Teeth are centred on ±x and ±y (20 teeth, 18° apart), tip arcs there.
        for axis in 0..2 {
            assert!(
                (max[axis] - r_tip).abs() < 1e-3 && (min[axis] + r_tip).abs() < 1e-3,
                "{max:?}"
            );
        }
        assert!(
            (max.z - FACE_WIDTH_MM / 2.0).abs() < 1e-6
                && (min.z + FACE_WIDTH_MM / 2.0).abs() < 1e-6
        );
        assert!((38.0..=42.0).contains(&(2.0 * r_tip)));
    }

    #[test]
    fn no_face_triangle_is_folded_over() {
        let mesh = mesh();
        let half_width_m = (FACE_WIDTH_MM / 2.0 * METRES_PER_MM) as f32;
        assert_flat_face_faces(&mesh, half_width_m, true);
        assert_flat_face_faces(&mesh, -half_width_m, false);
    }

    #[test]
    fn volume_lies_between_root_disc_and_tip_disc() {
        let volume_mm3 = clean_report(&mesh()).signed_volume_m3 * 1e9;
        let (r_tip, r_root) = (
            pitch_radius_mm() + ADDENDUM_MM,
            pitch_radius_mm() - DEDENDUM_MM,
        );
        let annulus = |r: f64| PI * (r * r - BORE_RADIUS_MM * BORE_RADIUS_MM) * FACE_WIDTH_MM;
        let teeth_ring_mm3 = annulus(r_tip) - annulus(r_root);
        // Teeth fill half the ring at the pitch circle, more below it and less above.
        let lower = annulus(r_root) + 0.35 * teeth_ring_mm3;
        let upper = annulus(r_root) + 0.65 * teeth_ring_mm3;
        assert!(
            lower < volume_mm3 && volume_mm3 < upper,
            "{lower} < {volume_mm3} < {upper}"
        );
    }

    #[test]
    fn tooth_turns_and_the_flip_about_x_are_exact_symmetries() {
        // Every tooth and both flanks are sampled alike, the bore has 4 vertices per tooth
        // and the faces are planes: each group element maps vertices onto the surface.
        assert_symmetry_holds(Part::Gear, 0.0);
    }
}
