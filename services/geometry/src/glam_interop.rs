//! The one place where nalgebra (estimation) and glam (parry3d, obvhs) types meet.

use nalgebra::{Point3, Vector3};

/// A mesh vertex as the glam vector parry3d and obvhs expect.
#[inline]
pub fn vec3_from_point(p: &Point3<f32>) -> glam::Vec3 {
    glam::Vec3::new(p.x, p.y, p.z)
}

/// A glam vector back as a nalgebra point.
#[inline]
pub fn point_from_vec3(v: glam::Vec3) -> Point3<f32> {
    Point3::new(v.x, v.y, v.z)
}

/// An `f64` query point narrowed to glam's `f32`.
#[inline]
pub fn vec3_from_point_f64(p: &Point3<f64>) -> glam::Vec3 {
    glam::Vec3::new(p.x as f32, p.y as f32, p.z as f32)
}

/// A glam vector widened to an `f64` nalgebra vector.
#[inline]
pub fn vector_f64_from_vec3(v: glam::Vec3) -> Vector3<f64> {
    Vector3::new(v.x as f64, v.y as f64, v.z as f64)
}
