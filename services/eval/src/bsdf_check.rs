//! How close a fitted material is to the truth (`glint calibrate eval-bsdf`): the part's
//! radiance rendered with the fitted and with the true material, on the fit's views and on a
//! held-out one. Evaluation only: it reads the capture's ground-truth materials.

use std::path::Path;

use glint_calibration::bsdf_fit::scene_fit::Capture;
use glint_calibration::material_file::{GroundTruthMaterials, MaterialFile, MaterialFileError};
use glint_render::bsdf::PrincipledParams;
use glint_render::integrator::{PixelRendering, path_pixel};
use glint_render::projector::Pattern;
use rayon::prelude::*;

use crate::metrics::median;

/// What [`part_radiance`] returns.
#[derive(Clone, Debug)]
pub struct PartRadiance {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// The part's interior pixels (u, v).
    pub pixels: Vec<(u32, u32)>,
    /// Radiance of each pixel with each of the two materials, W·sr⁻¹·m⁻².
    pub radiance: [Vec<f32>; 2],
}

/// The part's interior pixels (3 × 3 all part instances) seen from `t_w_c`, and their radiance
/// with each of `materials` on every part instance (rendered alike with `rendering`).
pub fn part_radiance(
    capture: &Capture,
    t_w_c: &nalgebra::Isometry3<f64>,
    materials: [&PrincipledParams<f32>; 2],
    rendering: &PixelRendering,
) -> PartRadiance {
    let [camera, _] = capture.rig.cameras(t_w_c);
    let projector = capture.rig.projector(t_w_c, Pattern::White);
    let (w, h) = (camera.intrinsics.width_px, camera.intrinsics.height_px);
    let is_part_instance = |i: u32| capture.part_instances.contains(&i);
    let shade = |u, v, m: &PrincipledParams<f32>, r: &PixelRendering| {
        path_pixel(&capture.scene, &camera, &projector, (u, v), r, |i| {
            if is_part_instance(i) {
                *m
            } else {
                *capture.scene.material_of(i)
            }
        })
    };
    let first_hits: Vec<bool> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            shade(i % w, i / w, materials[0], &PixelRendering::SINGLE_PATH)
                .is_some_and(|s| is_part_instance(s.instance))
        })
        .collect();
    let is_part = |u: u32, v: u32| first_hits[(v * w + u) as usize];
    let mut pixels = Vec::new();
    for v in 1..h - 1 {
        for u in 1..w - 1 {
            if (v - 1..=v + 1).all(|y| (u - 1..=u + 1).all(|x| is_part(x, y))) {
                pixels.push((u, v));
            }
        }
    }
    let render = |m| {
        pixels
            .par_iter()
            .map(|&(u, v)| shade(u, v, m, rendering).map_or(0.0, |s| s.radiance))
            .collect()
    };
    let radiance = [render(materials[0]), render(materials[1])];
    PartRadiance {
        width: w,
        height: h,
        pixels,
        radiance,
    }
}

/// sqrt(Σ (a − b)² / Σ b²): the relative RMS error of `a` against `b`.
pub fn relative_rms(a: &[f32], b: &[f32]) -> f64 {
    let (se, norm) = a.iter().zip(b).fold((0.0, 0.0), |(se, n), (&x, &y)| {
        (se + ((x - y) as f64).powi(2), n + (y as f64).powi(2))
    });
    (se / norm.max(f64::MIN_POSITIVE)).sqrt()
}

/// The median of |ln(a / b)| over the pixels where both are positive (NaN if none): the
/// typical pixel's relative error, which a few glints cannot dominate.
pub fn median_abs_log_ratio(a: &[f32], b: &[f32]) -> f64 {
    median(
        a.iter()
            .zip(b)
            .filter(|&(&x, &y)| x > 0.0 && y > 0.0)
            .map(|(&x, &y)| (x as f64 / y as f64).ln().abs())
            .collect(),
    )
}

/// The true material for `eval-bsdf` and the part's name when known: a capture's
/// `gt_materials.json` (its part), or a material file.
pub fn read_truth(path: &Path) -> anyhow::Result<(PrincipledParams<f32>, Option<String>)> {
    match GroundTruthMaterials::load(path) {
        Ok(gt) => Ok((gt.part_params()?, Some(gt.part))),
        Err(MaterialFileError::Malformed { .. }) => Ok((MaterialFile::load(path)?.params()?, None)),
        Err(e) => Err(e.into()),
    }
}
