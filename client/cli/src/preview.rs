//! A quick shaded preview of a mesh: orthographic ray casting with two directional lights.
//! Enough to see a part's shape in the README; physically based renders come from
//! `glint-render`.

use glint_geometry::TriMesh;
use glint_geometry::glam_interop::vec3_from_point;
use image::ImageEncoder;
use parry3d::query::{Ray, RayCast};
use parry3d::shape::TriMesh as ParryTriMesh;
use rayon::prelude::*;

/// Renders `mesh` seen from direction `view_dir` (from the camera towards the part) into a
/// `size`×`size` 8-bit RGB image, returned as PNG bytes.
pub fn render_png(mesh: &TriMesh, size: u32, view_dir: glam::Vec3) -> anyhow::Result<Vec<u8>> {
    let bvh = ParryTriMesh::new(
        mesh.vertices.iter().map(vec3_from_point).collect(),
        mesh.triangles.clone(),
    )
    .map_err(|e| anyhow::anyhow!("cannot build the preview BVH: {e:?}"))?;
    let (lo, hi) = mesh
        .aabb()
        .ok_or_else(|| anyhow::anyhow!("cannot preview an empty mesh"))?;
    let (lo, hi) = (vec3_from_point(&lo), vec3_from_point(&hi));
    let centre = (lo + hi) * 0.5;
    let radius = (hi - lo).length() * 0.5;
    let forward = view_dir.normalize();
    let right = forward
        .cross(glam::Vec3::Z)
        .try_normalize()
        .unwrap_or(glam::Vec3::X);
    let up = right.cross(forward);
    let lights = [
        (glam::Vec3::new(-0.4, -0.5, 1.0).normalize(), 0.75),
        (glam::Vec3::new(1.0, 0.6, 0.3).normalize(), 0.35),
    ];
    let half = radius * 1.05;
    let mut rgb = vec![0u8; (size * size * 3) as usize];
    rgb.par_chunks_mut((size * 3) as usize)
        .enumerate()
        .for_each(|(row, line)| {
            for col in 0..size as usize {
                let sx = ((col as f32 + 0.5) / size as f32 * 2.0 - 1.0) * half;
                let sy = (1.0 - (row as f32 + 0.5) / size as f32 * 2.0) * half;
                let origin = centre + right * sx + up * sy - forward * (2.0 * radius);
                let ray = Ray::new(origin, forward);
                let pixel = match bvh.cast_local_ray_and_get_normal(&ray, 4.0 * radius, false) {
                    Some(hit) => {
                        let n = if hit.normal.dot(forward) > 0.0 {
                            -hit.normal
                        } else {
                            hit.normal
                        };
                        let diffuse: f32 = lights.iter().map(|(l, w)| w * n.dot(*l).max(0.0)).sum();
                        let half_vector = (lights[0].0 - forward).normalize();
                        let specular = 0.35 * n.dot(half_vector).max(0.0).powf(40.0);
                        let shade = 0.12 + diffuse;
                        let tint = [0.78, 0.80, 0.86];
                        tint.map(|t| ((t * shade + specular).min(1.0) * 255.0) as u8)
                    }
                    None => [246, 246, 248],
                };
                line[col * 3..col * 3 + 3].copy_from_slice(&pixel);
            }
        });
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png).write_image(
        &rgb,
        size,
        size,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(png)
}
