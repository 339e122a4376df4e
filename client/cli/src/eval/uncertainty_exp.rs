//! `glint eval uncertainty`: the paper's Fig. 3 check (`glint_eval::depth_uncertainty`), for
//! one or several shot counts.

use std::path::PathBuf;

use anyhow::Context;
use glint_eval::depth_uncertainty::{DepthUncertaintyExperiment, run};
use glint_geometry::Part;
use glint_geometry::io::write_file_atomically;

#[derive(clap::Args)]
pub struct UncertaintyArgs {
    #[arg(long, default_value = "gear", value_parser = crate::mesh_cmd::parse_part)]
    pub part: Part,
    #[command(flatten)]
    pub bin: crate::capture_cmd::BinArgs,
    /// Captures of the static scene.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(3..=1000))]
    pub repeats: u32,
    /// Patterns per capture, K, each with the camera's window for it; several (e.g. `1,8`)
    /// compare the single-shot and the multi-shot camera, each in `DIR/shots-K`.
    #[arg(long, default_value = "8", value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..=64))]
    pub shots: Vec<u32>,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run_cmd(args: &UncertaintyArgs) -> anyhow::Result<()> {
    anyhow::ensure!(!args.shots.is_empty(), "--shots: give at least one count");
    let mut rows = Vec::new();
    for &shots in &args.shots {
        let experiment = DepthUncertaintyExperiment {
            part: args.part,
            spec: args.bin.spec(),
            shots,
            repeats: args.repeats,
        };
        let result = run(&experiment)?;
        let dir = if args.shots.len() == 1 {
            args.out.clone()
        } else {
            args.out.join(format!("shots-{shots}"))
        };
        let report = result.write(&experiment, &dir)?;
        println!("{report}\nwrote {}", dir.display());
        let side = 2 * result.window_radius_px + 1;
        rows.push(result.table_row(&format!("{shots} × {side}×{side}")));
    }
    if args.shots.len() > 1 {
        let summary = format!(
            "# Fig. 3 by shot count: {}, {} captures\n\n\
             | camera (K × window) | pixels | Pearson r | Spearman ρ | Pearson r of logs | median measured/predicted |\n\
             |---|---:|---:|---:|---:|---:|\n{}\n\nEach camera's scatter plot: `shots-K/scatter.png`.\n",
            args.part.display_name(),
            args.repeats,
            rows.join("\n")
        );
        let path = args.out.join("report.md");
        write_file_atomically(&path, summary.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        println!("{summary}");
    }
    Ok(())
}
