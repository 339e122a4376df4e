//! The Chrome Screw: an M6 × 30 pan-head screw, threaded along +z, head up.
//!
//! Object frame: z is the screw axis pointing from the tip to the head; the origin is the
//! middle of the screw's length. Symmetric under every turn about z up to the thread depth
//! (a turned helix is the same helix shifted along its axis).

use std::f64::consts::FRAC_PI_2;

use nalgebra::Point3;

use super::builder::{METRES_PER_MM, MeshBuilder};
use super::lathe::even_angles_rad;
use super::thread::Thread;
use crate::mesh::TriMesh;
use crate::symmetry::{Axis, Symmetry};

/// Crest radius of the thread, mm (M6).
const THREAD_MAJOR_RADIUS_MM: f64 = 3.0;
/// Thread pitch, mm (M6 coarse).
const THREAD_PITCH_MM: f64 = 1.0;
/// Radial thread depth, mm (ISO metric external thread: 0.6134 × pitch).
const THREAD_DEPTH_MM: f64 = 0.61;
/// Turns of the thread helix: the threaded section is (turns + 1) pitches = 29 mm long.
const THREAD_TURNS: usize = 28;
/// Axial (and radial) size of the 45° chamfer at the tip, mm; with the threaded section the
/// shank is 30 mm long.
const TIP_CHAMFER_MM: f64 = 1.0;
/// Radius of the pan head, mm (a 10 mm head, usual for M6 pan heads).
const HEAD_RADIUS_MM: f64 = 5.0;
/// Height of the pan head, mm.
const HEAD_HEIGHT_MM: f64 = 4.2;
/// Radius of the rounded edge between the head's side and its flat top, mm.
const HEAD_EDGE_RADIUS_MM: f64 = 1.6;

/// Vertex columns around the axis.
const ANGULAR_STEPS: usize = 64;
/// Segments of the head's rounded edge.
const HEAD_EDGE_STEPS: usize = 8;

const THREAD: Thread = Thread {
    major_radius_mm: THREAD_MAJOR_RADIUS_MM,
    depth_mm: THREAD_DEPTH_MM,
    pitch_mm: THREAD_PITCH_MM,
    turns: THREAD_TURNS,
};

/// The screw's mesh, metres.
pub(super) fn mesh() -> TriMesh {
    let mut builder = MeshBuilder::new();
    let angles = even_angles_rad(ANGULAR_STEPS);

    // Built with the tip at z = 0, then centred.
    let tip = builder.circle(&angles, THREAD.minor_radius_mm() - TIP_CHAMFER_MM, 0.0);
    builder.cap_start(Point3::origin(), &tip);
    let (thread_bottom, thread_top) =
        THREAD.add_section(&mut builder, TIP_CHAMFER_MM, ANGULAR_STEPS);
    builder.stitch(&tip, &thread_bottom);

    let z_under_head = TIP_CHAMFER_MM + THREAD.length_mm();
    let z_head_top = z_under_head + HEAD_HEIGHT_MM;
    // Head profile: out under the head, up the side, round the edge onto the flat top.
    let edge_centre = (
        HEAD_RADIUS_MM - HEAD_EDGE_RADIUS_MM,
        z_head_top - HEAD_EDGE_RADIUS_MM,
    );
    let head_profile =
        [(HEAD_RADIUS_MM, z_under_head)]
            .into_iter()
            .chain((0..=HEAD_EDGE_STEPS).map(|i| {
                let a = FRAC_PI_2 * i as f64 / HEAD_EDGE_STEPS as f64;
                (
                    edge_centre.0 + HEAD_EDGE_RADIUS_MM * a.cos(),
                    edge_centre.1 + HEAD_EDGE_RADIUS_MM * a.sin(),
                )
            }));
    let mut previous = thread_top;
    for (r, z) in head_profile {
        let ring = builder.circle(&angles, r, z);
        builder.stitch(&previous, &ring);
        previous = ring;
    }
    builder.cap_end(&previous, Point3::new(0.0, 0.0, z_head_top));

    builder.centre_along_z();
    builder.into_mesh()
}

/// Every turn about z, exact up to the thread depth.
pub(super) fn symmetry() -> Symmetry {
    Symmetry::continuous(Axis::Z).with_tolerance(THREAD_DEPTH_MM * METRES_PER_MM)
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;
    use crate::parts::Part;
    use crate::parts::test_support::{assert_symmetry_holds, clean_report, extent_mm};

    #[test]
    fn is_a_closed_clean_shell_of_m6_by_30_size() {
        let report = clean_report(&mesh());
        assert_eq!(report.components, 1);
        let shank_mm = TIP_CHAMFER_MM + THREAD.length_mm();
        assert!(
            (shank_mm - 30.0).abs() < 1e-9,
            "M6 × 30: shank {shank_mm} mm"
        );
        let (min, max) = extent_mm(&report);
        for axis in 0..2 {
            // The head's rim is the widest part: its polygon reaches the full radius at vertices.
            assert!((max[axis] - HEAD_RADIUS_MM).abs() < 1e-3, "{max:?}");
            assert!((min[axis] + HEAD_RADIUS_MM).abs() < 1e-3, "{min:?}");
        }
        let length_mm = shank_mm + HEAD_HEIGHT_MM;
        assert!((max.z - length_mm / 2.0).abs() < 1e-3 && (min.z + length_mm / 2.0).abs() < 1e-3);
    }

    #[test]
    fn volume_lies_between_core_and_crest_cylinders() {
        let volume_mm3 = clean_report(&mesh()).signed_volume_m3 * 1e9;
        let thread_mm = THREAD.length_mm();
        let head_core_mm3 = PI * (HEAD_RADIUS_MM - HEAD_EDGE_RADIUS_MM).powi(2) * HEAD_HEIGHT_MM;
        let head_hull_mm3 = PI * HEAD_RADIUS_MM.powi(2) * HEAD_HEIGHT_MM;
        let lower = PI * THREAD.minor_radius_mm().powi(2) * thread_mm + head_core_mm3;
        let upper =
            PI * THREAD_MAJOR_RADIUS_MM.powi(2) * (thread_mm + TIP_CHAMFER_MM) + head_hull_mm3;
        assert!(
            lower < volume_mm3 && volume_mm3 < upper,
            "{lower} < {volume_mm3} < {upper}"
        );
    }

    #[test]
    fn every_turn_about_the_axis_is_a_symmetry_up_to_the_thread_depth() {
        // Thread and head are radial graphs over evenly spaced columns: a turned vertex is at
        // most the thread depth plus the chord sag of the widest ring from the surface.
        let chord_sag_mm = HEAD_RADIUS_MM * (1.0 - (PI / ANGULAR_STEPS as f64).cos());
        let largest_m = assert_symmetry_holds(Part::ChromeScrew, chord_sag_mm * METRES_PER_MM);
        // The thread is really there: the half turn shifts it by half a pitch.
        assert!(
            largest_m > 0.5 * THREAD_DEPTH_MM * METRES_PER_MM,
            "{largest_m}"
        );
    }
}
