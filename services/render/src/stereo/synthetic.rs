//! Synthetic rectified pairs for the tests: a random-dot projector at the left camera's centre
//! lighting planar surfaces, rendered with real subpixel geometry.
//!
//! With the projector at the left camera's centre, a surface point seen at left-image
//! coordinates p is lit by the pattern at p, whatever its depth: the left image is the pattern
//! (times reflectance) and the right image is the pattern warped by the true disparity; surfaces
//! hidden from the left camera are in the projector's shadow. Every surface is a plane, whose
//! disparity is affine in left-image coordinates, `d(u, v) = d0 + du·u + dv·v` (1/z is affine in
//! the image for a plane), so the right pixel `x` on row `v` sees left coordinate
//! `u = (x + d0 + dv·v)/(1 − du)` exactly.
//!
//! The pattern is either what Glint's projector shows (`crate::projector::Pattern::random_dots`:
//! a random binary grid, bilinearly interpolated, each cell ≈ 2.2 camera pixels for the N35 rig
//! at any resolution) or a sum of Gaussian dots. Each pixel integrates its footprint with S×S
//! point samples (box filter), then gets Gaussian read noise and is clipped to [0, 1] like a
//! saturating sensor.

use glint_geometry::camera::StereoRig;
use glint_geometry::image::Image;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

/// A projected pattern, as a function of left-image coordinates (px).
pub enum Texture {
    Dots(DotPattern),
    Grid(BinaryGrid),
}

impl Texture {
    /// Glint's N35 projector: half the cameras' resolution over a 10 % wider field, binary
    /// cells lit with probability 0.5, so ≈ 2.2 px cells in the camera image.
    pub fn projector_like(seed: u64) -> Self {
        Texture::Grid(BinaryGrid::random(2.2, 0.5, 0.05, seed))
    }

    #[inline]
    pub fn value(&self, x: f64, y: f64) -> f64 {
        match self {
            Texture::Dots(dots) => dots.value(x, y),
            Texture::Grid(grid) => grid.value(x, y),
        }
    }
}

/// A random binary grid of `cell_px` cells, bilinearly interpolated between cell centres, plus
/// an ambient floor: `ambient + bilinear(cells)`. Cells are hashed from their indices, so the
/// grid is unbounded.
pub struct BinaryGrid {
    cell_px: f64,
    /// Cells with `hash < threshold` are lit.
    threshold: u64,
    ambient: f64,
    seed: u64,
}

impl BinaryGrid {
    pub fn random(cell_px: f64, fill: f64, ambient: f64, seed: u64) -> Self {
        Self {
            cell_px,
            threshold: (fill.clamp(0.0, 1.0) * u64::MAX as f64) as u64,
            ambient,
            seed,
        }
    }

    #[inline]
    fn lit(&self, i: i64, j: i64) -> f64 {
        // SplitMix64 of the cell's indices.
        let mut z = self.seed
            ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        if z < self.threshold { 1.0 } else { 0.0 }
    }

    pub fn value(&self, x: f64, y: f64) -> f64 {
        // Cell (i, j) has its centre at ((i + 0.5)·cell, (j + 0.5)·cell).
        let (gx, gy) = (x / self.cell_px - 0.5, y / self.cell_px - 0.5);
        let (i, j) = (gx.floor(), gy.floor());
        let (fx, fy) = (gx - i, gy - j);
        let (i, j) = (i as i64, j as i64);
        let top = self.lit(i, j) * (1.0 - fx) + self.lit(i + 1, j) * fx;
        let bottom = self.lit(i, j + 1) * (1.0 - fx) + self.lit(i + 1, j + 1) * fx;
        self.ambient + top * (1.0 - fy) + bottom * fy
    }
}

/// A random-dot pattern in left-image coordinates (px): `ambient + Σ exp(−|p − c|²/2σ²)`.
pub struct DotPattern {
    sigma_px: f64,
    ambient: f64,
    /// Left-image coordinate of the cell grid's corner (both axes).
    origin: f64,
    cell_px: f64,
    cells_x: usize,
    cells_y: usize,
    /// Dot centres bucketed by cell (cell size 4σ), `cell_start[i]..cell_start[i + 1]`.
    cell_start: Vec<u32>,
    centres: Vec<[f64; 2]>,
}

impl DotPattern {
    /// Dots with Poisson density `dots_per_px2` over `[−margin, width + margin] × [−margin,
    /// height + margin]`.
    pub fn random(
        width: u32,
        height: u32,
        dots_per_px2: f64,
        sigma_px: f64,
        ambient: f64,
        seed: u64,
    ) -> Self {
        let margin = 8.0 * sigma_px + 2.0;
        let cell_px = 4.0 * sigma_px;
        let (w, h) = (width as f64 + 2.0 * margin, height as f64 + 2.0 * margin);
        let cells_x = (w / cell_px).ceil() as usize;
        let cells_y = (h / cell_px).ceil() as usize;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let count = (dots_per_px2 * w * h).round() as usize;
        let mut dots: Vec<(usize, [f64; 2])> = (0..count)
            .map(|_| {
                let c = [
                    rng.random::<f64>() * w - margin,
                    rng.random::<f64>() * h - margin,
                ];
                let cell = Self::cell_of(c, margin, cell_px, cells_x, cells_y);
                (cell, c)
            })
            .collect();
        dots.sort_by_key(|d| d.0);
        let mut cell_start = vec![0u32; cells_x * cells_y + 1];
        for &(cell, _) in &dots {
            cell_start[cell + 1] += 1;
        }
        for i in 1..cell_start.len() {
            cell_start[i] += cell_start[i - 1];
        }
        let centres = dots.into_iter().map(|d| d.1).collect();
        Self {
            sigma_px,
            ambient,
            origin: -margin,
            cell_px,
            cells_x,
            cells_y,
            cell_start,
            centres,
        }
    }

    fn cell_of(c: [f64; 2], margin: f64, cell_px: f64, cells_x: usize, cells_y: usize) -> usize {
        let i = (((c[0] + margin) / cell_px) as usize).min(cells_x - 1);
        let j = (((c[1] + margin) / cell_px) as usize).min(cells_y - 1);
        j * cells_x + i
    }

    /// Pattern value at left-image point `(x, y)`.
    pub fn value(&self, x: f64, y: f64) -> f64 {
        let o = self.origin;
        let (ci, cj) = (
            ((x - o) / self.cell_px).floor() as i64,
            ((y - o) / self.cell_px).floor() as i64,
        );
        let inv = -0.5 / (self.sigma_px * self.sigma_px);
        let cutoff2 = (4.0 * self.sigma_px).powi(2);
        let mut sum = self.ambient;
        for j in cj - 1..=cj + 1 {
            for i in ci - 1..=ci + 1 {
                if i < 0 || j < 0 || i >= self.cells_x as i64 || j >= self.cells_y as i64 {
                    continue;
                }
                let cell = j as usize * self.cells_x + i as usize;
                for c in &self.centres
                    [self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize]
                {
                    let r2 = (x - c[0]).powi(2) + (y - c[1]).powi(2);
                    if r2 < cutoff2 {
                        sum += (r2 * inv).exp();
                    }
                }
            }
        }
        sum
    }
}

/// A plane, by its disparity in left-image coordinates, optionally cut to a rectangle of the
/// left image.
#[derive(Clone, Copy, Debug)]
pub struct Plane {
    pub d0: f64,
    pub du: f64,
    pub dv: f64,
    /// `[u0, v0, u1, v1]` in left-image continuous coordinates; `None`: everywhere.
    pub extent: Option<[f64; 4]>,
}

impl Plane {
    /// The plane `n · P = n · P0` (left camera frame, metres) seen through `rig`.
    pub fn from_point_normal(rig: &StereoRig, point_m: [f64; 3], normal: [f64; 3]) -> Self {
        let k = &rig.intrinsics;
        let c = normal[0] * point_m[0] + normal[1] * point_m[1] + normal[2] * point_m[2];
        // 1/z = n · K⁻¹(u, v, 1) / c, d = f·b/z (fx = fy assumed).
        let fb = k.fx_px * rig.baseline_m;
        let du = rig.baseline_m * normal[0] / c;
        let dv = rig.baseline_m * normal[1] / c;
        let d0 =
            fb * (normal[2] - normal[0] * k.cx_px / k.fx_px - normal[1] * k.cy_px / k.fy_px) / c;
        Self {
            d0,
            du,
            dv,
            extent: None,
        }
    }

    /// Fronto-parallel at depth `z_m`.
    pub fn fronto(rig: &StereoRig, z_m: f64) -> Self {
        Self {
            d0: rig.disparity_from_depth(z_m),
            du: 0.0,
            dv: 0.0,
            extent: None,
        }
    }

    pub fn cut(self, extent: [f64; 4]) -> Self {
        Self {
            extent: Some(extent),
            ..self
        }
    }

    #[inline]
    pub fn disparity(&self, u: f64, v: f64) -> f64 {
        self.d0 + self.du * u + self.dv * v
    }

    #[inline]
    fn contains(&self, u: f64, v: f64) -> bool {
        self.extent
            .is_none_or(|[u0, v0, u1, v1]| u >= u0 && u < u1 && v >= v0 && v < v1)
    }
}

/// How a rectangle of the left image (so of the surfaces seen there) looks.
#[derive(Clone, Copy, Debug)]
pub enum Paint {
    /// Reflectance times this (dark < 1, saturating ≫ 1).
    Gain(f64),
    /// A constant radiance, no pattern (a textureless patch).
    Constant(f64),
}

/// Planes, a pattern, paint and a sensor.
pub struct Scene {
    pub width: u32,
    pub height: u32,
    pub planes: Vec<Plane>,
    pub pattern: Texture,
    /// Radiance = `exposure · pattern` before paint, noise and clipping.
    pub exposure: f64,
    pub paint: Vec<([f64; 4], Paint)>,
    pub noise_std: f64,
    pub subsamples: usize,
    pub seed: u64,
}

impl Scene {
    /// The plane seen at left-image point (u, v): the nearest (largest disparity) containing it.
    fn visible_from_left(&self, u: f64, v: f64) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for (i, p) in self.planes.iter().enumerate() {
            let d = p.disparity(u, v);
            if p.contains(u, v) && best.is_none_or(|(_, bd)| d > bd) {
                best = Some((i, d));
            }
        }
        best.map(|b| b.0)
    }

    /// Radiance of the surface point at left coordinates (u, v), lit by the pattern.
    fn lit_radiance(&self, u: f64, v: f64) -> f64 {
        let mut value = self.exposure * self.pattern.value(u, v);
        for &([u0, v0, u1, v1], paint) in &self.paint {
            if u >= u0 && u < u1 && v >= v0 && v < v1 {
                value = match paint {
                    Paint::Gain(g) => value * g,
                    Paint::Constant(c) => c,
                };
            }
        }
        value
    }

    fn left_sample(&self, u: f64, v: f64) -> f64 {
        if self.visible_from_left(u, v).is_some() {
            self.lit_radiance(u, v)
        } else {
            0.0
        }
    }

    fn right_sample(&self, x: f64, v: f64) -> f64 {
        // The nearest plane along the right camera's ray, then whether the projector sees it.
        let mut best: Option<(usize, f64, f64)> = None;
        for (i, p) in self.planes.iter().enumerate() {
            let u = (x + p.d0 + p.dv * v) / (1.0 - p.du);
            let d = p.disparity(u, v);
            if p.contains(u, v) && best.is_none_or(|(_, _, bd)| d > bd) {
                best = Some((i, u, d));
            }
        }
        match best {
            Some((i, u, _)) if self.visible_from_left(u, v) == Some(i) => self.lit_radiance(u, v),
            _ => 0.0,
        }
    }

    fn render(&self, sample: impl Fn(f64, f64) -> f64 + Sync, seed: u64) -> Image<f32> {
        let (w, h, s) = (self.width as usize, self.height as usize, self.subsamples);
        let mut data = vec![0.0f32; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
            for (u, px) in row.iter_mut().enumerate() {
                let mut sum = 0.0;
                for j in 0..s {
                    for i in 0..s {
                        sum += sample(
                            u as f64 + (i as f64 + 0.5) / s as f64,
                            v as f64 + (j as f64 + 0.5) / s as f64,
                        );
                    }
                }
                *px = (sum / (s * s) as f64) as f32;
            }
        });
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let noise =
            Normal::new(0.0, self.noise_std.max(0.0)).unwrap_or(Normal::new(0.0, 0.0).unwrap());
        for px in &mut data {
            *px = (*px + noise.sample(&mut rng) as f32).clamp(0.0, 1.0);
        }
        Image::new(self.width, self.height, data).unwrap()
    }

    /// The rendered (left, right) pair.
    pub fn render_pair(&self) -> (Image<f32>, Image<f32>) {
        let left = self.render(|u, v| self.left_sample(u, v), self.seed ^ 0x1ef7);
        let right = self.render(|x, v| self.right_sample(x, v), self.seed ^ 0x5167);
        (left, right)
    }

    /// The true disparity at left pixel (u, v)'s centre (NaN where nothing is seen).
    pub fn true_disparity(&self, u: u32, v: u32) -> f64 {
        let (x, y) = (u as f64 + 0.5, v as f64 + 0.5);
        self.visible_from_left(x, y)
            .map_or(f64::NAN, |i| self.planes[i].disparity(x, y))
    }
}
