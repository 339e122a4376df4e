//! The paper's Table I on mock-camera data (`glint eval refine`): SDF refinement (ours)
//! against ICP (point-to-point, the paper's baseline, and point-to-plane) from the same initial
//! poses and the same depth points; rates are counted over GT instances at least 80 % visible
//! in the reference view, with paired McNemar tests and the share of trials each refiner leaves
//! further from the truth than it started. Evaluation only: reads ground
//! truth to draw initial poses and to score.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use glint_estimation::correlated_error::{
    CorrelatedDepthError, CorrelatedErrorFit, KnownPoseView, fit_correlated_error,
    information_with_correlated_error,
};
use glint_estimation::depth_alignment::{DepthAlignmentConfig, align_depth};
use glint_estimation::icp::{IcpConfig, IcpMethod, IcpModel, refine_icp};
use glint_estimation::points::DepthPoint;
use glint_estimation::pose_error_model::PoseErrorModel;
use glint_estimation::refine::{
    REFINE_SDF_PADDING_MM, SdfRefineConfig, refine_grid_config, refine_sdf,
};
use glint_estimation::view_bias::{
    SingleViewError, ViewBiasFit, ViewInformation, ViewPoseBias, measure_view_bias,
};
use glint_geometry::io::write_file_atomically;
use glint_geometry::pose_deviation::{CorrectThreshold, PoseDeviation, pose_deviation};
use glint_geometry::sdf::{SdfConfig, SdfGrid};
use glint_geometry::{LengthUnit, Part, Symmetry};
use nalgebra::{Isometry3, Matrix6, Point3};
use rand::SeedableRng;
use rand::seq::IndexedRandom;

use crate::initial_pose::InitialPoseNoise;
use crate::metrics::{chi2_mean_band, mcnemar_exact_p, mean, median, nees, symmetric_error};
use crate::scenes::{
    EvalObject, LoadedScene, OBJ_ID, SceneSpec, ensure_scene, eval_objects, load_scene,
};

/// The settings of one Table I run (`glint eval refine`'s flags).
#[derive(Clone, Debug)]
pub struct RefineExperiment {
    /// Parts to run, or (with `mesh`) ignored.
    pub parts: Vec<Part>,
    /// Run on this mesh (PLY/OBJ/STL, in `unit`) with `symmetry` instead of the parts.
    pub mesh: Option<PathBuf>,
    /// Length unit of `mesh`'s file.
    pub unit: LengthUnit,
    /// Symmetry of `mesh`, used to score pose errors.
    pub symmetry: Symmetry,
    /// Bins (scenes) per part.
    pub scenes: u32,
    /// Views captured per scene (over a spherical cap above the bin).
    pub views_per_scene: u32,
    /// View counts of the experiment; each at most `views_per_scene`.
    pub views: Vec<u32>,
    /// Parts per bin.
    pub instances: u32,
    /// Base seed: evaluation scenes use `seed·10⁴ + s`, tuning scenes `seed·10⁴ + 5000 + s`;
    /// it also seeds the initial poses, the views drawn per trial and ICP's model sampling.
    pub seed: u64,
    /// Camera resolution, px.
    pub resolution: (u32, u32),
    /// Samples per pixel of the multi-path renders.
    pub spp: u32,
    /// ICP's max correspondence distances to choose from, mm, on separate tuning scenes.
    pub icp_distances_mm: Vec<f64>,
    /// The SDF refiner's first gates to choose from, mm, on the same tuning scenes (each at
    /// most the grid's padding, [`glint_estimation::refine::REFINE_SDF_PADDING_MM`]).
    pub sdf_gates_mm: Vec<f64>,
    /// Tuning scenes per part for ICP's distance (seeds disjoint from the evaluation's).
    pub tune_scenes: u32,
    /// Tuning scenes per part the per-view pose bias is measured on (the first
    /// `tune_scenes` of them are the refiners' tuning scenes; all disjoint from the evaluation's).
    pub view_bias_scenes: u32,
    /// Control: paint the parts with the matte diffuse twin (scenes cached separately).
    pub matte: bool,
    /// Every refiner starts from the initial pose moved along the viewing rays onto the depth
    /// ([`align_depth`]), as the sessions do; off: from the initial pose itself.
    pub align_depth: bool,
    /// Patterns the mock camera projects per view (space-time matching over all of them).
    pub shots: u32,
    /// The mock camera's matching window radius, px.
    pub window_radius_px: u32,
    /// Mask erosion before refinement, px (default: the window radius).
    pub erode_px: Option<u32>,
    /// Voxel size of the SDF grid, mm.
    pub sdf_voxel_mm: f64,
    /// Output directory (scenes are cached in `out/scenes` and reused when rerun).
    pub out: PathBuf,
}

/// A pose estimator compared in the experiment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RefineMethod {
    /// The initial pose itself (the detector's row of Table I).
    Initial,
    /// The initial pose moved onto the depth along the viewing rays ([`align_depth`]): where
    /// every refiner starts (the initial pose itself when the alignment is off).
    Aligned,
    /// Uncertainty-weighted SDF refinement (ours, eq 8–11).
    Sdf,
    /// The ICP baseline, point-to-point (the paper's).
    Icp,
    /// ICP, point-to-plane.
    IcpPlane,
}

impl RefineMethod {
    /// Every method, in the order of Table I's rows.
    pub const ALL: [Self; 5] = [
        Self::Initial,
        Self::Aligned,
        Self::Sdf,
        Self::Icp,
        Self::IcpPlane,
    ];
    /// The refiners (every method but the initial pose).
    pub const REFINERS: [Self; 3] = [Self::Sdf, Self::Icp, Self::IcpPlane];

    /// The name in the output files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Initial => "initial",
            Self::Aligned => "aligned",
            Self::Sdf => "sdf",
            Self::Icp => "icp",
            Self::IcpPlane => "icp_plane",
        }
    }

    /// The label in Table I's rows.
    pub fn label(self) -> &'static str {
        match self {
            Self::Initial => "initial pose",
            Self::Aligned => "aligned start",
            Self::Sdf => "SDF (ours)",
            Self::Icp => "ICP",
            Self::IcpPlane => "ICP point-to-plane",
        }
    }

    /// The ICP variant of this method, if it is one.
    fn icp_method(self) -> Option<IcpMethod> {
        match self {
            Self::Icp => Some(IcpMethod::PointToPoint),
            Self::IcpPlane => Some(IcpMethod::PointToPlane),
            Self::Initial | Self::Aligned | Self::Sdf => None,
        }
    }
}

/// A pose's distance from the truth on the 5 mm/5° scale, `t / 5 mm + θ / 5°`: "further from
/// the truth than it started" compares this before and after refinement.
fn scaled_error(d: &PoseDeviation) -> f64 {
    d.translation_mm() / 5.0 + d.rotation_deg() / 5.0
}

/// One refinement problem: an instance, a reference view, and the views whose points it gets.
#[derive(Clone, Debug)]
pub struct Trial {
    object: String,
    scene_seed: u64,
    views: Vec<u32>,
    /// Index of the reference view (the first of `views`) in the scene.
    reference: usize,
    instance: usize,
    t_c_o_gt: Isometry3<f64>,
    t_c_o_init: Isometry3<f64>,
}

/// One method's result on one trial: its pose, its error against the truth, its cost.
#[derive(Clone, Debug)]
pub struct Outcome {
    method: RefineMethod,
    t_c_o: Isometry3<f64>,
    /// Against the truth, symmetry-aware.
    deviation: PoseDeviation,
    iterations: usize,
    time_ms: f64,
    status: String,
    /// NEES under eq 18's independent pixels, under the measured correlated depth error and
    /// under that plus the measured per-view pose bias; with its degrees of freedom.
    nees: Option<Nees>,
    /// The SDF result's information per view (correlated depth error) with each view's
    /// camera at the refined pose; empty for the other methods.
    views_information: Vec<ViewInformation>,
    /// The SDF refiner's own verdict that it made its start worse ([`glint_estimation::refine::RefineResult::cost_rose`]); false for the others.
    cost_rose: bool,
}

/// One SDF result's NEES (symmetry-aware) under two covariances.
#[derive(Clone, Copy, Debug)]
struct Nees {
    /// Against eq 18's information (independent pixels).
    independent: f64,
    /// Against [`information_with_correlated_error`]'s, with the model measured on the tuning
    /// scenes.
    correlated: f64,
    /// Against the correlated information with the part's per-view pose bias
    /// ([`ViewPoseBias::information`]), measured on the tuning scenes' single views.
    view_bias: f64,
    dof: usize,
}

/// Every trial of a scene: each instance ≥ 80 % visible in a reference view, with that view
/// plus k − 1 others drawn at random, for each k; the initial pose is drawn once per
/// (reference view, instance) so every k starts from the same pose.
fn trials_of_scene(
    object: &EvalObject,
    scene_seed: u64,
    scene: &LoadedScene,
    view_counts: &[u32],
    noise: &InitialPoseNoise,
    seed: u64,
) -> Vec<Trial> {
    let mut out = Vec::new();
    for (r, view) in scene.views.iter().enumerate() {
        for obj in view.objects.iter().filter(|o| o.visib_fract >= 0.8) {
            let mut rng = rand_pcg::Pcg64::seed_from_u64(
                seed ^ scene_seed.wrapping_mul(0x9E37_79B9)
                    ^ ((r as u64) << 32)
                    ^ (obj.instance as u64) << 48,
            );
            let t_c_o_init = noise.draw(&obj.t_c_o_gt, &object.symmetry, &mut rng);
            let others: Vec<usize> = (0..scene.views.len()).filter(|&v| v != r).collect();
            for &k in view_counts {
                let mut chosen = vec![r];
                chosen.extend(others.choose_multiple(&mut rng, k as usize - 1).copied());
                out.push(Trial {
                    object: object.name.clone(),
                    scene_seed,
                    views: chosen.iter().map(|&v| scene.views[v].im_id).collect(),
                    reference: r,
                    instance: obj.instance,
                    t_c_o_gt: obj.t_c_o_gt,
                    t_c_o_init,
                });
            }
        }
    }
    out
}

/// The trial's instance's points, one slice per view (a shared depth bias stays within a view),
/// each with its view's camera `t_w_c`.
fn trial_view_points<'a>(
    trial: &Trial,
    scene: &'a LoadedScene,
) -> Vec<(&'a [DepthPoint], Isometry3<f64>)> {
    scene
        .views
        .iter()
        .filter(|v| trial.views.contains(&v.im_id))
        .flat_map(|v| {
            v.objects
                .iter()
                .filter(|o| o.instance == trial.instance)
                .map(|o| (o.points.as_slice(), v.t_w_c))
        })
        .collect()
}

/// The settings of every refiner in a trial; each method reads only its own.
#[derive(Clone, Copy, Debug)]
struct RefinerSettings {
    sdf: SdfRefineConfig,
    icp: IcpConfigs,
    /// The correlated depth error the SDF result's NEES is also measured under.
    depth_error: CorrelatedDepthError,
    /// Every refiner starts from the initial pose aligned onto the depth.
    align_depth: bool,
}

impl RefinerSettings {
    /// The defaults with the SDF refiner's first gate at `gate_mm` and both ICP variants'
    /// correspondence distance at `distance_mm`; independent depth errors (the tuning passes).
    fn tuning(gate_mm: f64, distance_mm: f64, align_depth: bool) -> Self {
        Self {
            sdf: SdfRefineConfig {
                gate_m: gate_mm * 1e-3,
                ..SdfRefineConfig::default()
            },
            icp: IcpConfigs::at(distance_mm * 1e-3),
            depth_error: CorrelatedDepthError::INDEPENDENT,
            align_depth,
        }
    }
}

/// What the tuning scenes chose and measured.
struct Tunings {
    /// Each ICP variant's correspondence distance (point-to-point, point-to-plane).
    icp: Vec<SettingTuning>,
    /// The SDF refiner's first gate.
    sdf: SettingTuning,
    /// The correlated depth error.
    depth_error: CorrelatedErrorFit,
    /// Each part's per-view pose bias (`None`: no single-view refinement was correct).
    view_bias: Vec<Option<ViewBiasFit>>,
}

struct Refiners {
    sdf: SdfGrid,
    icp_model: IcpModel,
    /// The part's per-view pose bias, measured on the tuning scenes (none until then).
    view_bias: ViewPoseBias,
}

/// The ICP settings of each variant: point-to-point, point-to-plane.
#[derive(Clone, Copy, Debug)]
struct IcpConfigs {
    point_to_point: IcpConfig,
    point_to_plane: IcpConfig,
}

impl IcpConfigs {
    /// Both variants at one max correspondence distance (metres).
    fn at(distance_m: f64) -> Self {
        let with = |method| IcpConfig {
            max_correspondence_distance_m: distance_m,
            ..IcpConfig::with_method(method)
        };
        Self {
            point_to_point: with(IcpMethod::PointToPoint),
            point_to_plane: with(IcpMethod::PointToPlane),
        }
    }

    fn of(&self, method: IcpMethod) -> &IcpConfig {
        match method {
            IcpMethod::PointToPoint => &self.point_to_point,
            IcpMethod::PointToPlane => &self.point_to_plane,
        }
    }
}

fn run_trial(
    trial: &Trial,
    scene: &LoadedScene,
    refiners: &Refiners,
    settings: &RefinerSettings,
    symmetry: &Symmetry,
    methods: &[RefineMethod],
) -> Vec<Outcome> {
    let t_w_c = scene.views[trial.reference].t_w_c;
    let t_c_w = t_w_c.inverse();
    let t_o_w_detector = (t_w_c * trial.t_c_o_init).inverse();
    let t_o_w_gt = (t_w_c * trial.t_c_o_gt).inverse();
    let view_points = trial_view_points(trial, scene);
    // Stacked over the views (eq 7, 19).
    let points: Vec<DepthPoint> = view_points
        .iter()
        .flat_map(|(v, _)| v.iter().copied())
        .collect();
    // Every refiner's start: the detector's pose moved along its own camera's rays onto that
    // view's depth (the other views' rays would spread the search across the detector's
    // accurate axes).
    let reference_points = scene.views[trial.reference]
        .objects
        .iter()
        .find(|o| o.instance == trial.instance)
        .map_or(&[][..], |o| o.points.as_slice());
    let t_o_w_init = if settings.align_depth {
        align_depth(
            &refiners.sdf,
            reference_points,
            &t_o_w_detector,
            &DepthAlignmentConfig::default(),
        )
        .map_or(t_o_w_detector, |a| a.t_o_w)
    } else {
        t_o_w_detector
    };
    let outcome = |method, t_o_w: Isometry3<f64>, iterations, time_ms, status: String, n| {
        let t_c_o = t_c_w * t_o_w.inverse();
        let e = pose_deviation(&t_c_o, &trial.t_c_o_gt, symmetry);
        Outcome {
            method,
            t_c_o,
            deviation: e,
            iterations,
            time_ms,
            status,
            nees: n,
            views_information: Vec::new(),
            cost_rose: false,
        }
    };
    methods
        .iter()
        .map(|&method| match method {
            RefineMethod::Initial => {
                outcome(method, t_o_w_detector, 0, 0.0, "initial".into(), None)
            }
            RefineMethod::Aligned => outcome(method, t_o_w_init, 0, 0.0, "aligned".into(), None),
            RefineMethod::Sdf => {
                let start = Instant::now();
                let result = refine_sdf(&refiners.sdf, &points, &t_o_w_init, &settings.sdf);
                let ms = start.elapsed().as_secs_f64() * 1e3;
                match result {
                    Ok(r) => {
                        let (independent, dof) =
                            nees(&r.t_o_w, &t_o_w_gt, &r.information, symmetry);
                        let views_information: Vec<ViewInformation> = view_points
                            .iter()
                            .map(|(points, t_w_c)| ViewInformation {
                                information: information_with_correlated_error(
                                    &refiners.sdf,
                                    &[points],
                                    &r.t_o_w,
                                    &settings.sdf,
                                    &settings.depth_error,
                                ),
                                r_o_c: (r.t_o_w * t_w_c).rotation.to_rotation_matrix(),
                            })
                            .collect();
                        let correlated: Matrix6<f64> =
                            views_information.iter().map(|v| v.information).sum();
                        let biased = refiners.view_bias.information(&views_information);
                        let n = Nees {
                            independent,
                            correlated: nees(&r.t_o_w, &t_o_w_gt, &correlated, symmetry).0,
                            view_bias: nees(&r.t_o_w, &t_o_w_gt, &biased, symmetry).0,
                            dof,
                        };
                        let status = format!("{:?}", r.status).to_lowercase();
                        let mut o = outcome(method, r.t_o_w, r.iterations, ms, status, Some(n));
                        o.cost_rose = r.cost_rose();
                        o.views_information = views_information;
                        o
                    }
                    // A failed refinement keeps the initial pose, flagged.
                    Err(e) => outcome(method, t_o_w_init, 0, ms, format!("error: {e}"), None),
                }
            }
            RefineMethod::Icp | RefineMethod::IcpPlane => {
                let p_w: Vec<Point3<f64>> = points.iter().map(|p| p.p_w).collect();
                let config = method
                    .icp_method()
                    .map_or(&settings.icp.point_to_point, |m| settings.icp.of(m));
                let start = Instant::now();
                let result = refine_icp(&refiners.icp_model, &p_w, &t_o_w_init, config);
                let ms = start.elapsed().as_secs_f64() * 1e3;
                match result {
                    Ok(r) => {
                        let status = if r.converged {
                            "converged"
                        } else {
                            "max_iterations"
                        };
                        outcome(method, r.t_o_w, r.iterations, ms, status.into(), None)
                    }
                    Err(e) => outcome(method, t_o_w_init, 0, ms, format!("error: {e}"), None),
                }
            }
        })
        .collect()
}

/// Rates at (5 mm, 5°) and (2 mm, 2°).
fn rates(outcomes: &[&Outcome]) -> (f64, f64) {
    let n = outcomes.len().max(1) as f64;
    let hit = |threshold: &CorrectThreshold| {
        outcomes
            .iter()
            .filter(|o| o.deviation.is_correct(threshold))
            .count() as f64
            / n
    };
    (
        hit(&CorrectThreshold::MM5_DEG5),
        hit(&CorrectThreshold::MM2_DEG2),
    )
}

/// Runs the experiment and writes `results.csv`, `trials.csv`, `paired.csv`, `worse.csv`,
/// `notice.csv`, `nees.csv`, `table.md` and each part's error model `pose_error/<part>.json`
/// to `args.out`; returns the table.
pub fn run(args: &RefineExperiment) -> anyhow::Result<String> {
    if args.views.is_empty()
        || args
            .views
            .iter()
            .any(|&k| k == 0 || k > args.views_per_scene)
    {
        anyhow::bail!(
            "--views {:?}: each view count must be from 1 to --views-per-scene ({})",
            args.views,
            args.views_per_scene
        );
    }
    if args.icp_distances_mm.is_empty()
        || args
            .icp_distances_mm
            .iter()
            .any(|d| !(d.is_finite() && *d > 0.0))
    {
        anyhow::bail!("--icp-distances-mm: give positive distances, e.g. 2,5,10,20");
    }
    if args.sdf_gates_mm.is_empty()
        || args
            .sdf_gates_mm
            .iter()
            .any(|g| !(g.is_finite() && *g > 0.0 && *g <= REFINE_SDF_PADDING_MM))
    {
        anyhow::bail!(
            "--sdf-gates-mm: give gates above 0 and at most the SDF grid's padding, {REFINE_SDF_PADDING_MM} mm, e.g. 10,20,30"
        );
    }
    let objects = eval_objects(
        &args.parts,
        args.mesh.as_deref(),
        args.unit,
        &args.symmetry,
        args.matte,
    )?;
    let window_radius_px = args.window_radius_px;
    let mut spec = SceneSpec {
        matcher: String::new(),
        window_radius_px,
        shots: args.shots,
        instances: args.instances,
        views: args.views_per_scene,
        width_px: args.resolution.0,
        height_px: args.resolution.1,
        spp: args.spp,
    };
    spec.matcher = format!(
        "{:?}",
        spec.camera()
            .rig_and_config()
            .context("--window-radius-px")?
            .1
            .matcher
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let noise = InitialPoseNoise::default();
    let erode_px = args.erode_px.unwrap_or(window_radius_px);
    let scene_root = args
        .out
        .join(if args.matte { "scenes_matte" } else { "scenes" });
    // Evaluation seeds: seed·10⁴ + s; tuning seeds: seed·10⁴ + 5000 + s (disjoint for < 5000 scenes).
    let eval_seed = |s: u32| args.seed.wrapping_mul(10_000).wrapping_add(s as u64);
    let tune_seed = |s: u32| eval_seed(5000 + s);

    let mut refiners = Vec::new();
    for object in &objects {
        let grid_config = SdfConfig {
            voxel_size_m: args.sdf_voxel_mm * 1e-3,
            ..refine_grid_config()
        };
        let sdf = SdfGrid::build(&object.mesh, &grid_config)
            .with_context(|| format!("SDF of {}", object.name))?;
        let icp_model = IcpModel::from_mesh(&object.mesh, 50_000, args.seed)
            .with_context(|| format!("ICP model of {}", object.name))?;
        refiners.push(Refiners {
            sdf,
            icp_model,
            view_bias: ViewPoseBias::none(),
        });
    }

    // 1. Each refiner's one free setting by its best 2 mm/2° rate (all parts, all view counts)
    //    on the tuning scenes: each ICP variant's correspondence distance, the SDF refiner's
    //    first gate.
    let mut tune_trials = Vec::new();
    for (index, object) in objects.iter().enumerate() {
        for s in 0..args.tune_scenes {
            let seed = tune_seed(s);
            let dir = ensure_scene(&scene_root, object, seed, &spec)?;
            tune_trials.push((index, seed, dir));
        }
    }
    let bar = crate::progress::bar(tune_trials.len() as u64, "tune refiners");
    let icp_variants = [RefineMethod::Icp, RefineMethod::IcpPlane];
    // Per distance: (hits 2/2, n) of each variant.
    let mut per_distance = vec![[(0usize, 0usize); 2]; args.icp_distances_mm.len()];
    let mut per_gate = vec![(0usize, 0usize); args.sdf_gates_mm.len()];
    // The tuning scenes' instances at their true poses: what the correlated depth error is
    // measured on (ground truth of tuning scenes, as a camera is characterised).
    let mut known_views: Vec<(usize, Vec<DepthPoint>, Isometry3<f64>)> = Vec::new();
    for &(index, seed, ref dir) in &tune_trials {
        let object = &objects[index];
        let scene = load_scene(dir, OBJ_ID, window_radius_px, erode_px)?;
        let trials = trials_of_scene(object, seed, &scene, &args.views, &noise, args.seed);
        for view in &scene.views {
            for o in view.objects.iter().filter(|o| o.visib_fract >= 0.8) {
                let t_o_w = (view.t_w_c * o.t_c_o_gt).inverse();
                known_views.push((index, o.points.clone(), t_o_w));
            }
        }
        // Adds each method's (hits at 2 mm/2°, trials) over the scene's trials to `counts`.
        let tally = |settings: &RefinerSettings,
                     methods: &[RefineMethod],
                     counts: &mut [(usize, usize)]| {
            for t in &trials {
                let outcomes = run_trial(
                    t,
                    &scene,
                    &refiners[index],
                    settings,
                    &object.symmetry,
                    methods,
                );
                for (o, c) in outcomes.iter().zip(counts.iter_mut()) {
                    c.1 += 1;
                    c.0 += o.deviation.is_correct(&CorrectThreshold::MM2_DEG2) as usize;
                }
            }
        };
        for (d, acc) in args.icp_distances_mm.iter().zip(per_distance.iter_mut()) {
            let settings = RefinerSettings::tuning(REFINE_SDF_PADDING_MM, *d, args.align_depth);
            tally(&settings, &icp_variants, acc);
        }
        for (g, counts) in args.sdf_gates_mm.iter().zip(per_gate.iter_mut()) {
            let settings = RefinerSettings::tuning(*g, args.icp_distances_mm[0], args.align_depth);
            tally(
                &settings,
                &[RefineMethod::Sdf],
                std::slice::from_mut(counts),
            );
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let mut tunings = Vec::new();
    for v in 0..icp_variants.len() {
        let counts: Vec<(usize, usize)> = per_distance.iter().map(|acc| acc[v]).collect();
        let tuning = SettingTuning::choose(&args.icp_distances_mm, &counts)
            .context("--icp-distances-mm: give at least one distance")?;
        tracing::info!(
            "{} max correspondence distance: {} mm (tuning 2/2 rates: {})",
            icp_variants[v].label(),
            tuning.best,
            tuning.describe()
        );
        tunings.push(tuning);
    }
    let sdf_tuning = SettingTuning::choose(&args.sdf_gates_mm, &per_gate)
        .context("--sdf-gates-mm: give at least one gate")?;
    tracing::info!(
        "SDF first gate: {} mm (tuning 2/2 rates: {})",
        sdf_tuning.best,
        sdf_tuning.describe()
    );
    let sdf_config =
        RefinerSettings::tuning(sdf_tuning.best, args.icp_distances_mm[0], args.align_depth).sdf;
    let known: Vec<KnownPoseView> = known_views
        .iter()
        .map(|(index, points, t_o_w)| KnownPoseView {
            sdf: &refiners[*index].sdf,
            points,
            t_o_w: *t_o_w,
        })
        .collect();
    let cells_m: Vec<f64> = CORRELATION_CELLS_MM.iter().map(|c| c * 1e-3).collect();
    let depth_error_fit = fit_correlated_error(&known, &sdf_config, &cells_m)
        .context("the tuning scenes gave no depth points to measure the depth error on")?;
    tracing::info!(
        "correlated depth error: cell {} mm, σ_b {:.3} mm ({} points)",
        depth_error_fit.best.cell_m * 1e3,
        depth_error_fit.best.bias_sigma_m * 1e3,
        depth_error_fit.points
    );
    let settings = RefinerSettings {
        sdf: sdf_config,
        icp: IcpConfigs {
            point_to_point: IcpConfigs::at(tunings[0].best * 1e-3).point_to_point,
            point_to_plane: IcpConfigs::at(tunings[1].best * 1e-3).point_to_plane,
        },
        depth_error: depth_error_fit.best,
        align_depth: args.align_depth,
    };
    let mut bias_scenes = Vec::new();
    for (index, object) in objects.iter().enumerate() {
        for s in 0..args.view_bias_scenes {
            let seed = tune_seed(s);
            bias_scenes.push((index, seed, ensure_scene(&scene_root, object, seed, &spec)?));
        }
    }
    let view_bias = measure_view_biases(
        &objects,
        &bias_scenes,
        &mut refiners,
        &settings,
        &LoadSettings {
            window_radius_px,
            erode_px,
            noise: &noise,
            seed: args.seed,
        },
    )?;

    // 2. The evaluation.
    let mut all: Vec<(Trial, Vec<Outcome>)> = Vec::new();
    for (object, refiner) in objects.iter().zip(&refiners) {
        let bar = crate::progress::bar(args.scenes as u64, &object.name);
        for s in 0..args.scenes {
            let seed = eval_seed(s);
            let dir = ensure_scene(&scene_root, object, seed, &spec)?;
            let scene = load_scene(&dir, OBJ_ID, window_radius_px, erode_px)?;
            for trial in trials_of_scene(object, seed, &scene, &args.views, &noise, args.seed) {
                let outcomes = run_trial(
                    &trial,
                    &scene,
                    refiner,
                    &settings,
                    &object.symmetry,
                    &RefineMethod::ALL,
                );
                all.push((trial, outcomes));
            }
            bar.inc(1);
        }
        bar.finish_and_clear();
    }

    write_outputs(
        args,
        &objects,
        &all,
        &noise,
        &settings,
        &Tunings {
            icp: tunings,
            sdf: sdf_tuning,
            depth_error: depth_error_fit,
            view_bias,
        },
    )
}

/// How the tuning scenes are read and their trials drawn.
struct LoadSettings<'a> {
    window_radius_px: u32,
    erode_px: u32,
    noise: &'a InitialPoseNoise,
    seed: u64,
}

/// Each part's per-view pose bias from the tuning scenes: the SDF refiner's single-view
/// results that are correct at 5 mm/5° (the NEES's own selection), their errors against the
/// truth with the information the refiner (with the correlated depth error) gave them; sets
/// each part's [`Refiners::view_bias`].
fn measure_view_biases(
    objects: &[EvalObject],
    tune_scenes: &[(usize, u64, PathBuf)],
    refiners: &mut [Refiners],
    settings: &RefinerSettings,
    load: &LoadSettings<'_>,
) -> anyhow::Result<Vec<Option<ViewBiasFit>>> {
    let mut samples: Vec<Vec<SingleViewError>> = vec![Vec::new(); objects.len()];
    let bar = crate::progress::bar(tune_scenes.len() as u64, "measure view bias");
    for &(index, seed, ref dir) in tune_scenes {
        let object = &objects[index];
        let scene = load_scene(dir, OBJ_ID, load.window_radius_px, load.erode_px)?;
        for trial in trials_of_scene(object, seed, &scene, &[1], load.noise, load.seed) {
            let outcomes = run_trial(
                &trial,
                &scene,
                &refiners[index],
                settings,
                &object.symmetry,
                &[RefineMethod::Sdf],
            );
            let Some(o) = outcomes.first() else { continue };
            let [view] = o.views_information[..] else {
                continue;
            };
            if !o.deviation.is_correct(&CorrectThreshold::MM5_DEG5) {
                continue;
            }
            let t_w_c = scene.views[trial.reference].t_w_c;
            let t_o_w_est = (t_w_c * o.t_c_o).inverse();
            let t_o_w_gt = (t_w_c * trial.t_c_o_gt).inverse();
            samples[index].push(SingleViewError {
                error_o: symmetric_error(&t_o_w_est, &t_o_w_gt, &object.symmetry),
                information: view.information,
                r_o_c: view.r_o_c,
            });
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let fits: Vec<Option<ViewBiasFit>> = samples.iter().map(|s| measure_view_bias(s)).collect();
    for ((object, refiner), fit) in objects.iter().zip(refiners.iter_mut()).zip(&fits) {
        if let Some(fit) = fit {
            refiner.view_bias = fit.bias;
            let (t, r) = fit.bias.sigmas();
            tracing::info!(
                "{}: per-view pose bias σ_t ({:.3}, {:.3}, {:.3}) mm, σ_r ({:.3}, {:.3}, {:.3})° from {} single views",
                object.name,
                t[0] * 1e3,
                t[1] * 1e3,
                t[2] * 1e3,
                r[0].to_degrees(),
                r[1].to_degrees(),
                r[2].to_degrees(),
                fit.samples
            );
        }
    }
    Ok(fits)
}

/// Cell edges over which [`fit_correlated_error`] looks for a shared depth bias, mm (∞: one
/// cell a view): from a few matching windows (1 px ≈ 0.5 mm at 0.6 m) to the whole part.
const CORRELATION_CELLS_MM: [f64; 7] = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, f64::INFINITY];

/// One refiner's setting chosen on the tuning scenes: (value, hits at 2/2, trials) per
/// candidate value, and the value chosen (mm).
struct SettingTuning {
    tuning: Vec<(f64, usize, usize)>,
    best: f64,
}

impl SettingTuning {
    /// The value of best 2/2 rate among `values` with `(hits, trials)` each; ties go to the
    /// later (larger) value (`max_by` keeps the last maximum). `None` without values.
    fn choose(values: &[f64], counts: &[(usize, usize)]) -> Option<Self> {
        let tuning: Vec<(f64, usize, usize)> = values
            .iter()
            .zip(counts)
            .map(|(v, (hits, n))| (*v, *hits, *n))
            .collect();
        let best = tuning
            .iter()
            .max_by(|a, b| {
                (a.1 as f64 / a.2.max(1) as f64).total_cmp(&(b.1 as f64 / b.2.max(1) as f64))
            })?
            .0;
        Some(Self { tuning, best })
    }

    /// `10 mm → 12.3 %, …` for the report.
    fn describe(&self) -> String {
        self.tuning
            .iter()
            .map(|(d, h, n)| format!("{d} mm → {:.1} %", 100.0 * *h as f64 / (*n).max(1) as f64))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

fn write_outputs(
    args: &RefineExperiment,
    objects: &[EvalObject],
    all: &[(Trial, Vec<Outcome>)],
    noise: &InitialPoseNoise,
    settings: &RefinerSettings,
    tuned: &Tunings,
) -> anyhow::Result<String> {
    let (tunings, sdf_tuning, sdf_config) = (&tuned.icp, &tuned.sdf, &settings.sdf);
    let mut groups: Vec<String> = objects.iter().map(|o| o.name.clone()).collect();
    groups.push("all".into());
    let select = |group: &str, views: u32, method: RefineMethod| -> Vec<&Outcome> {
        all.iter()
            .filter(|(t, _)| {
                (group == "all" || t.object == group) && t.views.len() == views as usize
            })
            .flat_map(|(_, o)| o.iter().filter(|o| o.method == method))
            .collect()
    };
    let mut csv = String::from("part,views,method,n,rate_5mm5deg,rate_2mm2deg\n");
    for group in &groups {
        for &k in &args.views {
            for method in RefineMethod::ALL {
                let sel = select(group, k, method);
                let (r5, r2) = rates(&sel);
                let name = method.name();
                writeln!(csv, "{group},{k},{name},{},{r5:.4},{r2:.4}", sel.len())?;
            }
        }
    }
    let mut trials_csv = String::from(
        "part,scene_seed,views,instance,method,gt_t_mm_x,gt_t_mm_y,gt_t_mm_z,gt_qw,gt_qx,gt_qy,gt_qz,\
         init_t_mm_x,init_t_mm_y,init_t_mm_z,init_qw,init_qx,init_qy,init_qz,\
         est_t_mm_x,est_t_mm_y,est_t_mm_z,est_qw,est_qx,est_qy,est_qz,\
         translation_error_mm,rotation_error_deg,iterations,time_ms,status,nees,nees_dof,nees_correlated,nees_view_bias,cost_rose\n",
    );
    let pose = |p: &Isometry3<f64>| {
        let t = p.translation.vector * 1e3;
        let q = p.rotation.quaternion();
        format!(
            "{:.4},{:.4},{:.4},{:.8},{:.8},{:.8},{:.8}",
            t.x, t.y, t.z, q.w, q.i, q.j, q.k
        )
    };
    for (t, outcomes) in all {
        let views = t
            .views
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(" ");
        for o in outcomes {
            let (n, dof, nc, nb) = o.nees.map_or(Default::default(), |n| {
                (
                    format!("{:.4}", n.independent),
                    n.dof.to_string(),
                    format!("{:.4}", n.correlated),
                    format!("{:.4}", n.view_bias),
                )
            });
            writeln!(
                trials_csv,
                "{},{},{views},{},{},{},{},{},{:.4},{:.4},{},{:.3},\"{}\",{n},{dof},{nc},{nb},{}",
                t.object,
                t.scene_seed,
                t.instance,
                o.method.name(),
                pose(&t.t_c_o_gt),
                pose(&t.t_c_o_init),
                pose(&o.t_c_o),
                o.deviation.translation_mm(),
                o.deviation.rotation_deg(),
                o.iterations,
                o.time_ms,
                o.status.replace('"', "'"),
                o.cost_rose
            )?;
        }
    }

    // Table I layout: rows initial, then per view count sdf and icp; columns per part (5,5) (2,2).
    let mut table = String::new();
    writeln!(
        table,
        "# Pose refinement on mock-camera data (Table I layout)\n\n\
         Correct-detection rates (%) at (5 mm, 5°) and (2 mm, 2°), symmetry-aware, over GT instances ≥ 80 % visible in the \
         reference view. Mock SLI camera (physically based renders, real stereo matching), {}×{} px, {} spp, {} shot(s) per view \
         matched over {}×{} px windows, {} parts per bin, {} scenes × {} views per part, seed {}. Synthetic data, not ROBI.\n",
        args.resolution.0,
        args.resolution.1,
        args.spp,
        args.shots,
        2 * args.window_radius_px + 1,
        2 * args.window_radius_px + 1,
        args.instances,
        args.scenes,
        args.views_per_scene,
        args.seed
    )?;
    let mut header = String::from("| method |");
    let mut rule = String::from("|---|");
    for g in &groups {
        header += &format!(" {g} (5,5) | {g} (2,2) |");
        rule += "---:|---:|";
    }
    writeln!(table, "{header}\n{rule}")?;
    let row = |label: String, k: u32, method: RefineMethod| -> String {
        let mut line = format!("| {label} |");
        for g in &groups {
            let (r5, r2) = rates(&select(g, k, method));
            line += &format!(" {:.1} | {:.1} |", 100.0 * r5, 100.0 * r2);
        }
        line
    };
    writeln!(
        table,
        "{}",
        row("initial pose".into(), args.views[0], RefineMethod::Initial)
    )?;
    for &k in &args.views {
        let rows = std::iter::once(RefineMethod::Aligned)
            .filter(|_| args.align_depth)
            .chain(RefineMethod::REFINERS);
        for method in rows {
            writeln!(
                table,
                "{}",
                row(
                    format!(
                        "{k} view{} — {}",
                        if k > 1 { "s" } else { "" },
                        method.label()
                    ),
                    k,
                    method
                )
            )?;
        }
    }
    writeln!(table, "\nTrials per part and view count:")?;
    for g in &groups {
        let counts: Vec<String> = args
            .views
            .iter()
            .map(|&k| format!("{k} view(s): {}", select(g, k, RefineMethod::Sdf).len()))
            .collect();
        writeln!(table, "- {g}: {}", counts.join(", "))?;
    }
    writeln!(
        table,
        "\nInitial poses: {}.\n\nStart: {}.\n\nICP: k-d tree over 50 000 area-uniform model samples, 30 iterations (the SDF \
         refiner's budget); each variant's max correspondence distance is its best 2 mm/2° rate on {} separate tuning \
         scene(s) per part: point-to-point {} mm ({}), point-to-plane {} mm ({}).\n\nSDF refiner: its first gate chosen \
         the same way, {} mm ({}); {:?}.\n",
        noise.describe(),
        if args.align_depth {
            "every refiner starts from the initial pose moved along the reference view's mean viewing direction onto \
             that view's depth points (`glint_estimation::depth_alignment`: ±30 mm in 0.5 mm steps, the offset where most points \
             lie within 2 mm of a model face turned to their camera), the sessions' first step"
        } else {
            "every refiner starts from the initial pose itself (`--no-align-depth`)"
        },
        args.tune_scenes,
        tunings[0].best,
        tunings[0].describe(),
        tunings[1].best,
        tunings[1].describe(),
        sdf_tuning.best,
        sdf_tuning.describe(),
        sdf_config
    )?;

    // Paired comparison: the same trials, so McNemar's exact test on the discordant pairs.
    writeln!(
        table,
        "## SDF against ICP, paired\n\nOn the same trials (same initial pose, same points): b = trials SDF gets right and \
         the ICP variant wrong, c = the reverse; p = McNemar's exact two-sided test (binomial on b + c).\n\n\
         | part | views | threshold | vs | n | SDF | ICP | b | c | p |\n|---|---:|---|---|---:|---:|---:|---:|---:|---:|"
    )?;
    let mut paired_csv =
        String::from("part,views,threshold,baseline,n,sdf_rate,baseline_rate,b,c,p\n");
    for g in &groups {
        for &k in &args.views {
            let sdf = select(g, k, RefineMethod::Sdf);
            for baseline in [RefineMethod::Icp, RefineMethod::IcpPlane] {
                let other = select(g, k, baseline);
                for threshold in [CorrectThreshold::MM5_DEG5, CorrectThreshold::MM2_DEG2] {
                    let (mut b, mut c, mut ours, mut theirs) = (0, 0, 0, 0);
                    for (x, y) in sdf.iter().zip(&other) {
                        let (p, q) = (
                            x.deviation.is_correct(&threshold),
                            y.deviation.is_correct(&threshold),
                        );
                        ours += p as usize;
                        theirs += q as usize;
                        b += (p && !q) as usize;
                        c += (!p && q) as usize;
                    }
                    let n = sdf.len().min(other.len());
                    let pct = |x: usize| 100.0 * x as f64 / n.max(1) as f64;
                    let p = mcnemar_exact_p(b, c);
                    writeln!(
                        table,
                        "| {g} | {k} | {} | {} | {n} | {:.1} | {:.1} | {b} | {c} | {p:.3} |",
                        threshold.label,
                        baseline.label(),
                        pct(ours),
                        pct(theirs)
                    )?;
                    writeln!(
                        paired_csv,
                        "{g},{k},{},{},{n},{:.4},{:.4},{b},{c},{p:.5}",
                        threshold.label,
                        baseline.name(),
                        pct(ours) / 100.0,
                        pct(theirs) / 100.0
                    )?;
                }
            }
        }
    }

    // A refiner should not make a start worse.
    writeln!(
        table,
        "\n## Further from the truth than it started\n\nShare of trials (%) whose refined pose is further from the truth \
         than its start (the aligned start; the initial pose when the alignment is off), by `t / 5 mm + θ / 5°`; in brackets, among the trials that started correct at 5 mm/5°.\n\n\
         | part | views | SDF (ours) | ICP | ICP point-to-plane |\n|---|---:|---:|---:|---:|"
    )?;
    let mut worse_csv = String::from("part,views,method,n,worse,n_good_start,worse_good_start\n");
    for g in &groups {
        for &k in &args.views {
            let mut line = format!("| {g} | {k} |");
            for method in RefineMethod::REFINERS {
                let (mut n, mut worse, mut good, mut worse_good) = (0, 0, 0, 0);
                for (_, outcomes) in all
                    .iter()
                    .filter(|(t, _)| (g == "all" || &t.object == g) && t.views.len() == k as usize)
                {
                    let initial = outcomes.iter().find(|o| o.method == RefineMethod::Aligned);
                    let refined = outcomes.iter().find(|o| o.method == method);
                    if let (Some(i), Some(r)) = (initial, refined) {
                        let got_worse = scaled_error(&r.deviation) > scaled_error(&i.deviation);
                        n += 1;
                        worse += got_worse as usize;
                        if i.deviation.is_correct(&CorrectThreshold::MM5_DEG5) {
                            good += 1;
                            worse_good += got_worse as usize;
                        }
                    }
                }
                line += &format!(
                    " {:.1} ({:.1}) |",
                    100.0 * worse as f64 / n.max(1) as f64,
                    100.0 * worse_good as f64 / good.max(1) as f64
                );
                writeln!(
                    worse_csv,
                    "{g},{k},{},{n},{worse},{good},{worse_good}",
                    method.name()
                )?;
            }
            writeln!(table, "{line}")?;
        }
    }
    writeln!(table)?;

    // Does the SDF refiner notice? Its own verdict (final cost above the start's) against the
    // truth's, and what keeping the start on that verdict would give.
    writeln!(
        table,
        "## Does the SDF refiner notice?\n\nThe refiner's own verdict, no ground truth: its final robust cost above the cost of \
         its start under the same gate and points (`RefineResult::cost_rose`). *caught*: share of the trials it made \
         worse (above) that it flags; *false alarms*: share of the others it flags. *keep start*: Table I's rates if a \
         flagged result were replaced by its start.\n\n\
         | part | views | flagged | caught | false alarms | SDF (5,5) / (2,2) | keep start (5,5) / (2,2) |\n\
         |---|---:|---:|---:|---:|---|---|"
    )?;
    let mut notice_csv = String::from(
        "part,views,n,flagged,worse,caught,false_alarms,sdf_5mm5deg,sdf_2mm2deg,keep_start_5mm5deg,keep_start_2mm2deg\n",
    );
    for g in &groups {
        for &k in &args.views {
            let pairs: Vec<(&Outcome, &Outcome)> = all
                .iter()
                .filter(|(t, _)| (g == "all" || &t.object == g) && t.views.len() == k as usize)
                .filter_map(|(_, outcomes)| {
                    let initial = outcomes
                        .iter()
                        .find(|o| o.method == RefineMethod::Aligned)?;
                    let sdf = outcomes.iter().find(|o| o.method == RefineMethod::Sdf)?;
                    Some((initial, sdf))
                })
                .collect();
            let n = pairs.len();
            if n == 0 {
                continue;
            }
            let got_worse = |(i, r): &(&Outcome, &Outcome)| {
                scaled_error(&r.deviation) > scaled_error(&i.deviation)
            };
            let flagged = pairs.iter().filter(|(_, r)| r.cost_rose).count();
            let worse = pairs.iter().filter(|p| got_worse(p)).count();
            let caught = pairs
                .iter()
                .filter(|p| got_worse(p) && p.1.cost_rose)
                .count();
            let false_alarms = pairs
                .iter()
                .filter(|p| !got_worse(p) && p.1.cost_rose)
                .count();
            let rate = |pick: &dyn Fn(&(&Outcome, &Outcome)) -> PoseDeviation, threshold| {
                100.0
                    * pairs
                        .iter()
                        .filter(|p| pick(p).is_correct(threshold))
                        .count() as f64
                    / n as f64
            };
            let sdf = |p: &(&Outcome, &Outcome)| p.1.deviation;
            let keep = |p: &(&Outcome, &Outcome)| {
                if p.1.cost_rose {
                    p.0.deviation
                } else {
                    p.1.deviation
                }
            };
            let (s5, s2) = (
                rate(&sdf, &CorrectThreshold::MM5_DEG5),
                rate(&sdf, &CorrectThreshold::MM2_DEG2),
            );
            let (k5, k2) = (
                rate(&keep, &CorrectThreshold::MM5_DEG5),
                rate(&keep, &CorrectThreshold::MM2_DEG2),
            );
            let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
            writeln!(
                table,
                "| {g} | {k} | {:.1} | {:.1} | {:.1} | {s5:.1} / {s2:.1} | {k5:.1} / {k2:.1} |",
                pct(flagged, n),
                pct(caught, worse),
                pct(false_alarms, n - worse)
            )?;
            writeln!(
                notice_csv,
                "{g},{k},{n},{flagged},{worse},{caught},{false_alarms},{s5:.4},{s2:.4},{k5:.4},{k2:.4}"
            )?;
        }
    }
    writeln!(table)?;

    // Is the covariance honest? Mean NEES of SDF results that are correct at 5 mm/5°, under
    // eq 18 and under the correlated depth error measured on the tuning scenes.
    let fit = &tuned.depth_error;
    let cell = if fit.best.cell_m.is_finite() {
        format!("{:.0} mm cells", fit.best.cell_m * 1e3)
    } else {
        "one cell a view".into()
    };
    writeln!(
        table,
        "## Is the covariance honest?\n\nMean NEES of the SDF refiner's poses against its predicted covariance, over \
         refinements correct at 5 mm/5° (a local check: gross failures are a convergence question, not a covariance one). \
         Degrees of freedom 6, or 5 for a continuous symmetry; the band is the 95 % interval of the mean. \
         *eq 18*: independent pixels (the paper's). *correlated*: a depth bias shared by one view's points within a \
         world cell (`glint_estimation::correlated_error`), measured by maximum likelihood on the tuning scenes' \
         instances at their true poses ({} points): {cell}, σ_b = {:.3} mm (log-likelihood gain over independent \
         errors {:.0}). *+ view bias*: the correlated model plus a pose error shared by all of one view's points \
         (`glint_estimation::view_bias`), measured per part on the tuning scenes' correct single-view refinements \
         (table below).\n\n\
         | part | views | n | dof | 95 % band | mean NEES eq 18 | median eq 18 | mean NEES correlated | median correlated | mean NEES + view bias | median + view bias |\n\
         |---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|",
        fit.points,
        fit.best.bias_sigma_m * 1e3,
        fit.per_cell_size
            .iter()
            .map(|c| c.log_likelihood)
            .fold(f64::NEG_INFINITY, f64::max)
            - fit.independent_log_likelihood,
    )?;
    let mut nees_csv = String::from(
        "part,views,n,dof,band_lo,band_hi,mean_nees,median_nees,mean_nees_correlated,median_nees_correlated,\
         mean_nees_view_bias,median_nees_view_bias\n",
    );
    for g in &groups {
        for &k in &args.views {
            let values: Vec<Nees> = select(g, k, RefineMethod::Sdf)
                .iter()
                .filter(|o| o.deviation.is_correct(&CorrectThreshold::MM5_DEG5))
                .filter_map(|o| o.nees)
                .collect();
            let Some(first) = values.first() else {
                continue;
            };
            let n = values.len();
            let dof = first.dof;
            let (lo, hi) = chi2_mean_band(dof, n);
            let independent: Vec<f64> = values.iter().map(|v| v.independent).collect();
            let correlated: Vec<f64> = values.iter().map(|v| v.correlated).collect();
            let (mean_i, med_i) = (mean(&independent), median(independent.clone()));
            let (mean_c, med_c) = (mean(&correlated), median(correlated.clone()));
            let biased: Vec<f64> = values.iter().map(|v| v.view_bias).collect();
            let (mean_b, med_b) = (mean(&biased), median(biased.clone()));
            writeln!(
                table,
                "| {g} | {k} | {n} | {dof} | [{lo:.2}, {hi:.2}] | {mean_i:.2} | {med_i:.2} | {mean_c:.2} | {med_c:.2} | \
                 {mean_b:.2} | {med_b:.2} |"
            )?;
            writeln!(
                nees_csv,
                "{g},{k},{n},{dof},{lo:.4},{hi:.4},{mean_i:.4},{med_i:.4},{mean_c:.4},{med_c:.4},{mean_b:.4},{med_b:.4}"
            )?;
        }
    }
    writeln!(
        table,
        "\nThe fit per cell edge (σ_b, log-likelihood):\n\n| cell | σ_b mm | log-likelihood | cells |\n|---|---:|---:|---:|"
    )?;
    for c in &fit.per_cell_size {
        writeln!(
            table,
            "| {} | {:.3} | {:.0} | {} |",
            if c.error.cell_m.is_finite() {
                format!("{:.0} mm", c.error.cell_m * 1e3)
            } else {
                "view".into()
            },
            c.error.bias_sigma_m * 1e3,
            c.log_likelihood,
            c.cells
        )?;
    }
    writeln!(
        table,
        "| independent | 0 | {:.0} | |",
        fit.independent_log_likelihood
    )?;
    writeln!(
        table,
        "\nThe per-view pose bias B per part: standard deviations along the view frame's axes (the camera's, \
         through the part's origin; z the optical axis), by maximum likelihood (EM) over the tuning scenes' single-view \
         SDF refinements correct at 5 mm/5°, each error under the refiner's own information plus B; beside it the RMS \
         of those errors (noise and bias together, spin included):\n\n\
         | part | single views | B: σ_t x, y, z mm | B: σ_r x, y, z ° | errors' RMS t x, y, z mm | errors' RMS r x, y, z ° | EM steps |\n\
         |---|---:|---|---|---|---|---:|"
    )?;
    for (object, fit) in objects.iter().zip(&tuned.view_bias) {
        let Some(fit) = fit else {
            writeln!(table, "| {} | 0 | – | – | – | – | – |", object.name)?;
            continue;
        };
        let (t, r) = fit.bias.sigmas();
        let rms = |i: usize| fit.second_moment_v[(i, i)].sqrt();
        let mm = |v: [f64; 3]| format!("{:.3}, {:.3}, {:.3}", v[0] * 1e3, v[1] * 1e3, v[2] * 1e3);
        let deg = |v: [f64; 3]| {
            format!(
                "{:.3}, {:.3}, {:.3}",
                v[0].to_degrees(),
                v[1].to_degrees(),
                v[2].to_degrees()
            )
        };
        writeln!(
            table,
            "| {} | {} | {} | {} | {} | {} | {} |",
            object.name,
            fit.samples,
            mm(t),
            deg(r),
            mm([rms(0), rms(1), rms(2)]),
            deg([rms(3), rms(4), rms(5)]),
            fit.iterations,
        )?;
    }
    let timing: Vec<String> = RefineMethod::REFINERS
        .iter()
        .map(|m| {
            let times: Vec<f64> = all
                .iter()
                .flat_map(|(_, o)| o.iter().filter(|o| o.method == *m).map(|o| o.time_ms))
                .collect();
            format!(
                "{} {:.2} ms",
                m.name(),
                times.iter().sum::<f64>() / times.len().max(1) as f64
            )
        })
        .collect();
    writeln!(
        table,
        "\nMean time per refinement (all cores): {}.",
        timing.join(", ")
    )?;

    // Each part's error model, as sessions take it (`pose_error/<part>.json`).
    let models_dir = args.out.join("pose_error");
    std::fs::create_dir_all(&models_dir)
        .with_context(|| format!("creating {}", models_dir.display()))?;
    for (object, fit) in objects.iter().zip(&tuned.view_bias) {
        let Some(fit) = fit else { continue };
        let model = PoseErrorModel {
            depth_error: tuned.depth_error.best,
            view_bias: fit.bias,
        };
        let measured_on = format!(
            "glint eval refine --seed {}: the depth error on {} points of the tuning scenes' \
             instances at their true poses; B on {} correct single-view SDF refinements of \
             {} tuning scenes",
            args.seed, tuned.depth_error.points, fit.samples, args.view_bias_scenes
        );
        let path = models_dir.join(format!("{}.json", object.name));
        model
            .save(&path, &object.name, &measured_on)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    for (name, text) in [
        ("results.csv", &csv),
        ("trials.csv", &trials_csv),
        ("nees.csv", &nees_csv),
        ("paired.csv", &paired_csv),
        ("worse.csv", &worse_csv),
        ("notice.csv", &notice_csv),
        ("table.md", &table),
    ] {
        let path = args.out.join(name);
        write_file_atomically(&path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(table)
}
