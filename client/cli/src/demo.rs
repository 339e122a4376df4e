//! The main job (`cargo run --release` with no arguments): one active pose-refinement session
//! on a mock bin of a shiny part. Capture, refine, predict every candidate view, choose the
//! next by minimum entropy, repeat until the entropy threshold or the view budget; a table per
//! step and a report folder with an `index.html` over its pictures.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glint_camera::record::to_8bit;
use glint_eval::active::{
    ActiveScene, ActiveSceneSpec, CONST_SIGMA_Z_M, Masking, deviations, prediction_object,
    session_config, set_up,
};
use glint_geometry::io::write_file_atomically;
use glint_geometry::parts::Part;
use glint_geometry::pose_deviation::PoseDeviation;
use glint_orchestrator::local::{LocalEstimation, LocalPrediction};
use glint_orchestrator::session::{self, Session, Stages, StepRecord, ViewPolicy};
use glint_orchestrator::stages::PredictionObject;

pub const DEFAULT_OUT: &str = "glint-out";

#[derive(clap::Args, Clone)]
pub struct DemoArgs {
    /// Report folder (index.html, captures, plots).
    #[arg(long, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// The part in the bin.
    #[arg(long, default_value = "zigzag")]
    pub part: Part,
    /// How the next view is chosen: nbv, nbv-const-sigma, random, max-distance.
    #[arg(long, default_value = "nbv")]
    pub policy: ViewPolicy,
    /// The calibration the entropy policies' render workers use.
    #[command(flatten)]
    pub calibration: crate::calibration_args::CalibrationArgs,
    /// The render workers render the bin with the part (occlusion by its walls,
    /// inter-reflection from its floor), beyond the paper: `false` renders the part alone,
    /// as the paper does. On the Zigzag the bin brings the predicted entropy within 0.3 nats
    /// of the one reached (1.4 nats optimistic without; `glint eval active`).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub predict_bin: bool,
    /// Views at most (the first included).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub max_views: u32,
    /// Candidate views on the cap above the bin.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(2..=256))]
    pub candidates: u32,
    /// Parts in the bin.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub instances: u32,
    /// Stop once the pose is this certain: the entropy of a pose with this standard deviation
    /// in every translation axis (mm) and the same number in every rotation axis (degrees).
    #[arg(long, default_value_t = 0.03)]
    pub stop_sigma_mm_deg: f64,
    /// The part's pixels in a view: the silhouette of the pose hypothesis grown by this, mm
    /// (the detector's error), then re-masked at the first refinement with
    /// --final-mask-margin-mm and refined again.
    #[arg(long, default_value_t = 10.0)]
    pub mask_margin_mm: f64,
    #[arg(long, default_value_t = 3.0)]
    pub final_mask_margin_mm: f64,
    /// Depth points within this of the bin's floor (known from the cell's calibration) are
    /// background, mm.
    #[arg(long, default_value_t = 2.0)]
    pub floor_clearance_mm: f64,
    /// Seed of the bin, the detector's error, the captures and the predictions.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Camera resolution, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    /// Samples per pixel of the mock camera's renders.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub spp: u32,
}

impl Default for DemoArgs {
    fn default() -> Self {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Wrapper {
            #[command(flatten)]
            args: DemoArgs,
        }
        Wrapper::parse_from(["glint"]).args
    }
}

/// The entropy (nats) of a 6-D Gaussian pose with σ_t metres per translation axis and σ_r
/// radians per rotation axis: h = 3 ln(2πe) + 3 ln σ_t + 3 ln σ_r (eq 20).
fn entropy_of_sigmas(sigma_t_m: f64, sigma_r_rad: f64) -> f64 {
    3.0 * (2.0 * std::f64::consts::PI * std::f64::consts::E).ln()
        + 3.0 * sigma_t_m.ln()
        + 3.0 * sigma_r_rad.ln()
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.stop_sigma_mm_deg.is_finite() && args.stop_sigma_mm_deg > 0.0,
        "--stop-sigma-mm-deg: {} must be a positive number",
        args.stop_sigma_mm_deg
    );
    for (name, mm) in [
        ("--mask-margin-mm", args.mask_margin_mm),
        ("--final-mask-margin-mm", args.final_mask_margin_mm),
        ("--floor-clearance-mm", args.floor_clearance_mm),
    ] {
        anyhow::ensure!(
            mm.is_finite() && (0.0..=100.0).contains(&mm),
            "{name}: {mm} must be 0 to 100 mm"
        );
    }
    let started = Instant::now();
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let spec = ActiveSceneSpec {
        part: args.part,
        instances: args.instances,
        seed: args.seed,
        width_px: args.resolution.0,
        height_px: args.resolution.1,
        samples_per_pixel: args.spp,
        candidates: args.candidates as usize,
    };
    // The calibration first: a bad file fails before the bin is set up.
    let calibration = if args.policy.prediction(CONST_SIGMA_Z_M).is_some() {
        Some(args.calibration.load(args.part)?)
    } else {
        None
    };
    let scene = set_up(&spec)?;
    let entropy_threshold_nats = entropy_of_sigmas(
        args.stop_sigma_mm_deg * 1e-3,
        args.stop_sigma_mm_deg.to_radians(),
    );
    let masking = Masking {
        margin_m: args.mask_margin_mm * 1e-3,
        final_margin_m: args.final_mask_margin_mm * 1e-3,
        floor_clearance_m: args.floor_clearance_mm * 1e-3,
    };
    let config = session_config(
        &scene,
        args.policy,
        args.max_views as usize,
        Some(entropy_threshold_nats),
        args.seed,
        &masking,
    )?;
    let (initial, _) = deviations(&scene, &[]);
    println!(
        "Active session: {} (instance {} in a bin of {}), {} candidate views, policy {}, at most \
         {} views, stop below {entropy_threshold_nats:.1} nats ({} mm/{}° per axis).",
        args.part.display_name(),
        scene.target + 1,
        args.instances,
        args.candidates,
        args.policy.name(),
        args.max_views,
        args.stop_sigma_mm_deg,
        args.stop_sigma_mm_deg
    );
    println!(
        "Initial pose: a stand-in detector (ground truth perturbed as in `glint eval refine`), \
         {:.1} mm / {:.1}° off; the target is {:.0} % visible from the first view.",
        initial.translation_mm(),
        initial.rotation_deg(),
        100.0 * scene.target_visib_fract
    );
    println!(
        "The part's pixels in each view: the silhouette of the pose hypothesis grown by {} mm, \
         then by {} mm at the first refinement, without points within {} mm of the bin's floor \
         (no ground-truth masks).",
        args.mask_margin_mm, args.final_mask_margin_mm, args.floor_clearance_mm
    );
    let estimation = LocalEstimation::default();
    let workers = LocalPrediction::default();
    let prediction_object = match &calibration {
        Some(calibration) => Some(prediction_object(&scene, calibration, args.predict_bin)?),
        None => None,
    };
    let stages = Stages {
        camera: &scene.camera,
        estimation: &estimation,
        prediction: prediction_object.as_ref().map(|o| {
            (
                &workers as &dyn glint_orchestrator::stages::PredictionStage,
                o,
            )
        }),
    };
    let mut session = Session::new("demo".into(), config).map_err(anyhow::Error::msg)?;
    let bar = glint_eval::progress::bar(args.max_views as u64, "views");
    let header = table_header();
    bar.suspend(|| println!("{header}"));
    session::run(
        &mut session,
        &scene.object,
        &stages,
        |step| {
            let (_, devs) = deviations(&scene, std::slice::from_ref(step));
            bar.suspend(|| println!("{}", table_row(step, &devs[0])));
            bar.inc(1);
        },
        || false,
    )
    .map_err(anyhow::Error::msg)
    .context("the session failed")?;
    bar.finish_and_clear();
    let session_s = started.elapsed().as_secs_f64();
    println!(
        "Session {:?} after {} views in {session_s:.1} s.",
        session.state,
        session.steps.len()
    );
    let index = write_report(out, &scene, &session, &header, prediction_object.as_ref())?;
    println!("Report: {}", index.display());
    Ok(())
}

/// The σ̌_z map the render workers predicted for the view chosen after `step` (the same
/// request as the planner's, with maps), as EXR and PNG at `stem`.
fn predicted_map(
    object: &PredictionObject,
    predictor: &glint_uncertainty::PredictorObject,
    session: &Session,
    step: &StepRecord,
    next: usize,
    stem: &Path,
) -> anyhow::Result<()> {
    let settings = glint_uncertainty::PredictionSettings {
        shots: object.shots,
        window_radius_px: object.window_radius_px,
        with_maps: true,
        ..glint_uncertainty::PredictionSettings::default()
    };
    let prediction = glint_uncertainty::predict_candidate(
        predictor,
        &step.t_w_o,
        &session.config.candidates[next],
        &settings,
        glint_uncertainty::candidate_seed(session.config.seed, next as u32),
    )?;
    glint_eval::active::write_prediction_maps(&prediction, stem, 0.1e-3)
}

/// An entropy with two decimals, or "-" when there is none.
fn nats_or_dash(h: Option<f64>) -> String {
    h.map_or_else(|| "-".into(), |h| format!("{h:.2}"))
}

fn table_header() -> String {
    format!(
        "{:>4} {:>5} {:>7} {:>8} {:>10} {:>10} {:>8} {:>7} {:>9} {:>9}  {}",
        "step",
        "view",
        "points",
        "total",
        "h_pred",
        "h",
        "err_mm",
        "err_deg",
        "capture_s",
        "predict_s",
        "refine"
    )
}

fn table_row(step: &StepRecord, deviation: &PoseDeviation) -> String {
    format!(
        "{:>4} {:>5} {:>7} {:>8} {:>10} {:>10.2} {:>8.2} {:>7.2} {:>9.2} {:>9.2}  {}",
        step.step,
        step.view,
        step.view_points,
        step.total_points,
        nats_or_dash(step.predicted_entropy_nats),
        step.entropy_nats,
        deviation.translation_mm(),
        deviation.rotation_deg(),
        step.times.capture_ms * 1e-3,
        step.times.predict_ms * 1e-3,
        step.refine_status
    )
}

/// Writes the captures, the error-and-entropy plot and `index.html`; returns the index's path.
fn write_report(
    out: &Path,
    scene: &ActiveScene,
    session: &Session,
    header: &str,
    prediction: Option<&PredictionObject>,
) -> anyhow::Result<PathBuf> {
    let (initial, devs) = deviations(scene, &session.steps);
    let captures = out.join("captures");
    std::fs::create_dir_all(&captures)
        .with_context(|| format!("creating {}", captures.display()))?;
    let mut rows = String::new();
    // The render workers' view of the part, for the predicted maps.
    let predictor = match prediction {
        Some(object) => Some(
            object.predictor(
                glint_orchestrator::local::SdfCache::default()
                    .grid(&object.object)
                    .map_err(anyhow::Error::msg)?,
            ),
        ),
        None => None,
    };
    for (step, view) in session.steps.iter().zip(&session.views) {
        let m = &view.measurement;
        let left = to_8bit(&m.left[0], m.max_dn);
        let left_path = captures.join(format!("step{:02}_left.png", step.step));
        glint_camera::dataset::write_png_u8(&left_path, &left)
            .with_context(|| format!("writing {}", left_path.display()))?;
        let depth = &m.depth.depth_m;
        let (lo, hi) = glint_plot::padded_range(depth.data().iter().map(|&z| f64::from(z)), 0.0);
        let depth_png = glint_plot::scalar_image_png(
            depth.data(),
            depth.width(),
            depth.height(),
            lo,
            hi,
            [0, 0, 0],
        )?;
        let depth_path = captures.join(format!("step{:02}_depth.png", step.step));
        write_file_atomically(&depth_path, &depth_png)
            .with_context(|| format!("writing {}", depth_path.display()))?;
        let next_map = match (prediction.zip(predictor.as_ref()), step.next_view) {
            (Some((object, predictor)), Some(next)) => {
                let stem = captures.join(format!("step{:02}_next_view_sigma", step.step));
                predicted_map(object, predictor, session, step, next, &stem)?;
                format!(
                    "<img src=\"captures/step{:02}_next_view_sigma.png\" height=160>",
                    step.step
                )
            }
            _ => String::new(),
        };
        let _ = writeln!(
            rows,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.2}</td><td>{:.2} mm / {:.2}°</td>\
             <td><img src=\"captures/step{:02}_left.png\" width=320></td>\
             <td><img src=\"captures/step{:02}_depth.png\" width=320></td><td>{next_map}</td></tr>",
            step.step,
            step.view,
            step.total_points,
            nats_or_dash(step.predicted_entropy_nats),
            step.entropy_nats,
            devs[step.step].translation_mm(),
            devs[step.step].rotation_deg(),
            step.step,
            step.step
        );
    }
    let plot = progress_plot(&initial, &devs, &session.steps)?;
    write_file_atomically(&out.join("session.png"), &plot)
        .with_context(|| format!("writing {}", out.join("session.png").display()))?;
    let mut table = String::from(header);
    table.push('\n');
    for (s, d) in session.steps.iter().zip(&devs) {
        table += &table_row(s, d);
        table.push('\n');
    }
    write_file_atomically(&out.join("steps.txt"), table.as_bytes())?;
    let html = format!(
        "<!doctype html><html><head><meta charset=utf-8><title>Glint active session</title>\
         <style>body{{font-family:sans-serif;margin:2em}}td{{padding:4px;vertical-align:top}}</style></head><body>\
         <h1>Glint: active pose refinement of a {part}</h1>\
         <p>Policy <b>{policy}</b>, {n} views, state {state:?}. The initial pose comes from a stand-in \
         detector (ground truth perturbed as in <code>glint eval refine</code>): {e0t:.1} mm / {e0r:.1}° off. \
         Errors are against the mock camera's ground truth (evaluation only: the session never reads it).</p>\
         <img src=\"session.png\"><h2>Steps</h2><pre>{table}</pre>\
         <table><tr><th>step</th><th>view</th><th>points</th><th>h predicted</th><th>h</th><th>error</th>\
         <th>left pattern</th><th>depth</th><th>next view: predicted σ̌_z (0–0.1 mm; red: eq 16, magenta: eq 17, orange: right camera blind)</th></tr>{rows}</table></body></html>",
        part = scene.object.name,
        policy = session.config.policy.name(),
        n = session.steps.len(),
        state = session.state,
        e0t = initial.translation_mm(),
        e0r = initial.rotation_deg(),
    );
    let index = out.join("index.html");
    write_file_atomically(&index, html.as_bytes())
        .with_context(|| format!("writing {}", index.display()))?;
    Ok(index)
}

/// Pose error (mm, degrees) and entropy (nats) against the step.
fn progress_plot(
    initial: &PoseDeviation,
    devs: &[PoseDeviation],
    steps: &[StepRecord],
) -> anyhow::Result<Vec<u8>> {
    use plotters::prelude::*;
    let errors: Vec<(f64, f64, f64)> = std::iter::once(initial)
        .chain(devs)
        .enumerate()
        .map(|(i, d)| (i as f64, d.translation_mm(), d.rotation_deg()))
        .collect();
    let entropies: Vec<(f64, f64)> = steps
        .iter()
        .map(|s| ((s.step + 1) as f64, s.entropy_nats))
        .collect();
    let predicted: Vec<(f64, f64)> = steps
        .iter()
        .filter_map(|s| Some(((s.step + 1) as f64, s.predicted_entropy_nats?)))
        .collect();
    let n = errors.len() as f64;
    Ok(glint_plot::png(1000, 420, |root| {
        let (left, right) = root.split_horizontally(500);
        let top = errors.iter().map(|e| e.1.max(e.2)).fold(1e-3, f64::max) * 1.1;
        let mut chart = ChartBuilder::on(&left)
            .caption("pose error vs views", (glint_plot::FONT, 18))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..(n - 0.5).max(1.0), 0.0..top)?;
        chart
            .configure_mesh()
            .x_desc("views taken (0 = detector)")
            .y_desc("mm / degrees")
            .draw()?;
        chart
            .draw_series(LineSeries::new(errors.iter().map(|e| (e.0, e.1)), &BLUE))?
            .label("translation, mm")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], BLUE));
        chart
            .draw_series(LineSeries::new(errors.iter().map(|e| (e.0, e.2)), &RED))?
            .label("rotation, degrees")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], RED));
        chart.configure_series_labels().border_style(BLACK).draw()?;
        let (lo, hi) =
            glint_plot::padded_range(entropies.iter().chain(&predicted).map(|p| p.1), 0.1);
        let mut chart = ChartBuilder::on(&right)
            .caption("pose entropy vs views", (glint_plot::FONT, 18))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(0.5..(n - 0.5).max(1.5), lo..hi)?;
        chart
            .configure_mesh()
            .x_desc("views taken")
            .y_desc("nats")
            .draw()?;
        chart
            .draw_series(LineSeries::new(entropies.iter().copied(), &BLACK))?
            .label("achieved")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], BLACK));
        chart
            .draw_series(predicted.iter().map(|&p| Circle::new(p, 4, GREEN.filled())))?
            .label("predicted when chosen")
            .legend(|(x, y)| Circle::new((x + 7, y), 4, GREEN.filled()));
        chart.configure_series_labels().border_style(BLACK).draw()?;
        Ok(())
    })?)
}
