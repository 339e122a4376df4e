//! From a measured radiance map to a fit target: which pixels are the object's, and the
//! radiometric scale that turns relative exposure per second into W·sr⁻¹·m⁻².

use glint_geometry::image::Image;
use glint_render::bsdf::PrincipledParams;
use glint_render::integrator::{Camera, path_pixel, single_path_pixel};
use glint_render::projector::Projector;
use glint_render::scene::Scene;
use rayon::prelude::*;

use super::FitTarget;
use glint_render::integrator::PixelRendering;

/// A target built from a radiance map.
#[derive(Clone, Debug)]
pub struct MeasuredTarget {
    /// The object's pixels and their radiance, W·sr⁻¹·m⁻² (measured / `scale`).
    pub target: FitTarget,
    /// Relative radiance-map units per W·sr⁻¹·m⁻²: the median over reference pixels of
    /// measured / rendered.
    pub scale: f64,
    /// Reference pixels behind the scale.
    pub reference_pixels: usize,
    /// Object pixels left out because no exposure read them well (saturated or black in all).
    pub unmeasured_pixels: usize,
}

/// Why a target could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TargetError {
    /// The radiance map is not the camera's image size: it belongs to another camera.
    #[error("the radiance map is {map:?} px but the camera is {camera:?} px")]
    SizeMismatch {
        /// The map's (width, height), pixels.
        map: (u32, u32),
        /// The camera's (width, height), pixels.
        camera: (u32, u32),
    },
    /// Fewer than 100 reference pixels are seen whole, lit and measured (the count is given):
    /// the view must show more of the reference surface, lit by the projector and well exposed.
    #[error("only {0} reference pixels are lit and well exposed: cannot fix the radiometric scale")]
    NoReference(usize),
}

/// Object pixels (first hit one of `instances`, the whole 3 × 3 neighbourhood too: edge pixels
/// mix the object and its background in a real camera) with a finite measurement, their radiance
/// map value divided by the radiometric scale; the scale from every 4th pixel (in u and v)
/// whose 3 × 3 neighbourhood is all `reference_instance`, rendered with `rendering` and the
/// scene's materials (the reference's known one included), lit, and measured.
#[allow(clippy::too_many_arguments)]
pub fn measured_target(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    instances: &[u32],
    reference_instance: u32,
    reference_material: &PrincipledParams<f32>,
    radiance_map: &Image<f32>,
    rendering: &PixelRendering,
) -> Result<MeasuredTarget, TargetError> {
    let (w, h) = (camera.intrinsics.width_px, camera.intrinsics.height_px);
    if (radiance_map.width(), radiance_map.height()) != (w, h) {
        return Err(TargetError::SizeMismatch {
            map: (radiance_map.width(), radiance_map.height()),
            camera: (w, h),
        });
    }
    // First-hit instance per pixel (the material is irrelevant to which surface a ray hits).
    let hits: Vec<(u32, f32)> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            single_path_pixel(scene, camera, projector, i % w, i / w, |_| {
                *reference_material
            })
            .map_or((u32::MAX, 0.0), |s| (s.instance, s.radiance))
        })
        .collect();
    let render_reference = |u: u32, v: u32| {
        path_pixel(scene, camera, projector, (u, v), rendering, |i| {
            if i == reference_instance {
                *reference_material
            } else {
                *scene.material_of(i)
            }
        })
        .map_or(0.0, |s| s.radiance)
    };
    let interior = |u: u32, v: u32, which: &dyn Fn(u32) -> bool| {
        (u >= 1 && v >= 1 && u + 1 < w && v + 1 < h)
            && (v - 1..=v + 1).all(|y| (u - 1..=u + 1).all(|x| which(hits[(y * w + x) as usize].0)))
    };
    let is_reference = |i: u32| i == reference_instance;
    let is_object = |i: u32| instances.contains(&i);
    let mut ratios: Vec<f64> = (0..h)
        .into_par_iter()
        .step_by(4)
        .flat_map_iter(|v| {
            (0..w).step_by(4).filter_map(move |u| {
                let e = radiance_map.data()[(v * w + u) as usize];
                if !(interior(u, v, &is_reference) && e.is_finite() && e > 0.0) {
                    return None;
                }
                let rendered = render_reference(u, v);
                (rendered > 0.0).then(|| e as f64 / rendered as f64)
            })
        })
        .collect();
    let mut target = FitTarget::default();
    let mut unmeasured = 0;
    for v in 0..h {
        for u in 0..w {
            let i = (v * w + u) as usize;
            let e = radiance_map.data()[i];
            if interior(u, v, &is_object) {
                if e.is_finite() {
                    target.pixels.push((u, v));
                    target.radiance.push(e);
                } else {
                    unmeasured += 1;
                }
            }
        }
    }
    if ratios.len() < 100 {
        return Err(TargetError::NoReference(ratios.len()));
    }
    ratios.sort_by(f64::total_cmp);
    let scale = ratios[ratios.len() / 2];
    for r in &mut target.radiance {
        *r = (*r as f64 / scale) as f32;
    }
    Ok(MeasuredTarget {
        target,
        scale,
        reference_pixels: ratios.len(),
        unmeasured_pixels: unmeasured,
    })
}
