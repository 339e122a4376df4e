//! The Eye Bolt: an M8 lifting eye bolt, a ring in the xz-plane on a collar, and a threaded
//! shank along −z.
//!
//! Two closed shells that overlap: the ring (a torus about y) and the shank with its collar and
//! a neck that ends inside the ring's tube. Object frame: z is the shank axis pointing from
//! the tip to the ring; the origin is the middle of the bolt's length. The half turn about z
//! maps the ring onto itself and the thread onto itself shifted by half a pitch, so the
//! symmetry holds up to the thread depth.

use std::f64::consts::FRAC_PI_2;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::builder::{METRES_PER_MM, MeshBuilder};
use super::lathe::{Ring, even_angles_rad};
use super::thread::Thread;
use crate::mesh::TriMesh;
use crate::symmetry::{Axis, Symmetry};

/// Crest radius of the shank's thread, mm (M8).
const THREAD_MAJOR_RADIUS_MM: f64 = 4.0;
/// Thread pitch, mm (M8 coarse).
const THREAD_PITCH_MM: f64 = 1.25;
/// Radial thread depth, mm (ISO metric external thread: 0.6134 × pitch).
const THREAD_DEPTH_MM: f64 = 0.77;
/// Turns of the thread helix: the threaded section is (turns + 1) pitches = 28.75 mm long.
const THREAD_TURNS: usize = 22;
/// Axial (and radial) size of the 45° chamfer at the tip, mm; with the threaded section the
/// shank is 30 mm long.
const TIP_CHAMFER_MM: f64 = 1.25;
/// Radius of the collar between shank and ring, mm.
const COLLAR_RADIUS_MM: f64 = 6.5;
/// Height of the collar, mm.
const COLLAR_HEIGHT_MM: f64 = 2.0;
/// Size of the 45° chamfer on the collar's top edge, mm.
const COLLAR_CHAMFER_MM: f64 = 0.5;
/// Radius of the neck where it leaves the collar, mm.
const NECK_BASE_RADIUS_MM: f64 = 3.4;
/// Radius of the neck where it ends, on the centre line of the ring's tube, mm (less than the
/// tube radius, so the neck's end is hidden inside the ring).
const NECK_TOP_RADIUS_MM: f64 = 2.2;
/// Visible gap between the collar's top and the bottom of the ring, mm.
const NECK_GAP_MM: f64 = 1.5;
/// Radius of the ring's centre circle, mm.
const RING_MAJOR_RADIUS_MM: f64 = 9.0;
/// Radius of the ring's tube, mm.
const RING_TUBE_RADIUS_MM: f64 = 2.5;

/// Vertex columns around the shank's axis (even: the half turn maps columns onto columns).
const SHANK_ANGULAR_STEPS: usize = 64;
/// Vertex rings along the ring's centre circle (even, for the same reason).
const RING_STEPS_AROUND: usize = 96;
/// Vertices around the ring's tube.
const RING_TUBE_STEPS: usize = 32;

const THREAD: Thread = Thread {
    major_radius_mm: THREAD_MAJOR_RADIUS_MM,
    depth_mm: THREAD_DEPTH_MM,
    pitch_mm: THREAD_PITCH_MM,
    turns: THREAD_TURNS,
};

/// Height of the ring's tube centre line at its lowest point, above the collar's underside, mm.
const NECK_TOP_HEIGHT_MM: f64 = COLLAR_HEIGHT_MM + NECK_GAP_MM + RING_TUBE_RADIUS_MM;

/// The eye bolt's mesh, metres: shank shell then ring shell.
pub(super) fn mesh() -> TriMesh {
    let mut builder = shank();
    builder.append(ring());
    builder.centre_along_z();
    builder.into_mesh()
}

/// The shank, collar and neck, with the collar's underside at z = 0.
fn shank() -> MeshBuilder {
    let mut builder = MeshBuilder::new();
    let angles = even_angles_rad(SHANK_ANGULAR_STEPS);
    let z_tip = -(TIP_CHAMFER_MM + THREAD.length_mm());

    let tip = builder.circle(&angles, THREAD.minor_radius_mm() - TIP_CHAMFER_MM, z_tip);
    builder.cap_start(Point3::new(0.0, 0.0, z_tip), &tip);
    let (thread_bottom, thread_top) =
        THREAD.add_section(&mut builder, z_tip + TIP_CHAMFER_MM, SHANK_ANGULAR_STEPS);
    builder.stitch(&tip, &thread_bottom);

    // Out under the collar, up its side, over its chamfer and top, up the neck into the ring.
    let profile = [
        (COLLAR_RADIUS_MM, 0.0),
        (COLLAR_RADIUS_MM, COLLAR_HEIGHT_MM - COLLAR_CHAMFER_MM),
        (COLLAR_RADIUS_MM - COLLAR_CHAMFER_MM, COLLAR_HEIGHT_MM),
        (NECK_BASE_RADIUS_MM, COLLAR_HEIGHT_MM),
        (NECK_TOP_RADIUS_MM, NECK_TOP_HEIGHT_MM),
    ];
    let rings: Vec<Ring> = profile
        .iter()
        .map(|&(r, z)| builder.circle(&angles, r, z))
        .collect();
    builder.stitch(&thread_top, &rings[0]);
    builder.stitch_chain(&rings.iter().collect::<Vec<_>>());
    if let Some(neck_top) = rings.last() {
        builder.cap_end(neck_top, Point3::new(0.0, 0.0, NECK_TOP_HEIGHT_MM));
    }
    builder
}

/// The ring: a torus about the y axis whose centre circle passes through the neck's top.
fn ring() -> MeshBuilder {
    let mut builder = MeshBuilder::new();
    let angles = even_angles_rad(RING_STEPS_AROUND);
    // Built about z, the tube's cross-section traversed counter-clockwise in (r, z).
    let tube: Vec<Ring> = even_angles_rad(RING_TUBE_STEPS)
        .into_iter()
        .map(|phi| {
            builder.circle(
                &angles,
                RING_MAJOR_RADIUS_MM + RING_TUBE_RADIUS_MM * phi.cos(),
                RING_TUBE_RADIUS_MM * phi.sin(),
            )
        })
        .collect();
    builder.stitch_loop(&tube.iter().collect::<Vec<_>>());
    // A quarter turn about x takes the torus's axis from z to y.
    let upright = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -FRAC_PI_2);
    let lifted = Translation3::new(0.0, 0.0, NECK_TOP_HEIGHT_MM + RING_MAJOR_RADIUS_MM);
    builder.transform(&Isometry3::from_parts(lifted, upright));
    builder
}

/// The half turn about z, exact up to the thread depth.
pub(super) fn symmetry() -> Symmetry {
    Symmetry::cyclic(Axis::Z, 2).with_tolerance(THREAD_DEPTH_MM * METRES_PER_MM)
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;
    use crate::parts::Part;
    use crate::parts::test_support::{assert_symmetry_holds, clean_report, extent_mm};

    #[test]
    fn is_two_closed_clean_shells_of_eye_bolt_size() {
        let mesh = mesh();
        let report = clean_report(&mesh);
        assert_eq!(report.components, 2);
        for component in mesh.connected_components() {
            let shell = clean_report(&mesh.submesh(&component));
            assert!(shell.signed_volume_m3 > 0.0);
        }
        let (min, max) = extent_mm(&report);
        let ring_half_width = RING_MAJOR_RADIUS_MM + RING_TUBE_RADIUS_MM;
        assert!((max.x - ring_half_width).abs() < 1e-3 && (min.x + ring_half_width).abs() < 1e-3);
        assert!((max.y - COLLAR_RADIUS_MM).abs() < 1e-3 && (min.y + COLLAR_RADIUS_MM).abs() < 1e-3);
        // Tip to the top of the ring.
        let length_mm = TIP_CHAMFER_MM
            + THREAD.length_mm()
            + NECK_TOP_HEIGHT_MM
            + 2.0 * RING_MAJOR_RADIUS_MM
            + RING_TUBE_RADIUS_MM;
        assert!((max.z - min.z - length_mm).abs() < 1e-3, "{min:?} {max:?}");
        assert!((30.0..=70.0).contains(&length_mm));
    }

    #[test]
    fn neither_shell_hides_inside_the_other_and_the_volumes_match_their_shapes() {
        let mesh = mesh();
        let shells: Vec<TriMesh> = mesh
            .connected_components()
            .iter()
            .map(|c| mesh.submesh(c))
            .collect();
        // The shank is built first.
        let [shank_mesh, ring_mesh] = shells.as_slice() else {
            panic!("two shells")
        };
        let (shank, ring) = (clean_report(shank_mesh), clean_report(ring_mesh));
        // The shank reaches below the ring and the ring sticks out sideways beyond the shank.
        assert!(shank.aabb_min.z < ring.aabb_min.z && ring.aabb_max.x > shank.aabb_max.x);
        // The neck ends inside the ring's tube: its vertices above the ring's bottom are
        // closer than the tube radius to the ring's centre circle.
        let ring_centre_z_mm = f64::from(ring.aabb_min.z + ring.aabb_max.z) / 2.0 * 1e3;
        let neck_end: Vec<Point3<f64>> = shank_mesh
            .vertices
            .iter()
            .filter(|p| p.z > ring.aabb_min.z)
            .map(|p| Point3::from(p.coords.cast::<f64>() * 1e3))
            .collect();
        assert_eq!(
            neck_end.len(),
            SHANK_ANGULAR_STEPS + 1,
            "the neck's top ring and pole"
        );
        for p in &neck_end {
            let from_centre_circle = p.x.hypot(p.z - ring_centre_z_mm) - RING_MAJOR_RADIUS_MM;
            assert!(from_centre_circle.hypot(p.y) < RING_TUBE_RADIUS_MM, "{p:?}");
        }

        // Torus 2π²Rr², less what the inscribed polygons cut off: their areas are sin x / x ≈
        // 1 − x²/6 of the circles', x = 2π/32 around the tube (0.6 %), 2π/96 along the ring.
        let torus_mm3 = 2.0 * PI * PI * RING_MAJOR_RADIUS_MM * RING_TUBE_RADIUS_MM.powi(2);
        let ring_mm3 = ring.signed_volume_m3 * 1e9;
        assert!(
            ring_mm3 < torus_mm3 && ring_mm3 > 0.98 * torus_mm3,
            "{ring_mm3} vs {torus_mm3}"
        );

        // Shank: at least its core and the collar's inner cylinder, at most crest cylinders.
        let shank_mm3 = shank.signed_volume_m3 * 1e9;
        let neck_mm3 = PI * NECK_BASE_RADIUS_MM.powi(2) * (NECK_TOP_HEIGHT_MM - COLLAR_HEIGHT_MM);
        let lower = PI * THREAD.minor_radius_mm().powi(2) * THREAD.length_mm()
            + PI * (COLLAR_RADIUS_MM - COLLAR_CHAMFER_MM).powi(2) * COLLAR_HEIGHT_MM;
        let upper = PI * THREAD_MAJOR_RADIUS_MM.powi(2) * (THREAD.length_mm() + TIP_CHAMFER_MM)
            + PI * COLLAR_RADIUS_MM.powi(2) * COLLAR_HEIGHT_MM
            + neck_mm3;
        assert!(
            lower < shank_mm3 && shank_mm3 < upper,
            "{lower} < {shank_mm3} < {upper}"
        );
    }

    #[test]
    fn the_half_turn_about_z_is_a_symmetry_up_to_the_thread_depth() {
        // The ring and the collar map vertex onto vertex (even column counts); a thread vertex
        // lands within the thread depth plus the chord sag of the widest ring.
        let chord_sag_mm = COLLAR_RADIUS_MM * (1.0 - (PI / SHANK_ANGULAR_STEPS as f64).cos());
        let largest_m = assert_symmetry_holds(Part::EyeBolt, chord_sag_mm * METRES_PER_MM);
        // The thread is really there: the half turn shifts it by half a pitch.
        assert!(
            largest_m > 0.5 * THREAD_DEPTH_MM * METRES_PER_MM,
            "{largest_m}"
        );
    }
}
