//! The SLI projector: a point emitter at its centre whose radiant intensity is modulated by a
//! pattern image mapped through the projector's own pinhole intrinsics.
//!
//! Projector frame as a camera's: x right, y down, z forward (the optical axis).

use glam::Vec3A;
use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::Image;
use nalgebra::{Isometry3, Point2, Point3};
use rand::{Rng, SeedableRng};

/// What the projector shows.
#[derive(Clone, Debug)]
pub enum Pattern {
    /// Full intensity everywhere inside the frustum (for calibration and white images).
    White,
    /// Relative transmittance in [0, 1] per projector pixel, sampled bilinearly.
    Texture(Image<f32>),
}

impl Pattern {
    /// A random-dot pattern: each projector pixel is lit with probability `fill`, seeded.
    pub fn random_dots(width: u32, height: u32, fill: f64, seed: u64) -> Self {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let data = (0..width as usize * height as usize)
            .map(|_| {
                if rng.random_bool(fill.clamp(0.0, 1.0)) {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        // width, height > 0 is the caller's contract; a zero size falls back to white.
        Image::new(width, height, data).map_or(Pattern::White, Pattern::Texture)
    }

    /// Transmittance at continuous projector pixel coordinates (0 outside the image).
    #[inline]
    pub fn transmittance(&self, uv: Point2<f64>, intrinsics: &PinholeIntrinsics) -> f32 {
        let (w, h) = (intrinsics.width_px as f64, intrinsics.height_px as f64);
        if !(uv.x >= 0.0 && uv.x < w && uv.y >= 0.0 && uv.y < h) {
            return 0.0;
        }
        match self {
            Pattern::White => 1.0,
            Pattern::Texture(img) => {
                let taps = BilinearTaps::new(uv, intrinsics, img.width(), img.height());
                taps.sample(img.data())
            }
        }
    }
}

/// Where a bilinear lookup of a `width × height` texture mapped onto the projector frustum
/// reads, and with which weights: computed once, applied to any texture of that size (the
/// many patterns of a multi-shot capture).
#[derive(Clone, Copy, Debug)]
pub struct BilinearTaps {
    /// Row-major indices of the texels (x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1),
    /// clamped to the texture.
    pub index: [u32; 4],
    /// Horizontal fractional position between them, in [0, 1).
    pub fx: f32,
    /// Vertical fractional position between them, in [0, 1).
    pub fy: f32,
}

impl BilinearTaps {
    /// The taps at continuous projector pixel coordinates `uv` (inside the frustum).
    #[inline]
    pub fn new(uv: Point2<f64>, intrinsics: &PinholeIntrinsics, width: u32, height: u32) -> Self {
        // The texture may have its own resolution: map the frustum onto it.
        let x = uv.x / intrinsics.width_px as f64 * width as f64 - 0.5;
        let y = uv.y / intrinsics.height_px as f64 * height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let at = |i: f64, j: f64| {
            let i = i.clamp(0.0, width as f64 - 1.0) as u32;
            let j = j.clamp(0.0, height as f64 - 1.0) as u32;
            j * width + i
        };
        Self {
            index: [
                at(x0, y0),
                at(x0 + 1.0, y0),
                at(x0, y0 + 1.0),
                at(x0 + 1.0, y0 + 1.0),
            ],
            fx,
            fy,
        }
    }

    /// The interpolated value of `texels` (the texture's row-major data; 0 for an index
    /// beyond it).
    #[inline]
    pub fn sample(&self, texels: &[f32]) -> f32 {
        let t = |k: usize| texels.get(self.index[k] as usize).copied().unwrap_or(0.0);
        let (fx, fy) = (self.fx, self.fy);
        let top = t(0) * (1.0 - fx) + t(1) * fx;
        let bottom = t(2) * (1.0 - fx) + t(3) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// Light arriving at a surface point from the projector.
#[derive(Clone, Copy, Debug)]
pub struct Illumination {
    /// Unit direction from the point towards the projector centre.
    pub direction: Vec3A,
    /// Distance to the projector centre, metres.
    pub distance_m: f32,
    /// Radiant intensity towards the point, W/sr.
    pub intensity_w_per_sr: f32,
}

/// A projector placed in the world.
#[derive(Clone, Debug)]
pub struct Projector {
    /// Projector → world.
    pub t_w_p: Isometry3<f64>,
    /// Pinhole optics of the projector (focal lengths and principal point in px, image size):
    /// the frustum patterns are mapped onto.
    pub intrinsics: PinholeIntrinsics,
    /// What the projector shows.
    pub pattern: Pattern,
    /// Radiant intensity of a fully lit pattern pixel, W/sr.
    pub intensity_w_per_sr: f32,
}

impl Projector {
    /// The light this projector sends to world point `p_w`, or `None` outside its frustum or
    /// where the pattern is dark.
    #[inline]
    pub fn illuminate(&self, p_w: Vec3A) -> Option<Illumination> {
        let centre = self.t_w_p.translation.vector.cast::<f32>();
        let to_light = Vec3A::new(centre.x, centre.y, centre.z) - p_w;
        let distance_m = to_light.length();
        let uv = self.pattern_coordinates(p_w)?;
        let transmittance = self.pattern.transmittance(uv, &self.intrinsics);
        (transmittance > 0.0 && distance_m > 0.0).then(|| Illumination {
            direction: to_light / distance_m,
            distance_m,
            intensity_w_per_sr: self.intensity_w_per_sr * transmittance,
        })
    }

    /// Where world point `p_w` falls in the projector image: continuous pixel coordinates
    /// (pixel centres at +0.5), `None` behind the projector. Points outside the image get
    /// coordinates outside `0..width × 0..height` (transmittance 0).
    #[inline]
    pub fn pattern_coordinates(&self, p_w: Vec3A) -> Option<Point2<f64>> {
        let p_p = self.t_w_p.inverse_transform_point(&Point3::new(
            p_w.x as f64,
            p_w.y as f64,
            p_w.z as f64,
        ));
        self.intrinsics.project(&p_p)
    }
}
