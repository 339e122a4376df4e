//! `glint bench refine`: the SDF refiner against ICP (point-to-point, point-to-plane) on
//! benchmark problems with a known answer, timed at 1 thread and all cores; `--export` writes
//! each problem for `services/estimation/scripts/peer_icp_bench.py` (Open3D, small_gicp).
//!
//! A problem: a part at a seeded ground-truth pose `t_w_o_gt`, seen from V views on a cone
//! around the world's +z (25° off it, 0.5 m away). Each view keeps surface samples whose
//! normal faces the eye (cos > 0.2: grazing rays give an SLI camera no depth) and whose ray to
//! the eye leaves the SDF grid without entering the part (sphere tracing: self-occlusion), and
//! displaces them along the viewing ray by Gaussian depth noise σ_z. The initial pose is the
//! truth moved by a seeded translation and rotation of fixed magnitude in random directions.
//! The refiners never see the truth; it only scores their results.

use glint_eval::metrics::median;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glint_estimation::icp::{IcpConfig, IcpMethod, IcpModel, refine_icp};
use glint_estimation::points::DepthPoint;
use glint_estimation::refine::{SdfRefineConfig, refine_sdf};
use glint_geometry::parts::Part;
use glint_geometry::pose_deviation::{PoseDeviation, pose_deviation};
use glint_geometry::sampling::{SurfaceSample, surface_samples};
use glint_geometry::sdf::{SdfConfig, SdfGrid};
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// What `glint bench refine` was asked for.
#[derive(clap::Args)]
pub struct RefineBenchArgs {
    /// A part name or `all`.
    #[arg(long = "part", default_value = "all", value_parser = parse_parts)]
    pub parts: PartList,
    /// Data points per problem (comma-separated), split evenly over the views.
    #[arg(long, value_delimiter = ',', default_value = "2000,20000")]
    pub points: Vec<usize>,
    /// View counts (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "1,4")]
    pub views: Vec<usize>,
    /// Thread counts (comma-separated); `all` is every core.
    #[arg(long, value_delimiter = ',', default_value = "1,all", value_parser = parse_threads)]
    pub threads: Vec<usize>,
    /// Iteration budget of every method.
    #[arg(long, default_value_t = 30)]
    pub iterations: usize,
    /// Timed runs per row; the table gives the median.
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Surface samples of the ICP model (and of the exported model.ply).
    #[arg(long, default_value_t = 50_000)]
    pub model_samples: usize,
    /// Voxel size of the SDF grid, mm (the padding is 10 mm).
    #[arg(long, default_value_t = glint_estimation::refine::REFINE_SDF_VOXEL_MM)]
    pub sdf_voxel_mm: f64,
    /// Depth noise σ_z along the view ray, mm.
    #[arg(long, default_value_t = 0.3)]
    pub sigma_z_mm: f64,
    /// Translation of the initial pose from the truth, mm (random direction).
    #[arg(long, default_value_t = 3.0)]
    pub initial_mm: f64,
    /// Rotation of the initial pose from the truth, degrees (random axis).
    #[arg(long, default_value_t = 3.0)]
    pub initial_deg: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write the table as CSV here.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Write every problem (PLY point clouds, poses, Glint's results) under this directory.
    #[arg(long)]
    pub export: Option<PathBuf>,
}

/// Parts named on the command line.
#[derive(Clone, Debug)]
pub struct PartList(pub Vec<Part>);

fn parse_parts(s: &str) -> Result<PartList, String> {
    if s == "all" {
        Ok(PartList(Part::ALL.to_vec()))
    } else {
        crate::mesh_cmd::parse_part(s).map(|p| PartList(vec![p]))
    }
}

/// A thread count, `all` → 0 (every core).
fn parse_threads(s: &str) -> Result<usize, String> {
    match s {
        "all" => Ok(0),
        _ => match s.parse::<usize>() {
            Ok(n) if n >= 1 => Ok(n),
            _ => Err(format!(
                "`{s}` is not a thread count (a positive integer or `all`)"
            )),
        },
    }
}

/// Distance of the views' eyes from the object, metres.
const EYE_DISTANCE_M: f64 = 0.5;
/// Angle of the views' cone around +z.
const VIEW_CONE_DEG: f64 = 25.0;
/// A sample faces a view when cos(normal, to-eye) exceeds this.
const MIN_FACING_COS: f64 = 0.2;

/// A benchmark problem: identical inputs for every method.
struct Problem {
    part: Part,
    views: usize,
    points: Vec<DepthPoint>,
    t_o_w_gt: Isometry3<f64>,
    t_o_w_init: Isometry3<f64>,
}

/// One timed method on one problem at one thread count.
struct Row {
    part: Part,
    points: usize,
    views: usize,
    method: &'static str,
    threads: usize,
    iterations: usize,
    /// Residual evaluations (SDF: every point of every pass, coarse passes on their subset;
    /// ICP: points × (iterations + the final inlier pass)).
    point_evaluations: usize,
    time_s: f64,
    initial: PoseDeviation,
    error: PoseDeviation,
    status: String,
}

impl Row {
    /// points × iterations / time, the brief's rate.
    fn iteration_evals_per_s(&self) -> f64 {
        (self.points * self.iterations) as f64 / self.time_s
    }
    /// Every residual the method computed, per second.
    fn point_evals_per_s(&self) -> f64 {
        self.point_evaluations as f64 / self.time_s
    }
    /// The work in passes over all points (fractional when coarse passes ran on a subset).
    fn point_passes(&self) -> f64 {
        self.point_evaluations as f64 / self.points as f64
    }
}

pub fn run(args: &RefineBenchArgs) -> anyhow::Result<()> {
    anyhow::ensure!(!args.parts.0.is_empty(), "--part: no part given");
    anyhow::ensure!(
        args.points.iter().all(|&n| n >= 12),
        "--points: every count must be at least 12 (two per pose degree of freedom)"
    );
    anyhow::ensure!(
        !args.views.is_empty() && args.views.iter().all(|&v| (1..=16).contains(&v)),
        "--views: every count must be within 1..=16"
    );
    anyhow::ensure!(!args.threads.is_empty(), "--threads: no thread count given");
    anyhow::ensure!(args.iterations >= 1, "--iterations must be at least 1");
    anyhow::ensure!(args.repeats >= 1, "--repeats must be at least 1");
    anyhow::ensure!(
        args.model_samples >= 100,
        "--model-samples must be at least 100"
    );
    anyhow::ensure!(
        args.sigma_z_mm.is_finite() && args.sigma_z_mm > 0.0,
        "--sigma-z-mm must be finite and positive"
    );
    anyhow::ensure!(
        args.initial_mm.is_finite()
            && args.initial_mm >= 0.0
            && args.initial_deg.is_finite()
            && args.initial_deg >= 0.0,
        "--initial-mm and --initial-deg must be finite and non-negative"
    );
    let all_cores = rayon::current_num_threads();
    let mut pools = Vec::new();
    for &t in &args.threads {
        let n = if t == 0 { all_cores } else { t };
        pools.push((n, rayon::ThreadPoolBuilder::new().num_threads(n).build()?));
    }
    let sdf_config = SdfRefineConfig {
        max_iterations: args.iterations,
        ..SdfRefineConfig::default()
    };
    let icp_configs = [IcpMethod::PointToPoint, IcpMethod::PointToPlane].map(|method| IcpConfig {
        max_iterations: args.iterations,
        ..IcpConfig::with_method(method)
    });
    let problems = args.parts.0.len() * args.points.len() * args.views.len();
    let bar = glint_eval::progress::bar(problems as u64, "bench refine");
    let mut rows = Vec::new();
    for (part_index, &part) in args.parts.0.iter().enumerate() {
        bar.set_message(part.name());
        let mesh = part.mesh();
        let grid_config = SdfConfig {
            voxel_size_m: args.sdf_voxel_mm * 1e-3,
            ..SdfConfig::default()
        };
        let sdf = SdfGrid::build(&mesh, &grid_config)
            .with_context(|| format!("--sdf-voxel-mm: building the SDF of {part}"))?;
        let model_samples = surface_samples(&mesh, args.model_samples, args.seed ^ 0x5eed);
        let icp_model = IcpModel::new(&model_samples)
            .with_context(|| format!("building the ICP model of {part}"))?;
        for &n_points in &args.points {
            for &views in &args.views {
                let seed = args
                    .seed
                    .wrapping_mul(1_000_003)
                    .wrapping_add((part_index * 1_000_000 + n_points * 17 + views) as u64);
                let problem = make_problem(part, &mesh, &sdf, n_points, views, args, seed)?;
                let points_w: Vec<Point3<f64>> = problem.points.iter().map(|p| p.p_w).collect();
                let score = |t_o_w: &Isometry3<f64>| {
                    pose_deviation(
                        &t_o_w.inverse(),
                        &problem.t_o_w_gt.inverse(),
                        &part.symmetry(),
                    )
                };
                let initial = score(&problem.t_o_w_init);
                let first_row = rows.len();
                for (threads, pool) in &pools {
                    let mut row =
                        |method: &'static str,
                         f: &(
                              dyn Fn() -> anyhow::Result<(Isometry3<f64>, usize, usize, String)>
                                  + Sync
                          )|
                         -> anyhow::Result<()> {
                            let (times, result) = pool.install(|| time_runs(args.repeats, f))?;
                            let (t_o_w, iterations, point_evaluations, status) = result;
                            rows.push(Row {
                                part,
                                points: problem.points.len(),
                                views,
                                method,
                                threads: *threads,
                                iterations,
                                point_evaluations,
                                time_s: median(times),
                                initial,
                                error: score(&t_o_w),
                                status,
                            });
                            Ok(())
                        };
                    row("sdf", &|| {
                        let r = refine_sdf(&sdf, &problem.points, &problem.t_o_w_init, &sdf_config)
                            .with_context(|| format!("SDF refinement of {part}"))?;
                        Ok((
                            r.t_o_w,
                            r.iterations,
                            r.point_evaluations,
                            format!("{:?}", r.status).to_lowercase(),
                        ))
                    })?;
                    for config in &icp_configs {
                        row(config.method.name(), &|| {
                            let r = refine_icp(&icp_model, &points_w, &problem.t_o_w_init, config)
                                .with_context(|| format!("ICP of {part}"))?;
                            let status = if r.converged {
                                "converged"
                            } else {
                                "max_iterations"
                            };
                            let evaluations = points_w.len() * (r.iterations + 1);
                            Ok((r.t_o_w, r.iterations, evaluations, status.to_owned()))
                        })?;
                    }
                }
                if let Some(dir) = &args.export {
                    export_problem(
                        dir,
                        &problem,
                        &model_samples,
                        &rows[first_row..],
                        args,
                        &icp_configs[0],
                    )?;
                }
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    print_table(&rows, args, all_cores);
    if let Some(path) = &args.csv {
        write_csv(path, &rows, args.repeats)?;
        println!("\nwrote {}", path.display());
    }
    if let Some(dir) = &args.export {
        println!(
            "exported {problems} problems to {}; next: python3 services/estimation/scripts/peer_icp_bench.py {}",
            dir.display(),
            dir.display()
        );
    }
    Ok(())
}

/// Runs `f` `repeats` times; the wall times and the first run's result (runs are deterministic).
fn time_runs<T>(
    repeats: usize,
    f: &(dyn Fn() -> anyhow::Result<T> + Sync),
) -> anyhow::Result<(Vec<f64>, T)> {
    let mut times = Vec::with_capacity(repeats);
    let mut first = None;
    for _ in 0..repeats {
        let start = Instant::now();
        let result = f()?;
        times.push(start.elapsed().as_secs_f64());
        first.get_or_insert(result);
    }
    Ok((times, first.expect("repeats ≥ 1")))
}

/// A uniformly random rotation (normalised Gaussian quaternion).
fn random_rotation(rng: &mut impl Rng) -> UnitQuaternion<f64> {
    let q = nalgebra::Quaternion::new(
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
    );
    UnitQuaternion::from_quaternion(q)
}

fn random_direction(rng: &mut impl Rng) -> Unit<Vector3<f64>> {
    loop {
        let v = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
        if let Some(u) = Unit::try_new(v, 1e-9) {
            return u;
        }
    }
}

/// Whether the ray from `p_o` (on the surface) towards `eye_o` leaves the SDF grid without
/// touching the part (object frame): sphere tracing from 1 mm off the surface.
fn unoccluded(sdf: &SdfGrid, p_o: &Point3<f64>, eye_o: &Point3<f64>) -> bool {
    let to_eye = eye_o - p_o;
    let (d, length) = (to_eye.normalize(), to_eye.norm());
    let mut t = 1e-3;
    while t < length {
        let s = sdf.sample(&(p_o + d * t));
        if !s.inside_grid {
            return true;
        }
        if s.distance_m < 5e-5 {
            return false;
        }
        t += s.distance_m.max(2e-4);
    }
    true
}

fn make_problem(
    part: Part,
    mesh: &glint_geometry::TriMesh,
    sdf: &SdfGrid,
    n_points: usize,
    views: usize,
    args: &RefineBenchArgs,
    seed: u64,
) -> anyhow::Result<Problem> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let t_w_o_gt = Isometry3::from_parts(
        Translation3::new(0.02, -0.01, 0.05),
        random_rotation(&mut rng),
    );
    let (lo, hi) = mesh
        .aabb()
        .with_context(|| format!("{part}: the mesh has no vertices"))?;
    let centre_w = t_w_o_gt * nalgebra::center(&lo.cast::<f64>(), &hi.cast::<f64>());
    let sigma_z_m = args.sigma_z_mm * 1e-3;
    let azimuth0 = rng.random::<f64>() * std::f64::consts::TAU;
    let cone = VIEW_CONE_DEG.to_radians();
    let mut points = Vec::with_capacity(n_points);
    for view in 0..views {
        let want = n_points / views + usize::from(view < n_points % views);
        let azimuth = azimuth0 + std::f64::consts::TAU * view as f64 / views as f64;
        let dir = Vector3::new(
            cone.sin() * azimuth.cos(),
            cone.sin() * azimuth.sin(),
            cone.cos(),
        );
        let eye_w = centre_w + dir * EYE_DISTANCE_M;
        let eye_o = t_w_o_gt.inverse() * eye_w;
        let axis_w = -dir; // the optical axis looks at the object
        let mut kept = 0;
        for batch in 0..64u64 {
            let batch_seed = seed ^ ((view as u64 + 1) << 32) ^ (batch << 48);
            for s in surface_samples(mesh, (2 * want).max(256), batch_seed) {
                if kept == want {
                    break;
                }
                let facing = s.normal.dot(&(eye_o - s.point).normalize()) > MIN_FACING_COS;
                if !facing || !unoccluded(sdf, &s.point, &eye_o) {
                    continue;
                }
                let p_w = t_w_o_gt * s.point;
                let ray_w = (p_w - eye_w).normalize();
                // p = eye + z·ray/(ray·axis): ∂p/∂z along the ray, z the depth along the axis.
                let dp_dz_w = ray_w / ray_w.dot(&axis_w);
                let dz = rng.sample::<f64, _>(StandardNormal) * sigma_z_m;
                points.push(DepthPoint {
                    p_w: p_w + dp_dz_w * dz,
                    dp_dz_w,
                    sigma_z_m,
                });
                kept += 1;
            }
            if kept == want {
                break;
            }
        }
        anyhow::ensure!(
            kept == want,
            "{part}: view {view} sees only {kept} of the {want} points asked for"
        );
    }
    let t_w_o_init =
        Translation3::from(random_direction(&mut rng).into_inner() * args.initial_mm * 1e-3)
            * t_w_o_gt
            * UnitQuaternion::from_axis_angle(
                &random_direction(&mut rng),
                args.initial_deg.to_radians(),
            );
    Ok(Problem {
        part,
        views,
        points,
        t_o_w_gt: t_w_o_gt.inverse(),
        t_o_w_init: t_w_o_init.inverse(),
    })
}

fn print_table(rows: &[Row], args: &RefineBenchArgs, all_cores: usize) {
    println!(
        "Refinement: SDF (LM, Huber, graduated gates) vs ICP on identical noisy points (σ_z = {} mm \
         along the view ray, front-facing unoccluded surface), initial pose {} mm / {}° off, \
         budget {} iterations, ICP max correspondence {} mm; median of {} runs; all cores = {all_cores} threads\n",
        args.sigma_z_mm,
        args.initial_mm,
        args.initial_deg,
        args.iterations,
        IcpConfig::default().max_correspondence_distance_m * 1e3,
        args.repeats
    );
    println!(
        "| part | points | views | method | threads | iterations | point passes | time (ms) | points×iterations /s | point evaluations /s | initial error (mm / °) | final error (mm / °) | status |"
    );
    println!("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for r in rows {
        println!(
            "| {} | {} | {} | {} | {} | {} | {:.1} | {:.3} | {:.1} M | {:.1} M | {:.2} / {:.2} | {:.3} / {:.3} | {} |",
            r.part,
            r.points,
            r.views,
            r.method,
            r.threads,
            r.iterations,
            r.point_passes(),
            r.time_s * 1e3,
            r.iteration_evals_per_s() / 1e6,
            r.point_evals_per_s() / 1e6,
            r.initial.translation_mm(),
            r.initial.rotation_deg(),
            r.error.translation_mm(),
            r.error.rotation_deg(),
            r.status
        );
    }
}

/// The CSV header of `--csv`.
pub const CSV_HEADER: &str = "part,points,views,method,threads,iterations,point_passes,time_ms_median,repeats,iteration_evals_per_s,point_evals_per_s,initial_t_mm,initial_r_deg,t_err_mm,r_err_deg,status";

fn write_csv(path: &Path, rows: &[Row], repeats: usize) -> anyhow::Result<()> {
    let mut text = format!("{CSV_HEADER}\n");
    for r in rows {
        text += &format!(
            "{},{},{},{},{},{},{:.2},{:.6},{repeats},{:.0},{:.0},{:.6},{:.6},{:.6},{:.6},{}\n",
            r.part.name(),
            r.points,
            r.views,
            r.method,
            r.threads,
            r.iterations,
            r.point_passes(),
            r.time_s * 1e3,
            r.iteration_evals_per_s(),
            r.point_evals_per_s(),
            r.initial.translation_mm(),
            r.initial.rotation_deg(),
            r.error.translation_mm(),
            r.error.rotation_deg(),
            r.status
        );
    }
    glint_geometry::io::write_file_atomically(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// A matrix's entries, row-major (nalgebra stores column-major).
fn row_major<const R: usize, const C: usize>(m: &nalgebra::SMatrix<f64, R, C>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

/// Writes `DIR/<part>_p<points>_v<views>/`: `model.ply` (the ICP model's samples with normals,
/// object frame, metres), `points.ply` (the data, world frame, metres), `problem.json` (initial
/// and true `t_o_w` as row-major 4×4, the budget, the symmetry for scoring) and `glint.json`
/// (Glint's rows).
fn export_problem(
    dir: &Path,
    problem: &Problem,
    model: &[SurfaceSample],
    rows: &[Row],
    args: &RefineBenchArgs,
    icp: &IcpConfig,
) -> anyhow::Result<()> {
    let sub = dir.join(format!(
        "{}_p{}_v{}",
        problem.part.name(),
        problem.points.len(),
        problem.views
    ));
    std::fs::create_dir_all(&sub).with_context(|| format!("creating {}", sub.display()))?;
    let model_points: Vec<Point3<f64>> = model.iter().map(|s| s.point).collect();
    let model_normals: Vec<Vector3<f64>> = model.iter().map(|s| s.normal).collect();
    glint_geometry::io::write_ply_points(
        &sub.join("model.ply"),
        &model_points,
        Some(&model_normals),
    )?;
    let data: Vec<Point3<f64>> = problem.points.iter().map(|p| p.p_w).collect();
    glint_geometry::io::write_ply_points(&sub.join("points.ply"), &data, None)?;
    let symmetry = problem.part.symmetry();
    let discrete: Vec<Vec<f64>> = symmetry
        .discrete_rotations()
        .iter()
        .map(|q| row_major(q.to_rotation_matrix().matrix()))
        .collect();
    let problem_json = serde_json::json!({
        "part": problem.part.name(),
        "points": problem.points.len(),
        "views": problem.views,
        "frames": "t_o_w maps world (points.ply) to object (model.ply); 4x4 row-major; metres",
        "t_o_w_init": row_major(&problem.t_o_w_init.to_homogeneous()),
        "t_o_w_gt": row_major(&problem.t_o_w_gt.to_homogeneous()),
        "iterations": args.iterations,
        "max_correspondence_distance_m": icp.max_correspondence_distance_m,
        "sigma_z_m": args.sigma_z_mm * 1e-3,
        "seed": args.seed,
        "symmetry": {
            "discrete_rotations_row_major": discrete,
            "continuous_axis": symmetry.continuous_axis().map(|a| [a.x, a.y, a.z]),
        },
    });
    let glint_json = serde_json::json!({
        "repeats": args.repeats,
        "runs": rows.iter().map(|r| serde_json::json!({
            "method": r.method,
            "threads": r.threads,
            "iterations": r.iterations,
            "point_passes": r.point_passes(),
            "time_s_median": r.time_s,
            "t_err_mm": r.error.translation_mm(),
            "r_err_deg": r.error.rotation_deg(),
            "initial_t_mm": r.initial.translation_mm(),
            "initial_r_deg": r.initial.rotation_deg(),
            "status": r.status,
        })).collect::<Vec<_>>(),
    });
    for (name, value) in [("problem.json", problem_json), ("glint.json", glint_json)] {
        let path = sub.join(name);
        glint_geometry::io::write_file_atomically(
            &path,
            serde_json::to_string_pretty(&value)?.as_bytes(),
        )
        .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
