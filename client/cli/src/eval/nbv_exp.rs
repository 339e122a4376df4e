//! `glint eval nbv`: the paper's Fig. 9 on mock-camera data, every policy choosing every view
//! among the same candidates; the experiment itself is [`glint_eval::fig9`].

use std::path::PathBuf;

use anyhow::Context;
use glint_eval::active::Calibration;
use glint_eval::fig9::{NbvExperiment, NbvObject};
use glint_geometry::{LengthUnit, Part, Symmetry};
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
    #[arg(long, default_value_t = 0.8)]
    pub min_visib_fract: f64,
    /// Camera resolution, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    /// Samples per pixel of the mock camera's renders.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub spp: u32,
    /// Patterns the mock camera projects per view.
    #[arg(long, default_value_t = glint_camera::capture::DEFAULT_SHOTS, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub shots: u32,
    /// The mock camera's matching window radius, px (default: the camera's for --shots).
    #[arg(long)]
    pub window_radius_px: Option<u32>,
    /// Each part's calibration is read from DIR/<part>/material.json and response.json (the
    /// layout `glint demo` caches in glint-out/calibration); a part without one there uses the
    /// calibration shipped with Glint (assets/calibration/).
    #[arg(long)]
    pub calibrations: Option<PathBuf>,
    /// The fitted material of --mesh, or of the one part given (`glint calibrate bsdf`).
    #[arg(long, requires = "response")]
    pub material: Option<PathBuf>,
    /// The camera response that goes with --material (`glint calibrate response`).
    #[arg(long, requires = "material")]
    pub response: Option<PathBuf>,
    /// The render workers render the bin with the part (beyond the paper).
    #[arg(long)]
    pub predict_bin: bool,
    #[arg(long)]
    pub out: PathBuf,
}

/// A part's calibration: `--material/--response`, else `DIR/<part>/` of `--calibrations`,
/// else the one shipped.
fn calibration_of(args: &NbvArgs, part: Part) -> anyhow::Result<Calibration> {
    if let (Some(m), Some(r)) = (&args.material, &args.response) {
        return Ok(Calibration::load(m, r)?);
    }
    if let Some(root) = &args.calibrations {
        let dir = root.join(part.name());
        let (m, r) = (dir.join("material.json"), dir.join("response.json"));
        if m.is_file() && r.is_file() {
            return Ok(Calibration::load(&m, &r)?);
        }
    }
    Ok(Calibration::from_files_or_embedded(part, None, None)?)
}

pub fn run_cmd(args: &NbvArgs) -> anyhow::Result<()> {
    if !(args.min_visib_fract.is_finite() && (0.0..=1.0).contains(&args.min_visib_fract)) {
        anyhow::bail!(
            "--min-visib-fract {}: a share from 0 to 1",
            args.min_visib_fract
        );
    }
    let parts = super::parse_parts(&args.parts)?;
    if args.material.is_some() && args.mesh.is_none() && parts.len() != 1 {
        anyhow::bail!(
            "--material and --response calibrate one part: give one --parts, or use \
             --calibrations DIR for several"
        );
    }
    let objects = glint_eval::scenes::eval_objects(
        &parts,
        args.mesh.as_deref(),
        args.unit,
        &args.symmetry,
        false,
    )?;
    let mut with_calibration = Vec::new();
    for (i, object) in objects.into_iter().enumerate() {
        let calibration = match &args.mesh {
            Some(_) => calibration_of(args, Part::TubeFitting)?,
            None => calibration_of(args, parts[i])
                .with_context(|| format!("the {}'s calibration", parts[i].display_name()))?,
        };
        with_calibration.push(NbvObject {
            object,
            calibration,
        });
    }
    let spec = NbvExperiment {
        objects: with_calibration,
        scenes: args.scenes,
        detection_views: args.detection_views,
        max_views: args.max_views as usize,
        candidates: args.candidates as usize,
        instances: args.instances,
        seed: args.seed,
        resolution: args.resolution,
        spp: args.spp,
        shots: args.shots,
        window_radius_px: args
            .window_radius_px
            .unwrap_or_else(|| glint_camera::capture::default_window_radius_px(args.shots)),
        policies: args.policies.clone(),
        random_draws: args.random_draws,
        min_visib_fract: args.min_visib_fract,
        predict_with_bin: args.predict_bin,
        out: args.out.clone(),
    };
    println!(
        "Fig. 9 on mock data: {} part(s) × {} bins × {} detection views, {} policies, {} views \
         of {} candidates, {}×{} px, {} spp. Initial poses from the stand-in detector; errors \
         against the truth.",
        spec.objects.len(),
        spec.scenes,
        spec.detection_views,
        spec.policies.len(),
        spec.max_views,
        spec.candidates,
        spec.resolution.0,
        spec.resolution.1,
        spec.spp
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
