//! `glint eval nbv`: the paper's Fig. 9 on mock-camera data, every policy choosing every view
//! among the same candidates; the experiment itself is [`glint_eval::fig9`].

use std::path::PathBuf;

use anyhow::Context;

use glint_eval::fig9::NbvExperiment;
use glint_geometry::{LengthUnit, Symmetry};
use glint_orchestrator::session::ViewPolicy;

#[derive(clap::Args)]
pub struct NbvArgs {
    /// Parts: `all` or a comma-separated list of eye-bolt, tube-fitting, chrome-screw, gear,
    /// zigzag. Ignored with --mesh.
    #[arg(long, default_value = "all")]
    pub parts: String,
    /// Run on this mesh (PLY/OBJ/STL) instead of the five parts; needs --material and
    /// --response (its calibration).
    #[arg(long, requires = "material")]
    pub mesh: Option<PathBuf>,
    /// Unit of --mesh: mm or m.
    #[arg(long, default_value = "mm", value_parser = crate::mesh_cmd::parse_unit)]
    pub unit: LengthUnit,
    /// Symmetry of --mesh: none, continuous:z, discrete:z:6, dihedral:z:20:x.
    #[arg(long, default_value = "none")]
    pub symmetry: Symmetry,
    /// Bins per part.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub scenes: u32,
    /// Detection views per bin, spread over the candidates: a trial per instance at least
    /// --min-visib-fract visible from each.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub detection_views: u32,
    /// Views each policy takes per trial.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub max_views: u32,
    /// Candidate views on the cap above each bin.
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(2..=1000))]
    pub candidates: u32,
    /// Parts per bin.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Policies, comma separated.
    #[arg(
        long,
        default_value = "nbv,nbv-const-sigma,random,max-distance",
        value_delimiter = ','
    )]
    pub policies: Vec<ViewPolicy>,
    /// Draws of the Random policy per trial; its rates are their mean.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub random_draws: u32,
    /// An instance is a trial from a detection view where at least this share of it is
    /// visible (Table I's 0.8).
    #[arg(long, default_value_t = 0.8, value_parser = crate::calibrate_cmd::parse_unit_interval::<f64>)]
    pub min_visib_fract: f64,
    #[command(flatten)]
    pub camera: super::MockCameraArgs,
    // With --mesh, --material and --response are its calibration.
    #[command(flatten)]
    pub calibration: crate::calibration_args::PartCalibrationArgs,
    /// The render workers render the bin with the part (beyond the paper).
    #[arg(long)]
    pub predict_bin: bool,
    /// Beyond the paper: run NBV planned under the camera's error model on each part too
    /// (column nbv_error_model), as a session under it plans: `shipped`
    /// (assets/calibration/<part>/pose_error.json) or, for one part or --mesh, a file
    /// `glint eval refine` wrote (DIR/pose_error/<part>.json).
    #[arg(long)]
    pub nbv_error_model: Option<String>,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run_cmd(args: &NbvArgs) -> anyhow::Result<()> {
    let parts = super::parse_parts(&args.parts)?;
    let objects = glint_eval::scenes::eval_objects(
        &parts,
        args.mesh.as_deref(),
        args.unit,
        &args.symmetry,
        false,
    )?;
    let with_calibration =
        super::calibrated_objects(objects, &parts, &args.calibration, args.mesh.is_some())?;
    let error_models = match args.nbv_error_model.as_deref() {
        None => Vec::new(),
        Some("none") => anyhow::bail!(
            "--nbv-error-model none: leave the flag out to run without NBV under the model"
        ),
        Some(value) => {
            let parts: Vec<Option<glint_geometry::Part>> = match args.mesh {
                Some(_) => vec![None],
                None => parts.iter().copied().map(Some).collect(),
            };
            if value != "shipped" && parts.len() > 1 {
                anyhow::bail!(
                    "--nbv-error-model {value}: a file is one part's model; give one --parts, \
                     or `shipped` for several"
                );
            }
            parts
                .into_iter()
                .map(|part| {
                    super::error_model_arg("--nbv-error-model", value, part)?
                        .context("--nbv-error-model: a model")
                })
                .collect::<anyhow::Result<_>>()?
        }
    };
    let spec = NbvExperiment {
        objects: with_calibration,
        scenes: args.scenes,
        detection_views: args.detection_views,
        max_views: args.max_views as usize,
        candidates: args.candidates as usize,
        instances: args.instances,
        seed: args.seed,
        camera: args.camera.spec(),
        policies: args.policies.clone(),
        random_draws: args.random_draws,
        min_visib_fract: args.min_visib_fract,
        predict_with_bin: args.predict_bin,
        error_models,
        out: args.out.clone(),
    };
    println!(
        "Fig. 9 on mock data: {} part(s) × {} bins × {} detection views, {} policies, {} views \
         of {} candidates, {}. Initial poses from the stand-in detector; errors \
         against the truth.",
        spec.objects.len(),
        spec.scenes,
        spec.detection_views,
        spec.columns().len(),
        spec.max_views,
        spec.candidates,
        spec.camera
    );
    let started = std::time::Instant::now();
    let bar = glint_eval::progress::bar(u64::from(spec.scenes) * spec.objects.len() as u64, "bins");
    let rows = glint_eval::fig9::run(&spec, |part, scene, trials, so_far| {
        bar.suspend(|| {
            println!(
                "  {part} bin {scene}: {trials} trials ({:.0} s so far)",
                started.elapsed().as_secs_f64()
            )
        });
        bar.inc(1);
        // What is done is on disk before the next bin starts.
        glint_eval::fig9::write_outputs(&spec, so_far).map(|_| ())
    })?;
    bar.finish_and_clear();
    let table = glint_eval::fig9::write_outputs(&spec, &rows)?;
    println!("{table}");
    println!(
        "{:.0} s in all. Report: {}",
        started.elapsed().as_secs_f64(),
        spec.out.join("index.html").display()
    );
    Ok(())
}
