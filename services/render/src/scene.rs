//! A static scene of triangle meshes placed by instance poses, flattened to world-space
//! triangles under one compressed wide BVH (obvhs CWBVH).
//!
//! World frame, metres. Triangles are stored in BVH leaf order so a hit's primitive id indexes
//! them directly, without the `primitive_indices` indirection in the hot loop.

use std::time::Duration;

use glam::Vec3A;
use glint_geometry::TriMesh;
use nalgebra::Isometry3;
use obvhs::BvhBuildParams;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;

use crate::bsdf::PrincipledParams;

/// A mesh placed in the world.
#[derive(Clone, Debug)]
pub struct SceneInstance {
    /// Index into the scene's meshes.
    pub mesh: usize,
    /// Object → world.
    pub t_w_o: Isometry3<f64>,
    /// Index into the scene's materials.
    pub material: usize,
    /// Label written to instance masks; 0 is reserved for "no instance" (background).
    pub label: u16,
}

/// Why a scene could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    /// An instance's mesh index is out of range.
    #[error("instance {instance} refers to mesh {mesh}, but the scene has {meshes} meshes")]
    NoSuchMesh {
        /// Index of the instance.
        instance: usize,
        /// The mesh index it gives.
        mesh: usize,
        /// Number of meshes in the scene.
        meshes: usize,
    },
    /// An instance's material index is out of range.
    #[error(
        "instance {instance} refers to material {material}, but the scene has {materials} materials"
    )]
    NoSuchMaterial {
        /// Index of the instance.
        instance: usize,
        /// The material index it gives.
        material: usize,
        /// Number of materials in the scene.
        materials: usize,
    },
    /// An instance has label 0, which masks reserve for the background.
    #[error("instance {instance} has label 0, which is reserved for the background")]
    ReservedLabel {
        /// Index of the instance.
        instance: usize,
    },
    /// The instances hold no triangle (no instance, or only empty meshes).
    #[error("the scene has no triangles")]
    Empty,
}

/// The closest intersection of a ray with the scene.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the (unit) ray direction, metres.
    pub t: f32,
    /// World-space hit point.
    pub point: Vec3A,
    /// Unit geometric normal, flipped to face the ray's origin.
    pub normal: Vec3A,
    /// Index of the instance hit.
    pub instance: u32,
}

/// A built scene, ready for ray queries from many threads.
pub struct Scene {
    bvh: CwBvh,
    /// World-space triangles in BVH primitive order.
    triangles: Vec<Triangle>,
    /// Unit geometric normals, same order.
    normals: Vec<Vec3A>,
    /// Instance of each triangle, same order.
    instance_of: Vec<u32>,
    instances: Vec<SceneInstance>,
    materials: Vec<PrincipledParams<f32>>,
    /// World-space bounds of each instance, same order as `instances`.
    instance_bounds: Vec<(Vec3A, Vec3A)>,
}

/// Offset that lifts secondary-ray origins off the surface, metres: far above f32 rounding of
/// world coordinates ~1 m (~1e-7 m), far below any feature of a part.
pub const RAY_EPSILON_M: f32 = 2e-5;

impl Scene {
    /// Flattens `instances` of `meshes` into world space and builds the BVH.
    pub fn build(
        meshes: &[TriMesh],
        instances: Vec<SceneInstance>,
        materials: Vec<PrincipledParams<f32>>,
    ) -> Result<Self, SceneError> {
        let mut world = Vec::new();
        let mut owner = Vec::new();
        for (i, inst) in instances.iter().enumerate() {
            let mesh = meshes.get(inst.mesh).ok_or(SceneError::NoSuchMesh {
                instance: i,
                mesh: inst.mesh,
                meshes: meshes.len(),
            })?;
            if inst.material >= materials.len() {
                return Err(SceneError::NoSuchMaterial {
                    instance: i,
                    material: inst.material,
                    materials: materials.len(),
                });
            }
            if inst.label == 0 {
                return Err(SceneError::ReservedLabel { instance: i });
            }
            let t: Isometry3<f32> = inst.t_w_o.cast();
            let vertices: Vec<Vec3A> = mesh
                .vertices
                .iter()
                .map(|p| {
                    let q = t * p;
                    Vec3A::new(q.x, q.y, q.z)
                })
                .collect();
            for tri in &mesh.triangles {
                let [a, b, c] = tri.map(|k| vertices[k as usize]);
                world.push(Triangle {
                    v0: a,
                    v1: b,
                    v2: c,
                });
                owner.push(i as u32);
            }
        }
        if world.is_empty() {
            return Err(SceneError::Empty);
        }
        let bvh = build_cwbvh_from_tris(
            &world,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let triangles: Vec<Triangle> = bvh
            .primitive_indices
            .iter()
            .map(|&k| world[k as usize])
            .collect();
        let instance_of = bvh
            .primitive_indices
            .iter()
            .map(|&k| owner[k as usize])
            .collect();
        let normals = triangles.iter().map(Triangle::compute_normal).collect();
        let mut instance_bounds =
            vec![(Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY)); instances.len()];
        for (tri, &i) in world.iter().zip(&owner) {
            let b = &mut instance_bounds[i as usize];
            for p in [tri.v0, tri.v1, tri.v2] {
                *b = (b.0.min(p), b.1.max(p));
            }
        }
        Ok(Self {
            instance_bounds,
            bvh,
            triangles,
            normals,
            instance_of,
            instances,
            materials,
        })
    }

    /// The closest hit along `direction` (unit) from `origin` within `(0, t_max]`.
    #[inline]
    pub fn intersect(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        self.closest_hit(origin, direction, t_max, |_| true)
    }

    /// The closest hit on instance `instance` alone (every other instance is transparent):
    /// the ray query behind amodal masks.
    #[inline]
    pub fn intersect_instance(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        instance: u32,
    ) -> Option<Hit> {
        self.closest_hit(origin, direction, t_max, |i| i == instance)
    }

    /// The closest hit on a triangle whose instance `accept`s.
    #[inline]
    fn closest_hit(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        accept: impl Fn(u32) -> bool,
    ) -> Option<Hit> {
        let ray = Ray::new(origin, direction, 0.0, t_max);
        let mut hit = RayHit::none();
        let found = self.bvh.ray_traverse(ray, &mut hit, |ray, id| {
            if accept(self.instance_of[id]) {
                self.triangles[id].intersect(ray)
            } else {
                f32::INFINITY
            }
        });
        if !found {
            return None;
        }
        let id = hit.primitive_id as usize;
        let n = self.normals[id];
        Some(Hit {
            t: hit.t,
            point: origin + direction * hit.t,
            normal: if n.dot(direction) > 0.0 { -n } else { n },
            instance: self.instance_of[id],
        })
    }

    /// World-space axis-aligned bounds `(min, max)` of instance `instance`'s triangles.
    pub fn instance_bounds(&self, instance: u32) -> Option<(Vec3A, Vec3A)> {
        self.instance_bounds.get(instance as usize).copied()
    }

    /// Whether anything blocks the segment from `origin` along `direction` (unit) up to `distance`.
    #[inline]
    pub fn occluded(&self, origin: Vec3A, direction: Vec3A, distance: f32) -> bool {
        let ray = Ray::new(origin, direction, 0.0, distance);
        !self
            .bvh
            .ray_traverse_miss(ray, |ray, id| self.triangles[id].intersect(ray))
    }

    /// The instances, in the order given to [`Scene::build`] (a hit's `instance` indexes them).
    pub fn instances(&self) -> &[SceneInstance] {
        &self.instances
    }

    /// The material of an instance.
    #[inline]
    pub fn material_of(&self, instance: u32) -> &PrincipledParams<f32> {
        &self.materials[self.instances[instance as usize].material]
    }

    /// Number of world-space triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }
}
