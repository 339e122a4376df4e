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

mod fanout;
mod load;
mod nbv;
mod refine;

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
    /// The renderer and the mock camera on a bin scene: Mrays/s single- and multi-path (1 thread,
    /// all cores) and the wall time of one full stereo capture at two resolutions.
    Render {
        #[arg(long, default_value = "chrome-screw", value_parser = crate::mesh_cmd::parse_part)]
        part: Part,
        #[arg(long, default_value_t = 8)]
        instances: u32,
        /// Samples per pixel for the ray-throughput rows.
        #[arg(long, default_value_t = 2)]
        spp: u32,
        /// Instead of the tables, write the scene (white projector) for the Mitsuba 3 cross-check
        /// `services/render/scripts/mitsuba_crosscheck.py`, with Glint's radiance of it.
        #[arg(long)]
        mitsuba_export: Option<PathBuf>,
        /// Camera resolution of the export, WIDTHxHEIGHT (the N35's field of view is kept).
        #[arg(long, default_value = "640x512", value_parser = crate::capture_cmd::parse_resolution)]
        export_resolution: (u32, u32),
        /// Samples per pixel of the exported renders (Mitsuba renders with the same).
        #[arg(long, default_value_t = 64)]
        export_spp: u32,
        /// Seed of the exported Glint renders (another seed shows Glint's own noise).
        #[arg(long, default_value_t = 1)]
        export_seed: u64,
    },
    /// Pose refinement: the SDF refiner vs ICP (point-to-point, point-to-plane) on noisy points
    /// with a known answer: time per refinement, residual evaluations per second (1 thread, all
    /// cores), final errors. `--export` writes the problems for the Open3D/small_gicp script.
    Refine(refine::RefineBenchArgs),
    /// One next-best-view decision: every candidate predicted (render, σ̌_z, Fisher
    /// information), then the entropy plan; time per stage on 1 thread and all cores.
    Nbv(nbv::NbvBenchArgs),
    /// One decision spread over render-worker processes on loopback (1, 2, 4…) against
    /// in-process, with the wire's cost per candidate and a model of N machines; or whole
    /// sessions against a deployment's orchestrator (`--orchestrator`).
    Fanout(fanout::FanoutBenchArgs),
    /// Many concurrent sessions against one orchestrator: completed, refused (load shed),
    /// step latency p50/p99, throughput, the server's peak RSS.
    Load(load::LoadBenchArgs),
}

pub fn run(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Refine(args) => refine::run(&args),
        BenchCommand::Nbv(args) => nbv::run(&args),
        BenchCommand::Fanout(args) => fanout::run(&args),
        BenchCommand::Load(args) => load::run(&args),
        BenchCommand::Sdf {
            voxel_mm,
            padding_mm,
            samples,
            csv,
        } => bench_sdf(voxel_mm, padding_mm, samples, csv),
        BenchCommand::Render {
            part,
            instances,
            spp,
            mitsuba_export: None,
            ..
        } => bench_render(part, instances, spp),
        BenchCommand::Render {
            part,
            instances,
            mitsuba_export: Some(dir),
            export_resolution,
            export_spp,
            export_seed,
            ..
        } => export_render_scene(
            part,
            instances,
            &dir,
            export_resolution,
            export_spp,
            export_seed,
        ),
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
    let bar = glint_eval::progress::bar(Part::ALL.len() as u64, "bench sdf");
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

/// The render bench's scene: `instances` of `part` dropped into the default bin (seed 1) with
/// their ground-truth material, seen by `rig` from the first view of the spherical cap.
struct BenchScene {
    bin: glint_camera::bin::BinSpec,
    mesh: glint_geometry::TriMesh,
    poses: Vec<nalgebra::Isometry3<f64>>,
    part_material: glint_render::bsdf::PrincipledParams<f32>,
    scene: glint_render::scene::Scene,
    /// Left camera → world.
    t_w_c: nalgebra::Isometry3<f64>,
}

fn bench_scene(
    part: Part,
    instances: u32,
    rig: &glint_render::rig::SliRig,
) -> anyhow::Result<BenchScene> {
    use glint_camera::setup::{BinSetup, BinSetupSpec};
    use glint_camera::{materials, views};
    let mesh = part.mesh();
    let part_material = materials::ground_truth(part);
    let setup = BinSetup::new(
        &mesh,
        part_material,
        &BinSetupSpec {
            instances,
            seed: 1,
            width_px: rig.stereo.intrinsics.width_px,
            height_px: rig.stereo.intrinsics.height_px,
            samples_per_pixel: 4,
        },
    )?;
    // Straight down from 0.6 m: the bench's fixed view, not the capture cap's.
    let t_w_c = views::spherical_cap(1, 0.6, 0.0, setup.bin.centre(), rig.stereo.baseline_m)[0];
    let (bin, poses, scene) = (setup.bin, setup.poses, setup.scene);
    Ok(BenchScene {
        bin,
        mesh,
        poses,
        part_material,
        scene,
        t_w_c,
    })
}

fn bench_render(part: Part, instances: u32, spp: u32) -> anyhow::Result<()> {
    use glint_camera::capture::{CaptureConfig, MockSliCamera};
    use glint_render::integrator::{LightTransport, RenderSettings, render};
    use glint_render::rig::SliRig;

    anyhow::ensure!(
        instances >= 1 && spp >= 1,
        "--instances and --spp must be at least 1"
    );
    let full = SliRig::ensenso_n35();
    let BenchScene { scene, t_w_c, .. } = bench_scene(part, instances, &full)?;
    let [camera, _] = full.cameras(&t_w_c);
    let projector = full.projector(
        &t_w_c,
        glint_render::projector::Pattern::random_dots(640, 512, 0.5, 1),
    );
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let threads = rayon::current_num_threads();
    let mut rows = Vec::new();
    for (name, transport) in [
        ("single-path", LightTransport::SinglePath),
        ("multi-path (4 bounces)", LightTransport::MULTI_PATH_DEFAULT),
    ] {
        let settings = RenderSettings {
            transport,
            samples_per_pixel: spp,
            roi: None,
            seed: 1,
        };
        let time = |f: &dyn Fn() -> u64| {
            let start = Instant::now();
            let rays = f();
            rays as f64 / start.elapsed().as_secs_f64() / 1e6
        };
        let single = one_thread
            .install(|| time(&|| render(&scene, &camera, &projector, &settings).rays_traced));
        let all = time(&|| render(&scene, &camera, &projector, &settings).rays_traced);
        rows.push((name, single, all));
    }
    println!(
        "Renderer: {} × {instances} in the bin ({} triangles), 1280×1024, {spp} spp; {threads} threads for \"all cores\"\n",
        part.display_name(),
        scene.triangle_count()
    );
    println!("| light transport | Mrays/s, 1 thread | Mrays/s, all cores |");
    println!("|---|---:|---:|");
    for (name, single, all) in rows {
        println!("| {name} | {single:.2} | {all:.2} |");
    }
    println!(
        "\n| full stereo capture (render L+R multi-path 4 spp, sensor, matching) | wall time (s), all cores |"
    );
    println!("|---|---:|");
    for (w, h) in [(1280, 1024), (640, 512)] {
        let rig = full.resized(w, h)?;
        let camera = MockSliCamera {
            rig,
            scene: &scene,
            config: CaptureConfig::for_rig(&rig)?,
        };
        let start = Instant::now();
        let (capture, _truth) = camera.capture(&t_w_c, 1)?;
        println!(
            "| {w}×{h} (coverage of the image: {:.2}) | {:.2} |",
            capture.depth.coverage(),
            start.elapsed().as_secs_f64()
        );
    }
    bench_multi_shot(&scene, &full, &t_w_c)
}

/// The K-shot capture at 1280×1024: one path trace per camera (the pattern record) evaluated
/// under K patterns, K read-outs per camera, one space-time match; K = 1 is the single-shot
/// camera (direct renders). Each K at the camera's window for it.
fn bench_multi_shot(
    scene: &glint_render::scene::Scene,
    rig: &glint_render::rig::SliRig,
    t_w_c: &nalgebra::Isometry3<f64>,
) -> anyhow::Result<()> {
    use glint_camera::capture::{CaptureConfig, MockSliCamera};

    println!(
        "\n| K-shot capture, 1280×1024, multi-path 4 spp | window | render (s) | read-out (s) | match (s) | total (s) | total / single shot | coverage of the image |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut single = f64::NAN;
    for shots in [1u32, 2, 4, 8, 16] {
        let config = CaptureConfig::for_rig_and_shots(rig, shots)?;
        let side = config.matcher.window_side_px();
        let camera = MockSliCamera {
            rig: *rig,
            scene,
            config,
        };
        // The three stages of `capture`, timed apart.
        let start = Instant::now();
        let rendered = camera.render_shots(t_w_c, 1);
        let render_s = start.elapsed().as_secs_f64();
        let pairs = camera.read_out_shots(&rendered, 1);
        let read_out_s = start.elapsed().as_secs_f64() - render_s;
        let lefts: Vec<_> = pairs.iter().map(|p| &p[0]).collect();
        let rights: Vec<_> = pairs.iter().map(|p| &p[1]).collect();
        let (depth, _) = camera.match_shots(&lefts, &rights)?;
        let total = start.elapsed().as_secs_f64();
        if shots == 1 {
            single = total;
        }
        println!(
            "| {shots} | {side}×{side} | {render_s:.2} | {read_out_s:.2} | {:.2} | {total:.2} | {:.2} | {:.3} |",
            total - render_s - read_out_s,
            total / single,
            depth.coverage()
        );
    }
    Ok(())
}

/// The bench scene (same part, drop seed and view as [`bench_render`]) under the white pattern,
/// exported for Mitsuba with Glint's single- and multi-path radiance.
fn export_render_scene(
    part: Part,
    instances: u32,
    dir: &std::path::Path,
    (width, height): (u32, u32),
    spp: u32,
    seed: u64,
) -> anyhow::Result<()> {
    use crate::mitsuba_export::{ExportShape, MitsubaExport};
    use glint_camera::materials;
    use glint_render::projector::Pattern;
    use glint_render::rig::SliRig;

    anyhow::ensure!(
        instances >= 1 && spp >= 1,
        "--instances and --export-spp must be at least 1"
    );
    let rig = SliRig::ensenso_n35().resized(width, height)?;
    let BenchScene {
        bin,
        mesh,
        poses,
        part_material,
        scene,
        t_w_c,
    } = bench_scene(part, instances, &rig)?;
    let [camera, _] = rig.cameras(&t_w_c);
    let projector = rig.projector(&t_w_c, Pattern::White);
    let mut shapes: Vec<ExportShape> = poses
        .iter()
        .enumerate()
        .map(|(i, t_w_o)| ExportShape {
            name: format!("{}_{:02}", part.name(), i + 1),
            mesh_w: mesh.transformed(&t_w_o.cast()),
            material: part.name(),
            label: i as u16 + 1,
        })
        .collect();
    shapes.push(ExportShape {
        name: "bin".into(),
        mesh_w: bin.mesh(),
        material: "bin",
        label: glint_camera::bin::BIN_LABEL,
    });
    let export = MitsubaExport {
        scene: &scene,
        shapes,
        materials: vec![(part.name(), part_material), ("bin", materials::bin())],
        camera,
        projector: &projector,
        samples_per_pixel: spp,
        seed,
    };
    let path = crate::mitsuba_export::write(dir, &export)?;
    println!(
        "wrote {} ({} × {instances} and the bin, {width}×{height}, {spp} spp); next: \
         python3 services/render/scripts/mitsuba_crosscheck.py {}",
        path.display(),
        part.display_name(),
        dir.display()
    );
    Ok(())
}
