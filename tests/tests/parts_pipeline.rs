//! Every part through the pipeline a user runs: export to PLY in millimetres, read back,
//! build the SDF from the file, and check the declared symmetry on that SDF.

use glint_geometry::io::{self, PlyEncoding};
use glint_geometry::parts::Part;
use glint_geometry::sampling;
use glint_geometry::sdf::{SdfConfig, SdfGrid, symmetry_deviation_m};
use glint_geometry::{LengthUnit, Symmetry};
use nalgebra::{Rotation3, Unit, Vector3};

#[test]
fn parts_survive_files_and_keep_their_symmetry() {
    let dir = tempfile::tempdir().unwrap();
    let config = SdfConfig {
        voxel_size_m: 1e-3,
        padding_m: 5e-3,
    };
    for part in Part::ALL {
        let mesh = part.mesh();
        let path = dir.path().join(format!("{part}.ply"));
        io::write_ply(
            &path,
            &mesh,
            LengthUnit::Millimetre,
            PlyEncoding::BinaryLittleEndian,
        )
        .unwrap();
        let loaded = io::read_mesh(&path, LengthUnit::Millimetre).unwrap();
        assert!(
            loaded.report.is_watertight(),
            "{part}: {:?}",
            loaded.warnings
        );
        assert_eq!(loaded.mesh.triangles, mesh.triangles, "{part}");
        // mm in f32 and back: a few ulp of a ~50 mm coordinate, far below 1 µm.
        let worst = mesh
            .vertices
            .iter()
            .zip(&loaded.mesh.vertices)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-6, "{part}: {worst} m");

        let grid = SdfGrid::build(&loaded.mesh, &config).unwrap();
        let points = sampling::near_surface_points(&loaded.mesh, 3000, 2e-3, part as u64);
        let symmetry = part.symmetry();
        // Two trilinear samples, each within ½ voxel of exact: 1 voxel, plus what the part
        // declares as its deviation from exact symmetry.
        let bound = symmetry.tolerance_m + config.voxel_size_m;
        let deviation = symmetry_deviation_m(&grid, &points, &symmetry, 24);
        assert!(
            deviation <= bound,
            "{part}: symmetry {symmetry} deviates {deviation} m > {bound} m"
        );

        // The check can fail: a 7° turn about an oblique axis is no symmetry of any part.
        let turn = Rotation3::from_axis_angle(
            &Unit::new_normalize(Vector3::new(1.0, 0.3, 0.2)),
            7f64.to_radians(),
        );
        let broken = points
            .iter()
            .map(|p| (grid.sample(&(turn * p)).distance_m - grid.sample(p).distance_m).abs())
            .fold(0.0, f64::max);
        assert!(broken > bound, "{part}: a 7° turn deviates only {broken} m");
        // Nor is 2-fold symmetry about x unless declared.
        if symmetry.discrete_order() == 1 && symmetry.continuous_axis().is_none() {
            let flip: Symmetry = "discrete:x:2".parse().unwrap();
            assert!(
                symmetry_deviation_m(&grid, &points, &flip, 1) > bound,
                "{part}"
            );
        }
    }
}
