//! Scenes for the experiments: mock-camera bins written as BOP scenes (cached on disk, so a
//! rerun reads them back), and the reader that turns any BOP scene into per-view object
//! points with their depth uncertainty.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use glint_camera::capture::{CaptureConfig, MockSliCamera};
use glint_camera::dataset::bop::{
    BopSceneReader, BopSceneWriter, MaskKind, same_pose, write_models,
};
use glint_camera::dataset::rig_file::{read_rig_json, write_rig_json};
use glint_camera::dataset::{PatternImage, StereoSide, write_png_u8};
use glint_camera::materials;
use glint_camera::record::{to_8bit, write_bop_image};
use glint_camera::setup::{BinSetup, BinSetupSpec, capture_seed};
use glint_estimation::depth_sigma::{NoiseModel, depth_sigma};
use glint_estimation::points::{DepthPoint, DepthSigma, interior_mask, object_points};
use glint_geometry::image::{Image, normalised_intensity};
use glint_geometry::io::read_mesh;
use glint_geometry::io::write_file_atomically;
use glint_geometry::{LengthUnit, Part, Symmetry, TriMesh};
use glint_orchestrator::local::MockCamera;
use glint_orchestrator::stages::SessionObject;
use glint_render::bsdf::PrincipledParams;
use glint_render::rig::SliRig;
use nalgebra::Isometry3;

/// The object of an experiment: a mesh (metres, its own frame), its symmetry, and the
/// ground-truth material the mock camera paints it with.
#[derive(Clone, Debug)]
pub struct EvalObject {
    /// The object's name: its directory under the scene cache's root.
    pub name: String,
    /// The mesh, metres, in the object's frame.
    pub mesh: TriMesh,
    /// The object's symmetry, used to score pose errors.
    pub symmetry: Symmetry,
    /// The ground-truth material the mock camera renders the object with.
    pub material: PrincipledParams<f32>,
}

/// An object of an experiment with its calibration (what the render workers know of it).
#[derive(Clone, Debug)]
pub struct CalibratedObject {
    /// The part: mesh, symmetry and the material the mock camera paints it with.
    pub object: EvalObject,
    /// Its fitted material and calibrated response (`glint calibrate …`), never the truth.
    pub calibration: glint_calibration::shipped::Calibration,
}

/// The distinct `names` in the order they first appear (the parts of a result table).
pub fn names_in_order<'a>(names: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for name in names {
        if !out.contains(&name) {
            out.push(name);
        }
    }
    out
}

impl EvalObject {
    /// The part as a session knows it: its name and mesh (never its material or poses).
    pub fn session_object(&self) -> SessionObject {
        SessionObject::new(self.name.clone(), self.mesh.clone())
    }
}

/// The seed of bin `s` of an experiment with base seed `seed`: `seed·10⁴ + family + s`, where
/// each experiment has its own `family` (Fig. 9 8000, the prediction study 9000) so that no
/// two share bins and none meets the tuning seeds.
pub fn bin_seed(seed: u64, family: u64, s: u32) -> u64 {
    seed.wrapping_mul(10_000)
        .wrapping_add(family + u64::from(s))
}

/// A mock bin of `instances` copies of `object` dropped with `seed`, seen by `camera`, and
/// `views` candidate views on the cap above it.
pub fn mock_bin(
    object: &EvalObject,
    instances: u32,
    seed: u64,
    views: usize,
    camera: &MockCameraSpec,
) -> anyhow::Result<(MockCamera, Vec<Isometry3<f64>>)> {
    let mut setup = BinSetup::new(
        &object.mesh,
        object.material,
        &BinSetupSpec {
            instances,
            seed,
            width_px: camera.resolution.0,
            height_px: camera.resolution.1,
            samples_per_pixel: camera.spp,
        },
    )?;
    setup.config = camera.rig_and_config()?.1;
    let candidates = setup.views(views);
    Ok((MockCamera { setup }, candidates))
}

/// The objects of an experiment: `parts` (painted with their true materials, or with the matte
/// diffuse twin when `matte`), or instead the mesh file `mesh` (in `unit`, with `symmetry`),
/// painted like the shiny Tube Fitting.
pub fn eval_objects(
    parts: &[Part],
    mesh: Option<&Path>,
    unit: LengthUnit,
    symmetry: &Symmetry,
    matte: bool,
) -> anyhow::Result<Vec<EvalObject>> {
    let paint = |part: Part| {
        if matte {
            materials::diffuse_twin()
        } else {
            materials::ground_truth(part)
        }
    };
    if let Some(path) = mesh {
        let loaded =
            read_mesh(path, unit).with_context(|| format!("reading --mesh {}", path.display()))?;
        for w in &loaded.warnings {
            tracing::warn!("{}: {w}", path.display());
        }
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "mesh".into());
        return Ok(vec![EvalObject {
            name,
            mesh: loaded.mesh,
            symmetry: symmetry.clone(),
            material: paint(Part::TubeFitting),
        }]);
    }
    Ok(parts
        .iter()
        .map(|&p| EvalObject {
            name: p.name().into(),
            mesh: p.mesh(),
            symmetry: p.symmetry(),
            material: paint(p),
        })
        .collect())
}

/// How mock-camera scenes are made.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SceneSpec {
    /// The mock camera's matcher settings (Debug form): scenes matched differently are not
    /// reused.
    pub matcher: String,
    /// The matching window's radius, px (the rest of the matcher is the camera's default).
    pub window_radius_px: u32,
    /// Patterns projected per view (the space-time matcher matches over all of them).
    pub shots: u32,
    /// Parts per bin.
    pub instances: u32,
    /// Views captured per bin, on the cap above it.
    pub views: u32,
    /// Width of the mock camera's images, px.
    pub width_px: u32,
    /// Height of the mock camera's images, px.
    pub height_px: u32,
    /// Samples per pixel of the mock camera's renders.
    pub spp: u32,
}

/// The BOP object id the scenes give their object.
pub const OBJ_ID: u32 = 1;
/// The BOP scene holding one bin.
const SCENE: &str = "000001";

/// Two shots of view 0 for the noise model (photon transfer), next to the pattern images.
fn noise_shot_path(reader_or_writer_glint_dir: &Path, shot: char) -> PathBuf {
    reader_or_writer_glint_dir
        .join("noise_shots")
        .join(format!("{shot}.png"))
}

fn spec_path(dataset_dir: &Path) -> PathBuf {
    dataset_dir.join("glint_scene_spec.json")
}

/// The BOP dataset directory of `object`'s bin with `seed` under `root`, generated unless a
/// complete one with the same spec is already there. Returns the scene directory.
pub fn ensure_scene(
    root: &Path,
    object: &EvalObject,
    seed: u64,
    spec: &SceneSpec,
) -> anyhow::Result<PathBuf> {
    let dataset = root.join(&object.name).join(format!("seed_{seed}"));
    let scene_dir = dataset.join("test").join(SCENE);
    let done = spec_path(&dataset);
    if let Ok(text) = std::fs::read_to_string(&done)
        && serde_json::from_str::<SceneSpec>(&text).ok().as_ref() == Some(spec)
    {
        return Ok(scene_dir);
    }
    generate(&dataset, &scene_dir, object, seed, spec)?;
    write_file_atomically(&done, serde_json::to_string_pretty(spec)?.as_bytes())
        .with_context(|| format!("writing {}", done.display()))?;
    Ok(scene_dir)
}

/// The mock camera of an experiment: the Ensenso N35 rig at `resolution`, rendering with
/// `spp` samples per pixel, projecting `shots` patterns, matching `window_radius_px` windows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MockCameraSpec {
    /// Image size (width, height), px.
    pub resolution: (u32, u32),
    /// Samples per pixel of the renders.
    pub spp: u32,
    /// Patterns projected per view.
    pub shots: u32,
    /// The stereo matcher's window radius, px.
    pub window_radius_px: u32,
}

impl MockCameraSpec {
    /// The rig and the capture settings; the error names what is out of range.
    pub fn rig_and_config(&self) -> anyhow::Result<(SliRig, CaptureConfig)> {
        let rig = SliRig::ensenso_n35().resized(self.resolution.0, self.resolution.1)?;
        let mut config = CaptureConfig {
            samples_per_pixel: self.spp,
            ..CaptureConfig::for_rig_and_shots(&rig, self.shots)?
        };
        let r = self.window_radius_px;
        config.matcher.window_radius_px = r;
        // The edge pass re-matches with a smaller window; keep it smaller than the main one.
        config.matcher.edge_windows = config.matcher.edge_windows.filter(|_| r > 1).map(|mut e| {
            e.window_radius_px = e.window_radius_px.min(r - 1);
            e
        });
        config.matcher.validate()?;
        Ok((rig, config))
    }
}

impl std::fmt::Display for MockCameraSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let side = 2 * self.window_radius_px + 1;
        write!(
            f,
            "{}×{} px, {} spp, {} shots, {side}×{side} windows",
            self.resolution.0, self.resolution.1, self.spp, self.shots
        )
    }
}

impl SceneSpec {
    /// The camera the scenes are captured with.
    pub fn camera(&self) -> MockCameraSpec {
        MockCameraSpec {
            resolution: (self.width_px, self.height_px),
            spp: self.spp,
            shots: self.shots,
            window_radius_px: self.window_radius_px,
        }
    }
}

fn generate(
    dataset: &Path,
    scene_dir: &Path,
    object: &EvalObject,
    seed: u64,
    spec: &SceneSpec,
) -> anyhow::Result<()> {
    let setup = BinSetup::new(
        &object.mesh,
        object.material,
        &BinSetupSpec {
            instances: spec.instances,
            seed,
            width_px: spec.width_px,
            height_px: spec.height_px,
            samples_per_pixel: spec.spp,
        },
    )?;
    let rig = setup.rig;
    let camera = MockSliCamera {
        config: spec.camera().rig_and_config()?.1,
        ..setup.camera()
    };
    let view_poses = setup.views(spec.views as usize);
    let poses = &setup.poses;
    write_models(
        &dataset.join("models"),
        &[(OBJ_ID, &object.mesh, &object.symmetry)],
    )?;
    let mut bop = BopSceneWriter::create(scene_dir, BopSceneWriter::DEFAULT_DEPTH_SCALE_MM)?;
    let glint_dir = bop.layout().glint_dir();
    std::fs::create_dir_all(glint_dir.join("noise_shots"))
        .with_context(|| format!("creating {}", glint_dir.display()))?;
    write_rig_json(&bop.layout().rig_json(), &rig)?;
    let bar = crate::progress::bar(view_poses.len() as u64, &format!("{} {seed}", object.name));
    for (k, t_w_c) in view_poses.iter().enumerate() {
        let view_seed = capture_seed(seed, k);
        let (capture, truth) = camera.capture(t_w_c, view_seed)?;
        write_bop_image(&mut bop, k as u32, &capture, &camera, poses, OBJ_ID)?;
        if k == 0 {
            // Two more read-outs of this view's left pattern radiance: what a user does to
            // measure the sensor noise (two shots of a static scene).
            for (shot, s) in [('a', 11u64), ('b', 12u64)] {
                let dn = camera
                    .config
                    .sensor
                    .read_out(&truth.left_radiance, view_seed ^ s);
                let path = noise_shot_path(&glint_dir, shot);
                write_png_u8(&path, &to_8bit(&dn, camera.config.sensor.max_dn()))
                    .with_context(|| format!("writing {}", path.display()))?;
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    bop.finish()?;
    Ok(())
}

/// One object instance seen in one view: its depth points (world frame) and ground truth.
#[derive(Clone, Debug)]
pub struct InstanceView {
    /// The instance's number in the scene, the same in every view: instances are numbered in
    /// the order first seen, and matched across views by their world pose.
    pub instance: usize,
    /// Ground truth, evaluation only.
    pub t_c_o_gt: Isometry3<f64>,
    /// Share of the instance's silhouette visible in the view (BOP's `visib_fract`).
    pub visib_fract: f64,
    /// Depth points of the instance's visible mask, world frame, each with its σ_z (eq 1–7).
    pub points: Vec<DepthPoint>,
}

/// One image of a scene.
#[derive(Clone, Debug)]
pub struct LoadedView {
    /// The BOP image id.
    pub im_id: u32,
    /// Camera → world.
    pub t_w_c: Isometry3<f64>,
    /// The `obj_id` instances annotated in this view.
    pub objects: Vec<InstanceView>,
}

/// A static scene read back: its views, with instances numbered across views.
#[derive(Clone, Debug)]
pub struct LoadedScene {
    /// The scene's images, in BOP image-id order.
    pub views: Vec<LoadedView>,
}

fn pattern_as_normalised(image: PatternImage) -> (Image<f32>, u16) {
    match image {
        PatternImage::Bits8(img) => (normalised_intensity(&img.map(u16::from), 255), 255),
        PatternImage::Bits16(img) => (normalised_intensity(&img, u16::MAX), u16::MAX),
    }
}

/// Reads a BOP scene (`obj_id` instances only): per view, each instance's masked depth as
/// world points with σ_z (eq 1–7). Instances are identified across views by their world pose
/// (the scene is static), so multi-view trials can stack one instance's points.
///
/// `window_radius`: the matcher's window radius, px, over which eq 1–5 sums image gradients.
/// `erode_px`: only mask pixels whose `(2·erode_px + 1)²` window lies inside the mask give
/// points (see [`interior_mask`]); 0 keeps the whole mask.
pub fn load_scene(
    scene_dir: &Path,
    obj_id: u32,
    window_radius: u32,
    erode_px: u32,
) -> anyhow::Result<LoadedScene> {
    let reader = BopSceneReader::open(scene_dir)?;
    if !reader.has_gt() {
        bail!(
            "{}: the scene has no scene_gt.json; the experiment needs ground-truth poses",
            scene_dir.display()
        );
    }
    let layout = reader.layout().clone();
    let rig_path = layout.rig_json();
    // σ_z from the pattern images (eq 1–5), with a noise model fitted to `glint/noise_shots`.
    let rig = read_rig_json(&rig_path)?;
    let glint_dir = layout.glint_dir();
    let shot = |c| -> anyhow::Result<Image<f32>> {
        let path = noise_shot_path(&glint_dir, c);
        let img = image::open(&path)
            .with_context(|| format!("reading noise shot {}", path.display()))?
            .to_luma8();
        let dn = Image::new(
            img.width(),
            img.height(),
            img.as_raw().iter().map(|&v| v as u16).collect(),
        )?;
        Ok(normalised_intensity(&dn, 255))
    };
    let noise = NoiseModel::fit_from_pair(&shot('a')?, &shot('b')?, 255)
        .with_context(|| format!("noise model of {}", scene_dir.display()))?;
    let mut views = Vec::new();
    let mut instances_t_w_o: Vec<Isometry3<f64>> = Vec::new();
    for im_id in reader.image_ids() {
        let camera = reader.camera(im_id)?;
        let Some(t_c_w) = camera.t_c_w else {
            bail!(
                "{}: image {im_id} has no camera pose (cam_R_w2c/cam_t_w2c); multi-view \
                 refinement needs it",
                scene_dir.display()
            );
        };
        let t_w_c = t_c_w.inverse();
        let depth = reader.depth(im_id)?;
        // eq 1–5 over every shot of the view (the space-time window's gradients).
        let shots = |side| -> anyhow::Result<Vec<Image<f32>>> {
            Ok(reader
                .pattern_shots(im_id, side)?
                .into_iter()
                .map(|p| pattern_as_normalised(p).0)
                .collect())
        };
        let (left, right) = (shots(StereoSide::Left)?, shots(StereoSide::Right)?);
        let sigma_image = depth_sigma(&left, &right, &depth, &rig.stereo, &noise, window_radius)?;
        let gts = reader.gt(im_id).unwrap_or(&[]).to_vec();
        let infos = reader.gt_info(im_id).map(|i| i.to_vec());
        let mut objects = Vec::new();
        for (gt_index, gt) in gts.iter().enumerate() {
            if gt.obj_id != obj_id {
                continue;
            }
            let Some(info) = infos.as_ref().and_then(|i| i.get(gt_index)) else {
                bail!(
                    "{}: image {im_id} has no scene_gt_info.json entry for GT {gt_index}; the \
                     experiment keeps instances by visib_fract",
                    scene_dir.display()
                );
            };
            let t_w_o = t_w_c * gt.t_c_o;
            let instance = match instances_t_w_o.iter().position(|p| same_pose(p, &t_w_o)) {
                Some(i) => i,
                None => {
                    instances_t_w_o.push(t_w_o);
                    instances_t_w_o.len() - 1
                }
            };
            let mask = reader.mask(im_id, gt_index, MaskKind::Visible)?;
            let keep = interior_mask(mask.width(), mask.height(), erode_px, |u, v| {
                mask.get(u, v).is_some_and(|m| m > 127)
            });
            let mut points = Vec::new();
            object_points(
                &depth,
                |u, v| keep.get(u, v).unwrap_or(false),
                DepthSigma::PerPixel(&sigma_image),
                &camera.intrinsics,
                &t_w_c,
                &mut points,
            );
            objects.push(InstanceView {
                instance,
                t_c_o_gt: gt.t_c_o,
                visib_fract: info.visib_fract,
                points,
            });
        }
        views.push(LoadedView {
            im_id,
            t_w_c,
            objects,
        });
    }
    Ok(LoadedScene { views })
}
