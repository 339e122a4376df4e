//! `glint capture`: a bin of one part seen by the mock SLI camera from a few views, with the
//! same scene painted matte (the diffuse twin) for comparison.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glint_camera::capture::{CaptureTruth, DepthQuality, StereoCapture, depth_quality};
use glint_camera::dataset::write_png_u8;
use glint_camera::edge_errors::{EdgeBin, errors_by_edge_distance};
use glint_camera::effects::missing_causes;
use glint_camera::materials;
use glint_camera::record::{to_8bit, write_bop_image};
use glint_camera::setup::{BinSetup, BinSetupSpec, capture_seed};
use glint_eval::capture_folder::{PART_OBJ_ID, record_exposure_stacks, start_capture_folder};
use glint_geometry::image::Image;
use glint_geometry::io::write_file_atomically;
use glint_geometry::parts::Part;
use image::ImageEncoder;

#[derive(clap::Args)]
pub struct CaptureArgs {
    /// eye-bolt, tube-fitting, chrome-screw, gear or zigzag.
    #[arg(long, value_parser = crate::mesh_cmd::parse_part)]
    pub part: Part,
    #[command(flatten)]
    pub bin: BinArgs,
    /// Views, spread over a spherical cap above the bin.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=200))]
    pub views: u32,
    /// Instead of depth captures, take a white-pattern exposure stack of the left camera per
    /// view (for calibrating the camera response). Exposure times in MILLISECONDS, comma
    /// separated, e.g. `0.25,0.5,1,2,4,8`. Given without a list: 0.25,0.5,1,2,4,8,16,32,64 ms,
    /// which with the default sensor (its own Δt is 10 ms) spans from under-exposed (on the
    /// Gear and the Chrome Screw, a fifth or more of the part pixels below 2 % of full scale,
    /// none saturated) to over-exposed (over a third saturated); the matte Zigzag needs
    /// shorter times to reach under-exposure. Writes test/000001/glint/exposure_stack/XXXXXX/
    /// per view.
    #[arg(
        long,
        value_name = "MS,MS,...",
        num_args = 0..=1,
        require_equals = false,
        default_missing_value = DEFAULT_EXPOSURE_STACK_MS,
        value_parser = parse_exposures_ms
    )]
    pub exposure_stack: Option<ExposureTimes>,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
}

/// The mock bin a capturing command sets up (`glint capture`, `glint eval uncertainty`).
#[derive(clap::Args, Clone, Debug)]
pub struct BinArgs {
    /// Parts in the bin.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    /// Seed of the drop and of the captures' noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Camera resolution, WIDTHxHEIGHT (the N35's field of view is kept).
    #[arg(long, default_value = "1280x1024", value_parser = parse_resolution)]
    pub resolution: (u32, u32),
    /// Samples per pixel of the multi-path renders.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub spp: u32,
}

impl BinArgs {
    /// The set-up these flags describe.
    pub fn spec(&self) -> BinSetupSpec {
        BinSetupSpec {
            instances: self.instances,
            seed: self.seed,
            width_px: self.resolution.0,
            height_px: self.resolution.1,
            samples_per_pixel: self.spp,
        }
    }
}

/// The default exposure stack, milliseconds (the default sensor's own Δt is 10 ms).
pub const DEFAULT_EXPOSURE_STACK_MS: &str = "0.25,0.5,1,2,4,8,16,32,64";

/// Exposure times, seconds, increasing (a newtype so clap takes the list as one value).
#[derive(Clone, Debug, PartialEq)]
pub struct ExposureTimes(pub Vec<f64>);

/// Exposure times in ms → seconds, validated (≥ 2, finite, > 0, distinct) and sorted.
fn parse_exposures_ms(s: &str) -> Result<ExposureTimes, String> {
    let ms = s
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f64>()
                .map_err(|_| format!("exposure {x:?} is not a number of milliseconds"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let seconds: Vec<f64> = ms.iter().map(|m| m * 1e-3).collect();
    glint_camera::exposure::validated_exposures(&seconds)
        .map(ExposureTimes)
        .map_err(|e| format!("{e} (given in ms: {s})"))
}

pub(crate) fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or_else(|| format!("resolution {s:?} must look like 1280x1024"))?;
    let parse = |x: &str| x.parse::<u32>().ok().filter(|v| (64..=8192).contains(v));
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!(
            "resolution {s:?}: width and height must be integers from 64 to 8192"
        )),
    }
}

pub fn run(args: &CaptureArgs) -> anyhow::Result<()> {
    let mesh = args.part.mesh();
    let shiny = BinSetup::new(&mesh, materials::ground_truth(args.part), &args.bin.spec())?;
    let views = shiny.views(args.views as usize);
    if let Some(ExposureTimes(exposures_s)) = &args.exposure_stack {
        let bar = glint_eval::progress::bar(views.len() as u64, "exposure stacks");
        let recorded = record_exposure_stacks(
            &args.out,
            args.part,
            &shiny,
            args.bin.seed,
            &views,
            exposures_s,
            || bar.inc(1),
        )?;
        bar.finish_and_clear();
        println!("{}\nwrote {}", recorded.report, args.out.display());
        return Ok(());
    }
    let matte = shiny.repainted(&mesh, materials::diffuse_twin())?;
    let (rig, poses) = (shiny.rig, &shiny.poses);
    let radius = shiny.config.matcher.window_radius_px;
    let cameras = [("shiny", shiny.camera()), ("diffuse twin", matte.camera())];

    let mut report = format!(
        "# glint capture: {} × {}, {} views, seed {}, {}×{} px, {} spp multi-path\n\n\
         Per view and instance (instances with at least 200 pixels that could have depth): missing-depth fraction with the \
         part's ground-truth material and with a matte diffuse twin, depth RMSE against ground truth (5 mm outliers \
         excluded and counted), and the causes of the missing pixels on the shiny part (a pixel may have several).\n\n\
         | view | instance | pixels | missing (shiny) | missing (diffuse) | RMSE shiny (mm) | RMSE diffuse (mm) | >5 mm shiny | saturated | low SNR | inter-reflection | other |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        args.part.display_name(),
        args.bin.instances,
        args.views,
        args.bin.seed,
        args.bin.resolution.0,
        args.bin.resolution.1,
        args.bin.spp
    );
    // BOP layout: models/ (mm) and one scene, test/000001/, one image per view.
    let mut bop = start_capture_folder(&args.out, args.part, &shiny)?;
    let bar = glint_eval::progress::bar(views.len() as u64, "capture");
    let mut totals: [Vec<DepthQuality>; 2] = Default::default();
    let mut cause_totals = [0usize; 4];
    let part_labels: Vec<u16> = (1..=args.bin.instances as u16).collect();
    let mut edge_totals: [Vec<EdgeBin>; 2] = Default::default();
    for (k, t_w_c) in views.iter().enumerate() {
        let seed = capture_seed(args.bin.seed, k);
        let start = Instant::now();
        let (captures, truths): (Vec<StereoCapture>, Vec<CaptureTruth>) = cameras
            .iter()
            .map(|(_, c)| c.capture(t_w_c, seed))
            .collect::<Result<Vec<_>, _>>()?
            .into_iter()
            .unzip();
        tracing::info!(
            "view {k}: two captures in {:.1} s",
            start.elapsed().as_secs_f64()
        );
        let dir = args.out.join(format!("view_{k:03}"));
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        write_gray(
            &dir.join("left.png"),
            &captures[0].left,
            cameras[0].1.config.sensor.max_dn(),
        )?;
        write_gray(
            &dir.join("right.png"),
            &captures[0].right,
            cameras[0].1.config.sensor.max_dn(),
        )?;
        write_depth(&dir.join("depth.png"), &captures[0], &truths[0])?;
        write_depth(
            &dir.join("depth_diffuse_twin.png"),
            &captures[1],
            &truths[1],
        )?;
        write_capture_exr(&dir.join("capture.exr"), &captures[0], &truths[0])?;
        write_bop_image(
            &mut bop,
            k as u32,
            &captures[0],
            &cameras[0].1,
            poses,
            PART_OBJ_ID,
        )?;
        for (totals, (capture, truth)) in edge_totals.iter_mut().zip(captures.iter().zip(&truths)) {
            let bins = errors_by_edge_distance(capture, truth, &part_labels, &EDGE_BIN_BOUNDS_PX);
            if totals.is_empty() {
                *totals = bins;
            } else {
                for (t, b) in totals.iter_mut().zip(&bins) {
                    t.valid += b.valid;
                    t.farther_5mm += b.farther_5mm;
                    t.nearer_5mm += b.nearer_5mm;
                }
            }
        }
        for label in 1..=args.bin.instances as u16 {
            let q: Vec<_> = captures
                .iter()
                .zip(&truths)
                .map(|(c, t)| depth_quality(c, t, &rig, radius, Some(label)))
                .collect();
            if q[0].eligible < 200 {
                continue; // hardly visible from here
            }
            let causes =
                missing_causes(&cameras[0].1, &captures[0], &truths[0], label, seed ^ 0x51);
            for (t, qi) in totals.iter_mut().zip(&q) {
                t.push(*qi);
            }
            for (t, c) in cause_totals.iter_mut().zip([
                causes.saturated,
                causes.low_snr,
                causes.inter_reflection,
                causes.other,
            ]) {
                *t += c;
            }
            report += &format!(
                "| {k} | {label} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {} | {} |\n",
                q[0].eligible,
                q[0].missing_fraction(),
                q[1].missing_fraction(),
                q[0].rmse_m * 1e3,
                q[1].rmse_m * 1e3,
                q[0].outliers_5mm,
                causes.saturated,
                causes.low_snr,
                causes.inter_reflection,
                causes.other
            );
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let [shiny_all, diffuse_all] = totals.map(DepthQuality::pooled);
    report += &format!(
        "\n**All instances:** missing depth {:.3} shiny vs {:.3} diffuse twin; depth RMSE {:.3} mm shiny vs {:.3} mm diffuse \
         (5 mm outliers excluded); valid pixels more than 5 mm off: {:.3} shiny vs {:.3} diffuse; missing pixels on the shiny part by cause: \
         saturated {}, low SNR {}, inter-reflection {}, other {}.\n\nImages per view: `view_NNN/capture.exr` (float channels: matched `depth_m` with NaN where missing, and for evaluation the ground-truth `gt_depth_m`, `gt_label` and left radiance `gt_left_radiance`), `left.png`, `right.png` \
         (pattern images as read out), `depth.png` and `depth_diffuse_twin.png` (near = blue, far = red, missing = magenta).\n",
        shiny_all.missing_fraction(),
        diffuse_all.missing_fraction(),
        shiny_all.rmse_m * 1e3,
        diffuse_all.rmse_m * 1e3,
        shiny_all.outlier_share(),
        diffuse_all.outlier_share(),
        cause_totals[0],
        cause_totals[1],
        cause_totals[2],
        cause_totals[3]
    );
    report += &format!(
        "\n**Depth errors by distance to the nearest depth edge** (all views; part pixels with matched depth; \
         L∞ px to a true-depth step > 5 mm, the window radius is {radius} px): share more than 5 mm farther / nearer than the truth.\n\n\
         | distance (px) | pixels shiny | farther shiny | nearer shiny | pixels diffuse | farther diffuse | nearer diffuse |\n\
         |---|---:|---:|---:|---:|---:|---:|\n"
    );
    for (s, d) in edge_totals[0].iter().zip(&edge_totals[1]) {
        let share = |x: usize, n: usize| x as f64 / n.max(1) as f64;
        let range = if s.max_px == u32::MAX {
            format!("≥ {}", s.min_px)
        } else if s.min_px == s.max_px {
            format!("{}", s.min_px)
        } else {
            format!("{}–{}", s.min_px, s.max_px)
        };
        report += &format!(
            "| {range} | {} | {:.3} | {:.3} | {} | {:.3} | {:.3} |\n",
            s.valid,
            share(s.farther_5mm, s.valid),
            share(s.nearer_5mm, s.valid),
            d.valid,
            share(d.farther_5mm, d.valid),
            share(d.nearer_5mm, d.valid)
        );
    }
    bop.finish()?;
    let path = args.out.join("report.md");
    write_file_atomically(&path, report.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    println!("{report}\nwrote {}", args.out.display());
    Ok(())
}

/// Upper ends of the distance bins of the edge-error table, px.
const EDGE_BIN_BOUNDS_PX: [u32; 6] = [0, 1, 2, 3, 5, 8];

fn png_bytes(
    rgb_or_gray: &[u8],
    w: u32,
    h: u32,
    color: image::ExtendedColorType,
) -> anyhow::Result<Vec<u8>> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png).write_image(rgb_or_gray, w, h, color)?;
    Ok(png)
}

fn write_gray(path: &Path, img: &Image<u16>, max_dn: u16) -> anyhow::Result<()> {
    write_png_u8(path, &to_8bit(img, max_dn)).with_context(|| format!("writing {}", path.display()))
}

/// Depth as colour (blue near → red far over the capture's true depth range), missing magenta,
/// nothing-there black.
fn write_depth(path: &Path, capture: &StereoCapture, truth: &CaptureTruth) -> anyhow::Result<()> {
    let true_depth = truth.depth_m.data().iter().filter(|z| z.is_finite());
    let (lo, hi) = true_depth.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &z| {
        (lo.min(z), hi.max(z))
    });
    let span = (hi - lo).max(1e-6);
    let mut rgb = Vec::with_capacity(capture.depth.depth_m.data().len() * 3);
    for (&z, &t) in capture
        .depth
        .depth_m
        .data()
        .iter()
        .zip(truth.depth_m.data())
    {
        let px = if z.is_finite() {
            let x = ((z - lo) / span).clamp(0.0, 1.0);
            [
                (255.0 * x) as u8,
                (255.0 * (1.0 - (2.0 * x - 1.0).abs())) as u8,
                (255.0 * (1.0 - x)) as u8,
            ]
        } else if t.is_finite() {
            [255, 0, 255]
        } else {
            [0, 0, 0]
        };
        rgb.extend_from_slice(&px);
    }
    let png = png_bytes(
        &rgb,
        capture.depth.depth_m.width(),
        capture.depth.depth_m.height(),
        image::ExtendedColorType::Rgb8,
    )?;
    write_file_atomically(path, &png).with_context(|| format!("writing {}", path.display()))
}

/// The view's float images as one EXR.
fn write_capture_exr(
    path: &Path,
    capture: &StereoCapture,
    truth: &CaptureTruth,
) -> anyhow::Result<()> {
    let label = Image::new(
        truth.label.width(),
        truth.label.height(),
        truth.label.data().iter().map(|&l| l as f32).collect(),
    )?;
    glint_render::exr_io::write_exr(
        path,
        &[
            ("depth_m", &capture.depth.depth_m),
            ("gt_depth_m", &truth.depth_m),
            ("gt_label", &label),
            ("gt_left_radiance", &truth.left_radiance),
        ],
    )?;
    Ok(())
}
