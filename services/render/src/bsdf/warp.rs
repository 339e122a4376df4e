//! Warps from the unit square to directions, with their densities (solid-angle measure).

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4};

/// Shirley–Chiu concentric map of the unit square onto the unit disk (area preserving, low
/// distortion; Mitsuba's `square_to_uniform_disk_concentric`).
#[inline]
pub fn square_to_uniform_disk_concentric(u: [f32; 2]) -> Vec2 {
    let x = 2.0 * u[0] - 1.0;
    let y = 2.0 * u[1] - 1.0;
    if x == 0.0 && y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, phi) = if x.abs() > y.abs() {
        (x, FRAC_PI_4 * (y / x))
    } else {
        (y, 2.0 * FRAC_PI_4 - FRAC_PI_4 * (x / y))
    };
    let (sin, cos) = phi.sin_cos();
    Vec2::new(r * cos, r * sin)
}

/// Cosine-weighted hemisphere around +z (Malley's method on the concentric disk), density
/// cos θ / π.
#[inline]
pub fn square_to_cosine_hemisphere(u: [f32; 2]) -> Vec3 {
    let p = square_to_uniform_disk_concentric(u);
    let z = (1.0 - p.length_squared()).max(0.0).sqrt();
    Vec3::new(p.x, p.y, z)
}

/// Density of [`square_to_cosine_hemisphere`]: cos θ / π above the horizon, 0 below.
#[inline]
pub fn cosine_hemisphere_pdf(v: Vec3) -> f32 {
    if v.z > 0.0 { v.z * FRAC_1_PI } else { 0.0 }
}
