//! Depth errors that neighbouring pixels share, and the pose information that survives them.
//!
//! Eq 18 treats every depth point's error as independent, so its information grows with the
//! number of pixels: four views of a part look four times as sure as one, whatever the camera
//! gets wrong in all of them. A stereo matcher's errors are not independent: neighbouring
//! pixels share matching windows, surface curvature and inter-reflections, so their depths are
//! wrong together. Model: a point's depth error is its own noise (σ_z, eq 1–5) plus a bias `b`
//! shared by the points of one view inside one cell of a world-frame grid of edge `cell_m`,
//! `b ~ N(0, σ_b²)`, independent between cells and between views. In SDF residuals (eq 11) one
//! cell's covariance is `D + σ_b² g gᵀ`, with `D` eq 11's per-point variances and `g_i = G_i`
//! (the residual's change per metre of depth); Sherman–Morrison gives the cell's information
//!
//! `Σ w_i J_iᵀ J_i − σ_b² s sᵀ / (1 + σ_b² Σ w_i g_i²)`, `w_i = 1/Σ_sdf,i`, `s = Σ w_i g_i J_i`,
//!
//! so a cell of many points adds at most about `1/σ_b²` along its shared direction, however
//! many pixels it holds. `σ_b = 0` is eq 18 exactly.
//!
//! The two numbers describe the camera, not a result: [`fit_correlated_error`] measures them
//! as the maximum-likelihood fit to depth residuals at known poses (tuning scenes, never an
//! evaluation's). Points count where the refiner's last stage weighs them: inside the grid,
//! within its final gate, on a face turned towards their camera.

use std::collections::HashMap;

use glint_geometry::sdf::SdfGrid;
use nalgebra::{Isometry3, Matrix6, Point3, Vector6};

use crate::points::DepthPoint;
use crate::refine::{SdfRefineConfig, depth_gain, faces_away, point_terms};

/// A depth bias shared by one view's points within a world cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrelatedDepthError {
    /// Edge of the world-frame cells within which one view's points share a bias, metres;
    /// `f64::INFINITY` makes the whole view one cell (a per-view bias).
    pub cell_m: f64,
    /// σ_b, the shared bias's standard deviation along the viewing ray, metres; 0 is eq 18.
    pub bias_sigma_m: f64,
}

impl CorrelatedDepthError {
    /// No shared error: eq 18's independent pixels.
    pub const INDEPENDENT: Self = Self {
        cell_m: f64::INFINITY,
        bias_sigma_m: 0.0,
    };
}

/// One weighed point: Jacobian, `1/Σ_sdf`, `G` and residual, with its cell.
#[derive(Clone, Copy, Debug)]
struct WeighedPoint {
    cell: [i64; 3],
    j: Vector6<f64>,
    w: f64,
    g: f64,
    r: f64,
}

/// The points of one view the last stage weighs at `t_o_w`: inside the grid, `|r| ≤` the final
/// gate.
fn weighed_points(
    sdf: &SdfGrid,
    points: &[DepthPoint],
    t_o_w: &Isometry3<f64>,
    config: &SdfRefineConfig,
    cell_m: f64,
) -> Vec<WeighedPoint> {
    let model_var = config.model_sigma_m * config.model_sigma_m;
    let rot_o_w = t_o_w.rotation.to_rotation_matrix().into_inner();
    let cell_of = |x: f64| {
        if cell_m.is_finite() {
            (x / cell_m).floor() as i64
        } else {
            0
        }
    };
    points
        .iter()
        .filter_map(|point| {
            let p_o: Point3<f64> = t_o_w * point.p_w;
            let s = sdf.sample(&p_o);
            let g = depth_gain(&s.gradient, point, &rot_o_w);
            if !s.inside_grid
                || s.distance_m.abs() > config.final_gate_m
                || faces_away(g, point, config.back_facing_cos)
            {
                return None;
            }
            let (j, w) = point_terms(&s.gradient, &p_o, point, g, model_var);
            Some(WeighedPoint {
                cell: [
                    cell_of(point.p_w.x),
                    cell_of(point.p_w.y),
                    cell_of(point.p_w.z),
                ],
                j: Vector6::from(j),
                w,
                g,
                r: s.distance_m,
            })
        })
        .collect()
}

/// Per cell: `Σ w J Jᵀ`, `s = Σ w g J`, `q = Σ w g²`, and for the likelihood `Σ w r²`,
/// `t = Σ w g r`, `Σ ln(2π/w)`, the count.
#[derive(Clone, Copy, Debug)]
struct CellSums {
    h: Matrix6<f64>,
    s: Vector6<f64>,
    q: f64,
    wrr: f64,
    t: f64,
    log_var: f64,
    n: usize,
}

impl CellSums {
    const ZERO: Self = Self {
        h: Matrix6::new(
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            0.0, 0.0,
        ),
        s: Vector6::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        q: 0.0,
        wrr: 0.0,
        t: 0.0,
        log_var: 0.0,
        n: 0,
    };

    fn add(&mut self, p: &WeighedPoint) {
        self.h += p.j * p.j.transpose() * p.w;
        self.s += p.j * (p.w * p.g);
        self.q += p.w * p.g * p.g;
        self.wrr += p.w * p.r * p.r;
        self.t += p.w * p.g * p.r;
        self.log_var += (std::f64::consts::TAU / p.w).ln();
        self.n += 1;
    }

    /// The cell's information under a shared bias of variance `bias_var` (Sherman–Morrison).
    fn information(&self, bias_var: f64) -> Matrix6<f64> {
        self.h - self.s * self.s.transpose() * (bias_var / (1.0 + bias_var * self.q))
    }

    /// ln N(r; 0, D + bias_var g gᵀ) (matrix determinant lemma and Sherman–Morrison).
    fn log_likelihood(&self, bias_var: f64) -> f64 {
        let c = 1.0 + bias_var * self.q;
        -0.5 * (self.log_var + c.ln() + self.wrr - bias_var * self.t * self.t / c)
    }
}

/// The cells of one view's weighed points, in a fixed order (sorted by cell) so the sums do
/// not depend on hashing.
fn cell_sums(points: &[WeighedPoint]) -> Vec<CellSums> {
    let mut by_cell: HashMap<[i64; 3], CellSums> = HashMap::new();
    for p in points {
        by_cell.entry(p.cell).or_insert(CellSums::ZERO).add(p);
    }
    let mut cells: Vec<([i64; 3], CellSums)> = by_cell.into_iter().collect();
    cells.sort_by_key(|(k, _)| *k);
    cells.into_iter().map(|(_, c)| c).collect()
}

/// The Fisher information of a pose `t_o_w` from several views' depth points under `error`
/// (module doc; with [`CorrelatedDepthError::INDEPENDENT`] it is eq 18 over the points within
/// the final gate). `views[k]` holds view k's points: a bias is shared within a view only.
/// In the refiner's δ coordinates (translation first).
pub fn information_with_correlated_error(
    sdf: &SdfGrid,
    views: &[&[DepthPoint]],
    t_o_w: &Isometry3<f64>,
    config: &SdfRefineConfig,
    error: &CorrelatedDepthError,
) -> Matrix6<f64> {
    let bias_var = error.bias_sigma_m * error.bias_sigma_m;
    views
        .iter()
        .flat_map(|points| cell_sums(&weighed_points(sdf, points, t_o_w, config, error.cell_m)))
        .fold(Matrix6::zeros(), |acc, cell| {
            acc + cell.information(bias_var)
        })
}

/// One view of a part at a known pose: what [`fit_correlated_error`] learns from.
#[derive(Clone, Copy, Debug)]
pub struct KnownPoseView<'a> {
    /// The part's SDF grid.
    pub sdf: &'a SdfGrid,
    /// The view's depth points of the part.
    pub points: &'a [DepthPoint],
    /// The part's true pose, world → object.
    pub t_o_w: Isometry3<f64>,
}

/// One cell size's best σ_b and the log-likelihood it reaches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellSizeFit {
    /// The model at this cell size with its best σ_b.
    pub error: CorrelatedDepthError,
    /// Σ ln N(r; 0, Σ) over all cells of all views.
    pub log_likelihood: f64,
    /// Cells holding points.
    pub cells: usize,
}

/// What [`fit_correlated_error`] measured.
#[derive(Clone, Debug, PartialEq)]
pub struct CorrelatedErrorFit {
    /// The maximum-likelihood model over all cell sizes.
    pub best: CorrelatedDepthError,
    /// The log-likelihood of independent errors (σ_b = 0), for comparison.
    pub independent_log_likelihood: f64,
    /// Each cell size tried, in the order given.
    pub per_cell_size: Vec<CellSizeFit>,
    /// Points weighed, over all views.
    pub points: usize,
}

/// Measures a [`CorrelatedDepthError`] from depth at known poses: for each cell edge in
/// `cell_sizes_m` (metres; infinite for one cell a view), the σ_b in [1 µm, 10 mm] that
/// maximises the Gaussian likelihood of the views' SDF residuals (golden-section search on
/// ln σ_b, the likelihood being unimodal in σ_b² per cell), then the best over cell sizes.
/// `None` without any weighed point or any valid cell size.
pub fn fit_correlated_error(
    views: &[KnownPoseView<'_>],
    config: &SdfRefineConfig,
    cell_sizes_m: &[f64],
) -> Option<CorrelatedErrorFit> {
    let mut per_cell_size = Vec::new();
    let mut independent_log_likelihood = f64::NAN;
    let mut points = 0;
    for &cell_m in cell_sizes_m.iter().filter(|c| **c > 0.0) {
        let cells: Vec<CellSums> = views
            .iter()
            .flat_map(|v| cell_sums(&weighed_points(v.sdf, v.points, &v.t_o_w, config, cell_m)))
            .collect();
        if cells.is_empty() {
            return None;
        }
        points = cells.iter().map(|c| c.n).sum();
        let ll =
            |sigma: f64| -> f64 { cells.iter().map(|c| c.log_likelihood(sigma * sigma)).sum() };
        independent_log_likelihood = ll(0.0);
        let sigma = golden_max(|ln_s| ll(ln_s.exp()), 1e-6f64.ln(), 1e-2f64.ln(), 60).exp();
        let at_sigma = ll(sigma);
        let (sigma, log_likelihood) = if at_sigma > independent_log_likelihood {
            (sigma, at_sigma)
        } else {
            (0.0, independent_log_likelihood)
        };
        per_cell_size.push(CellSizeFit {
            error: CorrelatedDepthError {
                cell_m,
                bias_sigma_m: sigma,
            },
            log_likelihood,
            cells: cells.len(),
        });
    }
    let best = per_cell_size
        .iter()
        .max_by(|a, b| a.log_likelihood.total_cmp(&b.log_likelihood))?
        .error;
    Some(CorrelatedErrorFit {
        best,
        independent_log_likelihood,
        per_cell_size,
        points,
    })
}

/// The argmax of a unimodal `f` on `[lo, hi]` by golden-section search, `iterations` steps.
fn golden_max(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64, iterations: usize) -> f64 {
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let mut a = hi - ratio * (hi - lo);
    let mut b = lo + ratio * (hi - lo);
    let (mut fa, mut fb) = (f(a), f(b));
    for _ in 0..iterations {
        if fa < fb {
            lo = a;
            a = b;
            fa = fb;
            b = lo + ratio * (hi - lo);
            fb = f(b);
        } else {
            hi = b;
            b = a;
            fb = fa;
            a = hi - ratio * (hi - lo);
            fa = f(a);
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_geometry::mesh::TriMesh;
    use glint_geometry::sdf::SdfConfig;
    use nalgebra::Vector3;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A 60 mm cube's SDF and one camera's view of its top face from 0.5 m: a 40 × 40 mm
    /// patch of points at 1 mm spacing looking down −z, each with depth noise σ_z plus a bias
    /// shared within `cell_m` cells.
    fn biased_view(
        sigma_z: f64,
        error: &CorrelatedDepthError,
        seed: u64,
    ) -> (SdfGrid, Vec<DepthPoint>) {
        let mesh = TriMesh::cuboid([0.0; 3], [0.03; 3]);
        let sdf = SdfGrid::build(&mesh, &SdfConfig::default()).unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let noise = Normal::new(0.0, 1.0).unwrap();
        let mut bias: HashMap<[i64; 2], f64> = HashMap::new();
        let mut points = Vec::new();
        for iy in 0..40 {
            for ix in 0..40 {
                let (x, y) = (-0.0195 + ix as f64 * 1e-3, -0.0195 + iy as f64 * 1e-3);
                let cell = [
                    (x / error.cell_m).floor() as i64,
                    (y / error.cell_m).floor() as i64,
                ];
                let b = *bias
                    .entry(cell)
                    .or_insert_with(|| error.bias_sigma_m * noise.sample(&mut rng));
                // Depth along −z from a camera above: the error moves the point along the ray.
                let e = b + sigma_z * noise.sample(&mut rng);
                points.push(DepthPoint {
                    p_w: Point3::new(x, y, 0.03 - e),
                    dp_dz_w: Vector3::new(0.0, 0.0, -1.0),
                    sigma_z_m: sigma_z.max(1e-9),
                });
            }
        }
        (sdf, points)
    }

    fn config() -> SdfRefineConfig {
        SdfRefineConfig {
            model_sigma_m: 1e-5,
            ..SdfRefineConfig::default()
        }
    }

    #[test]
    fn independent_is_eq_18() {
        let error = CorrelatedDepthError::INDEPENDENT;
        let (sdf, points) = biased_view(0.2e-3, &error, 1);
        let t_o_w = Isometry3::identity();
        let cfg = config();
        let ours = information_with_correlated_error(&sdf, &[&points], &t_o_w, &cfg, &error);
        let eq18 = crate::refine::information_of_points(&sdf, &points, &t_o_w, cfg.model_sigma_m);
        assert!((ours - eq18).norm() <= 1e-9 * eq18.norm());
    }

    #[test]
    fn a_shared_bias_caps_the_information_of_one_cell() {
        // One cell for the whole patch: the z information of N points with σ_z is N/σ_z²
        // under eq 18, and 1/(σ_z²/N + σ_b²) with a shared bias — at most 1/σ_b².
        let sigma_z = 0.2e-3;
        let error = CorrelatedDepthError {
            cell_m: f64::INFINITY,
            bias_sigma_m: 0.1e-3,
        };
        let (sdf, points) = biased_view(sigma_z, &CorrelatedDepthError::INDEPENDENT, 2);
        let cfg = config();
        let h = information_with_correlated_error(
            &sdf,
            &[&points],
            &Isometry3::identity(),
            &cfg,
            &error,
        );
        let n = points.len() as f64;
        let var = sigma_z * sigma_z + cfg.model_sigma_m * cfg.model_sigma_m;
        let expected = 1.0 / (var / n + error.bias_sigma_m * error.bias_sigma_m);
        assert!(
            (h[(2, 2)] - expected).abs() <= 1e-6 * expected,
            "{} vs {expected}",
            h[(2, 2)]
        );
        // Two views, biased independently: twice one view's.
        let two = information_with_correlated_error(
            &sdf,
            &[&points, &points],
            &Isometry3::identity(),
            &cfg,
            &error,
        );
        assert!((two[(2, 2)] - 2.0 * expected).abs() <= 1e-6 * expected);
    }

    /// The fit over 40 patches whose depth errors follow `truth` (σ_z 0.1 mm, seeds from
    /// `seed`), each at its true pose.
    fn fit_patches(truth: &CorrelatedDepthError, seed: u64, cells_m: &[f64]) -> CorrelatedErrorFit {
        let views: Vec<(SdfGrid, Vec<DepthPoint>)> = (0..40)
            .map(|s| biased_view(0.1e-3, truth, seed + s))
            .collect();
        let known: Vec<KnownPoseView> = views
            .iter()
            .map(|(sdf, points)| KnownPoseView {
                sdf,
                points,
                t_o_w: Isometry3::identity(),
            })
            .collect();
        fit_correlated_error(&known, &config(), cells_m).unwrap()
    }

    #[test]
    fn the_fit_recovers_a_known_bias_and_cell() {
        // 40 views of a patch whose 8 mm cells share a bias of σ_b = 0.15 mm, σ_z = 0.1 mm.
        // 25 cells a view, 1000 cells in all: σ_b's relative standard error is about
        // 1/√(2·1000) ≈ 2.2 %, so 10 % is over 4σ.
        let truth = CorrelatedDepthError {
            cell_m: 8e-3,
            bias_sigma_m: 0.15e-3,
        };
        let fit = fit_patches(&truth, 100, &[2e-3, 8e-3, 32e-3, f64::INFINITY]);
        assert_eq!(fit.best.cell_m, 8e-3, "{fit:?}");
        let rel = (fit.best.bias_sigma_m - truth.bias_sigma_m).abs() / truth.bias_sigma_m;
        assert!(rel < 0.1, "{fit:?}");
        assert!(fit.per_cell_size[1].log_likelihood > fit.independent_log_likelihood);
    }

    #[test]
    fn independent_errors_fit_no_bias() {
        // Pure σ_z noise: the best σ_b is at most a few percent of σ_z (the search's floor or
        // noise: 40 × 1600 points pin the variance to ~0.6 %).
        let fit = fit_patches(
            &CorrelatedDepthError::INDEPENDENT,
            300,
            &[8e-3, f64::INFINITY],
        );
        assert!(fit.best.bias_sigma_m < 0.03e-3, "{fit:?}");
    }
}
