//! `glint calibrate`: the photometric calibration of §IV-A (camera response by Debevec–Malik)
//! and §IV-B (principled-BSDF fit by differentiable rendering), and their evaluation against
//! the mock camera's hidden ground truth (separate `eval-*` commands: calibration never reads
//! ground truth).

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glint_calibration::bsdf_fit::scene_fit::{
    Capture, CaptureReadError, CaptureReader, CaptureView, LossChoice, SceneFitConfig, fit_scene,
    fit_views, read_capture,
};
use glint_calibration::bsdf_fit::{
    FitProblem, Loss, Residual, error_map_png, fit_history_png, free_of,
};
use glint_calibration::material_file::MaterialFile;
use glint_calibration::response::{
    DebevecConfig, ExposureStack, ResponseTable, calibrate, response_png,
};
use glint_eval::bsdf_check::{
    PartRadiance, median_abs_log_ratio, part_radiance, read_truth, relative_rms,
};
use glint_geometry::io::write_file_atomically;
use glint_render::integrator::{LightTransport, PixelRendering};
use glint_render::sensor::ResponseCurve;

use glint_camera::dataset::calibration_scene;

#[derive(clap::Subcommand)]
pub enum CalibrateCommand {
    /// Camera response g and g⁻¹ from an exposure stack (Debevec–Malik).
    Response(ResponseArgs),
    /// Evaluation only: a recovered response against a ground-truth sensor file.
    EvalResponse(EvalResponseArgs),
    /// Principled-BSDF parameters of the part in a capture (differentiable rendering).
    Bsdf(BsdfArgs),
    /// Evaluation only: a fitted material against the ground truth, at the fitted and a
    /// held-out view.
    EvalBsdf(EvalBsdfArgs),
}

#[derive(clap::Args)]
pub struct BsdfArgs {
    /// The capture: the folder `glint capture --exposure-stack … --out DIR` wrote (DIR, or its
    /// BOP scene DIR/test/000001): labelled poses, camera poses, rig, reference surface and
    /// exposure stacks (ground-truth files are not read).
    #[arg(long)]
    pub scene: PathBuf,
    /// The camera response from `glint calibrate response`.
    #[arg(long)]
    pub response: PathBuf,
    /// Output material JSON; `<stem>.history.png` (loss and parameters) and `<stem>.error.png`
    /// (|fitted − target| map of the first view) are written beside it.
    #[arg(long)]
    pub out: PathBuf,
    /// Views (image ids) whose radiance maps enter the loss, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "0")]
    pub views: Vec<u32>,
    /// Adam iterations.
    #[arg(long, default_value_t = 300)]
    pub iterations: usize,
    /// Light transport of the fit's renders: `multi` (inter-reflections, as the camera sees
    /// them) or `single` (direct reflection only).
    #[arg(long, default_value = "multi", value_parser = parse_transport)]
    pub transport: LightTransport,
    /// Samples per pixel of multi-path renders.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub spp: u32,
    /// Use every N-th object pixel in u and v.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub pixel_step: u32,
    /// The gradient's residual with multi-path: `same` (the samples of the derivative) or
    /// `decorrelated` (an independent estimate: unbiased, one more render per pixel).
    #[arg(long, default_value = "decorrelated", value_parser = parse_residual)]
    pub residual: Residual,
    /// The loss: `l2` (Σ (r − t)² / Σ t², the paper's), `ln` (squared error of ln radiance,
    /// ε = 1 % of the mean target: every pixel counts alike) or `huber` (L2 up to δ = the
    /// 90th percentile of the target, linear beyond: fireflies get a bounded pull).
    #[arg(long, value_enum, default_value_t = LossArg::L2)]
    pub loss: LossArg,
    /// Compare the mean radiance of B × B pixel blocks instead of pixels (1: pixels): averages
    /// the Monte Carlo noise of render and capture alike. Blocks gather the pixels kept by
    /// --pixel-step.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub block_px: u32,
    /// Fresh Monte Carlo samples every iteration (stochastic gradient descent) instead of the
    /// same samples throughout.
    #[arg(long)]
    pub reseed: bool,
    /// Multi-path renders of the fit shade every vertex after the first as if at least this
    /// rough (path-space regularisation): glossy-to-glossy inter-reflections of the point-like
    /// projector are blurred, a bias, and lose the fireflies that otherwise swamp the loss on
    /// shiny metals. 0 renders exactly as the camera does.
    #[arg(long, default_value_t = 0.5, value_parser = parse_unit_interval::<f32>)]
    pub min_indirect_roughness: f32,
    /// Starting value of every free parameter, comma separated for several fits from
    /// different starts: the one with the lowest unbiased L2 (two independent renders at 4×
    /// the samples, the final floor) is kept. 0.5 is the paper's start;
    /// a near-mirror (the Chrome Screw) also needs a low one, e.g. `0.5,0.1`.
    #[arg(long, value_delimiter = ',', default_value = "0.5", value_parser = parse_unit_interval::<f32>)]
    pub start: Vec<f32>,
    /// The regularisation floor of the last iteration: it falls linearly from
    /// --min-indirect-roughness to this, so that the fit ends on nearly exact renders.
    #[arg(long, default_value_t = 0.1, value_parser = parse_unit_interval::<f32>)]
    pub final_min_indirect_roughness: f32,
    /// The part's metallic weight when its finish is known (1: bare metal, 0: painted or
    /// plastic): held at this value instead of fitted. A free fit can add a diffuse lobe to
    /// bare metal and still match the radiance (base colour and specular make up for it).
    #[arg(long, value_parser = parse_unit_interval::<f32>)]
    pub known_metallic: Option<f32>,
}

/// A number in [0, 1] (a share, a roughness), for clap.
pub(crate) fn parse_unit_interval<T>(s: &str) -> Result<T, String>
where
    T: std::str::FromStr + PartialOrd + From<u8>,
{
    match s.parse::<T>() {
        Ok(x) if (T::from(0)..=T::from(1)).contains(&x) => Ok(x),
        _ => Err(format!("{s:?} must be a number in [0, 1]")),
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LossArg {
    L2,
    Ln,
    Huber,
}

fn parse_residual(s: &str) -> Result<Residual, String> {
    match s {
        "same" => Ok(Residual::SameSamples),
        "decorrelated" => Ok(Residual::Decorrelated),
        _ => Err(format!("residual {s:?} must be `same` or `decorrelated`")),
    }
}

fn parse_transport(s: &str) -> Result<LightTransport, String> {
    match s {
        "single" => Ok(LightTransport::SinglePath),
        "multi" => Ok(LightTransport::MULTI_PATH_DEFAULT),
        _ => Err(format!("transport {s:?} must be `single` or `multi`")),
    }
}

#[derive(clap::Args)]
pub struct EvalBsdfArgs {
    /// The capture the material was fitted on (as for `calibrate bsdf`).
    #[arg(long)]
    pub scene: PathBuf,
    /// A material written by `glint calibrate bsdf`.
    #[arg(long)]
    pub material: PathBuf,
    /// Ground-truth material: the capture's `glint/gt_materials.json` (the default), another
    /// capture's, or a material file.
    #[arg(long)]
    pub gt_material: Option<PathBuf>,
    /// The held-out view (image id); default: the first view the fit did not use.
    #[arg(long)]
    pub held_out_view: Option<u32>,
    /// Optional PNG: |fitted − ground truth| radiance at the held-out view.
    #[arg(long)]
    pub error_map: Option<PathBuf>,
    /// Light transport of the comparison renders (both materials rendered alike).
    #[arg(long, default_value = "multi", value_parser = parse_transport)]
    pub transport: LightTransport,
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub spp: u32,
    /// Regularisation of the comparison renders, as `calibrate bsdf --min-indirect-roughness`
    /// (0: exact).
    #[arg(long, default_value_t = 0.0, value_parser = parse_unit_interval::<f32>)]
    pub min_indirect_roughness: f32,
    /// Optional: the response the fit used. Then the L2 loss against the measured radiance
    /// of the fitted views is printed for the fitted and the true material: a true material
    /// with the lower loss means the optimiser stopped short; with the higher loss, the
    /// measurement or the scene model is off.
    #[arg(long)]
    pub response: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct ResponseArgs {
    /// Directory with stack.json and its images.
    #[arg(long)]
    pub stack: PathBuf,
    /// Output JSON (g⁻¹ per DN level and g over ln exposure).
    #[arg(long)]
    pub out: PathBuf,
    /// Optional PNG plot of g (DN over ln exposure).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Smoothness weight λ.
    #[arg(long, default_value_t = 10.0)]
    pub lambda: f64,
    /// Number of sample pixels.
    #[arg(long, default_value_t = 70)]
    pub samples: usize,
}

#[derive(clap::Args)]
pub struct EvalResponseArgs {
    /// A response written by `glint calibrate response`.
    #[arg(long)]
    pub response: PathBuf,
    /// Ground-truth sensor JSON (a `Sensor`, or an object with a `response` or `sensor` field).
    #[arg(long)]
    pub gt_sensor: PathBuf,
    /// Well-exposed range compared, as fractions of full scale.
    #[arg(long, default_value_t = 0.1)]
    pub from: f64,
    #[arg(long, default_value_t = 0.9)]
    pub to: f64,
    /// Optional PNG: recovered and true g together.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

pub fn run(command: CalibrateCommand) -> anyhow::Result<()> {
    match command {
        CalibrateCommand::Response(args) => response(&args),
        CalibrateCommand::EvalResponse(args) => eval_response(&args),
        CalibrateCommand::Bsdf(args) => bsdf(&args),
        CalibrateCommand::EvalBsdf(args) => eval_bsdf(&args),
    }
}

/// The exposure stack in `dir` (the camera's folder format), validated for calibration.
fn read_stack(dir: &Path) -> anyhow::Result<ExposureStack> {
    let files = glint_camera::dataset::ExposureStackFiles::read(dir)?;
    ExposureStack::new(files.images, files.exposures_s, files.bit_depth)
        .with_context(|| format!("exposure stack {}", dir.display()))
}

fn response(args: &ResponseArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let stack = read_stack(&args.stack)?;
    let config = DebevecConfig {
        lambda: args.lambda,
        samples: args.samples,
    };
    let table = calibrate(&stack, &config)?;
    table.save(&args.out)?;
    if let Some(plot) = &args.plot {
        write_file_atomically(plot, &response_png(&table, None)?)?;
    }
    let (w, h) = stack.size();
    let inner = &table.inverse.ln_exposure[1..table.inverse.ln_exposure.len() - 1];
    let decreasing = inner.windows(2).filter(|p| p[1] < p[0]).count();
    println!(
        "response: {} exposures of {w}×{h} px, {} bits, {} samples, λ = {} → {}",
        stack.images().len(),
        stack.bit_depth(),
        table.solve.samples,
        table.solve.lambda,
        args.out.display()
    );
    println!(
        "  ln X over DN 1 … {}: {:.3} … {:.3} (dynamic range {:.1} stops), {} decreasing steps, rms residual {:.3}, {:.2} s",
        table.max_dn - 1,
        inner[0],
        inner[inner.len() - 1],
        (inner[inner.len() - 1] - inner[0]) / std::f64::consts::LN_2,
        decreasing,
        table.solve.rms_residual,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The true response in a ground-truth sensor file.
fn read_gt_response(path: &Path) -> anyhow::Result<ResponseCurve> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let found = value
        .get("response")
        .or_else(|| value.get("sensor").and_then(|s| s.get("response")))
        .with_context(|| {
            format!(
                "{}: no `response` (or `sensor.response`) field",
                path.display()
            )
        })?;
    serde_json::from_value(found.clone())
        .with_context(|| format!("{}: `response` is not a response curve", path.display()))
}

fn eval_response(args: &EvalResponseArgs) -> anyhow::Result<()> {
    if !(0.0..1.0).contains(&args.from) || !(args.from..=1.0).contains(&args.to) {
        anyhow::bail!(
            "--from {} / --to {} must satisfy 0 ≤ from < to ≤ 1",
            args.from,
            args.to
        );
    }
    let table = ResponseTable::load(&args.response)?;
    let truth = read_gt_response(&args.gt_sensor)?;
    let cmp = table.compare_with(&truth, (args.from, args.to));
    println!(
        "response vs ground truth {truth:?} over {:.0} % … {:.0} % of full scale ({} levels): \
         max |Δ ln g⁻¹| = {:.4}, rms = {:.4} (offset {:.3} removed)",
        args.from * 100.0,
        args.to * 100.0,
        cmp.levels,
        cmp.max_abs_ln_error,
        cmp.rms_ln_error,
        cmp.ln_offset
    );
    if let Some(plot) = &args.plot {
        let m = table.max_dn as f64;
        let reference: Vec<(f64, f64)> = (1..table.max_dn)
            .map(|dn| {
                let x = truth.invert((dn as f64 / m) as f32) as f64;
                (x.ln() + cmp.ln_offset, dn as f64)
            })
            .collect();
        write_file_atomically(
            plot,
            &response_png(&table, Some(("ground truth", &reference)))?,
        )?;
    }
    Ok(())
}

/// Format tag of a fitted material file.
fn stem_with(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or("material".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}.{suffix}"))
}

/// glint-camera's reader of calibration captures, for the fit in glint-calibration (which
/// cannot depend on camera): `glint calibrate bsdf`, `eval-bsdf` and the calibration server
/// read captures through it.
pub struct CameraCaptures;

impl CaptureReader for CameraCaptures {
    fn capture(&self, dir: &Path) -> Result<Capture, CaptureReadError> {
        let loaded = calibration_scene::load(dir).map_err(|e| CaptureReadError(Box::new(e)))?;
        Ok(Capture {
            scene_dir: loaded.scene_dir,
            obj_id: loaded.obj_id,
            scene: loaded.scene,
            part_instances: loaded.part_instances,
            bin_instance: loaded.bin_instance,
            reference: loaded.reference,
            rig: loaded.rig,
            views: loaded
                .views
                .into_iter()
                .map(|v| CaptureView {
                    im_id: v.im_id,
                    t_w_c: v.t_w_c,
                    stack_dir: v.stack_dir,
                })
                .collect(),
        })
    }

    fn exposure_stack(&self, dir: &Path) -> Result<ExposureStack, CaptureReadError> {
        let files = glint_camera::dataset::ExposureStackFiles::read(dir)
            .map_err(|e| CaptureReadError(Box::new(e)))?;
        ExposureStack::new(files.images, files.exposures_s, files.bit_depth)
            .map_err(|e| CaptureReadError(Box::new(e)))
    }
}

fn bsdf(args: &BsdfArgs) -> anyhow::Result<()> {
    let capture = read_capture(&CameraCaptures, &args.scene)?;
    capture.fitted_views(&args.views).context("--views")?;
    let table = ResponseTable::load(&args.response)?;
    let config = SceneFitConfig {
        views: args.views.clone(),
        iterations: args.iterations,
        transport: args.transport,
        spp: args.spp,
        pixel_step: args.pixel_step,
        residual: args.residual,
        loss: match args.loss {
            LossArg::L2 => LossChoice::L2,
            LossArg::Ln => LossChoice::Ln,
            LossArg::Huber => LossChoice::Huber,
        },
        block_px: args.block_px,
        reseed: args.reseed,
        min_indirect_roughness: args.min_indirect_roughness,
        final_min_indirect_roughness: args.final_min_indirect_roughness,
        starts: args.start.clone(),
        known_metallic: args.known_metallic,
    };
    let bar = glint_eval::progress::bar((args.iterations * args.start.len()) as u64, "BSDF fit");
    let fit = fit_scene(&CameraCaptures, capture, &table, &config, |_| {
        bar.inc(1);
        ControlFlow::Continue(())
    })?;
    bar.finish_and_clear();
    if fit.starts.len() > 1 {
        for f in &fit.starts {
            let p = &f.result.params;
            println!(
                "  start {}: base_color {:.3}, metallic {:.3}, roughness {:.3}, specular {:.3}; unbiased L2 {:.4}",
                f.start, p.base_color, p.metallic, p.roughness, p.specular, f.judged_l2
            );
        }
    }
    let result = &fit.result;
    let label = format!("obj {}", fit.capture.obj_id);
    // Plots first, the material last: a material file on disk means the run completed.
    let history = stem_with(&args.out, "history.png");
    write_file_atomically(&history, &fit_history_png(result, &label, None)?)?;
    let rendered = fit.problem().render(&result.params);
    let error = stem_with(&args.out, "error.png");
    let views = &fit.views;
    let k = &views[0].camera.intrinsics;
    write_file_atomically(
        &error,
        &error_map_png(
            k.width_px,
            k.height_px,
            &views[0].target.pixels,
            &rendered[0],
            &views[0].target.radiance,
            0.25,
        )?,
    )?;
    MaterialFile::new(&result.params, fit.provenance.clone()).save(&args.out)?;
    println!(
        "bsdf: {} — {} part instances, views {:?}: {} object pixels in the loss",
        fit.capture.scene_dir.display(),
        fit.capture.part_instances.len(),
        fit.im_ids,
        result.pixels,
    );
    for (im_id, m) in fit.im_ids.iter().zip(&fit.measured) {
        println!(
            "  view {im_id}: {} unmeasured pixels (saturated or black in every exposure), scale {:.4e} from {} reference pixels",
            m.unmeasured_pixels, m.scale, m.reference_pixels
        );
    }
    let p = &result.params;
    println!(
        "  base_color {:.3}, metallic {:.3}, roughness {:.3}, specular {:.3}; loss {:.4} → {:.4} in {} iterations, {:.2} s → {}",
        p.base_color,
        p.metallic,
        p.roughness,
        p.specular,
        result.loss[0],
        result.loss[result.loss.len() - 1],
        args.iterations,
        fit.elapsed_s,
        args.out.display()
    );
    Ok(())
}

fn eval_bsdf(args: &EvalBsdfArgs) -> anyhow::Result<()> {
    let loaded = read_capture(&CameraCaptures, &args.scene)?;
    let material = MaterialFile::load(&args.material)?;
    let fitted = material.params()?;
    let fitted_views: Vec<u32> = material
        .provenance
        .get("views")
        .map(|v| serde_json::from_value(v.clone()))
        .transpose()
        .with_context(|| {
            format!(
                "{}: views is not a list of image ids",
                args.material.display()
            )
        })?
        .unwrap_or_default();
    let gt_path = args
        .gt_material
        .clone()
        .unwrap_or_else(|| loaded.scene_dir.join("glint").join("gt_materials.json"));
    let (truth, part_name) = read_truth(&gt_path)?;
    let held_out = match args.held_out_view {
        Some(im_id) => im_id,
        None => loaded
            .views
            .iter()
            .map(|v| v.im_id)
            .find(|im_id| !fitted_views.contains(im_id))
            .with_context(|| {
                format!(
                    "{}: every view ({:?}) was used by the fit; capture more views or give --held-out-view",
                    loaded.scene_dir.display(),
                    fitted_views
                )
            })?,
    };
    let mut evaluated: Vec<(String, u32)> = fitted_views
        .iter()
        .map(|&im_id| (format!("fitted view {im_id}"), im_id))
        .collect();
    evaluated.push((format!("held-out view {held_out}"), held_out));
    let mut errors = Vec::new();
    let rendering = PixelRendering::new(
        args.transport.regularised(args.min_indirect_roughness),
        args.spp,
        7,
    );
    for (name, im_id) in &evaluated {
        let view = loaded.view(*im_id)?;
        let PartRadiance {
            width: w,
            height: h,
            pixels,
            radiance: [fit, gt],
        } = part_radiance(&loaded, &view.t_w_c, [&fitted, &truth], &rendering);
        if pixels.is_empty() {
            anyhow::bail!("{name}: no part pixels to compare");
        }
        let err = relative_rms(&fit, &gt);
        errors.push(err);
        println!(
            "  {name}: {} part pixels, relative RMS radiance error {:.4}, median |ln(fitted / true)| {:.4}",
            pixels.len(),
            err,
            median_abs_log_ratio(&fit, &gt)
        );
        if *im_id == held_out
            && let Some(path) = &args.error_map
        {
            write_file_atomically(path, &error_map_png(w, h, &pixels, &fit, &gt, 0.25)?)?;
        }
    }
    if let Some(response) = &args.response {
        let table = ResponseTable::load(response)?;
        let (views, _) = fit_views(
            &CameraCaptures,
            &loaded,
            &table,
            &fitted_views,
            &rendering,
            1,
        )?;
        let problem = FitProblem {
            scene: &loaded.scene,
            views: &views,
            instances: &loaded.part_instances,
            rendering,
            residual: Residual::SameSamples,
            loss: Loss::L2,
            block_px: 1,
        };
        let [loss_fitted, loss_truth] =
            [&fitted, &truth].map(|m| problem.loss_and_gradient(m, free_of(m)).0);
        println!(
            "  L2 loss against the measured radiance of views {fitted_views:?}: fitted {loss_fitted:.4}, true material {loss_truth:.4}"
        );
    }
    let part = part_name.unwrap_or_else(|| format!("obj {}", loaded.obj_id));
    let fitted_mean = if errors.len() > 1 {
        errors[..errors.len() - 1].iter().sum::<f64>() / (errors.len() - 1) as f64
    } else {
        f64::NAN
    };
    println!(
        "| {part} | {:.2} / {:.2} / {:.2} / {:.2} | {:.3} / {:.3} / {:.3} / {:.3} | {:.4} | {:.4} |",
        truth.base_color,
        truth.metallic,
        truth.roughness,
        truth.specular,
        fitted.base_color,
        fitted.metallic,
        fitted.roughness,
        fitted.specular,
        fitted_mean,
        errors[errors.len() - 1]
    );
    Ok(())
}
