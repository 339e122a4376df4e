//! `glint eval active`: the paper's Fig. 9 on mock-camera data — the view policies compared
//! over the same bins and detector poses (`glint_eval::policies`).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use glint_eval::active::Masking;
use glint_eval::policies::{PolicyComparison, StepRow, run, summary_markdown};
use glint_geometry::Part;
use glint_geometry::io::write_file_atomically;
use glint_orchestrator::session::ViewPolicy;
use plotters::prelude::*;

#[derive(clap::Args)]
pub struct ActiveArgs {
    #[arg(long, default_value = "zigzag", value_parser = crate::mesh_cmd::parse_part)]
    pub part: Part,
    /// Bins (one per seed), comma separated. Keep them apart from the seeds any setting was
    /// chosen on (the demo's seed 1, the tests' 3, 5).
    #[arg(long, default_value = "101,102,103,104,105", value_delimiter = ',')]
    pub seeds: Vec<u64>,
    /// Policies, comma separated.
    #[arg(
        long,
        default_value = "nbv,nbv-const-sigma,random,max-distance",
        value_delimiter = ','
    )]
    pub policies: Vec<ViewPolicy>,
    /// Views per session, the detector's first view included.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub views: u32,
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(2..=256))]
    pub candidates: u32,
    #[command(flatten)]
    pub bin: super::BinArgs,
    #[command(flatten)]
    pub calibration: crate::calibration_args::CalibrationArgs,
    /// The render workers render the bin with the part (occlusion by its walls,
    /// inter-reflection from its floor), beyond the paper.
    #[arg(long)]
    pub predict_bin: bool,
    /// Refine from the detector's pose as given, without first moving it along the viewing
    /// rays onto the depth (the alignment is on by default).
    #[arg(long)]
    pub no_align_depth: bool,
    /// The margin around the hypothesis' silhouette of the first masking pass, mm (the
    /// sessions' default: 10, the detector's error).
    #[arg(long, default_value_t = 10.0, value_parser = parse_margin_mm)]
    pub mask_margin_mm: f64,
    /// The margin around the first pass's refined silhouette of the second pass, mm.
    #[arg(long, default_value_t = 3.0, value_parser = parse_margin_mm)]
    pub final_mask_margin_mm: f64,
    /// The camera's error model on the part the sessions refine and plan under: `shipped`
    /// (assets/calibration/<part>/pose_error.json), a file `glint eval refine` wrote
    /// (`DIR/pose_error/<part>.json`), or `none` for eq 18's independent pixels.
    #[arg(long, default_value = "shipped")]
    pub error_model: String,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run_cmd(args: &ActiveArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let needs = args.policies.iter().any(|p| p.prediction(1e-3).is_some());
    let calibration = if needs {
        Some(args.calibration.load(args.part)?)
    } else {
        None
    };
    let spec = PolicyComparison {
        part: args.part,
        seeds: args.seeds.clone(),
        policies: args.policies.clone(),
        views: args.views as usize,
        candidates: args.candidates as usize,
        instances: args.bin.instances,
        width_px: args.bin.resolution.0,
        height_px: args.bin.resolution.1,
        samples_per_pixel: args.bin.spp,
        masking: Masking {
            align_depth: !args.no_align_depth,
            margin_m: args.mask_margin_mm * 1e-3,
            final_margin_m: args.final_mask_margin_mm * 1e-3,
            ..Masking::default()
        },
        predict_with_bin: args.predict_bin,
        error_model: super::error_model_arg("--error-model", &args.error_model, Some(args.part))?,
    };
    println!(
        "Fig. 9 on mock data: {} bins of the {} × {} policies, {} views each, {} candidates, \
         {}×{} px, {} spp. Initial poses from the stand-in detector; errors against the truth.",
        spec.seeds.len(),
        args.part.display_name(),
        spec.policies.len(),
        spec.views,
        spec.candidates,
        spec.width_px,
        spec.height_px,
        spec.samples_per_pixel
    );
    let started = std::time::Instant::now();
    let bar =
        glint_eval::progress::bar((spec.seeds.len() * spec.policies.len()) as u64, "sessions");
    let rows = run(&spec, calibration.as_ref(), |session| {
        if let Some(last) = session.last() {
            bar.suspend(|| {
                println!(
                    "  bin {} {:<16} {} views: {:.2} mm / {:.2}°, h {:.2} nats",
                    last.seed,
                    last.policy,
                    last.views,
                    last.err_mm,
                    last.err_deg,
                    last.entropy_nats
                )
            });
        }
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    let summary = summary_markdown(&rows, &spec.policies, spec.views);
    println!("{summary}");
    println!("{:.0} s in all.", started.elapsed().as_secs_f64());

    let mut csv = String::from(
        "seed,policy,views,view,points,err_mm,err_deg,entropy_nats,predicted_entropy_nats,nees,nees_pixels,nees_dof,predict_s,step_s\n",
    );
    for r in &rows {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{:.4},{:.4},{:.4},{},{:.4},{:.4},{},{:.3},{:.3}",
            r.seed,
            r.policy,
            r.views,
            r.view,
            r.points,
            r.err_mm,
            r.err_deg,
            r.entropy_nats,
            r.predicted_entropy_nats
                .map_or(String::new(), |h| format!("{h:.4}")),
            r.nees,
            r.nees_pixels,
            r.nees_dof,
            r.predict_s,
            r.step_s
        );
    }
    write_file_atomically(&args.out.join("steps.csv"), csv.as_bytes())?;
    write_file_atomically(&args.out.join("summary.md"), summary.as_bytes())?;
    let plot = plot_png(&rows, &spec.policies, spec.views)?;
    write_file_atomically(&args.out.join("policies.png"), &plot)?;
    let html = format!(
        "<!doctype html><html><head><meta charset=utf-8><title>Glint: view policies</title></head>\
         <body style=\"font-family:sans-serif;margin:2em\"><h1>View policies on the {}</h1>\
         <p>{} bins, seeds {:?}; steps in <a href=steps.csv>steps.csv</a>.</p>\
         <img src=policies.png><pre>{summary}</pre></body></html>",
        args.part.display_name(),
        spec.seeds.len(),
        spec.seeds
    );
    write_file_atomically(&args.out.join("index.html"), html.as_bytes())?;
    println!("Report: {}", args.out.join("index.html").display());
    Ok(())
}

/// Mean entropy and mean translation error against views, one line per policy.
fn plot_png(rows: &[StepRow], policies: &[ViewPolicy], views: usize) -> anyhow::Result<Vec<u8>> {
    let series = |policy: &ViewPolicy, f: &dyn Fn(&StepRow) -> f64| -> Vec<(f64, f64)> {
        (1..=views)
            .filter_map(|k| {
                let at: Vec<f64> = rows
                    .iter()
                    .filter(|r| r.policy == policy.name() && r.views == k)
                    .map(f)
                    .collect();
                (!at.is_empty()).then(|| (k as f64, at.iter().sum::<f64>() / at.len() as f64))
            })
            .collect()
    };
    let colours = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    Ok(glint_plot::png(1000, 420, |root| {
        let (left, right) = root.split_horizontally(500);
        for (area, title, y_desc, f) in [
            (
                &left,
                "mean pose entropy vs views",
                "nats",
                &(|r: &StepRow| r.entropy_nats) as &dyn Fn(&StepRow) -> f64,
            ),
            (
                &right,
                "mean translation error vs views",
                "mm",
                &(|r: &StepRow| r.err_mm) as &dyn Fn(&StepRow) -> f64,
            ),
        ] {
            let all: Vec<f64> = policies
                .iter()
                .flat_map(|p| series(p, f))
                .map(|p| p.1)
                .collect();
            let (lo, hi) = glint_plot::padded_range(all.into_iter(), 0.1);
            let mut chart = ChartBuilder::on(area)
                .caption(title, (glint_plot::FONT, 18))
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(50)
                .build_cartesian_2d(0.5..views as f64 + 0.5, lo..hi)?;
            chart
                .configure_mesh()
                .x_desc("views taken")
                .y_desc(y_desc)
                .draw()?;
            for (p, colour) in policies.iter().zip(colours.iter().cycle()) {
                let c = *colour;
                chart
                    .draw_series(LineSeries::new(series(p, f), c.stroke_width(2)))?
                    .label(p.name())
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], c));
            }
            chart.configure_series_labels().border_style(BLACK).draw()?;
        }
        Ok(())
    })?)
}

/// A mask margin in mm: finite, in [0, 100].
fn parse_margin_mm(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("{s:?} is not a number of millimetres"))?;
    if v.is_finite() && (0.0..=100.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} mm must be between 0 and 100"))
    }
}
