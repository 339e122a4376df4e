//! Whole-image renders: radiance, depth and labels of every pixel, rows in parallel.

use glam::Vec3A;
use glint_geometry::image::{Image, PixelRect};
use rand::SeedableRng;
use rayon::prelude::*;

use super::camera::{camera_image, camera_ray, pixel_sample_ray};
use super::path::trace;
use super::{Camera, RenderSettings};
use crate::projector::Projector;
use crate::scene::Scene;

/// What a render produces, all full-size images (pixels outside the ROI untouched).
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Mean radiance per pixel, W·sr⁻¹·m⁻².
    pub radiance: Image<f32>,
    /// Depth z of the first surface through the pixel centre, metres; NaN where nothing is hit.
    pub depth_m: Image<f32>,
    /// Label of the instance hit through the pixel centre; 0 where nothing is hit.
    pub label: Image<u16>,
    /// Rays traced (camera, shadow and bounce rays), for throughput figures.
    pub rays_traced: u64,
}

/// Renders what `camera` sees of `scene` under `projector`.
///
/// # Panics
/// When the camera's intrinsics have a zero side (see [`glint_geometry::camera::PinholeIntrinsics::new`]).
pub fn render(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    settings: &RenderSettings,
) -> RenderOutput {
    render_with_single_path(scene, camera, projector, settings).0
}

/// [`render`], and from the same paths the single-path radiance (each sample's first-vertex
/// next-event term, W·sr⁻¹·m⁻², averaged like the radiance): the paper's I_single and I_multi
/// (eq 14–15) from one trace instead of two. Its expectation is a single-path render's; being
/// a part of the same samples, it never exceeds the radiance, so I_single / I_multi ≤ 1 exactly.
///
/// # Panics
/// When the camera's intrinsics have a zero side (see [`glint_geometry::camera::PinholeIntrinsics::new`]).
pub fn render_with_single_path(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    settings: &RenderSettings,
) -> (RenderOutput, Image<f32>) {
    let mut sinks = vec![(); camera.intrinsics.height_px as usize];
    render_with_sinks(scene, camera, projector, settings, None, &mut sinks)
}

/// [`render_with_single_path`] over only the pixels where `rendered` is true (a pixel past
/// the mask's extent counts as true); the others stay as outside an ROI (0, NaN and label 0).
/// For a caller that needs a few pixels of a crop, such as the part and the matcher's window
/// around it. A row's random stream is drawn by its rendered pixels alone, so the estimates
/// are a full render's in distribution, not to the bit.
///
/// # Panics
/// When the camera's intrinsics have a zero side (see [`glint_geometry::camera::PinholeIntrinsics::new`]).
pub fn render_with_single_path_where(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    settings: &RenderSettings,
    rendered: &Image<bool>,
) -> (RenderOutput, Image<f32>) {
    let mut sinks = vec![(); camera.intrinsics.height_px as usize];
    render_with_sinks(
        scene,
        camera,
        projector,
        settings,
        Some(rendered),
        &mut sinks,
    )
}

/// Receives every next-event contribution of a render, one sink per image row: what
/// [`crate::pattern_record`] records to evaluate other projector patterns without tracing again.
pub(crate) trait DirectSink: Send {
    /// Column `u` of the sink's row received `radiance` (the path throughput × the projector's
    /// direct light, W·sr⁻¹·m⁻², not yet divided by the samples per pixel) from the surface
    /// point `point_w` (world). Called in the order the samples are traced.
    fn direct(&mut self, u: u32, point_w: Vec3A, radiance: f32);
}

impl DirectSink for () {
    #[inline]
    fn direct(&mut self, _: u32, _: Vec3A, _: f32) {}
}

/// [`render_with_single_path`] (over the pixels `rendered` allows, as
/// [`render_with_single_path_where`]), handing every next-event contribution of row v to
/// `sinks[v]` (`sinks` has one entry per image row; rows without one are not rendered).
pub(crate) fn render_with_sinks<S: DirectSink>(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    settings: &RenderSettings,
    rendered: Option<&Image<bool>>,
    sinks: &mut [S],
) -> (RenderOutput, Image<f32>) {
    let k = &camera.intrinsics;
    let (w, h) = (k.width_px, k.height_px);
    let roi = settings
        .roi
        .and_then(|r| r.clipped_to(w, h))
        .unwrap_or(PixelRect::full(w, h));
    let mut radiance = camera_image(k, 0f32);
    let mut single_path = radiance.clone();
    let mut depth = Image::filled_like(&radiance, f32::NAN);
    let mut label = Image::filled_like(&radiance, 0u16);
    let (rotation, origin) = camera.rotation_and_origin();
    let spp = settings.samples_per_pixel.max(1);
    let rows = radiance
        .data_mut()
        .par_chunks_mut(w as usize)
        .zip(single_path.data_mut().par_chunks_mut(w as usize))
        .zip(depth.data_mut().par_chunks_mut(w as usize))
        .zip(label.data_mut().par_chunks_mut(w as usize))
        .zip(sinks.par_iter_mut());
    let rays_traced: u64 = rows
        .enumerate()
        .filter(|(v, _)| (roi.v_min..roi.v_min + roi.height).contains(&(*v as u32)))
        .map(
            |(v, ((((radiance_row, single_path_row), depth_row), label_row), sink))| {
                let mut rng = rand_pcg::Pcg32::seed_from_u64(
                    settings.seed ^ (v as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                );
                let mut rays = 0u64;
                for u in roi.u_min..roi.u_min + roi.width {
                    if rendered.is_some_and(|m| m.get(u, v as u32) == Some(false)) {
                        continue;
                    }
                    let (mut sum, mut single_path_sum) = (0.0f32, 0.0f32);
                    for s in 0..spp {
                        let (d_c, direction) =
                            pixel_sample_ray(k, &rotation, (u, v as u32), s, &mut rng);
                        let path = trace(
                            scene,
                            projector,
                            origin,
                            direction,
                            settings.transport,
                            &mut rng,
                            &|i| *scene.material_of(i),
                            None,
                            &mut |point, radiance| sink.direct(u, point, radiance),
                        );
                        rays += path.rays;
                        sum += path.radiance;
                        single_path_sum += path.single_path_radiance;
                        if s == 0
                            && let Some((t, instance)) = path.first_hit
                        {
                            depth_row[u as usize] = t * d_c.z; // ray length → z
                            label_row[u as usize] = scene.instances()[instance as usize].label;
                        }
                    }
                    radiance_row[u as usize] = sum / spp as f32;
                    single_path_row[u as usize] = single_path_sum / spp as f32;
                }
                rays
            },
        )
        .sum();
    let output = RenderOutput {
        radiance,
        depth_m: depth,
        label,
        rays_traced,
    };
    (output, single_path)
}

/// The depth (z along the optical axis, metres; NaN where nothing is hit) and the label (0
/// where nothing is hit) of the first surface through each pixel centre: primary rays only,
/// no shading, the same centre rays as [`render`]'s, so its `depth_m` and `label` to the bit.
/// With `only_instance`, every other instance is transparent, which gives that instance's whole
/// (amodal) silhouette. Pixels outside `roi` stay NaN and 0.
///
/// # Panics
/// When the camera's intrinsics have a zero side (see [`glint_geometry::camera::PinholeIntrinsics::new`]).
pub fn render_first_surface(
    scene: &Scene,
    camera: &Camera,
    roi: Option<PixelRect>,
    only_instance: Option<u32>,
) -> (Image<f32>, Image<u16>) {
    let k = &camera.intrinsics;
    let (w, h) = (k.width_px, k.height_px);
    let mut depth = camera_image(k, f32::NAN);
    let mut label = camera_image(k, 0u16);
    let Some(roi) = roi.map_or(Some(PixelRect::full(w, h)), |r| r.clipped_to(w, h)) else {
        return (depth, label);
    };
    let (rotation, origin) = camera.rotation_and_origin();
    depth
        .data_mut()
        .par_chunks_mut(w as usize)
        .zip(label.data_mut().par_chunks_mut(w as usize))
        .enumerate()
        .filter(|(v, _)| (roi.v_min..roi.v_min + roi.height).contains(&(*v as u32)))
        .for_each(|(v, (depth_row, label_row))| {
            for u in roi.u_min..roi.u_min + roi.width {
                let (d_c, direction) = camera_ray(k, &rotation, u as f32 + 0.5, v as f32 + 0.5);
                let hit = match only_instance {
                    None => scene.intersect(origin, direction, f32::INFINITY),
                    Some(i) => scene.intersect_instance(origin, direction, f32::INFINITY, i),
                };
                if let Some(hit) = hit {
                    depth_row[u as usize] = hit.t * d_c.z; // ray length → z
                    label_row[u as usize] = scene.instances()[hit.instance as usize].label;
                }
            }
        });
    (depth, label)
}

/// The label image of [`render_first_surface`].
///
/// # Panics
/// When the camera's intrinsics have a zero side (see [`glint_geometry::camera::PinholeIntrinsics::new`]).
pub fn render_labels(
    scene: &Scene,
    camera: &Camera,
    roi: Option<PixelRect>,
    only_instance: Option<u32>,
) -> Image<u16> {
    render_first_surface(scene, camera, roi, only_instance).1
}
