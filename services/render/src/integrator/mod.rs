//! Light transport from the projector to a pinhole camera.
//!
//! - **Single-path** (the paper's I_single, eq 16): the first surface a camera ray hits, lit
//!   directly by the projector through a shadow ray. This is the signal an SLI camera matches.
//! - **Multi-path** (I_multi): unidirectional path tracing with next-event estimation towards
//!   the projector at every vertex, BSDF importance sampling between vertices, Russian
//!   roulette after `roulette_after` bounces. The projector is a point emitter, so paths only
//!   gather light through next-event estimation (no MIS needed).
//! - **Regularised multi-path** (`min_indirect_roughness` > 0): vertices after the first are
//!   sampled and shaded as if at least that rough (path-space regularisation, Kaplanyan &
//!   Dachsbacher 2013). A point light seen through two glossy bounces is a caustic that
//!   next-event estimation finds only by the luck of the first bounce's direction: the
//!   estimator's variance grows like 1/α² of the second vertex. Regularising trades that
//!   variance for a blur of those inter-reflections (a bias, 0 when the floor is 0); the
//!   first vertex, which the camera sees directly, stays exact.
//!
//! Radiance is in W·sr⁻¹·m⁻² for a projector intensity in W/sr. Every row has its own RNG
//! stream derived from `(seed, row)`: a render is reproducible whatever the thread count.
//!
//! The module's parts: [`Camera`] (a pinhole placed in the world), whole-image renders
//! ([`render`], [`render_first_surface`], [`render_labels`]), the per-pixel estimators the BSDF fit differentiates
//! ([`single_path_pixel`], [`path_pixel`], [`direct_light`]) and the path tracer they share.

mod camera;
mod image;
mod path;
mod pixel;
#[cfg(test)]
mod tests;

pub use camera::Camera;
pub(crate) use image::{DirectSink, render_with_sinks};
pub use image::{
    RenderOutput, render, render_first_surface, render_labels, render_with_single_path,
    render_with_single_path_where,
};
pub use pixel::{
    SinglePathSample, direct_light, path_pixel, path_pixel_frozen_sampling, single_path_pixel,
};

use glint_geometry::image::PixelRect;

/// Which light paths a render follows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightTransport {
    /// Direct reflection of the projector only.
    SinglePath,
    /// Direct and inter-reflected light, up to `max_bounces` surface interactions.
    MultiPath {
        /// Most surface interactions per path (0 is treated as 1).
        max_bounces: u32,
        /// Number of surface interactions after which Russian roulette may end a path.
        roulette_after: u32,
        /// Roughness floor of every vertex after the first (0: exact, as the camera renders).
        min_indirect_roughness: f32,
    },
}

impl LightTransport {
    /// Path tracing with 4 bounces, Russian roulette from the 3rd, unregularised.
    pub const MULTI_PATH_DEFAULT: Self = LightTransport::MultiPath {
        max_bounces: 4,
        roulette_after: 3,
        min_indirect_roughness: 0.0,
    };

    /// This transport with vertices after the first regularised to at least
    /// `min_indirect_roughness` (see the module doc); single-path is returned unchanged.
    pub fn regularised(self, min_indirect_roughness: f32) -> Self {
        match self {
            LightTransport::SinglePath => self,
            LightTransport::MultiPath {
                max_bounces,
                roulette_after,
                ..
            } => LightTransport::MultiPath {
                max_bounces,
                roulette_after,
                min_indirect_roughness,
            },
        }
    }
}

/// How to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Which light paths to follow.
    pub transport: LightTransport,
    /// Samples per pixel (≥ 1). One sample goes through the pixel centre; more are jittered.
    pub samples_per_pixel: u32,
    /// Render only these pixels (others stay 0 / NaN); `None` for the full image.
    pub roi: Option<PixelRect>,
    /// Seed of the random streams; a render is reproducible for a given seed.
    pub seed: u64,
}

/// How a per-pixel estimator ([`path_pixel`]) renders one pixel: the light paths, the samples
/// and the seed. With multi-path, the same seed gives common random numbers: the estimate is a
/// deterministic function of the materials apart from lobe-selection jumps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelRendering {
    /// Which light paths the render follows.
    pub transport: LightTransport,
    /// Samples per pixel (≥ 1; one through the pixel centre, more jittered).
    pub samples_per_pixel: u32,
    /// Seed of the pixel's random stream.
    pub seed: u64,
}

impl PixelRendering {
    /// The direct reflection only, one ray through the pixel centre (the paper's I_single).
    pub const SINGLE_PATH: Self = Self {
        transport: LightTransport::SinglePath,
        samples_per_pixel: 1,
        seed: 0,
    };

    /// `samples_per_pixel` samples with multi-path transports, one with single-path (its
    /// only ray goes through the pixel centre, so more would repeat it).
    pub fn new(transport: LightTransport, samples_per_pixel: u32, seed: u64) -> Self {
        let samples_per_pixel = if transport == LightTransport::SinglePath {
            1
        } else {
            samples_per_pixel
        };
        Self {
            transport,
            samples_per_pixel,
            seed,
        }
    }
}
