//! Checks shared by the parts' tests: closed clean shells and numerically verified symmetries.

use nalgebra::{Point3, Rotation3, Vector3};
use parry3d::query::PointQuery;

use super::Part;
use crate::glam_interop::{vec3_from_point, vec3_from_point_f64};
use crate::mesh::{MeshReport, TriMesh};

/// Rounding allowance, metres, for a point that should lie on the surface: 50 ulp of `f32`
/// at the parts' 3 cm scale (1.9 nm per ulp), covering the stored vertices, the rotation and
/// parry3d's `f32` projection.
const NUMERIC_SLACK_M: f64 = 1e-7;

/// Metres per millimetre.
const M_PER_MM: f64 = 1e-3;

/// The mesh's report, after asserting it is closed, clean and outward.
pub(super) fn clean_report(mesh: &TriMesh) -> MeshReport {
    let report = mesh.validate().expect("a usable mesh");
    assert!(report.is_watertight(), "{report:?}");
    assert_eq!(report.degenerate_triangles, 0, "{report:?}");
    assert!(report.signed_volume_m3 > 0.0, "{report:?}");
    report
}

/// The report's bounding box, millimetres.
pub(super) fn extent_mm(report: &MeshReport) -> (Vector3<f64>, Vector3<f64>) {
    let mm = |p: Point3<f32>| p.coords.cast::<f64>() / M_PER_MM;
    (mm(report.aabb_min), mm(report.aabb_max))
}

/// Largest distance, metres, from the image `S · v` of a vertex `v` to the mesh's surface,
/// over all vertices and the given rotations `S` about the origin.
fn largest_displacement_m(mesh: &TriMesh, rotations: &[Rotation3<f64>]) -> f64 {
    let surface = parry3d::shape::TriMesh::new(
        mesh.vertices.iter().map(vec3_from_point).collect(),
        mesh.triangles.clone(),
    )
    .expect("a non-empty mesh");
    let vertices: Vec<Point3<f64>> = mesh.vertices.iter().map(|p| p.cast::<f64>()).collect();
    rotations
        .iter()
        .flat_map(|s| vertices.iter().map(move |v| s * v))
        .map(|image| {
            let query = vec3_from_point_f64(&image);
            f64::from(
                surface
                    .project_local_point(query, false)
                    .point
                    .distance(query),
            )
        })
        .fold(0.0, f64::max)
}

/// Asserts that every sampled element of the part's symmetry group maps each vertex to within
/// `tolerance_m + discretisation_m` (plus rounding) of the surface, and that a 7° turn about x,
/// no symmetry of any part, moves some vertex farther. Returns the largest displacement under
/// the group, metres.
pub(super) fn assert_symmetry_holds(part: Part, discretisation_m: f64) -> f64 {
    let mesh = part.mesh();
    let symmetry = part.symmetry();
    let bound_m = symmetry.tolerance_m + discretisation_m + NUMERIC_SLACK_M;

    let group = symmetry.sample(24);
    assert!(
        group.len() >= 2,
        "{part}: {symmetry} has no element besides the identity"
    );
    let largest_m = largest_displacement_m(&mesh, &group);
    assert!(
        largest_m <= bound_m,
        "{part}: {symmetry} moves a vertex {largest_m} m > {bound_m} m"
    );

    let off_symmetry = Rotation3::from_axis_angle(&Vector3::x_axis(), 7f64.to_radians());
    let moved_m = largest_displacement_m(&mesh, &[off_symmetry]);
    assert!(
        moved_m > bound_m,
        "{part}: a 7° turn about x moves vertices only {moved_m} m"
    );
    largest_m
}

/// Asserts that the mesh has triangles lying in the plane `z = z_m` and that all of them face
/// `+z` (`facing_up`) or `−z`: no triangle of a flat face is folded over.
pub(super) fn assert_flat_face_faces(mesh: &TriMesh, z_m: f32, facing_up: bool) {
    let in_plane = |p: &Point3<f32>| (p.z - z_m).abs() < 1e-9;
    let mut count = 0;
    for i in 0..mesh.triangles.len() {
        if mesh.triangle(i).iter().all(in_plane) {
            count += 1;
            let up = mesh.triangle_cross(i).z > 0.0;
            assert_eq!(
                up, facing_up,
                "triangle {i} of the face at z = {z_m} m is flipped"
            );
        }
    }
    assert!(count > 0, "no face at z = {z_m} m");
}
