//! The main job (`cargo run --release` with no arguments): one active pose-refinement session
//! on a mock bin of a shiny part, run the way a deployment runs it. It starts `glint serve all`
//! inside this process on a loopback port and drives it as any client does (`glint session
//! run`'s code): set up the mock bin, ask a stand-in detector, start the session, print a row
//! per streamed step. The report — captures, the σ̌_z map the render workers predicted for each
//! chosen view, an error-and-entropy plot, `index.html` — reads the session from the
//! orchestrator this process runs.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use glint_camera::record::to_8bit;
use glint_geometry::io::write_file_atomically;
use glint_geometry::parts::Part;
use glint_geometry::pose_deviation::PoseDeviation;
use glint_orchestrator::session::{StepRecord, ViewPolicy};
use glint_orchestrator::stages::{
    PartCalibration, PredictionObject, PredictionRequest, PredictionStage,
};
use glint_orchestrator::store::StoredSession;

use crate::serve_cmd::{AllArgs, CameraArgs, FanOutArgs, InProcessServer};
use glint_client::calibration::{
    CALIBRATION_EXPOSURES_S, CALIBRATION_VIEWS, CalibrationCache, CalibrationEvent,
    MockCalibrationSpec, calibrate_mock_part,
};
use glint_client::{MockSession, RunOutcome, run_mock_session, table_header};
use glint_eval::active::Calibration;

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
    /// The part's fitted material (`glint calibrate bsdf`) for the render workers. Without
    /// --material and --response the demo calibrates the part through its calibration service
    /// once and caches the result in OUT/calibration/PART/.
    #[arg(long, requires = "response")]
    pub material: Option<PathBuf>,
    /// The camera response (`glint calibrate response`) that goes with --material.
    #[arg(long, requires = "material")]
    pub response: Option<PathBuf>,
    /// Samples per pixel of the first calibration's capture (2 views × 11 exposures).
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub calibration_spp: u32,
    /// Adam iterations of the first calibration's BSDF fit.
    #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u32).range(1..=10000))]
    pub calibration_iterations: u32,
    /// The part's metallic weight, when its finish is known (1: bare metal, 0: painted or
    /// plastic), held by the first calibration's BSDF fit instead of fitted. A cached
    /// calibration is used as it is.
    #[arg(long, value_parser = crate::calibrate_cmd::parse_unit_interval::<f64>)]
    pub calibration_known_metallic: Option<f64>,
    /// Start values of the first calibration's BSDF fit, comma separated: one fit per start,
    /// the lowest unbiased loss kept (a near-mirror such as the Chrome Screw needs `0.5,0.1`;
    /// see `glint calibrate bsdf --start`).
    #[arg(long, value_delimiter = ',', default_value = "0.5", value_parser = crate::calibrate_cmd::parse_unit_interval::<f64>)]
    pub calibration_start: Vec<f64>,
    /// Views at most (the first included).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub max_views: u32,
    /// Candidate views on the cap above the bin.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(2..=256))]
    pub candidates: u32,
    /// Parts in the bin.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    /// Stop once the pose is this certain: the entropy of a pose with this standard deviation
    /// in every translation axis (mm) and the same number in every rotation axis (degrees).
    #[arg(long, default_value_t = 0.4)]
    pub stop_sigma_mm_deg: f64,
    /// Seed of the bin, the detector's error, the captures and the predictions.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Camera resolution, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    /// Samples per pixel of the mock camera's renders.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub spp: u32,
    /// The orchestrator's fan-out and what it knows of the cell (`--cell none`: the render
    /// workers see the part alone, as the paper renders it).
    #[command(flatten)]
    pub fan_out: FanOutArgs,
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

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.stop_sigma_mm_deg.is_finite() && args.stop_sigma_mm_deg > 0.0,
        "--stop-sigma-mm-deg: {} must be a positive number",
        args.stop_sigma_mm_deg
    );
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    // Calibration files first: a bad file fails before anything starts.
    let given = match (&args.material, &args.response) {
        (Some(material), Some(response)) => Some(Calibration::load(material, response)?),
        _ => None,
    };
    let entropy_threshold_nats = glint_estimation::nbv::entropy_of_axis_sigmas(
        args.stop_sigma_mm_deg * 1e-3,
        args.stop_sigma_mm_deg.to_radians(),
    );
    let spec = MockSession {
        part: args.part,
        instances: args.instances,
        policy: args.policy,
        max_views: args.max_views,
        entropy_threshold_nats,
        candidates: args.candidates,
        seed: args.seed,
        width_px: args.resolution.0,
        height_px: args.resolution.1,
        samples_per_pixel: args.spp,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        let all = AllArgs {
            camera: CameraArgs::empty(),
            workers: None,
            fan_out: args.fan_out.clone(),
            state: Default::default(),
        };
        let server = InProcessServer::start(&all, Duration::from_secs(10)).await?;
        println!(
            "Glint's services (`glint serve all`) on {} in this process; the session runs \
             through them over gRPC.",
            server.addr
        );
        let calibration = match demo_calibration(args, given, &server.addr.to_string()).await {
            Ok(c) => c,
            Err(e) => {
                server.stop().await?;
                return Err(e);
            }
        };
        let calibration_note = calibration.as_ref().map_or_else(
            || {
                format!(
                    "none: the {} policy renders no predictions",
                    args.policy.name()
                )
            },
            |(_, note)| note.clone(),
        );
        let calibration = calibration.map(|(c, _)| c);
        println!(
            "Active session: {} in a bin of {}, {} candidate views, policy {}, at most {} views, \
             stop below {entropy_threshold_nats:.1} nats ({} mm/{}° per axis).",
            args.part.display_name(),
            args.instances,
            args.candidates,
            args.policy.name(),
            args.max_views,
            args.stop_sigma_mm_deg,
            args.stop_sigma_mm_deg
        );
        println!(
            "The part's pixels in each view: the silhouette of the pose hypothesis, dilated \
             (no ground-truth masks); errors are against the mock camera's truth, read by this \
             client only."
        );
        let started = Instant::now();
        let bar = glint_eval::progress::bar(u64::from(args.max_views), "views");
        let mut rows = vec![table_header()];
        let addr = server.addr.to_string();
        let outcome = run_mock_session(
            &addr,
            &addr,
            &spec,
            calibration.as_ref(),
            &Default::default(),
            |row, step| {
                bar.suspend(|| println!("{row}"));
                if step.is_some() {
                    bar.inc(1);
                    rows.push(row.to_owned());
                }
            },
        )
        .await;
        bar.finish_and_clear();
        let outcome = match outcome {
            Ok(o) => o,
            Err(e) => {
                server.stop().await?;
                return Err(e.context("the session failed"));
            }
        };
        let session_s = started.elapsed().as_secs_f64();
        println!(
            "Session {} {} after {} views in {session_s:.1} s: pose error {}.",
            outcome.session.session_id,
            glint_proto::v1::SessionState::try_from(outcome.session.state)
                .map_or("?", |s| s.as_str_name()),
            outcome.steps.len(),
            error_summary(&outcome)
        );
        let orchestrator = server.orchestrator.clone();
        let out = out.clone();
        let error = outcome_error(&outcome).map(str::to_owned);
        // The store's reads and the render workers' object (it asks the camera for its rig
        // over gRPC, a blocking call) belong on a blocking thread, as the report does.
        let report = tokio::task::spawn_blocking(move || {
            let stored = orchestrator
                .stored(&outcome.session.session_id)
                .map_err(anyhow::Error::msg)?;
            let object = orchestrator
                .prediction_object(&stored)
                .map_err(anyhow::Error::msg)?;
            write_report(
                &out,
                &stored,
                orchestrator.prediction.as_ref(),
                object.as_ref(),
                &outcome,
                &rows,
                &calibration_note,
            )
        })
        .await
        .context("the report writer panicked")?;
        server.stop().await?;
        println!("Report: {}", report?.display());
        if let Some(e) = error {
            anyhow::bail!("the session failed: {e}");
        }
        Ok(())
    })
}

/// The render workers' calibration, with a note of where it came from for the report: none
/// when the policy renders nothing, else the files given, else [`calibrate_once`]'s.
async fn demo_calibration(
    args: &DemoArgs,
    given: Option<Calibration>,
    addr: &str,
) -> anyhow::Result<Option<(PartCalibration, String)>> {
    if args.policy.prediction(0.0).is_none() {
        return Ok(None);
    }
    let (files, source) = match given {
        Some(files) => {
            println!("Calibration: the files given (--material, --response).");
            (files, "the files given (--material, --response)".to_owned())
        }
        None => calibrate_once(args, addr).await?,
    };
    let p = files.material.params()?;
    let note = format!(
        "{source}; material base colour {:.3}, metallic {:.3}, roughness {:.3}, specular {:.3}, \
         radiometric scale {:.1}",
        p.base_color,
        p.metallic,
        p.roughness,
        p.specular,
        files.material.radiometric_scale().unwrap_or(f64::NAN)
    );
    let calibration =
        PartCalibration::from_files(&files).map_err(|e| anyhow::anyhow!("the calibration: {e}"))?;
    Ok(Some((calibration, note)))
}

/// The part's calibration from the cache in the report folder, or — the first time — through
/// the calibration service of the in-process servers at `addr` (see
/// [`glint_client::calibration`]), cached for the next run; with where it came from.
async fn calibrate_once(args: &DemoArgs, addr: &str) -> anyhow::Result<(Calibration, String)> {
    let cache = CalibrationCache::of_part(&args.out.join("calibration"), args.part);
    let cached = cache.load().with_context(|| {
        format!(
            "the calibration cached in {} (delete the folder to calibrate again)",
            cache.dir.display()
        )
    })?;
    if let Some(cached) = cached {
        println!(
            "Calibration: cached in {} (delete it to calibrate again).",
            cache.dir.display()
        );
        if args.calibration_known_metallic.is_some() || args.calibration_start != [0.5] {
            tracing::warn!(
                "--calibration-known-metallic and --calibration-start apply to a new calibration \
                 only: the cached one in {} is used as it is",
                cache.dir.display()
            );
        }
        let source = format!(
            "cached in {} by an earlier run, which fitted it through the calibration service",
            cache.dir.display()
        );
        return Ok((cached, source));
    }
    println!(
        "Calibration (first run only): no calibration cached in {}; calibrating the {} through \
         the calibration service — a capture of {CALIBRATION_VIEWS} views × {} exposures of a \
         bin of known poses at {} spp, the response (CalibrateResponse), the material \
         (FitBsdf, {} iterations{}).",
        cache.dir.display(),
        args.part.display_name(),
        CALIBRATION_EXPOSURES_S.len(),
        args.calibration_spp,
        args.calibration_iterations,
        args.calibration_known_metallic
            .map_or(String::new(), |m| format!(", metallic held at {m}")),
    );
    let spec = MockCalibrationSpec {
        part: args.part,
        width_px: args.resolution.0,
        height_px: args.resolution.1,
        samples_per_pixel: args.calibration_spp,
        fit_iterations: args.calibration_iterations,
        known_metallic: args.calibration_known_metallic,
        starts: args.calibration_start.clone(),
    };
    let started = Instant::now();
    let capture_bar = glint_eval::progress::bar(CALIBRATION_VIEWS as u64, "calibration capture");
    // Made once the fit starts: two bars at once would draw over each other.
    let mut fit_bar = None;
    let mut losses = (f64::NAN, f64::NAN);
    let calibration = calibrate_mock_part(addr, &Default::default(), &spec, &cache, |event| {
        match event {
            CalibrationEvent::ViewRecorded => capture_bar.inc(1),
            CalibrationEvent::ResponseSolved {
                samples,
                residual_rms,
            } => {
                capture_bar.finish_and_clear();
                println!(
                    "  response: {samples} sample pixels, residual RMS {residual_rms:.3} (ln units)"
                );
            }
            CalibrationEvent::FitProgress(p) => {
                if p.iteration == 0 {
                    losses.0 = p.loss;
                }
                losses.1 = p.loss;
                fit_bar
                    .get_or_insert_with(|| {
                        glint_eval::progress::bar(u64::from(p.iterations_total), "BSDF fit")
                    })
                    .set_position(u64::from(p.iteration) + 1);
            }
        }
    })
    .await;
    capture_bar.finish_and_clear();
    if let Some(bar) = fit_bar {
        bar.finish_and_clear();
    }
    let calibration = calibration.context("calibrating through the calibration service")?;
    let p = calibration.material.params()?;
    println!(
        "  material: base colour {:.3}, metallic {:.3}, roughness {:.3}, specular {:.3} \
         (loss {:.4} → {:.4}), radiometric scale {:.1}; {:.1} s in all → {}",
        p.base_color,
        p.metallic,
        p.roughness,
        p.specular,
        losses.0,
        losses.1,
        calibration.material.radiometric_scale().unwrap_or(f64::NAN),
        started.elapsed().as_secs_f64(),
        cache.dir.display()
    );
    let source = format!(
        "fitted through the calibration service on this run ({} s) and cached in {}",
        started.elapsed().as_secs_f64().round(),
        cache.dir.display()
    );
    Ok((calibration, source))
}

fn outcome_error(outcome: &RunOutcome) -> Option<&str> {
    (!outcome.session.error.is_empty()).then_some(outcome.session.error.as_str())
}

/// "11.9 mm / 5.4° (detector) → 1.5 mm / 3.0°".
fn error_summary(outcome: &RunOutcome) -> String {
    let d0 = &outcome.initial_deviation;
    let mut s = format!(
        "{:.1} mm / {:.1}° (detector)",
        d0.translation_mm(),
        d0.rotation_deg()
    );
    if let Some(d) = outcome.deviations.last() {
        let _ = write!(
            s,
            " → {:.2} mm / {:.2}°",
            d.translation_mm(),
            d.rotation_deg()
        );
    }
    s
}

/// The σ̌_z map the render workers predicted for the view chosen after `step` — the very
/// request of the decision (same pose, candidate index and seed), now with maps — as EXR and
/// PNG at `stem`.
fn predicted_map(
    stored: &StoredSession,
    prediction: &dyn PredictionStage,
    object: Option<&PredictionObject>,
    step: &StepRecord,
    next: usize,
    stem: &Path,
) -> anyhow::Result<bool> {
    let (Some(object), Some(sigma)) = (
        object,
        stored
            .session
            .config
            .policy
            .prediction(stored.session.config.const_sigma_z_m),
    ) else {
        return Ok(false);
    };
    let config = &stored.session.config;
    let request = PredictionRequest {
        t_w_o: step.t_w_o,
        candidates: vec![(next as u32, config.candidates[next])],
        sigma,
        seed: config.seed,
        with_maps: true,
    };
    let predicted = prediction
        .predict(object, &request)
        .map_err(anyhow::Error::msg)?;
    let maps = predicted
        .first()
        .and_then(|p| p.maps.as_ref())
        .context("the render worker sent no maps")?;
    glint_eval::active::write_prediction_maps(&maps.sigma_z_m, &maps.cause, stem, 0.1e-3)?;
    Ok(true)
}

/// Writes the captures, the predicted maps, the error-and-entropy plot, the step table and
/// `index.html`; returns the index's path.
fn write_report(
    out: &Path,
    stored: &StoredSession,
    prediction: &dyn PredictionStage,
    object: Option<&PredictionObject>,
    outcome: &RunOutcome,
    table: &[String],
    calibration_note: &str,
) -> anyhow::Result<PathBuf> {
    let session = &stored.session;
    let devs = &outcome.deviations;
    let captures = out.join("captures");
    std::fs::create_dir_all(&captures)
        .with_context(|| format!("creating {}", captures.display()))?;
    let bar = glint_eval::progress::bar(session.steps.len() as u64, "report");
    let mut rows = String::new();
    for ((step, view), dev) in session.steps.iter().zip(&session.views).zip(devs) {
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
        let stem = captures.join(format!("step{:02}_next_view_sigma", step.step));
        let next_map = match step.next_view {
            Some(next) if predicted_map(stored, prediction, object, step, next, &stem)? => format!(
                "<img src=\"captures/step{:02}_next_view_sigma.png\" height=160>",
                step.step
            ),
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
            step.predicted_entropy_nats
                .map_or_else(|| "-".into(), |h| format!("{h:.2}")),
            step.entropy_nats,
            dev.translation_mm(),
            dev.rotation_deg(),
            step.step,
            step.step
        );
        bar.inc(1);
    }
    bar.finish_and_clear();
    let plot = progress_plot(&outcome.initial_deviation, devs, &session.steps)?;
    write_file_atomically(&out.join("session.png"), &plot)
        .with_context(|| format!("writing {}", out.join("session.png").display()))?;
    let table = table.join("\n") + "\n";
    write_file_atomically(&out.join("steps.txt"), table.as_bytes())?;
    let initial = &outcome.initial_deviation;
    let html = format!(
        "<!doctype html><html><head><meta charset=utf-8><title>Glint active session</title>\
         <style>body{{font-family:sans-serif;margin:2em}}td{{padding:4px;vertical-align:top}}</style></head><body>\
         <h1>Glint: active pose refinement of a {part}</h1>\
         <p>Session {id}, policy <b>{policy}</b>, {n} views, state {state:?}, run through Glint's gRPC \
         services. The initial pose comes from a stand-in detector (ground truth perturbed as in \
         <code>glint eval refine</code>): {e0t:.1} mm / {e0r:.1}° off. Errors are against the mock \
         camera's ground truth (evaluation only: the session never reads it).</p>\
         <p>Calibration of the render workers: {calibration_note}.</p>\
         <img src=\"session.png\"><h2>Steps</h2><pre>{table}</pre>\
         <table><tr><th>step</th><th>view</th><th>points</th><th>h predicted</th><th>h</th><th>error</th>\
         <th>left pattern</th><th>depth</th><th>next view: predicted σ̌_z (0–0.1 mm; red: eq 16, magenta: eq 17, orange: right camera blind)</th></tr>{rows}</table></body></html>",
        part = stored.object.name,
        id = session.id,
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
