//! `glint bench …`: speed tables. Timings are wall-clock on this machine; compare rows
//! measured in the same run, not across machines.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Subcommand;
use glint_geometry::parts::Part;
use glint_geometry::sdf::{SdfConfig, SdfGrid};
use nalgebra::Point3;
use rayon::prelude::*;

#[derive(Subcommand)]
pub enum BenchCommand {
    /// SDF grids of the five parts: size, build time, samples with gradient per second.
    Sdf {
        /// Voxel edge, mm.
        #[arg(long, default_value_t = 1.0)]
        voxel_mm: f64,
        /// Padding around the part, mm.
        #[arg(long, default_value_t = 10.0)]
        padding_mm: f64,
        /// Query points per measurement.
        #[arg(long, default_value_t = 2_000_000)]
        samples: usize,
        /// Also write the table as CSV here.
        #[arg(long)]
        csv: Option<PathBuf>,
    },
}

pub fn run(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Sdf {
            voxel_mm,
            padding_mm,
            samples,
            csv,
        } => bench_sdf(voxel_mm, padding_mm, samples, csv),
    }
}

struct SdfRow {
    part: Part,
    triangles: usize,
    dims: [usize; 3],
    build_s: f64,
    single_per_s: f64,
    all_per_s: f64,
}

fn bench_sdf(
    voxel_mm: f64,
    padding_mm: f64,
    samples: usize,
    csv: Option<PathBuf>,
) -> anyhow::Result<()> {
    anyhow::ensure!(samples > 0, "--samples must be positive");
    let config = SdfConfig {
        voxel_size_m: voxel_mm * 1e-3,
        padding_m: padding_mm * 1e-3,
    };
    let threads = rayon::current_num_threads();
    let bar = crate::progress::bar(Part::ALL.len() as u64, "bench sdf");
    let mut rows = Vec::new();
    for part in Part::ALL {
        bar.set_message(part.name());
        let mesh = part.mesh();
        let start = Instant::now();
        let grid = SdfGrid::build(&mesh, &config)
            .with_context(|| format!("building the SDF of {part}"))?;
        let build_s = start.elapsed().as_secs_f64();
        let points = glint_geometry::sampling::near_surface_points(&mesh, samples, 2e-3, 7);
        // Single thread: a plain loop. The checksum keeps the work from being optimised away.
        let start = Instant::now();
        let checksum: f64 = points.iter().map(|p| sample_checksum(&grid, p)).sum();
        let single_per_s = samples as f64 / start.elapsed().as_secs_f64();
        let start = Instant::now();
        let checksum_all: f64 = points.par_iter().map(|p| sample_checksum(&grid, p)).sum();
        let all_per_s = samples as f64 / start.elapsed().as_secs_f64();
        anyhow::ensure!(
            (checksum - checksum_all).abs() <= 1e-6 * checksum.abs().max(1.0),
            "parallel sampling disagrees"
        );
        rows.push(SdfRow {
            part,
            triangles: mesh.triangles.len(),
            dims: grid.dims(),
            build_s,
            single_per_s,
            all_per_s,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();

    println!(
        "SDF grids: voxel {voxel_mm} mm, padding {padding_mm} mm, {samples} samples near the surface (σ = 2 mm); {threads} threads for \"all cores\"\n"
    );
    println!(
        "| part | triangles | grid (nodes) | build (s, all cores) | samples+gradient /s, 1 thread | samples+gradient /s, all cores |"
    );
    println!("|---|---:|---:|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {} | {} | {}×{}×{} | {:.3} | {:.1} M | {:.1} M |",
            r.part,
            r.triangles,
            r.dims[0],
            r.dims[1],
            r.dims[2],
            r.build_s,
            r.single_per_s / 1e6,
            r.all_per_s / 1e6
        );
    }
    if let Some(path) = csv {
        let mut text = String::from(
            "part,triangles,nx,ny,nz,build_s,samples_per_s_1_thread,samples_per_s_all_cores,threads\n",
        );
        for r in &rows {
            text += &format!(
                "{},{},{},{},{},{:.6},{:.0},{:.0},{threads}\n",
                r.part,
                r.triangles,
                r.dims[0],
                r.dims[1],
                r.dims[2],
                r.build_s,
                r.single_per_s,
                r.all_per_s
            );
        }
        glint_geometry::io::write_file_atomically(&path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        println!("\nwrote {}", path.display());
    }
    Ok(())
}

#[inline]
fn sample_checksum(grid: &SdfGrid, p: &Point3<f64>) -> f64 {
    let s = grid.sample(p);
    s.distance_m + s.gradient.x
}
