//! `glint bench nbv`: one next-best-view decision — every candidate predicted by the render
//! workers, then the minimum-entropy plan — on a mock bin, with the time per stage, on 1
//! thread and on all cores.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glint_estimation::nbv::{PosePrior, plan_next_view, shortlist};
use glint_eval::active::{
    ActiveScene, ActiveSceneSpec, CONST_SIGMA_Z_M, Calibration, prediction_object, set_up,
};
use glint_geometry::Part;
use glint_geometry::image::PixelRect;
use glint_geometry::io::write_file_atomically;
use glint_orchestrator::local::SdfCache;
use glint_orchestrator::stages::PredictionObject;
use glint_uncertainty::{
    CandidatePrediction, HypothesisScene, PredictionSettings, PredictorObject, SigmaModel,
    candidate_seed, predict_candidate_in,
};
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
    /// Also time cheaper decisions and judge each against the full one: render only the K
    /// candidates a constant-σ_z screen ranks best (comma separated; K ≥ --candidates renders
    /// them all) …
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub shortlist: Vec<u32>,
    /// … at these samples per pixel of the prediction renders (comma separated; default the
    /// workers' 2).
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..=64))]
    pub prediction_spp: Vec<u32>,
    /// Judge the cheaper decisions by a full decision at this many samples per pixel (less
    /// noisy than the workers' 2; default: the benchmarked full decision itself).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub judge_spp: Option<u32>,
    /// Also write the cheaper decisions' table as CSV here.
    #[arg(long)]
    pub variants_csv: Option<PathBuf>,
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

impl DecisionTimes {
    fn add(&mut self, p: &CandidatePrediction) {
        self.render_ms += p.render_ms;
        self.sigma_ms += p.sigma_ms;
        self.fim_ms += p.information_ms;
    }
}

/// What the benchmarked decisions share: the scene, the render workers' object, the seed.
struct Decider<'a> {
    scene: &'a ActiveScene,
    predictor: &'a PredictorObject,
    seed: u64,
}

impl Decider<'_> {
    /// The predictions of candidates `indices` from the decision's scene `hypothesis`, in
    /// parallel as the workers make them; each candidate's render seed is its index's, so a
    /// candidate predicts the same in every decision.
    fn predict(
        &self,
        hypothesis: &HypothesisScene,
        indices: &[usize],
        settings: &PredictionSettings,
    ) -> anyhow::Result<Vec<CandidatePrediction>> {
        Ok(indices
            .par_iter()
            .map(|&i| {
                predict_candidate_in(
                    self.predictor,
                    hypothesis,
                    &self.scene.candidates[i],
                    settings,
                    candidate_seed(self.seed, i as u32),
                )
            })
            .collect::<Result<_, _>>()?)
    }

    /// One decision: the candidates `shortlist_k` allows (all, or the best by a constant-σ_z
    /// screen, whose time is `screen_ms`) predicted with `settings`, then the entropy plan.
    /// Returns the chosen candidate, the plan over the predicted ones, the times and the
    /// screen's time.
    fn decide(
        &self,
        settings: &PredictionSettings,
        shortlist_k: Option<usize>,
    ) -> anyhow::Result<Decision> {
        let started = Instant::now();
        let mut times = DecisionTimes::default();
        let all: Vec<usize> = (0..self.scene.candidates.len()).collect();
        let prior = PosePrior::default();
        // One scene for the decision's hypothesis, as a worker builds it per request; its
        // build counts as rendering.
        let hypothesis = HypothesisScene::build(self.predictor, &self.scene.initial_t_w_o)?;
        times.render_ms += hypothesis.build_ms;
        let indices = match shortlist_k {
            Some(k) if k < all.len() => {
                let screen = PredictionSettings {
                    sigma: SigmaModel::Constant {
                        sigma_z_m: CONST_SIGMA_Z_M,
                    },
                    ..*settings
                };
                let cheap: Vec<Matrix6<f64>> = (self.predict(&hypothesis, &all, &screen)?)
                    .into_iter()
                    .map(|p| p.information)
                    .collect();
                shortlist(&Matrix6::zeros(), &cheap, &[], &prior, k)?
            }
            _ => all,
        };
        let screen_ms = started.elapsed().as_secs_f64() * 1e3;
        let predictions = self.predict(&hypothesis, &indices, settings)?;
        // The stage times are the shortlisted predictions'; the screen's are in `screen_ms`.
        predictions.iter().for_each(|p| times.add(p));
        let informations: Vec<Matrix6<f64>> = predictions.iter().map(|p| p.information).collect();
        let t = Instant::now();
        let plan = plan_next_view(&Matrix6::zeros(), &informations, &[], &prior)?;
        times.entropy_ms = t.elapsed().as_secs_f64() * 1e3;
        times.total_ms = started.elapsed().as_secs_f64() * 1e3;
        Ok(Decision {
            chosen: indices[plan.chosen],
            entropies_nats: plan.entropies_nats,
            crops: predictions
                .iter()
                .map(|p| (p.crop, p.right_crop_u_min_px))
                .collect(),
            times,
            screen_ms,
        })
    }
}

/// A benchmarked decision.
struct Decision {
    /// The chosen candidate's index among all.
    chosen: usize,
    /// Entropy of each predicted candidate (in prediction order), nats.
    entropies_nats: Vec<Option<f64>>,
    /// Each predicted candidate's crops (left crop, right crop's first column), for the export.
    crops: Vec<(Option<PixelRect>, Option<i64>)>,
    times: DecisionTimes,
    /// Time to the shortlist (0 without one), milliseconds.
    screen_ms: f64,
}

/// How a decision's choice ranks by a judging full decision's predicted entropies
/// (`reference`, every candidate, no view taken): its rank (1: the same view or one as good)
/// and its entropy above the best, nats.
fn judge(reference: &[Option<f64>], chosen: usize) -> (usize, f64) {
    let h: Vec<f64> = reference
        .iter()
        .map(|h| h.unwrap_or(f64::INFINITY))
        .collect();
    let best = h.iter().copied().fold(f64::INFINITY, f64::min);
    let rank = 1 + h.iter().filter(|&&x| x < h[chosen]).count();
    (rank, h[chosen] - best)
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
    let decider = Decider {
        scene: &scene,
        predictor: &predictor,
        seed: args.seed,
    };
    let all = rayon::current_num_threads();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    // A warm-up decision: caches, page faults.
    decider.decide(&settings, None)?;
    let one_thread = one.install(|| decider.decide(&settings, None))?.times;
    let reference = decider.decide(&settings, None)?;
    let all_threads = reference.times;
    let crops = &reference.crops;
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
    if !(args.shortlist.is_empty() && args.prediction_spp.is_empty()) {
        let ks: Vec<Option<usize>> = if args.shortlist.is_empty() {
            vec![None]
        } else {
            args.shortlist.iter().map(|&k| Some(k as usize)).collect()
        };
        let spps = if args.prediction_spp.is_empty() {
            vec![settings.samples_per_pixel]
        } else {
            args.prediction_spp.clone()
        };
        let judged;
        let judge_by = match args.judge_spp {
            Some(spp) => {
                let judging = PredictionSettings {
                    samples_per_pixel: spp,
                    ..settings
                };
                judged = decider.decide(&judging, None)?;
                &judged
            }
            None => &reference,
        };
        let judge_spp = args.judge_spp.unwrap_or(settings.samples_per_pixel);
        // The worst candidate's rank and regret say how much a choice can lose here.
        let (worst_rank, worst_regret) = (0..args.candidates as usize)
            .map(|i| judge(&judge_by.entropies_nats, i))
            .fold((1, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        let mut table = format!(
            "Cheaper decisions on {all} threads, each judged by the predicted entropies of a full \
             decision at {judge_spp} spp (it chose candidate {}; its worst candidate ranks \
             {worst_rank}, {worst_regret:.3} nats above it): render only the K best by a \
             constant-σ_z screen, at fewer samples per pixel.\n\n\
             | shortlist K | prediction spp | screen ms | total ms | speed-up | chosen | rank by the judge | entropy above its best, nats |\n\
             |---:|---:|---:|---:|---:|---:|---:|---:|\n",
            judge_by.chosen
        );
        let mut csv = String::from(
            "threads,candidates,shortlist,prediction_spp,screen_ms,total_ms,chosen,reference_rank,entropy_regret_nats\n",
        );
        for &k in &ks {
            for &spp in &spps {
                let cheaper = PredictionSettings {
                    samples_per_pixel: spp,
                    ..settings
                };
                let d = decider.decide(&cheaper, k)?;
                let (rank, regret) = judge(&judge_by.entropies_nats, d.chosen);
                let k = k.map_or(args.candidates as usize, |k| {
                    k.min(args.candidates as usize)
                });
                let _ = writeln!(
                    table,
                    "| {k} | {spp} | {:.0} | {:.0} | {:.1} | {} | {rank} | {regret:.3} |",
                    d.screen_ms,
                    d.times.total_ms,
                    all_threads.total_ms / d.times.total_ms,
                    d.chosen
                );
                let _ = writeln!(
                    csv,
                    "{all},{},{k},{spp},{:.3},{:.3},{},{rank},{regret:.6}",
                    args.candidates, d.screen_ms, d.times.total_ms, d.chosen
                );
            }
        }
        println!("{table}");
        if let Some(path) = &args.variants_csv {
            write_file_atomically(path, csv.as_bytes())?;
        }
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
        let path = export_decision(dir, &scene, &object, &settings, crops, glint_times)?;
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
