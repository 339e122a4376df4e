//! Many projector patterns from one path trace.
//!
//! Light transport is linear in the projector's pattern: the projector is a point emitter whose
//! intensity towards a surface point is `I₀ · t(u_p, v_p)`, with `t` the pattern's
//! transmittance at the point's projector pixel coordinates, and no random decision of a path
//! (jitter, BSDF sampling, Russian roulette) looks at the pattern. So a pixel's radiance under
//! any pattern is
//!
//! ```text
//! L(t) = (1/N) Σ_i w_i · t(u_i, v_i)
//! ```
//!
//! over the next-event terms i of its N samples, where `w_i` is the term under a fully lit
//! pattern (t = 1) and `(u_i, v_i)` is where that vertex lies in the projector image. A
//! [`PatternRecord`] traces every pixel's paths once, with the projector fully lit, and keeps
//! those `(u_i, v_i, w_i)`; [`PatternRecord::radiance`] then evaluates any pattern with one
//! texture lookup per term instead of a new trace. With the same settings and seed it equals
//! [`crate::integrator::render`] under that pattern up to f32 rounding (the paths are the
//! same ones; the coordinates are stored in f32, see [`ProjectorHit`]).
//!
//! Memory: 12 bytes per lit next-event term — about `spp × (1 + lit bounces)` per pixel.

use glam::Vec3A;
use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::Image;
use rayon::prelude::*;

use crate::integrator::{Camera, DirectSink, RenderOutput, RenderSettings, render_with_sinks};
use crate::projector::{BilinearTaps, Pattern, Projector};
use crate::scene::Scene;

/// One next-event term of a pixel's paths: where it reaches the projector and what it carries
/// under a fully lit pattern.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectorHit {
    /// Continuous projector pixel column of the lit vertex (pixel centres at +0.5), in f32:
    /// within 2⁻²⁴ · 2048 ≈ 1.2e-4 px of the f64 coordinate a direct render uses, for
    /// projectors up to 2048 px wide.
    pub u_px: f32,
    /// Continuous projector pixel row of the lit vertex, same convention as `u_px`.
    pub v_px: f32,
    /// The term's radiance under transmittance 1, already divided by the samples per pixel,
    /// W·sr⁻¹·m⁻².
    pub radiance: f32,
}

/// One image row's terms, pixel by pixel.
#[derive(Clone, Debug, Default)]
struct RecordRow {
    /// `hits[column_end[u − 1]..column_end[u]]` are column u's terms (`column_end[−1]` = 0).
    column_end: Vec<u32>,
    hits: Vec<ProjectorHit>,
}

/// The sink that records one row while it is traced.
struct RowRecorder<'a> {
    projector: &'a Projector,
    inv_spp: f32,
    row: RecordRow,
}

impl DirectSink for RowRecorder<'_> {
    #[inline]
    fn direct(&mut self, u: u32, point_w: Vec3A, radiance: f32) {
        let u = u as usize;
        // Samples arrive column by column, so every column up to u is complete.
        while self.row.column_end.len() < u {
            self.row.column_end.push(self.row.hits.len() as u32);
        }
        if radiance > 0.0
            && let Some(uv) = self.projector.pattern_coordinates(point_w)
        {
            self.row.hits.push(ProjectorHit {
                u_px: uv.x as f32,
                v_px: uv.y as f32,
                radiance: radiance * self.inv_spp,
            });
        }
    }
}

/// Every pixel's next-event terms of one render, for evaluating any projector pattern.
#[derive(Clone, Debug)]
pub struct PatternRecord {
    width: u32,
    projector_intrinsics: PinholeIntrinsics,
    rows: Vec<RecordRow>,
    /// Depth of the first surface through each pixel centre, metres (NaN: nothing hit).
    pub depth_m: Image<f32>,
    /// Label of the instance hit through each pixel centre (0: nothing hit).
    pub label: Image<u16>,
    /// Rays traced once for all patterns.
    pub rays_traced: u64,
}

/// Traces what `camera` sees of `scene` lit by `projector` (its pattern is ignored: the trace
/// is made fully lit) with `settings`, and records each pixel's next-event terms.
pub fn record_pattern_paths(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    settings: &RenderSettings,
) -> PatternRecord {
    let lit = Projector {
        pattern: Pattern::White,
        ..projector.clone()
    };
    let inv_spp = (settings.samples_per_pixel.max(1) as f32).recip();
    let (w, h) = (camera.intrinsics.width_px, camera.intrinsics.height_px);
    let mut sinks: Vec<RowRecorder<'_>> = (0..h)
        .map(|_| RowRecorder {
            projector: &lit,
            inv_spp,
            row: RecordRow::default(),
        })
        .collect();
    let (out, _) = render_with_sinks(scene, camera, &lit, settings, None, &mut sinks);
    let rows = sinks
        .into_iter()
        .map(|sink| {
            let mut row = sink.row;
            row.column_end.resize(w as usize, row.hits.len() as u32);
            row
        })
        .collect();
    PatternRecord {
        width: w,
        projector_intrinsics: projector.intrinsics,
        rows,
        depth_m: out.depth_m,
        label: out.label,
        rays_traced: out.rays_traced,
    }
}

impl PatternRecord {
    /// Recorded next-event terms over the whole image.
    pub fn hit_count(&self) -> usize {
        self.rows.iter().map(|r| r.hits.len()).sum()
    }

    /// The terms of pixel (u, v); empty outside the image.
    pub fn pixel_hits(&self, u: u32, v: u32) -> &[ProjectorHit] {
        let Some(row) = self.rows.get(v as usize) else {
            return &[];
        };
        let u = u as usize;
        let Some(&end) = row.column_end.get(u) else {
            return &[];
        };
        let start = if u == 0 { 0 } else { row.column_end[u - 1] };
        &row.hits[start as usize..end as usize]
    }

    /// The radiance image under `pattern`, W·sr⁻¹·m⁻²: `Σ_i w_i · t(u_i, v_i)` per pixel.
    pub fn radiance(&self, pattern: &Pattern) -> Image<f32> {
        let w = self.width as usize;
        // Same size as the recorded images by construction (no fallible constructor needed).
        let mut image = self.depth_m.clone();
        image
            .data_mut()
            .par_chunks_mut(w.max(1))
            .zip(self.rows.par_iter())
            .for_each(|(out, row)| {
                let mut start = 0usize;
                for (value, &end) in out.iter_mut().zip(&row.column_end) {
                    let end = end as usize;
                    *value = row.hits[start..end]
                        .iter()
                        .map(|hit| {
                            let uv = nalgebra::Point2::new(hit.u_px as f64, hit.v_px as f64);
                            hit.radiance * pattern.transmittance(uv, &self.projector_intrinsics)
                        })
                        .sum();
                    start = end;
                }
            });
        image
    }

    /// The radiance images under each of `patterns`, as [`Self::radiance`] gives them (bit for
    /// bit), in one pass over the record: each term's texel taps are found once for all
    /// patterns of one texture size.
    pub fn radiances(&self, patterns: &[Pattern]) -> Vec<Image<f32>> {
        let Some(Pattern::Texture(first)) = patterns.first() else {
            return patterns.iter().map(|p| self.radiance(p)).collect();
        };
        let (tw, th) = (first.width(), first.height());
        let same_size = patterns
            .iter()
            .all(|p| matches!(p, Pattern::Texture(t) if (t.width(), t.height()) == (tw, th)));
        if !same_size {
            return patterns.iter().map(|p| self.radiance(p)).collect();
        }
        let texels: Vec<&[f32]> = patterns
            .iter()
            .filter_map(|p| match p {
                Pattern::Texture(t) => Some(t.data()),
                Pattern::White => None,
            })
            .collect();
        let k = texels.len();
        let w = self.width as usize;
        let (pw, ph) = (
            self.projector_intrinsics.width_px as f64,
            self.projector_intrinsics.height_px as f64,
        );
        // Pixel-interleaved: K values per pixel, one row at a time.
        let mut interleaved = vec![0f32; w * self.rows.len() * k];
        interleaved
            .par_chunks_mut((w * k).max(1))
            .zip(self.rows.par_iter())
            .for_each(|(out, row)| {
                let mut start = 0usize;
                for (values, &end) in out.chunks_exact_mut(k).zip(&row.column_end) {
                    let end = end as usize;
                    for hit in &row.hits[start..end] {
                        let uv = nalgebra::Point2::new(hit.u_px as f64, hit.v_px as f64);
                        // Outside the frustum the transmittance is 0 (as in `transmittance`).
                        if !(uv.x >= 0.0 && uv.x < pw && uv.y >= 0.0 && uv.y < ph) {
                            continue;
                        }
                        let taps = BilinearTaps::new(uv, &self.projector_intrinsics, tw, th);
                        for (value, texels) in values.iter_mut().zip(&texels) {
                            *value += hit.radiance * taps.sample(texels);
                        }
                    }
                    start = end;
                }
            });
        (0..k)
            .map(|shot| {
                let mut image = self.depth_m.clone();
                image
                    .data_mut()
                    .iter_mut()
                    .zip(interleaved.iter().skip(shot).step_by(k))
                    .for_each(|(out, &v)| *out = v);
                image
            })
            .collect()
    }

    /// [`crate::integrator::render`]'s output under `pattern`, from the record.
    pub fn render(&self, pattern: &Pattern) -> RenderOutput {
        RenderOutput {
            radiance: self.radiance(pattern),
            depth_m: self.depth_m.clone(),
            label: self.label.clone(),
            rays_traced: self.rays_traced,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::PrincipledParams;
    use crate::integrator::{LightTransport, render};
    use crate::scene::SceneInstance;
    use glint_geometry::TriMesh;
    use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

    /// A glossy floor and a diffuse wall meeting at a right angle, seen from above at 45° by a
    /// 160×128 camera with the projector 5 cm beside it: inter-reflections on both.
    fn corner() -> (Scene, Camera, Projector) {
        let square = TriMesh::new(
            vec![
                Point3::new(-0.1, -0.1, 0.0),
                Point3::new(0.1, -0.1, 0.0),
                Point3::new(0.1, 0.1, 0.0),
                Point3::new(-0.1, 0.1, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let wall = Isometry3::from_parts(
            Translation3::new(0.0, 0.1, 0.1),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2),
        );
        let instances = vec![
            SceneInstance {
                mesh: 0,
                t_w_o: Isometry3::identity(),
                material: 0,
                label: 1,
            },
            SceneInstance {
                mesh: 0,
                t_w_o: wall,
                material: 1,
                label: 2,
            },
        ];
        let materials = vec![
            PrincipledParams::new(0.8, 1.0, 0.3, 0.5).unwrap(),
            PrincipledParams::new(0.7, 0.0, 1.0, 0.0).unwrap(),
        ];
        let scene = Scene::build(&[square], instances, materials).unwrap();
        let intrinsics = PinholeIntrinsics::ensenso_n35().resized(160, 128).unwrap();
        let eye = Point3::new(0.0, -0.35, 0.45);
        let t_w_c = Isometry3::face_towards(&eye, &Point3::new(0.0, 0.05, 0.0), &-Vector3::z());
        let camera = Camera { intrinsics, t_w_c };
        let projector = Projector {
            t_w_p: t_w_c * Isometry3::translation(0.05, 0.0, 0.0),
            intrinsics: PinholeIntrinsics::ensenso_n35().resized(128, 100).unwrap(),
            pattern: Pattern::White,
            intensity_w_per_sr: 1.0,
        };
        (scene, camera, projector)
    }

    /// Linearity: the record evaluated with a pattern is the direct render with that pattern.
    /// Same seed, so the same paths; what separates them is rounding only. Per term, the f32
    /// projector coordinates are within 2⁻²⁴·128 of the f64 ones on each axis, and a bilinear
    /// transmittance moves by at most (texels per projector pixel) × that per axis; the sums
    /// and products of n positive terms add a relative (n + 4)·2⁻²⁴. So per pixel
    /// `|L_record − L_direct| ≤ L_white · 2⁻²⁴ · (2·128·s + n + 4)`, with s the texture's
    /// texels per projector pixel and L_white the fully lit radiance; asserted with a factor 2.
    #[test]
    fn record_evaluates_patterns_as_direct_renders_do() {
        let (scene, camera, projector) = corner();
        let settings = RenderSettings {
            transport: LightTransport::MULTI_PATH_DEFAULT,
            samples_per_pixel: 3,
            roi: None,
            seed: 17,
        };
        let record = record_pattern_paths(&scene, &camera, &projector, &settings);
        let white = record.radiance(&Pattern::White);
        // Every lit pixel has a term; inter-reflections give some pixels more terms than samples.
        let lit_pixels = white.data().iter().filter(|&&l| l > 0.0).count();
        assert!(
            lit_pixels > 2000 && record.hit_count() > lit_pixels,
            "{lit_pixels} lit, {} terms",
            record.hit_count()
        );
        let most = (0..128)
            .flat_map(|v| (0..160).map(move |u| (u, v)))
            .map(|(u, v)| record.pixel_hits(u, v).len())
            .max();
        assert!(most > Some(3), "{most:?}");
        // Projector-resolution dots and dots twice as fine (s = 2), several draws.
        let patterns = [
            (Pattern::random_dots(128, 100, 0.5, 1), 1.0),
            (Pattern::random_dots(128, 100, 0.3, 2), 1.0),
            (Pattern::random_dots(256, 200, 0.5, 3), 2.0),
            (Pattern::White, 1.0),
        ];
        let eps = f32::EPSILON as f64 / 2.0;
        for (pattern, texels) in patterns {
            let direct = render(
                &scene,
                &camera,
                &Projector {
                    pattern: pattern.clone(),
                    ..projector.clone()
                },
                &settings,
            );
            let from_record = record.radiance(&pattern);
            assert_eq!(direct.depth_m.data().len(), from_record.data().len());
            let mut lit = 0;
            for v in 0..128 {
                for u in 0..160 {
                    let a = direct.radiance.get(u, v).unwrap() as f64;
                    let b = from_record.get(u, v).unwrap() as f64;
                    let n = record.pixel_hits(u, v).len() as f64;
                    let l_white = white.get(u, v).unwrap() as f64;
                    let bound = 2.0 * l_white * eps * (2.0 * 128.0 * texels + n + 4.0);
                    assert!(
                        (a - b).abs() <= bound,
                        "({u}, {v}): {a} vs {b}, bound {bound}"
                    );
                    lit += (a > 0.0) as usize;
                }
            }
            assert!(lit > 1000, "{lit}");
            assert_eq!(direct.label.data(), record.label.data());
        }
        // All patterns in one pass: the same images, bit for bit.
        let shots: Vec<Pattern> = (0..3)
            .map(|k| Pattern::random_dots(128, 100, 0.5, 20 + k))
            .collect();
        for (one_pass, pattern) in record.radiances(&shots).iter().zip(&shots) {
            assert_eq!(one_pass.data(), record.radiance(pattern).data());
        }
        // Linear in the pattern: a pattern and its complement add up to white.
        let Pattern::Texture(dots) = Pattern::random_dots(128, 100, 0.5, 9) else {
            panic!("a texture");
        };
        let mut complement = dots.clone();
        complement.data_mut().iter_mut().for_each(|t| *t = 1.0 - *t);
        let (a, b) = (
            record.radiance(&Pattern::Texture(dots)),
            record.radiance(&Pattern::Texture(complement)),
        );
        for ((x, y), w) in a.data().iter().zip(b.data()).zip(white.data()) {
            assert!(((x + y) - w).abs() <= 1e-5 * w, "{x} + {y} vs {w}");
        }
    }
}
