//! `glint bench render --mitsuba-export DIR`: the bench scene as files Mitsuba 3 can load, with
//! Glint's own radiance of it, for `services/render/scripts/mitsuba_crosscheck.py`.
//!
//! `DIR/scene.json` (written last: its presence means the export is complete) describes:
//! - `shapes`: one PLY per instance, world frame, metres, with its material's index;
//! - `materials`: principled parameters under Mitsuba's `principled` names (Glint is
//!   monochrome: `base_color` is one grey value);
//! - `camera`: pinhole intrinsics (pixels; pixel (u, v) covers [u, u+1) × [v, v+1), so its
//!   centre is u + 0.5) and `t_w_c` as a row-major 4×4, camera frame x right, y down, z forward;
//! - `projector`: the same for the projector, a white pattern, and its radiant intensity in W/sr,
//!   constant over its frustum and zero outside;
//! - `renders`: per light transport, Glint's settings, its wall time and the EXR with channel
//!   `radiance` (W·sr⁻¹·m⁻²), `depth_m` and `label` (instance label through the pixel centre:
//!   1… for the parts in `shapes` order, the bin's label, 0 for nothing).

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::PixelRect;
use glint_geometry::io::{PlyEncoding, write_file_atomically, write_ply};
use glint_geometry::{LengthUnit, TriMesh};
use glint_render::bsdf::PrincipledParams;
use glint_render::integrator::{Camera, LightTransport, RenderSettings, render};
use glint_render::projector::Projector;
use glint_render::scene::Scene;
use nalgebra::Isometry3;
use serde_json::{Value, json};

/// One mesh of the exported scene, already in the world frame.
pub struct ExportShape<'a> {
    pub name: String,
    pub mesh_w: TriMesh,
    pub material: &'a str,
    /// The label the scene gives it in `label` images.
    pub label: u16,
}

/// What to export: the scene as Glint renders it and the same scene as meshes and materials.
pub struct MitsubaExport<'a> {
    pub scene: &'a Scene,
    pub shapes: Vec<ExportShape<'a>>,
    pub materials: Vec<(&'a str, PrincipledParams<f32>)>,
    pub camera: Camera,
    /// Must show the white pattern (Mitsuba's side reproduces that, not a texture).
    pub projector: &'a Projector,
    pub samples_per_pixel: u32,
    pub seed: u64,
}

fn matrix_rows(t: &Isometry3<f64>) -> Value {
    let m = t.to_homogeneous();
    json!(
        (0..4)
            .map(|r| (0..4).map(|c| m[(r, c)]).collect::<Vec<_>>())
            .collect::<Vec<_>>()
    )
}

fn intrinsics_json(k: &PinholeIntrinsics) -> Value {
    json!({
        "width_px": k.width_px, "height_px": k.height_px,
        "fx_px": k.fx_px, "fy_px": k.fy_px, "cx_px": k.cx_px, "cy_px": k.cy_px,
    })
}

fn principled_json(p: &PrincipledParams<f32>) -> Value {
    let mut map = serde_json::Map::new();
    for (name, value) in PrincipledParams::<f32>::NAMES.iter().zip(p.to_array()) {
        map.insert((*name).into(), json!(value));
    }
    Value::Object(map)
}

/// Most surface interactions per path and the interaction after which Russian roulette may
/// end one (none for single-path).
fn path_depth(transport: LightTransport) -> (u32, Option<u32>) {
    match transport {
        LightTransport::SinglePath => (1, None),
        LightTransport::MultiPath {
            max_bounces,
            roulette_after,
            ..
        } => (max_bounces, Some(roulette_after)),
    }
}

/// Writes each shape's PLY under `dir/meshes/` and returns the `shapes` and `materials` of a
/// scene description (each shape names its material by index).
fn write_shapes(
    dir: &Path,
    shapes: &[ExportShape],
    materials: &[(&str, PrincipledParams<f32>)],
) -> anyhow::Result<(Vec<Value>, Vec<Value>)> {
    std::fs::create_dir_all(dir.join("meshes"))
        .with_context(|| format!("creating {}", dir.join("meshes").display()))?;
    let mut shapes_json = Vec::new();
    for shape in shapes {
        let file = format!("meshes/{}.ply", shape.name);
        write_ply(
            &dir.join(&file),
            &shape.mesh_w,
            LengthUnit::Metre,
            PlyEncoding::BinaryLittleEndian,
        )
        .with_context(|| format!("writing {}", dir.join(&file).display()))?;
        let material = materials
            .iter()
            .position(|(name, _)| *name == shape.material)
            .with_context(|| format!("shape {} has no material {}", shape.name, shape.material))?;
        shapes_json.push(json!({
            "name": shape.name,
            "file": file,
            "material": material,
            "label": shape.label,
        }));
    }
    let materials_json = materials
        .iter()
        .map(|(name, p)| json!({ "name": name, "principled": principled_json(p) }))
        .collect();
    Ok((shapes_json, materials_json))
}

/// Writes the export into `dir` (created if missing) and returns the path of `scene.json`.
pub fn write(dir: &Path, export: &MitsubaExport) -> anyhow::Result<std::path::PathBuf> {
    anyhow::ensure!(
        matches!(
            export.projector.pattern,
            glint_render::projector::Pattern::White
        ),
        "the Mitsuba export needs the projector's white pattern"
    );
    let (shapes, materials) = write_shapes(dir, &export.shapes, &export.materials)?;

    let threads = rayon::current_num_threads();
    let mut renders = Vec::new();
    for (name, transport) in [
        ("single-path", LightTransport::SinglePath),
        ("multi-path", LightTransport::MULTI_PATH_DEFAULT),
    ] {
        let settings = RenderSettings {
            transport,
            samples_per_pixel: export.samples_per_pixel,
            roi: None,
            seed: export.seed,
        };
        let start = Instant::now();
        let out = render(export.scene, &export.camera, export.projector, &settings);
        let time_s = start.elapsed().as_secs_f64();
        let file = format!("glint_{name}.exr");
        let label = glint_geometry::image::Image::new(
            out.label.width(),
            out.label.height(),
            out.label.data().iter().map(|&l| f32::from(l)).collect(),
        )?;
        glint_render::exr_io::write_exr(
            &dir.join(&file),
            &[
                ("radiance", &out.radiance),
                ("depth_m", &out.depth_m),
                ("label", &label),
            ],
        )
        .with_context(|| format!("writing {}", dir.join(&file).display()))?;
        let (max_bounces, roulette_after) = path_depth(transport);
        renders.push(json!({
            "transport": name,
            // Surface interactions with next-event estimation at each (Mitsuba's max_depth is
            // this + 1: it counts the segment to the light too).
            "max_bounces": max_bounces,
            "roulette_after": roulette_after,
            "samples_per_pixel": export.samples_per_pixel,
            "seed": export.seed,
            "exr": file,
            "time_s": time_s,
            "rays_traced": out.rays_traced,
            "threads": threads,
        }));
    }

    let p = export.projector;
    let scene_json = json!({
        "written_by": "glint bench render --mitsuba-export",
        "length_unit": "m",
        "radiance_unit": "W/(sr m^2)",
        "monochrome": true,
        "shading": "geometric (face) normals, two-sided",
        "shapes": shapes,
        "materials": materials,
        "camera": {
            "intrinsics": intrinsics_json(&export.camera.intrinsics),
            "t_w_c": matrix_rows(&export.camera.t_w_c),
            "frame": "x right, y down, z forward",
        },
        "projector": {
            "intrinsics": intrinsics_json(&p.intrinsics),
            "t_w_p": matrix_rows(&p.t_w_p),
            "frame": "x right, y down, z forward",
            "pattern": "white",
            "intensity_w_per_sr": p.intensity_w_per_sr,
            "profile": "constant radiant intensity inside the frustum, zero outside",
        },
        "renders": renders,
    });
    let path = dir.join("scene.json");
    write_file_atomically(&path, serde_json::to_string_pretty(&scene_json)?.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// One candidate view of a `glint bench nbv` decision: where the rig stands and the crops the
/// prediction rendered (none when the part is not in view).
pub struct NbvExportCandidate {
    /// Left and right cameras (full-sensor intrinsics, placed in the world).
    pub cameras: [Camera; 2],
    /// Projector → world.
    pub t_w_p: Isometry3<f64>,
    /// The left crop the prediction rendered.
    pub left_crop: Option<PixelRect>,
    /// First column of the right crop (the left crop's size and rows), px; may be off the
    /// sensor.
    pub right_crop_u_min_px: Option<i64>,
}

/// What `glint bench nbv --mitsuba-export` hands `mitsuba_nbv_bench.py`: the prediction's scene
/// (the part at the hypothesis pose with the fitted material, the known surroundings), the
/// candidates and Glint's times of the same decision.
pub struct NbvExport<'a> {
    pub shapes: Vec<ExportShape<'a>>,
    pub materials: Vec<(&'a str, PrincipledParams<f32>)>,
    /// The projector's optics and radiant intensity (its pose is per candidate).
    pub projector: &'a Projector,
    pub candidates: Vec<NbvExportCandidate>,
    /// Samples per pixel of every prediction render.
    pub samples_per_pixel: u32,
    /// The multi-path white render's transport.
    pub multi_path: LightTransport,
    /// Glint's decision times, one JSON object per thread count.
    pub glint_times: Vec<Value>,
}

/// Writes the NBV export into `dir` (created if missing) and returns the path of
/// `nbv_scene.json` (written last: its presence means the export is complete).
pub fn write_nbv(dir: &Path, export: &NbvExport) -> anyhow::Result<std::path::PathBuf> {
    let (shapes, materials) = write_shapes(dir, &export.shapes, &export.materials)?;
    let crop_json = |r: &PixelRect, u_min: i64| json!({ "u_min": u_min, "v_min": r.v_min, "width": r.width, "height": r.height });
    let candidates: Vec<Value> = export
        .candidates
        .iter()
        .map(|c| {
            let crops = match (c.left_crop, c.right_crop_u_min_px) {
                (Some(r), Some(u_right)) => {
                    json!([crop_json(&r, i64::from(r.u_min)), crop_json(&r, u_right)])
                }
                _ => Value::Null,
            };
            json!({
                "cameras": c.cameras.iter().map(|cam| json!({
                    "intrinsics": intrinsics_json(&cam.intrinsics),
                    "t_w_c": matrix_rows(&cam.t_w_c),
                })).collect::<Vec<_>>(),
                "t_w_p": matrix_rows(&c.t_w_p),
                "crops": crops,
            })
        })
        .collect();
    let (max_bounces, roulette_after) = path_depth(export.multi_path);
    let p = export.projector;
    let scene_json = json!({
        "written_by": "glint bench nbv --mitsuba-export",
        "length_unit": "m",
        "radiance_unit": "W/(sr m^2)",
        "monochrome": true,
        "shading": "geometric (face) normals, two-sided",
        "frame": "cameras and projector: x right, y down, z forward",
        "shapes": shapes,
        "materials": materials,
        "projector": {
            "intrinsics": intrinsics_json(&p.intrinsics),
            "pattern": "white",
            "intensity_w_per_sr": p.intensity_w_per_sr,
            "profile": "constant radiant intensity inside the frustum, zero outside",
        },
        "candidates": candidates,
        "renders_per_candidate": "single-path and multi-path white, left and right crop",
        "samples_per_pixel": export.samples_per_pixel,
        "multi_path": { "max_bounces": max_bounces, "roulette_after": roulette_after },
        "glint": export.glint_times,
    });
    let path = dir.join("nbv_scene.json");
    write_file_atomically(&path, serde_json::to_string_pretty(&scene_json)?.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}
