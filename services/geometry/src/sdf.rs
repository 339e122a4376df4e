//! Signed distance grids: exact signed distances at the nodes of a regular grid over a mesh's
//! padded bounding box, trilinear interpolation between them, and the analytic gradient of
//! that interpolant (the ∂SDF/∂p_o of eq 10).
//!
//! Sign convention: negative inside the solid, positive outside, metres.
//!
//! The node values come from closest-point queries on a BVH (parry3d) with the sign of the
//! angle-weighted pseudo-normal at the closest feature, which is exact for a closed,
//! consistently oriented surface. A mesh made of several closed shells is handled shell by
//! shell: outward shells (positive volume) are solids joined by `min`, inward shells (negative
//! volume) are cavities cut by `max`. Overlapping solids (an eye bolt's ring and shank, say)
//! therefore get the right zero set and exact outside distances, which a single closest-point
//! query over all triangles would not (it would find the faces buried inside the overlap).

use nalgebra::{Point3, Vector3};
use parry3d::query::PointQuery;
use parry3d::shape::{TriMesh as ParryTriMesh, TriMeshFlags};
use rayon::prelude::*;

use crate::glam_interop::vec3_from_point;
use crate::mesh::{MeshError, TriMesh};

/// Grid resolution and extent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SdfConfig {
    /// Edge length of one voxel, metres.
    pub voxel_size_m: f64,
    /// Margin added around the mesh's bounding box on every side, metres.
    pub padding_m: f64,
}

impl Default for SdfConfig {
    /// 1 mm voxels and 10 mm padding: fine enough for the 2 mm/2° metric on parts of tens of
    /// millimetres, and wide enough that points of a pose 10 mm off still land in the grid.
    fn default() -> Self {
        Self {
            voxel_size_m: 1e-3,
            padding_m: 10e-3,
        }
    }
}

/// Why a grid could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SdfError {
    /// The mesh is unusable or not watertight; see the [`MeshError`] for what to repair.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// [`SdfConfig::voxel_size_m`] (the value, metres) is zero, negative, NaN or infinite.
    #[error("voxel size {0} m must be finite and positive")]
    BadVoxelSize(f64),
    /// [`SdfConfig::padding_m`] (the value, metres) is negative, NaN or infinite.
    #[error("padding {0} m must be finite and non-negative")]
    BadPadding(f64),
    /// The grid would have more than [`MAX_GRID_NODES`] nodes; use a larger voxel size or less
    /// padding, and check the mesh's length unit.
    #[error(
        "a grid of {nx}×{ny}×{nz} nodes is over the limit of {limit} nodes: use a larger voxel \
         size or less padding (is the mesh unit right? a mm mesh read as metres is 1000× too big)"
    )]
    TooLarge {
        /// Nodes along x.
        nx: usize,
        /// Nodes along y.
        ny: usize,
        /// Nodes along z.
        nz: usize,
        /// The node limit, [`MAX_GRID_NODES`].
        limit: usize,
    },
}

/// Most nodes a grid may have (~1 GiB of f32).
pub const MAX_GRID_NODES: usize = 256 << 20;

/// A signed distance value and its gradient at a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SdfSample {
    /// Signed distance, metres (negative inside).
    pub distance_m: f64,
    /// ∇SDF, dimensionless (≈ unit length near the surface).
    pub gradient: Vector3<f64>,
    /// False when the point lies outside the grid and the value was extrapolated.
    pub inside_grid: bool,
}

/// A dense signed distance grid in the mesh (object) frame.
#[derive(Clone, Debug)]
pub struct SdfGrid {
    /// Position of node (0, 0, 0), metres.
    origin_m: Point3<f64>,
    voxel_size_m: f64,
    /// Node counts along x, y, z (each ≥ 2).
    dims: [usize; 3],
    /// Node values, metres, x fastest then y then z.
    values_m: Vec<f32>,
}

/// One closed shell of a mesh, ready for signed closest-point queries.
struct Shell {
    bvh: ParryTriMesh,
    /// +1 for a solid (outward faces), −1 for a cavity (inward faces).
    orientation: f32,
}

impl Shell {
    /// Signed distance to this shell's surface, negative inside its solid side.
    fn signed_distance(&self, p: glam::Vec3) -> f32 {
        let projection = self.bvh.project_local_point(p, false);
        let d = (projection.point - p).length();
        if projection.is_inside { -d } else { d }
    }
}

impl SdfGrid {
    /// Builds the grid of `mesh`, which must be watertight. Runs on all rayon threads.
    pub fn build(mesh: &TriMesh, config: &SdfConfig) -> Result<Self, SdfError> {
        Self::build_with_progress(mesh, config, |_, _| {})
    }

    /// [`SdfGrid::build`], calling `progress(z_slices_done, z_slices_total)` as slices finish.
    pub fn build_with_progress(
        mesh: &TriMesh,
        config: &SdfConfig,
        progress: impl Fn(usize, usize) + Sync,
    ) -> Result<Self, SdfError> {
        if !(config.voxel_size_m.is_finite() && config.voxel_size_m > 0.0) {
            return Err(SdfError::BadVoxelSize(config.voxel_size_m));
        }
        if !(config.padding_m.is_finite() && config.padding_m >= 0.0) {
            return Err(SdfError::BadPadding(config.padding_m));
        }
        let report = mesh.validate()?;
        report.require_watertight("a signed distance field")?;

        let lo = report.aabb_min.cast::<f64>() - Vector3::repeat(config.padding_m);
        let hi = report.aabb_max.cast::<f64>() + Vector3::repeat(config.padding_m);
        let h = config.voxel_size_m;
        let count = |extent: f64| (extent / h).ceil() as usize + 1;
        let dims = [count(hi.x - lo.x), count(hi.y - lo.y), count(hi.z - lo.z)].map(|n| n.max(2));
        let total = dims.iter().try_fold(1usize, |acc, &n| acc.checked_mul(n));
        if total.is_none_or(|t| t > MAX_GRID_NODES) {
            let [nx, ny, nz] = dims;
            return Err(SdfError::TooLarge {
                nx,
                ny,
                nz,
                limit: MAX_GRID_NODES,
            });
        }
        // Centre the grid on the padded box so padding is symmetric.
        let span = Vector3::new(dims[0] - 1, dims[1] - 1, dims[2] - 1).cast::<f64>() * h;
        let origin_m = Point3::from((lo.coords + hi.coords - span) * 0.5);

        let shells = Self::shells(mesh)?;
        let [nx, ny, nz] = dims;
        let done = std::sync::atomic::AtomicUsize::new(0);
        let mut values_m = vec![0f32; nx * ny * nz];
        values_m
            .par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, slice)| {
                for j in 0..ny {
                    for i in 0..nx {
                        let p = origin_m + Vector3::new(i as f64, j as f64, k as f64) * h;
                        slice[j * nx + i] = signed_distance(
                            &shells,
                            glam::Vec3::new(p.x as f32, p.y as f32, p.z as f32),
                        );
                    }
                }
                let finished = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                progress(finished, nz);
            });
        Ok(Self {
            origin_m,
            voxel_size_m: h,
            dims,
            values_m,
        })
    }

    fn shells(mesh: &TriMesh) -> Result<Vec<Shell>, SdfError> {
        let mut shells = Vec::new();
        for component in mesh.connected_components() {
            let sub = mesh.submesh(&component);
            let orientation = if sub.signed_volume() >= 0.0 {
                1.0
            } else {
                -1.0
            };
            let vertices = sub.vertices.iter().map(vec3_from_point).collect();
            // validate() has already rejected empty meshes, so parry's only error cannot occur;
            // map it anyway rather than unwrap.
            let bvh = ParryTriMesh::with_flags(vertices, sub.triangles, TriMeshFlags::ORIENTED)
                .map_err(|_| MeshError::Empty {
                    vertices: 0,
                    triangles: 0,
                })?;
            shells.push(Shell { bvh, orientation });
        }
        Ok(shells)
    }

    /// Node counts along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Voxel edge length, metres.
    pub fn voxel_size_m(&self) -> f64 {
        self.voxel_size_m
    }

    /// The grid's box (first and last node), metres.
    pub fn bounds(&self) -> (Point3<f64>, Point3<f64>) {
        let span = Vector3::new(self.dims[0] - 1, self.dims[1] - 1, self.dims[2] - 1).cast::<f64>();
        (self.origin_m, self.origin_m + span * self.voxel_size_m)
    }

    /// The exact signed distance stored at node `(i, j, k)`, metres.
    pub fn node_value(&self, i: usize, j: usize, k: usize) -> Option<f32> {
        let [nx, ny, nz] = self.dims;
        (i < nx && j < ny && k < nz).then(|| self.values_m[(k * ny + j) * nx + i])
    }

    /// Signed distance and gradient at `p` (object frame, metres).
    ///
    /// Inside the grid: trilinear interpolation of the node values and its exact gradient.
    /// Outside: `SDF(q) + |p − q|` with `q` the nearest point of the grid box, an upper bound of
    /// the true distance (SDFs are 1-Lipschitz) that keeps growing away from the part, with the
    /// exact gradient of that expression; `inside_grid` is then false so callers can treat the
    /// point as an outlier. A non-finite `p` gives a NaN distance.
    #[inline]
    pub fn sample(&self, p: &Point3<f64>) -> SdfSample {
        let (lo, hi) = self.bounds();
        let q = p
            .coords
            .zip_zip_map(&lo.coords, &hi.coords, |x, l, h| x.clamp(l, h));
        let outside = p.coords - q;
        let (value, mut gradient) = self.trilinear(&Point3::from(q));
        let offset = outside.norm();
        if offset == 0.0 {
            return SdfSample {
                distance_m: value,
                gradient,
                inside_grid: p.coords.iter().all(|c| c.is_finite()),
            };
        }
        for axis in 0..3 {
            if outside[axis] != 0.0 {
                gradient[axis] = 0.0; // clamped axis: the interpolant no longer moves with p
            }
        }
        SdfSample {
            distance_m: value + offset,
            gradient: gradient + outside / offset,
            inside_grid: false,
        }
    }

    /// Trilinear value and gradient at a point inside the grid box.
    #[inline]
    fn trilinear(&self, p: &Point3<f64>) -> (f64, Vector3<f64>) {
        let [nx, ny, nz] = self.dims;
        let g = (p - self.origin_m) / self.voxel_size_m;
        // Cell index clamped so the last node row is reached with fraction 1.
        let cell = |x: f64, n: usize| -> (usize, f64) {
            // x ≥ 0 inside the box, where truncation is floor (and NaN → 0); a floor call is
            // not inlined on baseline x86-64 and this is the refiner's hot loop.
            let i = (x.max(0.0) as usize).min(n - 2);
            (i, x - i as f64)
        };
        let ((i, fx), (j, fy), (k, fz)) = (cell(g.x, nx), cell(g.y, ny), cell(g.z, nz));
        let at = |di: usize, dj: usize, dk: usize| {
            self.values_m[((k + dk) * ny + j + dj) * nx + i + di] as f64
        };
        let (c000, c100, c010, c110) = (at(0, 0, 0), at(1, 0, 0), at(0, 1, 0), at(1, 1, 0));
        let (c001, c101, c011, c111) = (at(0, 0, 1), at(1, 0, 1), at(0, 1, 1), at(1, 1, 1));
        // Interpolate along x, then y, then z; differentiate each stage.
        let c00 = c000 + (c100 - c000) * fx;
        let c10 = c010 + (c110 - c010) * fx;
        let c01 = c001 + (c101 - c001) * fx;
        let c11 = c011 + (c111 - c011) * fx;
        let c0 = c00 + (c10 - c00) * fy;
        let c1 = c01 + (c11 - c01) * fy;
        let value = c0 + (c1 - c0) * fz;

        let dx0 = (c100 - c000) + ((c110 - c010) - (c100 - c000)) * fy;
        let dx1 = (c101 - c001) + ((c111 - c011) - (c101 - c001)) * fy;
        let dx = dx0 + (dx1 - dx0) * fz;
        let dy = (c10 - c00) + ((c11 - c01) - (c10 - c00)) * fz;
        let dz = c1 - c0;
        (value, Vector3::new(dx, dy, dz) / self.voxel_size_m)
    }
}

/// How far a symmetry is from exact on a grid: the largest `|SDF(S·p) − SDF(p)|`, metres, over
/// the points `p` (object frame) and the group elements `S` sampled with `continuous_steps`
/// per continuous axis. An exact symmetry gives the grid's interpolation error (< ½ voxel at
/// each of the two samples); the declared `tolerance_m` adds to that.
pub fn symmetry_deviation_m(
    grid: &SdfGrid,
    points: &[Point3<f64>],
    symmetry: &crate::symmetry::Symmetry,
    continuous_steps: usize,
) -> f64 {
    let elements = symmetry.sample(continuous_steps);
    points
        .par_iter()
        .map(|p| {
            let d = grid.sample(p).distance_m;
            elements
                .iter()
                .map(|s| (grid.sample(&(s * p)).distance_m - d).abs())
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max)
}

/// The signed distance to the union of solid shells minus the cavities.
fn signed_distance(shells: &[Shell], p: glam::Vec3) -> f32 {
    let mut solid = f32::INFINITY;
    let mut cavity_cut = f32::NEG_INFINITY;
    for shell in shells {
        let d = shell.signed_distance(p);
        if shell.orientation > 0.0 {
            solid = solid.min(d);
        } else {
            cavity_cut = cavity_cut.max(d);
        }
    }
    if solid.is_infinite() {
        cavity_cut
    } else {
        solid.max(cavity_cut)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// An axis-aligned box with half extents `e`, centred at the origin.
    pub(crate) fn cuboid(e: [f32; 3]) -> TriMesh {
        TriMesh::cuboid([0.0; 3], e.map(f64::from))
    }

    fn exact_box_sdf(p: &Point3<f64>, e: [f64; 3]) -> f64 {
        let q = Vector3::new(p.x.abs() - e[0], p.y.abs() - e[1], p.z.abs() - e[2]);
        q.map(|c| c.max(0.0)).norm() + q.max().min(0.0)
    }

    const H: f64 = 1e-3;

    fn random_points(lo: Point3<f64>, hi: Point3<f64>, n: usize, seed: u64) -> Vec<Point3<f64>> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                Point3::new(
                    rng.random_range(lo.x..hi.x),
                    rng.random_range(lo.y..hi.y),
                    rng.random_range(lo.z..hi.z),
                )
            })
            .collect()
    }

    #[test]
    fn sphere_distances_within_half_a_voxel() {
        let r = 0.02;
        // 128 segments: chord sag r(1 − cos(π/128)) ≈ 6 µm, far below the half-voxel bound.
        let grid = SdfGrid::build(
            &TriMesh::uv_sphere(r as f32, 128),
            &SdfConfig {
                voxel_size_m: H,
                padding_m: 5e-3,
            },
        )
        .unwrap();
        let (lo, hi) = grid.bounds();
        let mut worst: f64 = 0.0;
        for p in random_points(lo, hi, 20_000, 1) {
            // The sphere's SDF has a kink at its centre; trilinear cells touching it are excluded.
            if p.coords.norm() < 2.0 * H {
                continue;
            }
            let s = grid.sample(&p);
            assert!(s.inside_grid);
            worst = worst.max((s.distance_m - (p.coords.norm() - r)).abs());
            if (p.coords.norm() - r).abs() < 3.0 * H {
                assert!(
                    (s.gradient.norm() - 1.0).abs() < 0.05,
                    "|∇| = {} at {p}",
                    s.gradient.norm()
                );
                assert!(s.gradient.normalize().dot(&p.coords.normalize()) > 0.99);
            }
        }
        assert!(worst < 0.5 * H, "worst error {worst}");
    }

    #[test]
    fn box_distances_within_half_a_voxel() {
        let e = [0.015, 0.01, 0.005];
        let grid = SdfGrid::build(
            &cuboid(e.map(|x| x as f32)),
            &SdfConfig {
                voxel_size_m: H,
                padding_m: 6e-3,
            },
        )
        .unwrap();
        let (lo, hi) = grid.bounds();
        let mut worst: f64 = 0.0;
        for p in random_points(lo, hi, 20_000, 2) {
            let exact = exact_box_sdf(&p, e);
            let s = grid.sample(&p);
            worst = worst.max((s.distance_m - exact).abs());
            // Near a face and two voxels away from every edge the field is a plane: |∇| = 1.
            let q = [p.x.abs() - e[0], p.y.abs() - e[1], p.z.abs() - e[2]];
            let mut sorted = q;
            sorted.sort_by(|a, b| b.total_cmp(a));
            if exact.abs() < 3.0 * H && sorted[1] < -2.0 * H - exact.abs() {
                assert!(
                    (s.gradient.norm() - 1.0).abs() < 1e-3,
                    "|∇| = {} at {p}",
                    s.gradient.norm()
                );
            }
        }
        assert!(worst < 0.5 * H, "worst error {worst}");
    }

    #[test]
    fn gradient_is_the_derivative_of_the_value() {
        let grid = SdfGrid::build(
            &TriMesh::uv_sphere(0.02, 64),
            &SdfConfig {
                voxel_size_m: H,
                padding_m: 4e-3,
            },
        )
        .unwrap();
        let (lo, hi) = grid.bounds();
        let step = 1e-7;
        // Points inside and outside the grid; the interpolant is smooth within a cell, so
        // central differences agree to O(step) unless a cell face is crossed (rare; skipped).
        let mut checked = 0;
        for p in random_points(
            lo - Vector3::repeat(0.01),
            hi + Vector3::repeat(0.01),
            2000,
            3,
        ) {
            let s = grid.sample(&p);
            let numeric = Vector3::from_fn(|a, _| {
                let mut d = Vector3::zeros();
                d[a] = step;
                (grid.sample(&(p + d)).distance_m - grid.sample(&(p - d)).distance_m) / (2.0 * step)
            });
            let crosses_cell = (0..3).any(|a| {
                let g = (p[a] - lo[a]) / H;
                (g - g.round()).abs() < 1e-3
            });
            if !crosses_cell {
                assert!(
                    (numeric - s.gradient).norm() < 1e-5,
                    "at {p}: {numeric} vs {}",
                    s.gradient
                );
                checked += 1;
            }
        }
        assert!(checked > 1500);
    }

    #[test]
    fn outside_the_grid_is_defined_and_flagged() {
        let grid = SdfGrid::build(
            &cuboid([0.01; 3]),
            &SdfConfig {
                voxel_size_m: H,
                padding_m: 2e-3,
            },
        )
        .unwrap();
        let far = Point3::new(0.5, 0.0, 0.0);
        let s = grid.sample(&far);
        assert!(!s.inside_grid);
        // Upper bound of the true distance 0.49 m, exceeding it by at most the clamped value's error.
        assert!(s.distance_m >= 0.49 - 0.5 * H && s.distance_m < 0.5);
        assert!((s.gradient - Vector3::x()).norm() < 1e-3);
        assert!(
            grid.sample(&Point3::new(f64::NAN, 0.0, 0.0))
                .distance_m
                .is_nan()
        );
    }

    #[test]
    fn overlapping_shells_union_and_cavities_subtract() {
        // Two overlapping boxes: the point in the overlap's centre is inside by the larger depth,
        // and the buried faces inside the overlap do not create a false zero.
        let mut union = cuboid([0.01; 3]);
        union.append(
            &cuboid([0.01; 3]).transformed(&nalgebra::Isometry3::translation(0.01, 0.0, 0.0)),
        );
        let grid = SdfGrid::build(
            &union,
            &SdfConfig {
                voxel_size_m: H,
                padding_m: 2e-3,
            },
        )
        .unwrap();
        let s = grid.sample(&Point3::new(0.01, 0.0, 0.0));
        assert!((s.distance_m + 0.01).abs() < 0.5 * H, "{}", s.distance_m);

        // A hollow box: an inward 5 mm shell inside a 10 mm one.
        let mut hollow = cuboid([0.01; 3]);
        let mut inner = cuboid([0.005; 3]);
        for t in &mut inner.triangles {
            t.swap(1, 2);
        }
        hollow.append(&inner);
        let grid = SdfGrid::build(
            &hollow,
            &SdfConfig {
                voxel_size_m: H,
                padding_m: 2e-3,
            },
        )
        .unwrap();
        assert!((grid.sample(&Point3::origin()).distance_m - 0.005).abs() < 0.5 * H);
        let wall = grid.sample(&Point3::new(0.0065, 0.0, 0.0)).distance_m;
        assert!((wall + 0.0015).abs() < 0.5 * H, "{wall}");
    }

    #[test]
    fn bad_configs_and_open_meshes_are_errors() {
        let mesh = cuboid([0.01; 3]);
        assert_eq!(
            SdfGrid::build(
                &mesh,
                &SdfConfig {
                    voxel_size_m: 0.0,
                    padding_m: 0.0
                }
            )
            .unwrap_err(),
            SdfError::BadVoxelSize(0.0)
        );
        assert!(matches!(
            SdfGrid::build(
                &mesh,
                &SdfConfig {
                    voxel_size_m: 1e-3,
                    padding_m: f64::NAN
                }
            ),
            Err(SdfError::BadPadding(_))
        ));
        assert!(matches!(
            SdfGrid::build(&mesh.scaled(1000.0), &SdfConfig::default()),
            Err(SdfError::TooLarge { .. })
        ));
        let mut open = mesh.clone();
        open.triangles.pop();
        assert!(matches!(
            SdfGrid::build(&open, &SdfConfig::default()),
            Err(SdfError::Mesh(MeshError::NotWatertight { .. }))
        ));
    }
}
