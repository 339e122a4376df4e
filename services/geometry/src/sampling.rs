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

/// A point on a mesh surface with the outward unit normal of its triangle (object frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    /// Position, metres.
    pub point: Point3<f64>,
    /// Outward unit normal of the triangle the point lies on.
    pub normal: Vector3<f64>,
}

/// `n` points drawn uniformly by area over the surface of `mesh` (object frame, metres), each with
/// its triangle's outward normal: a triangle is picked with probability ∝ its area, then a point
/// uniformly inside it (`√u` barycentric warp). Degenerate triangles get no samples. The mean
/// spacing of the samples is about `√(area / n)`. Deterministic for a given `seed`; empty for a
/// mesh without area.
pub fn surface_samples(mesh: &TriMesh, n: usize, seed: u64) -> Vec<SurfaceSample> {
    // Cumulative twice-areas, and the unit normals of the triangles that have area.
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0f64;
    for i in 0..mesh.triangles.len() {
        let twice_area = if mesh.is_degenerate(i) {
            0.0
        } else {
            mesh.triangle_cross(i).cast::<f64>().norm()
        };
        total += twice_area;
        cumulative.push(total);
    }
    if total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let target = rng.random::<f64>() * total;
            // First triangle whose cumulative area exceeds the target: never a zero-area one.
            let i = cumulative
                .partition_point(|&c| c <= target)
                .min(cumulative.len() - 1);
            let [a, b, c] = mesh.triangle(i).map(|p| p.cast::<f64>());
            let (u, v): (f64, f64) = (rng.random(), rng.random());
            let su = u.sqrt();
            let point = a + (b - a) * (su * (1.0 - v)) + (c - a) * (su * v);
            let normal = (b - a).cross(&(c - a)).normalize();
            SurfaceSample { point, normal }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surface_samples_are_uniform_by_area_with_outward_normals() {
        let h = [0.01, 0.02, 0.03];
        let mesh = TriMesh::cuboid([0.0; 3], h);
        let n = 20_000;
        let samples = surface_samples(&mesh, n, 3);
        assert_eq!(samples.len(), n);
        let mut on_axis = [0usize; 3];
        let mut plus_x_mean = Vector3::zeros();
        let mut plus_x = 0usize;
        for s in &samples {
            // Every sample lies on the face its normal points out of (f32 vertices: 1e-9 m).
            let axis = s.normal.iamax();
            assert!((s.normal.norm() - 1.0).abs() < 1e-12);
            assert!((s.normal[axis].abs() - 1.0).abs() < 1e-12);
            let face = h[axis] * s.normal[axis].signum();
            assert!((s.point[axis] - face).abs() < 1e-9, "{s:?}");
            for (x, h) in s.point.iter().zip(h) {
                assert!(x.abs() <= h + 1e-9);
            }
            on_axis[axis] += 1;
            if axis == 0 && s.normal.x > 0.0 {
                plus_x_mean += s.point.coords;
                plus_x += 1;
            }
        }
        // Face pairs get samples ∝ area: binomial standard deviation √(p(1−p)/n), 4σ bound.
        let areas = [h[1] * h[2], h[0] * h[2], h[0] * h[1]];
        let total: f64 = areas.iter().sum();
        for k in 0..3 {
            let p = areas[k] / total;
            let got = on_axis[k] as f64 / n as f64;
            let sd = (p * (1.0 - p) / n as f64).sqrt();
            assert!((got - p).abs() < 4.0 * sd, "axis {k}: {got} vs {p}");
        }
        // Uniform inside the +x face: the mean lies at its centre within 4 standard errors
        // (a uniform coordinate on [−h, h] has standard deviation h/√3).
        plus_x_mean /= plus_x as f64;
        for k in 1..3 {
            let se = h[k] / 3f64.sqrt() / (plus_x as f64).sqrt();
            assert!(plus_x_mean[k].abs() < 4.0 * se, "{plus_x_mean}");
        }
    }

    #[test]
    fn surface_samples_of_a_mesh_without_area_are_empty() {
        assert!(surface_samples(&TriMesh::default(), 10, 1).is_empty());
        let flat = TriMesh::new(
            vec![
                Point3::origin(),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(2.0, 0.0, 0.0),
            ],
            vec![[0, 1, 2]],
        );
        assert!(surface_samples(&flat, 10, 1).is_empty());
    }
}
