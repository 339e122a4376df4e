//! Seeded point samples for checks and benchmarks.

use crate::mesh::TriMesh;
use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// Points like a refinement sees: mesh vertices (object frame, metres) jittered by isotropic
/// Gaussian noise of `sigma_m` per axis. Deterministic for a given `seed`.
pub fn near_surface_points(mesh: &TriMesh, n: usize, sigma_m: f64, seed: u64) -> Vec<Point3<f64>> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    if mesh.vertices.is_empty() {
        return Vec::new();
    }
    (0..n)
        .map(|_| {
            let v = mesh.vertices[rng.random_range(0..mesh.vertices.len())].cast::<f64>();
            v + Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal) * sigma_m)
        })
        .collect()
}
