//! One constructor for a mock-camera set-up: the rig, the default bin, the part dropped into it
//! (seeded), the render scene, and the capture settings — what `glint capture`, the experiments,
//! the benchmarks and the camera server all start from.

use glint_geometry::TriMesh;
use glint_render::bsdf::PrincipledParams;
use glint_render::rig::SliRig;
use glint_render::scene::{Scene, SceneError};
use glint_render::stereo::StereoError;
use nalgebra::Isometry3;

use crate::bin::{BinError, BinSpec, bin_scene, drop_parts};
use crate::capture::{CaptureConfig, MockSliCamera};
use crate::views;
use crate::visibility::{InstanceVisibility, instance_visibility};

/// Working distance of the capture views from the bin's centre, metres (like ROBI's robot-arm
/// views); every command that captures a bin uses it and [`VIEW_CAP_DEG`].
pub const VIEW_DISTANCE_M: f64 = 0.5;
/// Polar half-angle of the cap of capture views around world +z, degrees.
pub const VIEW_CAP_DEG: f64 = 35.0;

/// The noise seed of view `view` of the scene seeded `scene_seed`: every capture of a scene
/// gets its own, reproducible noise.
pub fn capture_seed(scene_seed: u64, view: usize) -> u64 {
    scene_seed.wrapping_mul(1000).wrapping_add(view as u64)
}

/// Why a set-up could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// The rig could not be resized to the requested resolution; use a width and height in
    /// `1..=65535` px.
    #[error("rig: {0}")]
    Rig(#[from] glint_geometry::camera::CameraError),
    /// The parts could not be dropped into the bin (see [`BinError`]).
    #[error("dropping the parts: {0}")]
    Drop(#[from] BinError),
    /// The parts and the bin did not form a renderable scene.
    #[error("building the scene: {0}")]
    Scene(#[from] SceneError),
    /// The default matcher's disparity range could not be set up for the rig.
    #[error("matcher: {0}")]
    Matcher(#[from] StereoError),
}

/// What a bin set-up is made from.
#[derive(Clone, Debug)]
pub struct BinSetupSpec {
    /// Parts per bin.
    pub instances: u32,
    /// Seed of the drop (the parts' poses).
    pub seed: u64,
    /// Camera image width, px.
    pub width_px: u32,
    /// Camera image height, px.
    pub height_px: u32,
    /// Samples per pixel of the capture's renders.
    pub samples_per_pixel: u32,
}

/// A bin of one part seen by the mock camera.
pub struct BinSetup {
    /// The Ensenso N35 rig at the spec's resolution.
    pub rig: SliRig,
    /// The bin the parts lie in.
    pub bin: BinSpec,
    /// Object → world of each instance (scene labels 1..=N).
    pub poses: Vec<Isometry3<f64>>,
    /// The render scene: the parts (instances 0..N, labels 1..=N), then the bin
    /// ([`crate::bin::BIN_LABEL`]).
    pub scene: Scene,
    /// The camera's capture settings.
    pub config: CaptureConfig,
}

impl BinSetup {
    /// `spec.instances` copies of `mesh` (metres) dropped into the default bin, painted with
    /// `material`, seen by an Ensenso N35 rig at `spec`'s resolution with the camera's default
    /// capture settings at `spec.samples_per_pixel`.
    pub fn new(
        mesh: &TriMesh,
        material: PrincipledParams<f32>,
        spec: &BinSetupSpec,
    ) -> Result<Self, SetupError> {
        let rig = SliRig::ensenso_n35().resized(spec.width_px, spec.height_px)?;
        let bin = BinSpec::default();
        let poses = drop_parts(mesh, spec.instances as usize, &bin, spec.seed)?;
        let scene = bin_scene(mesh, &poses, material, &bin)?;
        let config = CaptureConfig {
            samples_per_pixel: spec.samples_per_pixel,
            ..CaptureConfig::for_rig(&rig)?
        };
        Ok(Self {
            rig,
            bin,
            poses,
            scene,
            config,
        })
    }

    /// The same bin (poses) with the part in another material, e.g. its diffuse twin.
    pub fn repainted(
        &self,
        mesh: &TriMesh,
        material: PrincipledParams<f32>,
    ) -> Result<Self, SetupError> {
        Ok(Self {
            rig: self.rig,
            bin: self.bin,
            poses: self.poses.clone(),
            scene: bin_scene(mesh, &self.poses, material, &self.bin)?,
            config: self.config.clone(),
        })
    }

    /// The mock camera looking at this bin.
    pub fn camera(&self) -> MockSliCamera<'_> {
        MockSliCamera {
            rig: self.rig,
            scene: &self.scene,
            config: self.config.clone(),
        }
    }

    /// `count` capture views (left camera → world) on the cap above the bin.
    pub fn views(&self, count: usize) -> Vec<Isometry3<f64>> {
        views::spherical_cap(
            count,
            VIEW_DISTANCE_M,
            VIEW_CAP_DEG,
            self.bin.centre(),
            self.rig.stereo.baseline_m,
        )
    }

    /// How much of each instance (in [`BinSetup::poses`] order) the rig's left camera sees
    /// from `t_w_c` (left camera → world).
    pub fn instance_visibility(&self, t_w_c: &Isometry3<f64>) -> Vec<InstanceVisibility> {
        let [left, _] = self.rig.cameras(t_w_c);
        let labels: Vec<u16> = (1..=self.poses.len() as u16).collect();
        instance_visibility(&self.scene, &left, &labels)
    }
}

/// A flat square of side `2·half_m` in the plane z = 0 of the world, centred on the origin,
/// in `material` (label 1): the reference target cameras are validated on.
pub fn plane_scene(half_m: f32, material: PrincipledParams<f32>) -> Result<Scene, SceneError> {
    use glint_render::scene::SceneInstance;
    use nalgebra::Point3;
    let plane = TriMesh::new(
        vec![
            Point3::new(-half_m, -half_m, 0.0),
            Point3::new(half_m, -half_m, 0.0),
            Point3::new(half_m, half_m, 0.0),
            Point3::new(-half_m, half_m, 0.0),
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    );
    let instance = SceneInstance {
        mesh: 0,
        t_w_o: Isometry3::identity(),
        material: 0,
        label: 1,
    };
    Scene::build(&[plane], vec![instance], vec![material])
}

/// A camera pose (camera → world) straight above the world origin at `height_m`, looking down
/// at it, image y along world +y.
pub fn looking_down(height_m: f64) -> Isometry3<f64> {
    use nalgebra::{Point3, Vector3};
    Isometry3::face_towards(
        &Point3::new(0.0, 0.0, height_m),
        &Point3::origin(),
        &Vector3::y(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_geometry::Part;

    #[test]
    fn a_set_up_is_reproducible_and_repainting_keeps_the_poses() {
        let spec = BinSetupSpec {
            instances: 3,
            seed: 7,
            width_px: 64,
            height_px: 48,
            samples_per_pixel: 1,
        };
        let mesh = Part::Zigzag.mesh();
        let a = BinSetup::new(&mesh, crate::materials::ground_truth(Part::Zigzag), &spec)
            .expect("valid spec");
        let b = BinSetup::new(&mesh, crate::materials::ground_truth(Part::Zigzag), &spec)
            .expect("valid spec");
        assert_eq!(a.poses, b.poses);
        assert_eq!(a.poses.len(), 3);
        let matte = a
            .repainted(&mesh, crate::materials::diffuse_twin())
            .expect("same bin");
        assert_eq!(matte.poses, a.poses);
        assert_eq!(a.rig.stereo.intrinsics.width_px, 64);
        assert_eq!(a.views(5).len(), 5);
        assert_ne!(capture_seed(1, 0), capture_seed(1, 1));
        assert_ne!(capture_seed(1, 0), capture_seed(2, 0));
    }
}
