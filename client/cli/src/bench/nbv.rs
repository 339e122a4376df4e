//! `glint bench nbv`: one next-best-view decision — every candidate predicted by the render
//! workers, then the minimum-entropy plan — on a mock bin, with the time per stage, on 1
//! thread and on all cores.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glint_estimation::nbv::{PosePrior, plan_next_view};
use glint_eval::active::{ActiveScene, ActiveSceneSpec, Calibration, prediction_object, set_up};
use glint_geometry::Part;
use glint_geometry::image::PixelRect;
use glint_geometry::io::write_file_atomically;
use glint_orchestrator::local::SdfCache;
use glint_orchestrator::stages::PredictionObject;
use glint_uncertainty::{PredictionSettings, candidate_seed, predict_candidate};
use nalgebra::Matrix6;
use rayon::prelude::*;

#[derive(clap::Args)]
pub struct NbvBenchArgs {
    #[arg(long, default_value = "zigzag", value_parser = crate::mesh_cmd::parse_part)]
    pub part: Part,
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(2..=1024))]
    pub candidates: u32,
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub instances: u32,
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    /// Render the bin with the part.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub predict_bin: bool,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write the table as CSV here.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Also export the decision's scene, candidates, crops and times to this folder for
    /// `services/render/scripts/mitsuba_nbv_bench.py`, which renders the same images with
    /// Mitsuba 3 and prints the time ratio.
    #[arg(long)]
    pub mitsuba_export: Option<PathBuf>,
}

/// One decision, milliseconds: per stage the sum over the candidates of each one's own time
/// (candidates run in parallel, so on n threads the stages add up to about n × the wall
/// time), and the decision's wall time.
#[derive(Clone, Copy, Debug, Default)]
struct DecisionTimes {
    render_ms: f64,
    sigma_ms: f64,
    fim_ms: f64,
    entropy_ms: f64,
    total_ms: f64,
}

/// The bin one NBV decision is benchmarked on (2 spp captures) and what the render workers
/// know of it (the shipped calibration; with the bin rendered when `predict_bin`).
pub fn decision_scene(
    part: Part,
    instances: u32,
    seed: u64,
    (width_px, height_px): (u32, u32),
    candidates: u32,
    predict_bin: bool,
) -> anyhow::Result<(ActiveScene, PredictionObject)> {
    let scene = set_up(&ActiveSceneSpec {
        part,
        instances,
        seed,
        width_px,
        height_px,
        samples_per_pixel: 2,
        candidates: candidates as usize,
    })?;
    let calibration = Calibration::from_files_or_embedded(part, None, None)?;
    let object = prediction_object(&scene, &calibration, predict_bin)?;
    Ok((scene, object))
}

pub fn run(args: &NbvBenchArgs) -> anyhow::Result<()> {
    let (scene, object) = decision_scene(
        args.part,
        args.instances,
        args.seed,
        args.resolution,
        args.candidates,
        args.predict_bin,
    )?;
    let predictor = object.predictor(
        SdfCache::with_config(glint_uncertainty::predict::prediction_grid_config())
            .grid(&object.object)
            .map_err(anyhow::Error::msg)?,
    );
    let settings = PredictionSettings {
        shots: object.shots,
        window_radius_px: object.window_radius_px,
        ..PredictionSettings::default()
    };
    // Each candidate's crops (left crop, right crop's first column), for the export.
    type Crops = Vec<(Option<PixelRect>, Option<i64>)>;
    let decide = || -> anyhow::Result<(DecisionTimes, Crops)> {
        let started = Instant::now();
        let mut times = DecisionTimes::default();
        // As the workers do: candidates in parallel.
        let predictions: Vec<_> = scene
            .candidates
            .par_iter()
            .enumerate()
            .map(|(i, t_w_c)| {
                predict_candidate(
                    &predictor,
                    &scene.initial_t_w_o,
                    t_w_c,
                    &settings,
                    candidate_seed(args.seed, i as u32),
                )
            })
            .collect::<Result<_, _>>()?;
        let mut informations = Vec::with_capacity(predictions.len());
        let mut crops = Vec::with_capacity(predictions.len());
        for p in predictions {
            crops.push((p.crop, p.right_crop_u_min_px));
            times.render_ms += p.render_ms;
            times.sigma_ms += p.sigma_ms;
            times.fim_ms += p.information_ms;
            informations.push(p.information);
        }
        let t = Instant::now();
        plan_next_view(&Matrix6::zeros(), &informations, &[], &PosePrior::default())?;
        times.entropy_ms = t.elapsed().as_secs_f64() * 1e3;
        times.total_ms = started.elapsed().as_secs_f64() * 1e3;
        Ok((times, crops))
    };
    let all = rayon::current_num_threads();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    // A warm-up decision: caches, page faults.
    decide()?;
    let (one_thread, _) = one.install(decide)?;
    let (all_threads, crops) = decide()?;
    let rows = [(1, one_thread), (all, all_threads)];
    let mut table = format!(
        "One NBV decision on the {} ({} in the bin, {}×{} px, bin rendered: {}): {} candidates \
         predicted (render, σ̌_z, FIM), then the entropy plan.\n\n\
         | threads | render ms | σ̌_z ms | FIM ms | entropy ms | total ms | per candidate ms |\n\
         |---:|---:|---:|---:|---:|---:|---:|\n",
        args.part.display_name(),
        args.instances,
        args.resolution.0,
        args.resolution.1,
        args.predict_bin,
        args.candidates
    );
    let mut csv =
        String::from("threads,candidates,render_ms,sigma_ms,fim_ms,entropy_ms,total_ms\n");
    for (threads, t) in rows {
        let _ = writeln!(
            table,
            "| {threads} | {:.0} | {:.0} | {:.1} | {:.2} | {:.0} | {:.1} |",
            t.render_ms,
            t.sigma_ms,
            t.fim_ms,
            t.entropy_ms,
            t.total_ms,
            t.total_ms / args.candidates as f64
        );
        let _ = writeln!(
            csv,
            "{threads},{},{:.3},{:.3},{:.3},{:.3},{:.3}",
            args.candidates, t.render_ms, t.sigma_ms, t.fim_ms, t.entropy_ms, t.total_ms
        );
    }
    println!("{table}");
    if let Some(path) = &args.csv {
        write_file_atomically(path, csv.as_bytes())?;
    }
    if let Some(dir) = &args.mitsuba_export {
        let glint_times = rows
            .iter()
            .map(|(threads, t)| {
                serde_json::json!({
                    "threads": threads, "render_ms": t.render_ms, "sigma_ms": t.sigma_ms,
                    "fim_ms": t.fim_ms, "entropy_ms": t.entropy_ms, "total_ms": t.total_ms,
                })
            })
            .collect();
        let path = export_decision(dir, &scene, &object, &settings, &crops, glint_times)?;
        println!(
            "wrote {}; next: python3 services/render/scripts/mitsuba_nbv_bench.py {}",
            path.display(),
            dir.display()
        );
    }
    Ok(())
}

/// The decision's prediction scene (the part at the hypothesis pose, the known surroundings),
/// its candidates and their crops as [`crate::mitsuba_export::write_nbv`] writes them.
fn export_decision(
    dir: &Path,
    scene: &ActiveScene,
    object: &PredictionObject,
    settings: &PredictionSettings,
    crops: &[(Option<PixelRect>, Option<i64>)],
    glint_times: Vec<serde_json::Value>,
) -> anyhow::Result<PathBuf> {
    use crate::mitsuba_export::{ExportShape, NbvExport, NbvExportCandidate, write_nbv};
    use glint_render::integrator::LightTransport;
    use glint_render::projector::Pattern;

    // Labels as the prediction gives them: the part 1, the surroundings 2, 3, …
    let mut shapes = vec![ExportShape {
        name: object.object.name.clone(),
        mesh_w: object.object.mesh.transformed(&scene.initial_t_w_o.cast()),
        material: "part",
        label: 1,
    }];
    let mut materials = vec![("part", object.material)];
    let names: Vec<String> = (0..object.surroundings.len())
        .map(|i| format!("surrounding_{i}"))
        .collect();
    for (i, surface) in object.surroundings.iter().enumerate() {
        shapes.push(ExportShape {
            name: names[i].clone(),
            mesh_w: surface.mesh.transformed(&surface.t_w_s.cast()),
            material: &names[i],
            label: i as u16 + 2,
        });
        materials.push((&names[i], surface.material));
    }
    let candidates = scene
        .candidates
        .iter()
        .zip(crops)
        .map(
            |(t_w_c, &(left_crop, right_crop_u_min_px))| NbvExportCandidate {
                cameras: object.rig.cameras(t_w_c),
                t_w_p: object.rig.projector(t_w_c, Pattern::White).t_w_p,
                left_crop,
                right_crop_u_min_px,
            },
        )
        .collect();
    let projector = object.rig.projector(&scene.candidates[0], Pattern::White);
    write_nbv(
        dir,
        &NbvExport {
            shapes,
            materials,
            projector: &projector,
            candidates,
            samples_per_pixel: settings.samples_per_pixel,
            multi_path: LightTransport::MULTI_PATH_DEFAULT,
            glint_times,
        },
    )
}
