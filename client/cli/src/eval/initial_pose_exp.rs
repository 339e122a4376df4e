//! `glint eval initial-poses`: the initial-pose distribution fitted to the paper's initial row
//! of Table I (issue 16 item 5), and the rates it gives per part.

use glint_eval::initial_pose::{
    InitialPoseNoise, PAPER_INITIAL_RATES_ALL, RateSample, fit_initial_pose_shape,
    paper_initial_rates,
};
use glint_geometry::parts::Part;

#[derive(clap::Args)]
pub struct InitialPosesArgs {
    /// Draws per part (uniformly random orientations, six standard normals each).
    #[arg(long, default_value_t = 20_000, value_parser = clap::value_parser!(u32).range(100..=10_000_000))]
    pub samples: u32,
    /// Seed of the draws the fit runs on.
    #[arg(long, default_value_t = 16)]
    pub seed: u64,
    /// Seed of the draws the fitted and the default distribution are checked on.
    #[arg(long, default_value_t = 1601)]
    pub check_seed: u64,
    /// Ratios σ_depth / σ_lat to fit at; the one whose per-part rates are closest to the
    /// paper's is chosen.
    #[arg(
        long,
        default_value = "1,1.5,2,3,4,6,8,12,16,24,32,48",
        value_delimiter = ','
    )]
    pub depth_to_lateral: Vec<f64>,
}

pub fn run(args: &InitialPosesArgs) -> anyhow::Result<()> {
    let symmetries: Vec<_> = Part::ALL.iter().map(|p| p.symmetry()).collect();
    let fit_sample = RateSample::new(&symmetries, args.samples as usize, args.seed);
    anyhow::ensure!(
        !args.depth_to_lateral.is_empty()
            && args
                .depth_to_lateral
                .iter()
                .all(|r| r.is_finite() && *r > 0.0),
        "--depth-to-lateral: positive ratios"
    );
    let per_part: Vec<_> = Part::ALL.iter().map(|p| paper_initial_rates(*p)).collect();
    let candidates = fit_initial_pose_shape(
        &fit_sample,
        PAPER_INITIAL_RATES_ALL,
        &per_part,
        &args.depth_to_lateral,
    );
    println!(
        "| σ_depth / σ_lat | σ_lat (mm) | σ_rot (°) | per-part misfit |\n|---:|---:|---:|---:|"
    );
    let mut sorted = candidates.clone();
    sorted.sort_by(|a, b| a.depth_to_lateral.total_cmp(&b.depth_to_lateral));
    for c in &sorted {
        match &c.fit {
            Ok(n) => println!(
                "| {:.3} | {:.3} | {:.3} | {:.3} |",
                c.depth_to_lateral,
                n.lateral_sigma_m * 1e3,
                n.rotation_sigma_rad.to_degrees(),
                c.per_part_misfit
            ),
            Err(e) => println!("| {:.3} | – | – | {e} |", c.depth_to_lateral),
        }
    }
    let chosen = candidates
        .first()
        .ok_or_else(|| anyhow::anyhow!("no ratio to fit at"))?;
    let fitted = chosen.fit.clone()?;
    println!();
    let check = RateSample::new(&symmetries, args.samples as usize, args.check_seed);
    println!(
        "Fitted on seed {} ({} draws per part) to the paper's initial row on `all` ({:.1} % / {:.2} %):\n  {}\n  σ_lat = {:.4} mm, σ_rot = {:.4}°\n",
        args.seed,
        args.samples,
        PAPER_INITIAL_RATES_ALL.mm5_deg5 * 100.0,
        PAPER_INITIAL_RATES_ALL.mm2_deg2 * 100.0,
        fitted.describe(),
        fitted.lateral_sigma_m * 1e3,
        fitted.rotation_sigma_rad.to_degrees(),
    );
    let default = InitialPoseNoise::default();
    println!(
        "Rates on seed {} (%; paper: Line-2D within 30 mm/30°, Table I):\n",
        args.check_seed
    );
    println!(
        "| part | paper 5/5 | paper 2/2 | fitted 5/5 | fitted 2/2 | default 5/5 | default 2/2 |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    let (fitted_rates, default_rates) = (check.rates(&fitted), check.rates(&default));
    for (i, part) in Part::ALL.iter().enumerate() {
        let paper = paper_initial_rates(*part);
        println!(
            "| {} | {:.1} | {:.2} | {:.1} | {:.2} | {:.1} | {:.2} |",
            part.display_name(),
            paper.mm5_deg5 * 100.0,
            paper.mm2_deg2 * 100.0,
            fitted_rates[i].mm5_deg5 * 100.0,
            fitted_rates[i].mm2_deg2 * 100.0,
            default_rates[i].mm5_deg5 * 100.0,
            default_rates[i].mm2_deg2 * 100.0,
        );
    }
    let (f, d) = (check.mean_rates(&fitted), check.mean_rates(&default));
    println!(
        "| all | {:.1} | {:.2} | {:.1} | {:.2} | {:.1} | {:.2} |",
        PAPER_INITIAL_RATES_ALL.mm5_deg5 * 100.0,
        PAPER_INITIAL_RATES_ALL.mm2_deg2 * 100.0,
        f.mm5_deg5 * 100.0,
        f.mm2_deg2 * 100.0,
        d.mm5_deg5 * 100.0,
        d.mm2_deg2 * 100.0,
    );
    println!("\ndefault: {}", default.describe());
    Ok(())
}
