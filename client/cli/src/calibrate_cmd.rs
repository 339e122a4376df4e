//! `glint calibrate`: the photometric calibration of §IV-A (camera response by Debevec–Malik)
//! and §IV-B (principled-BSDF fit by differentiable rendering), and their evaluation against
//! the mock camera's hidden ground truth (separate `eval-*` commands: calibration never reads
//! ground truth).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glint_calibration::bsdf_fit::{
    FREE_NAMES, FitConfig, FitProblem, FitTarget, PixelRendering, error_map_png, fit_history_png,
    measured_target,
};
use glint_calibration::response::{
    DebevecConfig, ExposureStack, ResponseTable, calibrate, response_png,
};
use glint_calibration::scene_file::{CalibrationScene, params_from_map, params_to_map};
use glint_camera::bin::BinSpec;
use glint_geometry::io::write_file_atomically;
use glint_geometry::parts::Part;
use glint_render::integrator::{LightTransport, path_pixel};
use glint_render::projector::Pattern;
use glint_render::rig::SliRig;
use glint_render::scene::{Scene, SceneInstance};
use glint_render::sensor::ResponseCurve;
use rayon::prelude::*;

#[derive(clap::Subcommand)]
pub enum CalibrateCommand {
    /// Camera response g and g⁻¹ from an exposure stack (Debevec–Malik).
    Response(ResponseArgs),
    /// Evaluation only: a recovered response against a ground-truth sensor file.
    EvalResponse(EvalResponseArgs),
    /// Principled-BSDF parameters of the part in a calibration scene (differentiable rendering).
    Bsdf(BsdfArgs),
    /// Evaluation only: a fitted material against the ground truth, at the fitted and a
    /// held-out view.
    EvalBsdf(EvalBsdfArgs),
}

#[derive(clap::Args)]
pub struct BsdfArgs {
    /// Calibration scene directory (calib_scene.json, exposure_stack/).
    #[arg(long)]
    pub scene: PathBuf,
    /// The camera response from `glint calibrate response`.
    #[arg(long)]
    pub response: PathBuf,
    /// Output material JSON; `<stem>.history.png` (loss and parameters) and `<stem>.error.png`
    /// (|fitted − target| map) are written beside it.
    #[arg(long)]
    pub out: PathBuf,
    /// Adam iterations.
    #[arg(long, default_value_t = 300)]
    pub iterations: usize,
    /// Light transport of the fit's renders: `multi` (inter-reflections, as the camera sees
    /// them) or `single` (direct reflection only).
    #[arg(long, default_value = "multi", value_parser = parse_transport)]
    pub transport: LightTransport,
    /// Samples per pixel of multi-path renders.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub spp: u32,
    /// Use every N-th object pixel in u and v.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub pixel_step: u32,
}

/// How to render pixels: `spp` samples with multi-path, one with single-path.
fn rendering_of(transport: LightTransport, spp: u32, seed: u64) -> PixelRendering {
    let samples_per_pixel = if transport == LightTransport::SinglePath {
        1
    } else {
        spp
    };
    PixelRendering {
        transport,
        samples_per_pixel,
        seed,
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
    #[arg(long)]
    pub scene: PathBuf,
    /// A material written by `glint calibrate bsdf`.
    #[arg(long)]
    pub material: PathBuf,
    /// Ground-truth material (name → value JSON), e.g. DIR/gt/gt_material.json.
    #[arg(long)]
    pub gt_material: PathBuf,
    /// Optional PNG: |fitted − ground truth| radiance at the held-out view.
    #[arg(long)]
    pub error_map: Option<PathBuf>,
    /// Light transport of the comparison renders (both materials rendered alike).
    #[arg(long, default_value = "multi", value_parser = parse_transport)]
    pub transport: LightTransport,
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub spp: u32,
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

fn response(args: &ResponseArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let stack = ExposureStack::load(&args.stack)?;
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
const MATERIAL_FORMAT: &str = "glint-material/1";

/// A calibration scene as the renderer needs it: the part (scene instance 0) in the bin
/// (instance 1), the rig, the fitted and held-out views.
struct LoadedScene {
    file: CalibrationScene,
    scene: Scene,
    rig: SliRig,
    t_w_c: nalgebra::Isometry3<f64>,
    held_out_t_w_c: nalgebra::Isometry3<f64>,
}

/// Scene indices of the part and the bin in [`LoadedScene::scene`].
const PART_INSTANCE: u32 = 0;
const BIN_INSTANCE: u32 = 1;

fn load_scene(dir: &Path) -> anyhow::Result<LoadedScene> {
    let file = CalibrationScene::load(&dir.join("calib_scene.json")).map_err(anyhow::Error::msg)?;
    let part: Part = file
        .part
        .parse()
        .map_err(|e: String| anyhow::anyhow!("calib_scene.json: part: {e}"))?;
    let reference = file.reference().map_err(anyhow::Error::msg)?;
    let t_w_o = file
        .t_w_o
        .to_isometry("t_w_o")
        .map_err(anyhow::Error::msg)?;
    let t_w_c = file
        .t_w_c
        .to_isometry("t_w_c")
        .map_err(anyhow::Error::msg)?;
    let held_out_t_w_c = file
        .held_out_t_w_c
        .to_isometry("held_out_t_w_c")
        .map_err(anyhow::Error::msg)?;
    let [w, h] = file.resolution;
    let rig = SliRig::ensenso_n35()
        .resized(w, h)
        .with_context(|| format!("calib_scene.json: resolution {w}×{h}"))?;
    // The bin carries the scene file's reference material; the part's is a placeholder (the fit
    // and the evaluation shade it with their own).
    let scene = Scene::build(
        &[part.mesh(), BinSpec::default().mesh()],
        vec![
            SceneInstance {
                mesh: 0,
                t_w_o,
                material: 0,
                label: 1,
            },
            SceneInstance {
                mesh: 1,
                t_w_o: nalgebra::Isometry3::identity(),
                material: 1,
                label: 2,
            },
        ],
        vec![reference, reference],
    )?;
    Ok(LoadedScene {
        file,
        scene,
        rig,
        t_w_c,
        held_out_t_w_c,
    })
}

fn stem_with(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or("material".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}.{suffix}"))
}

fn bsdf(args: &BsdfArgs) -> anyhow::Result<()> {
    let loaded = load_scene(&args.scene)?;
    let stack = ExposureStack::load(&args.scene.join("exposure_stack"))?;
    let table = ResponseTable::load(&args.response)?;
    let radiance_map = table.radiance_map(&stack)?;
    let [camera, _] = loaded.rig.cameras(&loaded.t_w_c);
    let projector = loaded.rig.projector(&loaded.t_w_c, Pattern::White);
    let reference = loaded.file.reference().map_err(anyhow::Error::msg)?;
    let rendering = rendering_of(args.transport, args.spp, 1);
    let measured = measured_target(
        &loaded.scene,
        &camera,
        &projector,
        PART_INSTANCE,
        BIN_INSTANCE,
        &reference,
        &radiance_map,
        &rendering,
    )?;
    let step = args.pixel_step;
    let mut target = FitTarget::default();
    for (&(u, v), &r) in measured.target.pixels.iter().zip(&measured.target.radiance) {
        if u % step == 0 && v % step == 0 {
            target.pixels.push((u, v));
            target.radiance.push(r);
        }
    }
    let problem = FitProblem {
        scene: &loaded.scene,
        camera,
        projector: &projector,
        instance: PART_INSTANCE,
        target: &target,
        rendering,
    };
    let config = FitConfig {
        iterations: args.iterations,
        ..FitConfig::default()
    };
    let bar = crate::progress::bar(args.iterations as u64, "BSDF fit");
    let result = problem.fit_with_progress(&config, |_, _| bar.inc(1))?;
    bar.finish_and_clear();

    let json = serde_json::json!({
        "format": MATERIAL_FORMAT,
        "part": loaded.file.part,
        "params": params_to_map(&result.params),
        "free": FREE_NAMES,
        "transport": format!("{:?}", args.transport),
        "samples_per_pixel": rendering.samples_per_pixel,
        "pixels": result.pixels,
        "unmeasured_pixels": measured.unmeasured_pixels,
        "radiometric_scale": measured.scale,
        "reference_pixels": measured.reference_pixels,
        "elapsed_s": result.elapsed_s,
        "loss": result.loss,
        "trajectory": result.trajectory,
    });
    write_file_atomically(&args.out, &serde_json::to_vec_pretty(&json)?)?;
    let history = stem_with(&args.out, "history.png");
    write_file_atomically(
        &history,
        &fit_history_png(&result, &loaded.file.part, None)?,
    )?;
    let rendered = problem.render(&result.params);
    let error = stem_with(&args.out, "error.png");
    let k = &camera.intrinsics;
    write_file_atomically(
        &error,
        &error_map_png(
            k.width_px,
            k.height_px,
            &target.pixels,
            &rendered,
            &target.radiance,
            0.25,
        )?,
    )?;
    let p = &result.params;
    println!(
        "bsdf: {} — {} object pixels ({} unmeasured: saturated or black in every exposure), scale from {} reference pixels",
        loaded.file.part, result.pixels, measured.unmeasured_pixels, measured.reference_pixels
    );
    println!(
        "  base_color {:.3}, metallic {:.3}, roughness {:.3}, specular {:.3}; loss {:.4} → {:.4} in {} iterations, {:.2} s → {}",
        p.base_color,
        p.metallic,
        p.roughness,
        p.specular,
        result.loss[0],
        result.loss[result.loss.len() - 1],
        args.iterations,
        result.elapsed_s,
        args.out.display()
    );
    Ok(())
}

/// What [`part_radiance`] returns: image size, the part's pixels, their radiance per material.
type PartRadiance = (u32, u32, Vec<(u32, u32)>, [Vec<f32>; 2]);

/// The part's interior pixels (3 × 3 all part) seen from `t_w_c`, and their radiance with each
/// of `materials` (rendered alike with `rendering`).
fn part_radiance(
    loaded: &LoadedScene,
    t_w_c: &nalgebra::Isometry3<f64>,
    materials: [&glint_render::bsdf::PrincipledParams<f32>; 2],
    rendering: &PixelRendering,
) -> PartRadiance {
    let [camera, _] = loaded.rig.cameras(t_w_c);
    let projector = loaded.rig.projector(t_w_c, Pattern::White);
    let (w, h) = (camera.intrinsics.width_px, camera.intrinsics.height_px);
    let shade = |u, v, m: &glint_render::bsdf::PrincipledParams<f32>, r: &PixelRendering| {
        path_pixel(
            &loaded.scene,
            &camera,
            &projector,
            u,
            v,
            r.transport,
            r.samples_per_pixel,
            r.seed,
            |i| {
                if i == PART_INSTANCE {
                    *m
                } else {
                    *loaded.scene.material_of(i)
                }
            },
        )
    };
    let is_part = |u: u32, v: u32| {
        shade(u, v, materials[0], &PixelRendering::SINGLE_PATH)
            .is_some_and(|s| s.instance == PART_INSTANCE)
    };
    let mut pixels = Vec::new();
    for v in 1..h - 1 {
        for u in 1..w - 1 {
            if is_part(u, v) && (v - 1..=v + 1).all(|y| (u - 1..=u + 1).all(|x| is_part(x, y))) {
                pixels.push((u, v));
            }
        }
    }
    let render = |m| {
        pixels
            .par_iter()
            .map(|&(u, v)| shade(u, v, m, rendering).map_or(0.0, |s| s.radiance))
            .collect()
    };
    (
        w,
        h,
        pixels.clone(),
        [render(materials[0]), render(materials[1])],
    )
}

/// sqrt(Σ (a − b)² / Σ b²).
fn relative_rms(a: &[f32], b: &[f32]) -> f64 {
    let (se, norm) = a.iter().zip(b).fold((0.0, 0.0), |(se, n), (&x, &y)| {
        (se + ((x - y) as f64).powi(2), n + (y as f64).powi(2))
    });
    (se / norm.max(f64::MIN_POSITIVE)).sqrt()
}

fn eval_bsdf(args: &EvalBsdfArgs) -> anyhow::Result<()> {
    let loaded = load_scene(&args.scene)?;
    let read_map = |path: &Path, field: &str| -> anyhow::Result<_> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        let map = value.get(field).unwrap_or(&value).clone();
        let map: std::collections::BTreeMap<String, f32> = serde_json::from_value(map)
            .with_context(|| format!("{}: not a parameter map", path.display()))?;
        params_from_map(&map, &path.display().to_string()).map_err(anyhow::Error::msg)
    };
    let fitted = read_map(&args.material, "params")?;
    let truth = read_map(&args.gt_material, "params")?;
    let mut errors = Vec::new();
    for (name, t_w_c) in [
        ("fitted view", loaded.t_w_c),
        ("held-out view", loaded.held_out_t_w_c),
    ] {
        let rendering = rendering_of(args.transport, args.spp, 7);
        let (w, h, pixels, [fit, gt]) =
            part_radiance(&loaded, &t_w_c, [&fitted, &truth], &rendering);
        let err = relative_rms(&fit, &gt);
        errors.push(err);
        println!(
            "  {name}: {} part pixels, relative RMS radiance error {:.4}",
            pixels.len(),
            err
        );
        if name == "held-out view"
            && let Some(path) = &args.error_map
        {
            write_file_atomically(path, &error_map_png(w, h, &pixels, &fit, &gt, 0.25)?)?;
        }
    }
    println!(
        "| {} | {:.2} / {:.2} / {:.2} / {:.2} | {:.3} / {:.3} / {:.3} / {:.3} | {:.4} | {:.4} |",
        loaded.file.part,
        truth.base_color,
        truth.metallic,
        truth.roughness,
        truth.specular,
        fitted.base_color,
        fitted.metallic,
        fitted.roughness,
        fitted.specular,
        errors[0],
        errors[1]
    );
    Ok(())
}
