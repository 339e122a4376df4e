//! `glint eval camera`: the mock camera against known geometry
//! (`glint_eval::camera_validation`).

use std::path::PathBuf;

use glint_eval::camera_validation::{CameraValidation, run};
use glint_geometry::parts::Part;

#[derive(clap::Args)]
pub struct CameraArgs {
    /// Parts: `all` or a comma-separated list of eye-bolt, tube-fitting, chrome-screw, gear,
    /// zigzag.
    #[arg(long, default_value = "all")]
    pub parts: String,
    /// Shot counts K to compare (comma-separated).
    #[arg(long, default_value = "1,2,4,8,16", value_delimiter = ',')]
    pub shots: Vec<u32>,
    /// Window radii r (px; the window is (2r+1)²) to compare, comma-separated.
    #[arg(long, default_value = "1,2,3,5", value_delimiter = ',')]
    pub window_radius_px: Vec<u32>,
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    /// Views per part (on the capture cap above the bin).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub views: u32,
    #[arg(long, default_value = "640x512", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub spp: u32,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long)]
    pub out: PathBuf,
}

fn parse_parts(s: &str) -> anyhow::Result<Vec<Part>> {
    if s == "all" {
        return Ok(Part::ALL.to_vec());
    }
    s.split(',')
        .map(|p| crate::mesh_cmd::parse_part(p.trim()).map_err(anyhow::Error::msg))
        .collect()
}

pub fn run_cmd(args: &CameraArgs) -> anyhow::Result<()> {
    let validation = CameraValidation {
        parts: parse_parts(&args.parts)?,
        shots: args.shots.clone(),
        window_radius_px: args.window_radius_px.clone(),
        instances: args.instances,
        views: args.views,
        resolution: args.resolution,
        spp: args.spp,
        seed: args.seed,
        out: args.out.clone(),
    };
    let table = run(&validation)?;
    println!("{table}\nwrote {}", args.out.display());
    Ok(())
}
