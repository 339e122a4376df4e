//! Bins of parts: an open box and N instances of one part dropped into it in random,
//! non-intersecting poses.
//!
//! World frame: z up, the bin's floor top at z = 0, the bin centred on the z axis.

use glint_geometry::TriMesh;
use glint_geometry::sdf::{SdfConfig, SdfError, SdfGrid};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rand::{Rng, SeedableRng};

/// The open box parts are dropped into.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BinSpec {
    /// Inner floor size along x and y, metres.
    pub inner_size_m: [f64; 2],
    /// Wall height above the floor, metres.
    pub wall_height_m: f64,
    /// Wall and floor thickness, metres.
    pub wall_thickness_m: f64,
}

impl Default for BinSpec {
    /// A parts bin: 240 × 180 mm inside, 80 mm walls.
    fn default() -> Self {
        Self {
            inner_size_m: [0.24, 0.18],
            wall_height_m: 0.08,
            wall_thickness_m: 0.005,
        }
    }
}

/// Why parts could not be placed.
#[derive(Debug, thiserror::Error)]
pub enum BinError {
    /// The part mesh's collision SDF (1 mm voxels) could not be built: the mesh is unusable,
    /// not watertight, or too big (check that it is in metres).
    #[error("the part's collision SDF: {0}")]
    Sdf(#[from] SdfError),
    /// No collision-free start pose was found for every part within 20 attempts per part;
    /// use fewer instances or a bigger bin.
    #[error(
        "could only place {placed} of {requested} parts in the bin after {attempts} attempts: use fewer instances or a bigger bin"
    )]
    Crowded {
        /// Parts placed before giving up.
        placed: usize,
        /// Parts asked for.
        requested: usize,
        /// Drop attempts made, successful or not.
        attempts: usize,
    },
}

impl BinSpec {
    /// The bin as a mesh: a floor slab and four wall slabs (closed boxes, overlapping at the
    /// corners, which is fine for rendering).
    pub fn mesh(&self) -> TriMesh {
        let [sx, sy] = self.inner_size_m;
        let (h, t) = (self.wall_height_m, self.wall_thickness_m);
        let mut mesh = TriMesh::default();
        let slabs = [
            // centre, half extents
            ([0.0, 0.0, -t / 2.0], [sx / 2.0 + t, sy / 2.0 + t, t / 2.0]),
            (
                [sx / 2.0 + t / 2.0, 0.0, h / 2.0],
                [t / 2.0, sy / 2.0 + t, h / 2.0],
            ),
            (
                [-sx / 2.0 - t / 2.0, 0.0, h / 2.0],
                [t / 2.0, sy / 2.0 + t, h / 2.0],
            ),
            (
                [0.0, sy / 2.0 + t / 2.0, h / 2.0],
                [sx / 2.0, t / 2.0, h / 2.0],
            ),
            (
                [0.0, -sy / 2.0 - t / 2.0, h / 2.0],
                [sx / 2.0, t / 2.0, h / 2.0],
            ),
        ];
        for (c, e) in slabs {
            mesh.append(&TriMesh::cuboid(c, e));
        }
        mesh
    }

    /// The centre of the floor, where views look.
    pub fn centre(&self) -> Point3<f64> {
        Point3::origin()
    }

    /// The bin's bounding box in the world, metres: `(min, max)` corners of the floor slab and
    /// the walls.
    pub fn bounds(&self) -> (Point3<f64>, Point3<f64>) {
        let [sx, sy] = self.inner_size_m;
        let t = self.wall_thickness_m;
        (
            Point3::new(-sx / 2.0 - t, -sy / 2.0 - t, -t),
            Point3::new(sx / 2.0 + t, sy / 2.0 + t, self.wall_height_m),
        )
    }

    /// Distance (metres) along the optical axis of a camera at `t_w_c` (camera → world; the
    /// axis is the camera's +z from its centre) to where the axis enters the bin's bounding box
    /// ([`Self::bounds`]); 0 when the camera is inside it, `None` when the axis misses it (or
    /// the box lies behind the camera).
    pub fn optical_axis_entry_m(&self, t_w_c: &Isometry3<f64>) -> Option<f64> {
        let origin = t_w_c.translation.vector;
        let direction = t_w_c.rotation * nalgebra::Vector3::z();
        let (min, max) = self.bounds();
        // Slab test: the ray's parameter interval inside each pair of planes, intersected.
        let (mut near, mut far) = (0.0f64, f64::INFINITY);
        for axis in 0..3 {
            let (o, d) = (origin[axis], direction[axis]);
            if d.abs() < 1e-12 {
                if o < min[axis] || o > max[axis] {
                    return None;
                }
                continue;
            }
            let (a, b) = ((min[axis] - o) / d, (max[axis] - o) / d);
            near = near.max(a.min(b));
            far = far.min(a.max(b));
        }
        (near <= far).then_some(near)
    }
}

/// Label of the bin in instance masks (parts are 1..=N).
pub const BIN_LABEL: u16 = u16::MAX;

/// The render scene of `part_mesh` at `poses` (labels 1..=N, `part_material`) in `bin`.
pub fn bin_scene(
    part_mesh: &TriMesh,
    poses: &[Isometry3<f64>],
    part_material: glint_render::bsdf::PrincipledParams<f32>,
    bin: &BinSpec,
) -> Result<glint_render::scene::Scene, glint_render::scene::SceneError> {
    bin_scene_with_bin_material(
        part_mesh,
        poses,
        part_material,
        bin,
        crate::materials::bin(),
    )
}

/// [`bin_scene`] with the bin in `bin_material` (e.g. a calibration's reference surface).
/// Instances 0..N are the parts, N the bin.
pub fn bin_scene_with_bin_material(
    part_mesh: &TriMesh,
    poses: &[Isometry3<f64>],
    part_material: glint_render::bsdf::PrincipledParams<f32>,
    bin: &BinSpec,
    bin_material: glint_render::bsdf::PrincipledParams<f32>,
) -> Result<glint_render::scene::Scene, glint_render::scene::SceneError> {
    use glint_render::scene::{Scene, SceneInstance};
    let mut instances: Vec<SceneInstance> = poses
        .iter()
        .enumerate()
        .map(|(i, t_w_o)| SceneInstance {
            mesh: 0,
            t_w_o: *t_w_o,
            material: 0,
            label: i as u16 + 1,
        })
        .collect();
    instances.push(SceneInstance {
        mesh: 1,
        t_w_o: Isometry3::identity(),
        material: 1,
        label: BIN_LABEL,
    });
    Scene::build(
        &[part_mesh.clone(), bin.mesh()],
        instances,
        vec![part_material, bin_material],
    )
}

/// Collision probe points per part: a subsample of its vertices.
const PROBE_POINTS: usize = 1500;
/// Height step of the drop, metres.
const DROP_STEP_M: f64 = 5e-4;

/// Drops `count` instances of `mesh` (object frame, metres) into the bin one after another:
/// each starts above the bin at a random x, y and a uniformly random orientation, and moves
/// straight down until the next step would touch the floor, a wall or a part already placed
/// (vertex probes tested against the other part's SDF, both ways). Returns `t_w_o` per
/// instance. Seeded and reproducible. The poses touch their support but are not physically
/// settled (no toppling).
pub fn drop_parts(
    mesh: &TriMesh,
    count: usize,
    bin: &BinSpec,
    seed: u64,
) -> Result<Vec<Isometry3<f64>>, BinError> {
    let sdf = SdfGrid::build(
        mesh,
        &SdfConfig {
            voxel_size_m: 1e-3,
            padding_m: 2e-3,
        },
    )?;
    let step = (mesh.vertices.len() / PROBE_POINTS).max(1);
    let probes: Vec<Point3<f64>> = mesh
        .vertices
        .iter()
        .step_by(step)
        .map(|p| p.cast())
        .collect();
    let radius = probes.iter().map(|p| p.coords.norm()).fold(0.0, f64::max);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut placed: Vec<Isometry3<f64>> = Vec::with_capacity(count);
    let max_attempts = 20 * count.max(1);
    let [sx, sy] = bin.inner_size_m;
    let mut attempts = 0;
    while placed.len() < count && attempts < max_attempts {
        attempts += 1;
        let rotation = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            rng.sample::<f64, _>(rand_distr::StandardNormal),
            rng.sample(rand_distr::StandardNormal),
            rng.sample(rand_distr::StandardNormal),
            rng.sample(rand_distr::StandardNormal),
        ));
        let margin_x = (sx / 2.0 - radius).max(0.0);
        let margin_y = (sy / 2.0 - radius).max(0.0);
        let x = rng.random_range(-margin_x..=margin_x);
        let y = rng.random_range(-margin_y..=margin_y);
        let collides = |t_w_o: &Isometry3<f64>| -> bool {
            let in_world = probes.iter().map(|p| t_w_o * p);
            let outside_bin = in_world
                .clone()
                .any(|q| q.z < 0.0 || q.x.abs() > sx / 2.0 || q.y.abs() > sy / 2.0);
            outside_bin
                || placed.iter().any(|other| {
                    let t_other_new = other.inverse() * t_w_o;
                    probes
                        .iter()
                        .any(|p| sdf.sample(&(t_other_new * p)).distance_m < 0.0)
                        || probes
                            .iter()
                            .any(|p| sdf.sample(&(t_other_new.inverse() * p)).distance_m < 0.0)
                })
        };
        let highest = placed.iter().map(|t| t.translation.z).fold(0.0, f64::max) + 3.0 * radius;
        let mut z = highest;
        let pose_at = |z: f64| Isometry3::from_parts(Translation3::new(x, y, z), rotation);
        if collides(&pose_at(z)) {
            continue;
        }
        while z > -radius && !collides(&pose_at(z - DROP_STEP_M)) {
            z -= DROP_STEP_M;
        }
        placed.push(pose_at(z));
    }
    if placed.len() < count {
        return Err(BinError::Crowded {
            placed: placed.len(),
            requested: count,
            attempts,
        });
    }
    Ok(placed)
}

/// The lowest world z (metres) of `mesh` placed at `t_w_o`: ≥ 0 when it rests on or above the floor.
pub fn lowest_point(mesh: &TriMesh, t_w_o: &Isometry3<f64>) -> f64 {
    mesh.vertices
        .iter()
        .map(|p| (t_w_o * p.cast::<f64>()).z)
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_geometry::parts::Part;

    #[test]
    fn dropped_gears_rest_in_the_bin_without_overlapping() {
        let mesh = Part::Gear.mesh();
        let bin = BinSpec::default();
        let poses = drop_parts(&mesh, 6, &bin, 3).unwrap();
        assert_eq!(poses, drop_parts(&mesh, 6, &bin, 3).unwrap(), "seeded");
        let sdf = SdfGrid::build(
            &mesh,
            &SdfConfig {
                voxel_size_m: 1e-3,
                padding_m: 2e-3,
            },
        )
        .unwrap();
        for (i, a) in poses.iter().enumerate() {
            // Resting: within one drop step (+ probe sparsity) of the floor or of another part.
            let low = lowest_point(&mesh, a);
            assert!(low >= -1e-9, "part {i} below the floor: {low}");
            for b in &poses[i + 1..] {
                let t_b_a = b.inverse() * a;
                // Every vertex (not only the probes) outside the other part, up to half a voxel of SDF error.
                let deepest = mesh
                    .vertices
                    .iter()
                    .map(|p| sdf.sample(&(t_b_a * p.cast::<f64>())).distance_m)
                    .fold(f64::INFINITY, f64::min);
                assert!(deepest > -1e-3, "parts {i} overlap by {deepest} m");
            }
        }
        // Something supports each part: the floor or a part below, within a few drop steps.
        for (i, a) in poses.iter().enumerate() {
            let on_floor = lowest_point(&mesh, a) < 3e-3;
            let on_part = poses.iter().enumerate().any(|(j, b)| {
                j != i
                    && mesh
                        .vertices
                        .iter()
                        .any(|p| sdf.sample(&(b.inverse() * a * p.cast::<f64>())).distance_m < 3e-3)
            });
            assert!(on_floor || on_part, "part {i} floats");
        }
    }

    #[test]
    fn optical_axes_hit_the_bin_or_miss_it() {
        use nalgebra::Vector3;
        let bin = BinSpec::default();
        let above = Isometry3::face_towards(
            &Point3::new(0.0, 0.0, 0.5),
            &Point3::origin(),
            &Vector3::y(),
        );
        // Straight down from 0.5 m: the axis enters the box at the walls' top, z = 0.08 m.
        let entry = bin.optical_axis_entry_m(&above).unwrap();
        assert!((entry - (0.5 - bin.wall_height_m)).abs() < 1e-12, "{entry}");
        // Looking up, or down beside the bin: no hit.
        let up = Isometry3::face_towards(
            &Point3::new(0.0, 0.0, 0.5),
            &Point3::new(0.0, 0.0, 1.0),
            &Vector3::y(),
        );
        assert_eq!(bin.optical_axis_entry_m(&up), None);
        let beside = Isometry3::face_towards(
            &Point3::new(0.5, 0.0, 0.5),
            &Point3::new(0.5, 0.0, 0.0),
            &Vector3::y(),
        );
        assert_eq!(bin.optical_axis_entry_m(&beside), None);
        // Inside the box.
        assert_eq!(
            bin.optical_axis_entry_m(&Isometry3::translation(0.0, 0.0, 0.01)),
            Some(0.0)
        );
    }

    #[test]
    fn an_overfull_bin_is_an_error() {
        let bin = BinSpec {
            inner_size_m: [0.03, 0.03],
            wall_height_m: 0.01,
            wall_thickness_m: 0.005,
        };
        assert!(matches!(
            drop_parts(&Part::Gear.mesh(), 3, &bin, 1),
            Err(BinError::Crowded { .. })
        ));
    }
}
