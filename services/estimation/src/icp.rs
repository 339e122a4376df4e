//! The ICP baseline: point-to-point (the paper's baseline, Besl–McKay with a closed-form
//! Kabsch/Umeyama step) and point-to-plane (Chen–Medioni, linearised normal equations), refining
//! `t_o_w` (object ← world) from world-frame points against dense model surface samples.
//!
//! Each iteration maps the points into the object frame with the current `t_o_w`, pairs every
//! point with its nearest model sample (a k-d tree over the samples, object frame), keeps pairs
//! closer than the maximum correspondence distance, and updates the pose on the left,
//! `t_o_w ← ΔT·t_o_w`, with ΔT in the object frame:
//! - point-to-point: ΔT = argmin Σ |ΔT·q − m|², in closed form from the SVD of the centred
//!   cross-covariance, with the reflection case folded back into SO(3);
//! - point-to-plane: ΔT = exp(δ), δ = (ρ, φ) from the Gauss–Newton normal equations of
//!   r = n·(exp(δ)·q − m) with the left-perturbation Jacobian `nᵀ[I | −[q]×]` (the same
//!   convention as the SDF refiner, eq 10). Directions the data cannot observe (a cylinder's
//!   roll) get no update — the minimum-norm step — and are counted in the result.
//!
//! Units are metres and radians. Non-finite points (missing depth) are skipped and counted;
//! other bad input and failures are errors, never panics or silent poses. Nothing here reads
//! ground truth.

use glint_geometry::TriMesh;
use glint_geometry::sampling::{SurfaceSample, surface_samples};
use glint_geometry::se3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6,
};
use rayon::prelude::*;

/// Which ICP error metric to minimise.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum IcpMethod {
    /// Σ |q − m|²: the paper's baseline.
    PointToPoint,
    /// Σ (n·(q − m))², with the model sample's normal n.
    PointToPlane,
}

impl IcpMethod {
    /// The name used in tables and files: `icp-p2p` / `icp-p2plane`.
    pub fn name(self) -> &'static str {
        match self {
            IcpMethod::PointToPoint => "icp-p2p",
            IcpMethod::PointToPlane => "icp-p2plane",
        }
    }

    /// Correspondences needed to determine a pose: 3 (non-collinear) points fix a rigid motion
    /// for point-to-point; point-to-plane gives one scalar equation per pair, so 6.
    pub fn min_correspondences(self) -> usize {
        match self {
            IcpMethod::PointToPoint => 3,
            IcpMethod::PointToPlane => 6,
        }
    }
}

/// ICP settings. [`Default`] is the baseline's documented configuration; the experiment chooses
/// `max_correspondence_distance_m` over a small grid on separate seeds.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IcpConfig {
    /// Error metric. Default: point-to-point, the paper's baseline.
    pub method: IcpMethod,
    /// Pairs farther apart than this (object frame, metres) are outliers. Default 10 mm: a third
    /// of the largest initial error the experiment draws (30 mm), twice its 5 mm threshold.
    pub max_correspondence_distance_m: f64,
    /// Iteration budget (pose updates). Default 30, the SDF refiner's budget.
    pub max_iterations: usize,
    /// Converged when one update moves the pose by less than this translation (metres) …
    /// Default 1 µm.
    pub convergence_translation_m: f64,
    /// … and less than this rotation (radians). Default 1e-6 rad (≈ 6·10⁻⁵ °).
    pub convergence_rotation_rad: f64,
    /// Diverged when the centroid of the points has moved farther than this in the object frame
    /// from where the initial pose put it (metres). Default 0.1 m: more than the largest part
    /// (57 mm) plus the largest initial error (30 mm).
    pub max_displacement_m: f64,
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            method: IcpMethod::PointToPoint,
            max_correspondence_distance_m: 0.010,
            max_iterations: 30,
            convergence_translation_m: 1e-6,
            convergence_rotation_rad: 1e-6,
            max_displacement_m: 0.1,
        }
    }
}

impl IcpConfig {
    /// The default configuration with another metric.
    pub fn with_method(method: IcpMethod) -> Self {
        Self {
            method,
            ..Self::default()
        }
    }

    fn validate(&self) -> Result<(), IcpError> {
        let positive = |field: &'static str, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(IcpError::InvalidConfig {
                    field,
                    reason: format!("must be finite and > 0, got {value}"),
                })
            }
        };
        positive(
            "max_correspondence_distance_m",
            self.max_correspondence_distance_m,
        )?;
        positive("convergence_translation_m", self.convergence_translation_m)?;
        positive("convergence_rotation_rad", self.convergence_rotation_rad)?;
        positive("max_displacement_m", self.max_displacement_m)?;
        if self.max_iterations == 0 {
            return Err(IcpError::InvalidConfig {
                field: "max_iterations",
                reason: "must be at least 1".into(),
            });
        }
        Ok(())
    }
}

/// Why ICP could not produce a pose.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum IcpError {
    /// The model was built from no surface samples; sample the mesh with `n > 0`.
    #[error("the ICP model has no surface samples")]
    EmptyModel,
    /// A model sample has a non-finite position, or a normal that is zero or non-finite; fix
    /// the mesh (degenerate or NaN triangles) or the samples given.
    #[error("ICP model sample {index} has a non-finite position or normal")]
    NonFiniteModelSample {
        /// Index of the offending sample.
        index: usize,
    },
    /// The k-d tree over the model samples could not be built; the message is the tree's.
    #[error("ICP model: {0}")]
    ModelTree(String),
    /// A setting of [`IcpConfig`] is out of range: a distance or threshold that is not finite
    /// and positive, or a zero iteration budget.
    #[error("invalid ICP config: {field} {reason}")]
    InvalidConfig {
        /// Name of the offending [`IcpConfig`] field.
        field: &'static str,
        /// What the value must be, and the value given.
        reason: String,
    },
    /// The point set is empty; the view gave no depth on the part.
    #[error("ICP got no points")]
    NoPoints,
    /// Every point is non-finite (missing depth); the view gave no usable depth on the part.
    #[error("ICP got {count} points, none of them finite")]
    NoFinitePoints {
        /// Number of points given.
        count: usize,
    },
    /// The initial pose `t_o_w` has a NaN or infinite translation or rotation.
    #[error("the initial pose t_o_w is not finite")]
    NonFiniteInitialPose,
    /// Too few points lie within the maximum correspondence distance of the model to fix a
    /// pose: the initial pose is too far off, or the distance too small for it.
    #[error(
        "ICP iteration {iteration}: only {found} points within {max_distance_m} m of the model, \
         {method:?} needs at least {required}"
    )]
    TooFewCorrespondences {
        /// Pose updates made before the failing correspondence search.
        iteration: usize,
        /// Pairs found within the distance.
        found: usize,
        /// Pairs the metric needs ([`IcpMethod::min_correspondences`]).
        required: usize,
        /// The maximum correspondence distance, metres.
        max_distance_m: f64,
        /// The metric used.
        method: IcpMethod,
    },
    /// The matched pairs do not determine a pose update: the points are collinear or
    /// coincident, the normal equations have no usable direction, or the sums are not finite.
    #[error(
        "ICP iteration {iteration}: the {found} matched pairs do not determine a pose \
         (collinear or coincident points, or non-finite sums)"
    )]
    Degenerate {
        /// Pose updates made before the failing step.
        iteration: usize,
        /// Pairs matched in that step.
        found: usize,
    },
    /// An update moved the points' centroid (object frame) farther than
    /// [`IcpConfig::max_displacement_m`] from where the initial pose put it, or made the pose
    /// non-finite: the initial pose is too far off for the data.
    #[error(
        "ICP diverged at iteration {iteration}: the points moved {displacement_m} m from where \
         the initial pose put them (limit {max_displacement_m} m)"
    )]
    Diverged {
        /// Pose updates made, counting the one that diverged.
        iteration: usize,
        /// Distance the centroid moved, metres (+∞ for a non-finite pose).
        displacement_m: f64,
        /// The limit, metres.
        max_displacement_m: f64,
    },
}

/// A refined pose and how it was reached.
#[derive(Clone, Debug, PartialEq)]
pub struct IcpResult {
    /// Object ← world.
    pub t_o_w: Isometry3<f64>,
    /// Pose updates made (≤ the budget).
    pub iterations: usize,
    /// Whether the last update was below both convergence thresholds (else the budget ran out).
    pub converged: bool,
    /// RMS of the point-to-sample distances of the inliers at the final pose, metres (the
    /// Euclidean distance for both metrics, so they compare).
    pub rms_m: f64,
    /// Points within the maximum correspondence distance at the final pose.
    pub inliers: usize,
    /// Non-finite input points that were skipped.
    pub non_finite_skipped: usize,
    /// Point-to-plane only: the most pose directions left without update in one iteration
    /// because the matched surface does not constrain them (0 for a well-posed view).
    pub unobservable_dofs: usize,
}

/// The model side of ICP: dense surface samples with outward normals in the object frame and a
/// k-d tree over them. Build once per part; share between refinements and threads.
pub struct IcpModel {
    /// f32 coordinates search faster; at part scale (< 0.1 m) they round by < 4 nm, and the
    /// distances used are recomputed in f64 from `points`.
    tree: ImmutableKdTree<f32, 3>,
    points: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
}

impl std::fmt::Debug for IcpModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IcpModel")
            .field("samples", &self.points.len())
            .finish()
    }
}

impl IcpModel {
    /// A model from given samples (object frame, metres; normals need not be unit length).
    pub fn new(samples: &[SurfaceSample]) -> Result<Self, IcpError> {
        if samples.is_empty() {
            return Err(IcpError::EmptyModel);
        }
        let mut points = Vec::with_capacity(samples.len());
        let mut normals = Vec::with_capacity(samples.len());
        for (index, s) in samples.iter().enumerate() {
            let normal = s
                .normal
                .try_normalize(0.0)
                .filter(|_| s.point.coords.iter().all(|c| c.is_finite()))
                .ok_or(IcpError::NonFiniteModelSample { index })?;
            if !normal.iter().all(|c| c.is_finite()) {
                return Err(IcpError::NonFiniteModelSample { index });
            }
            points.push(s.point);
            normals.push(normal);
        }
        let coords: Vec<[f32; 3]> = points
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect();
        let tree = ImmutableKdTree::new_from_slice(&coords)
            .map_err(|e| IcpError::ModelTree(format!("{e:?}")))?;
        Ok(Self {
            tree,
            points,
            normals,
        })
    }

    /// A model of `n` area-uniform samples of `mesh` (see [`surface_samples`]), seeded.
    pub fn from_mesh(mesh: &TriMesh, n: usize, seed: u64) -> Result<Self, IcpError> {
        Self::new(&surface_samples(mesh, n, seed))
    }

    /// Number of model samples.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the model has no samples (never true for a constructed model).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The nearest sample to `q` (object frame): its index and squared distance, m².
    #[inline]
    fn nearest(&self, q: &Vector3<f64>) -> (usize, f64) {
        let hit = self
            .tree
            .query(&[q.x as f32, q.y as f32, q.z as f32])
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute();
        let j = hit.item as usize;
        (j, (self.points[j].coords - q).norm_squared())
    }
}

/// Points per rayon task: large enough to amortise scheduling, small enough to balance 2–64
/// threads over the 10³–10⁵ points of a view.
const CHUNK: usize = 512;

/// Per-pair statistics summed over the inliers of one iteration (no allocation).
trait PairSums: Copy + Send + Default {
    fn add(&mut self, q: &Vector3<f64>, m: &Point3<f64>, n: &Vector3<f64>, d2: f64);
    fn merge(self, other: Self) -> Self;
}

/// Point-to-point: count, Σq, Σm, Σ q mᵀ, Σ|q|² + Σ|m|² and Σ d².
#[derive(Clone, Copy, Default)]
struct PointSums {
    n: usize,
    sum_q: Vector3<f64>,
    sum_m: Vector3<f64>,
    sum_qm: Matrix3<f64>,
    sum_norms2: f64,
    sum_d2: f64,
}

impl PairSums for PointSums {
    #[inline]
    fn add(&mut self, q: &Vector3<f64>, m: &Point3<f64>, _n: &Vector3<f64>, d2: f64) {
        self.n += 1;
        self.sum_q += q;
        self.sum_m += m.coords;
        self.sum_qm += q * m.coords.transpose();
        self.sum_norms2 += q.norm_squared() + m.coords.norm_squared();
        self.sum_d2 += d2;
    }
    fn merge(self, o: Self) -> Self {
        Self {
            n: self.n + o.n,
            sum_q: self.sum_q + o.sum_q,
            sum_m: self.sum_m + o.sum_m,
            sum_qm: self.sum_qm + o.sum_qm,
            sum_norms2: self.sum_norms2 + o.sum_norms2,
            sum_d2: self.sum_d2 + o.sum_d2,
        }
    }
}

/// Point-to-plane: the normal equations JᵀJ, Jᵀr with J = [nᵀ, (q × n)ᵀ], r = n·(q − m).
#[derive(Clone, Copy, Default)]
struct PlaneSums {
    n: usize,
    jtj: Matrix6<f64>,
    jtr: Vector6<f64>,
    sum_d2: f64,
}

impl PairSums for PlaneSums {
    #[inline]
    fn add(&mut self, q: &Vector3<f64>, m: &Point3<f64>, n: &Vector3<f64>, d2: f64) {
        // nᵀ[I | −[q]×] = [nᵀ, (q × n)ᵀ] (se3::point_jacobian_left projected on n).
        let qxn = q.cross(n);
        let j = Vector6::new(n.x, n.y, n.z, qxn.x, qxn.y, qxn.z);
        let r = n.dot(&(q - m.coords));
        self.n += 1;
        self.jtj += j * j.transpose();
        self.jtr += j * r;
        self.sum_d2 += d2;
    }
    fn merge(self, o: Self) -> Self {
        Self {
            n: self.n + o.n,
            jtj: self.jtj + o.jtj,
            jtr: self.jtr + o.jtr,
            sum_d2: self.sum_d2 + o.sum_d2,
        }
    }
}

/// Pairs every finite point (mapped by `t_o_w`) with its nearest model sample and sums the
/// inliers in parallel over chunks.
fn correspond<S: PairSums>(
    model: &IcpModel,
    points_w: &[Point3<f64>],
    t_o_w: &Isometry3<f64>,
    max_d2: f64,
) -> S {
    let r = t_o_w.rotation.to_rotation_matrix().into_inner();
    let t = t_o_w.translation.vector;
    points_w
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut sums = S::default();
            for p in chunk {
                if !p.coords.iter().all(|c| c.is_finite()) {
                    continue;
                }
                let q = r * p.coords + t;
                let (j, d2) = model.nearest(&q);
                if d2 <= max_d2 {
                    sums.add(&q, &model.points[j], &model.normals[j], d2);
                }
            }
            sums
        })
        .reduce(S::default, S::merge)
}

/// Singular values of the cross-covariance below this fraction of its scale count as zero.
const RANK_RELATIVE_TOLERANCE: f64 = 1e-9;

/// The rigid ΔT minimising Σ |ΔT·q − m|² over the pairs (Kabsch/Umeyama without scale), or
/// `None` when the matched points are (nearly) collinear.
fn kabsch_step(s: &PointSums) -> Option<Isometry3<f64>> {
    let n = s.n as f64;
    let q_bar = s.sum_q / n;
    let m_bar = s.sum_m / n;
    // Σ (q − q̄)(m − m̄)ᵀ = Σ q mᵀ − n q̄ m̄ᵀ; the points are object-frame (centimetres from the
    // origin), so the subtraction loses nothing that matters.
    let h = s.sum_qm - q_bar * m_bar.transpose() * n;
    if !h.iter().all(|c| c.is_finite()) {
        return None;
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let sv = svd.singular_values; // descending
    // Rank < 2 (collinear or coincident points): the rotation about their line is free. The
    // scale is that of the uncentred sums (Σ|q|² + Σ|m|²)/2 ≥ ‖Σ q mᵀ‖, so that rounding in
    // the centring subtraction never passes for spread.
    if sv[1] <= RANK_RELATIVE_TOLERANCE * 0.5 * s.sum_norms2 {
        return None;
    }
    let v = v_t.transpose();
    // R = V·diag(1, 1, sign det(V Uᵀ))·Uᵀ: the closest proper rotation (no reflection).
    let mut d = Matrix3::identity();
    if (v * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rot = Rotation3::from_matrix_unchecked(v * d * u.transpose());
    let t = m_bar - rot * q_bar;
    Some(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&rot),
    ))
}

/// Relative eigenvalue below which a (scaled) point-to-plane direction counts as unobservable.
const UNOBSERVABLE_RELATIVE_EIGENVALUE: f64 = 1e-9;

/// The Gauss–Newton step δ = −(JᵀJ)⁺ Jᵀr, minimum-norm over unobservable directions, and how
/// many directions were dropped. Rotation columns are scaled by the RMS lever arm so that the
/// eigenvalue test compares like with like (m vs rad·m).
fn plane_step(s: &PlaneSums, lever_m: f64) -> Option<(Vector6<f64>, usize)> {
    if !(s.jtj.iter().chain(s.jtr.iter()).all(|c| c.is_finite()) && lever_m > 0.0) {
        return None;
    }
    let scale = Vector6::new(1.0, 1.0, 1.0, lever_m, lever_m, lever_m);
    let d_inv = Matrix6::from_diagonal(&scale.map(|x| 1.0 / x));
    // In scaled coordinates y = D δ: (D⁻¹ JᵀJ D⁻¹) y = −D⁻¹ Jᵀr.
    let a = d_inv * s.jtj * d_inv;
    let b = -(d_inv * s.jtr);
    let eig = a.symmetric_eigen();
    let max = eig.eigenvalues.max();
    if max <= 0.0 {
        return None;
    }
    let mut y = Vector6::zeros();
    let mut dropped = 0;
    for k in 0..6 {
        let lambda = eig.eigenvalues[k];
        let e = eig.eigenvectors.column(k);
        if lambda > UNOBSERVABLE_RELATIVE_EIGENVALUE * max {
            y += e * (e.dot(&b) / lambda);
        } else {
            dropped += 1;
        }
    }
    Some((d_inv * y, dropped))
}

/// Refines `t_o_w` (object ← world) so that `points_w` (world frame, metres; from one or several
/// views, stacked) lie on the model. Non-finite points are skipped and counted.
pub fn refine_icp(
    model: &IcpModel,
    points_w: &[Point3<f64>],
    t_o_w_init: &Isometry3<f64>,
    config: &IcpConfig,
) -> Result<IcpResult, IcpError> {
    config.validate()?;
    if points_w.is_empty() {
        return Err(IcpError::NoPoints);
    }
    let finite = |p: &&Point3<f64>| p.coords.iter().all(|c| c.is_finite());
    let (finite_count, centroid_sum) = points_w
        .iter()
        .filter(finite)
        .fold((0usize, Vector3::zeros()), |(n, s), p| {
            (n + 1, s + p.coords)
        });
    if finite_count == 0 {
        return Err(IcpError::NoFinitePoints {
            count: points_w.len(),
        });
    }
    let pose_finite = |t: &Isometry3<f64>| {
        t.translation.vector.iter().all(|c| c.is_finite())
            && t.rotation.coords.iter().all(|c| c.is_finite())
    };
    if !pose_finite(t_o_w_init) {
        return Err(IcpError::NonFiniteInitialPose);
    }
    let centroid_w = Point3::from(centroid_sum / finite_count as f64);
    let centroid_o_init = t_o_w_init * centroid_w;
    let max_d2 = config.max_correspondence_distance_m.powi(2);
    let required = config.method.min_correspondences();
    let too_few = |iteration: usize, found: usize| IcpError::TooFewCorrespondences {
        iteration,
        found,
        required,
        max_distance_m: config.max_correspondence_distance_m,
        method: config.method,
    };

    let mut t_o_w = *t_o_w_init;
    let mut iterations = 0;
    let mut converged = false;
    let mut unobservable_dofs = 0;
    while iterations < config.max_iterations {
        let step = match config.method {
            IcpMethod::PointToPoint => {
                let sums: PointSums = correspond(model, points_w, &t_o_w, max_d2);
                if sums.n < required {
                    return Err(too_few(iterations, sums.n));
                }
                kabsch_step(&sums).ok_or(IcpError::Degenerate {
                    iteration: iterations,
                    found: sums.n,
                })?
            }
            IcpMethod::PointToPlane => {
                let sums: PlaneSums = correspond(model, points_w, &t_o_w, max_d2);
                if sums.n < required {
                    return Err(too_few(iterations, sums.n));
                }
                // trace of the rotation block of JᵀJ = Σ |q × n|²: its RMS is the lever arm.
                let rot_trace = (3..6).map(|k| sums.jtj[(k, k)]).sum::<f64>();
                // Zero when no pair constrains any rotation (a sphere about the origin): then
                // leave the scale at 1 m and let the eigenvalue test drop those directions.
                let lever_m = Some((rot_trace / sums.n as f64).sqrt())
                    .filter(|l| *l > 0.0)
                    .unwrap_or(1.0);
                let (delta, dropped) = plane_step(&sums, lever_m).ok_or(IcpError::Degenerate {
                    iteration: iterations,
                    found: sums.n,
                })?;
                unobservable_dofs = unobservable_dofs.max(dropped);
                se3::exp(&delta)
            }
        };
        t_o_w = step * t_o_w;
        iterations += 1;
        let displacement_m = if pose_finite(&t_o_w) {
            (t_o_w * centroid_w - centroid_o_init).norm()
        } else {
            f64::INFINITY
        };
        if displacement_m.is_nan() || displacement_m > config.max_displacement_m {
            return Err(IcpError::Diverged {
                iteration: iterations,
                displacement_m,
                max_displacement_m: config.max_displacement_m,
            });
        }
        if step.translation.vector.norm() < config.convergence_translation_m
            && step.rotation.angle() < config.convergence_rotation_rad
        {
            converged = true;
            break;
        }
    }

    // Report the inliers at the pose returned, not at the one before the last update.
    let last: PointSums = correspond(model, points_w, &t_o_w, max_d2);
    if last.n == 0 {
        return Err(too_few(iterations, 0));
    }
    Ok(IcpResult {
        t_o_w,
        iterations,
        converged,
        rms_m: (last.sum_d2 / last.n as f64).sqrt(),
        inliers: last.n,
        non_finite_skipped: points_w.len() - finite_count,
        unobservable_dofs,
    })
}

#[cfg(test)]
mod tests;
