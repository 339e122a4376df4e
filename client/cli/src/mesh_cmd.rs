//! `glint mesh …`: export the parametric parts, inspect mesh files.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use glint_geometry::io::{self, PlyEncoding};
use glint_geometry::parts::Part;
use glint_geometry::{LengthUnit, TriMesh};

#[derive(Subcommand)]
pub enum MeshCommand {
    /// Writes one of the five parts as a PLY file (and optionally a PNG preview).
    Export {
        /// eye-bolt, tube-fitting, chrome-screw, gear or zigzag.
        #[arg(long, value_parser = parse_part)]
        part: Part,
        /// Output PLY path.
        #[arg(long)]
        out: PathBuf,
        /// Unit of the written vertices (BOP models are in mm).
        #[arg(long, default_value = "mm", value_parser = parse_unit)]
        unit: LengthUnit,
        /// Write ascii instead of binary little-endian PLY.
        #[arg(long)]
        ascii: bool,
        /// Also write a shaded PNG preview here.
        #[arg(long)]
        preview: Option<PathBuf>,
    },
    /// Reads a mesh file (PLY, OBJ, STL) and reports its size, topology and problems.
    Info {
        /// The mesh file.
        path: PathBuf,
        /// Unit the file is written in.
        #[arg(long, value_parser = parse_unit)]
        unit: LengthUnit,
        /// Output format.
        #[arg(long, value_enum, default_value_t = InfoFormat::Text)]
        format: InfoFormat,
    },
}

#[derive(Clone, Copy, ValueEnum)]
pub enum InfoFormat {
    Text,
    Json,
}

pub fn parse_part(s: &str) -> Result<Part, String> {
    s.parse()
}

pub fn parse_unit(s: &str) -> Result<LengthUnit, String> {
    s.parse()
}

/// Preview size in pixels.
const PREVIEW_PX: u32 = 512;

/// The direction previews look along: from above and to the side.
pub fn preview_direction() -> glam::Vec3 {
    glam::Vec3::new(-0.55, -0.75, -0.6)
}

pub fn run(cmd: MeshCommand) -> anyhow::Result<()> {
    match cmd {
        MeshCommand::Export {
            part,
            out,
            unit,
            ascii,
            preview,
        } => {
            let mesh = part.mesh();
            export(&mesh, &out, unit, ascii)?;
            println!(
                "wrote {} ({} triangles, {unit}, symmetry {})",
                out.display(),
                mesh.triangles.len(),
                part.symmetry()
            );
            if let Some(png) = preview {
                write_preview(&mesh, &png)?;
                println!("wrote {}", png.display());
            }
            Ok(())
        }
        MeshCommand::Info { path, unit, format } => {
            let loaded = io::read_mesh(&path, unit)?;
            let r = &loaded.report;
            let extent_mm = (r.aabb_max - r.aabb_min).cast::<f64>() * 1e3;
            match format {
                InfoFormat::Text => {
                    println!("{}", path.display());
                    println!("  vertices            {}", r.vertices);
                    println!("  triangles           {}", r.triangles);
                    println!(
                        "  extent (mm)         {:.3} × {:.3} × {:.3}",
                        extent_mm.x, extent_mm.y, extent_mm.z
                    );
                    println!("  volume (mm³)        {:.1}", r.signed_volume_m3 * 1e9);
                    println!("  components          {}", r.components);
                    println!("  watertight          {}", r.is_watertight());
                    for w in &loaded.warnings {
                        println!("  warning: {w}");
                    }
                }
                InfoFormat::Json => {
                    let json = serde_json::json!({
                        "path": path.display().to_string(),
                        "vertices": r.vertices,
                        "triangles": r.triangles,
                        "extent_mm": [extent_mm.x, extent_mm.y, extent_mm.z],
                        "volume_mm3": r.signed_volume_m3 * 1e9,
                        "components": r.components,
                        "watertight": r.is_watertight(),
                        "warnings": loaded.warnings,
                    });
                    println!("{}", serde_json::to_string_pretty(&json)?);
                }
            }
            Ok(())
        }
    }
}

/// Writes `mesh` as PLY in `unit`.
pub fn export(
    mesh: &TriMesh,
    out: &std::path::Path,
    unit: LengthUnit,
    ascii: bool,
) -> anyhow::Result<()> {
    let encoding = if ascii {
        PlyEncoding::Ascii
    } else {
        PlyEncoding::BinaryLittleEndian
    };
    io::write_ply(out, mesh, unit, encoding).with_context(|| format!("writing {}", out.display()))
}

/// Writes a shaded PNG preview of `mesh`.
pub fn write_preview(mesh: &TriMesh, out: &std::path::Path) -> anyhow::Result<()> {
    let png = crate::preview::render_png(mesh, PREVIEW_PX, preview_direction())?;
    io::write_file_atomically(out, &png).with_context(|| format!("writing {}", out.display()))
}
