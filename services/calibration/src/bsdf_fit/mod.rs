//! The principled-BSDF fit of §IV-B by differentiable rendering: with the projector, the
//! camera and the object's pose known, find the BSDF parameters whose render (single- or
//! multi-path) matches target radiance maps over the object's pixels, in one or more views.
//!
//! - Renderer: [`glint_render::integrator::single_path_pixel`], the camera's own ray
//!   generation, intersection and shading ([`glint_render::integrator::direct_light`]),
//!   evaluated with forward-mode dual numbers (`Dual32`, one pass per free parameter, each
//!   seeding that parameter's derivative): each pixel's radiance and its exact derivatives with
//!   respect to the four free parameters. (num-dual's vector duals would do it in one pass, but
//!   need its `nalgebra` feature, which pulls in a second nalgebra.)
//! - Loss ([`Loss`]): normalised L2, L = Σ_p (r_p − t_p)² / Σ_p t_p² (scale-free, so one
//!   learning rate suits any radiance unit), or the squared error of ln radiance, over the
//!   object pixels with a finite target, all views pooled.
//! - Multi-path: the same seed every iteration (common random numbers); the derivative holds
//!   the sampling density and the lobe choices fixed (detached, as differentiable path tracers
//!   do), which [`FitProblem::loss_with_frozen_sampling`] makes checkable by finite differences.
//! - Optimiser: Adam (Kingma & Ba), every free parameter started at 0.5 as in the paper, each
//!   step projected onto the parameters' valid range: [0, 1], roughness [√α_min, 1]
//!   ([`free_lower_bounds`]).
//! - Shiny metals: multi-path renders may be regularised (later vertices at least
//!   `min_indirect_roughness` rough, [`LightTransport::regularised`]), the floor falling over
//!   the iterations ([`FitConfig::final_min_indirect_roughness`]).
//! - Free parameters: base_color, metallic, roughness, specular (metallic held where the
//!   finish is known, [`FitConfig::known_metallic`]); the others stay at
//!   [`FitConfig::fixed`] (default: their lobes off, as the mock camera's metals have them).

mod plot;
pub mod scene_fit;
mod target;

pub use plot::{error_map_png, fit_history_png};
pub use target::{MeasuredTarget, TargetError, measured_target};

use std::ops::ControlFlow;
use std::time::Instant;

use glint_render::bsdf::PrincipledParams;
use glint_render::integrator::{
    Camera, LightTransport, PixelRendering, path_pixel_frozen_sampling,
};
use glint_render::projector::Projector;
use glint_render::scene::Scene;
use num_dual::Dual32;
use rayon::prelude::*;

/// Names of the free parameters, in the order of every `[f32; FREE]` here.
pub const FREE_NAMES: [&str; FREE] = ["base_color", "metallic", "roughness", "specular"];
/// Number of free parameters.
pub const FREE: usize = 4;
/// Index of metallic in every `[f32; FREE]` ([`FREE_NAMES`]).
const METALLIC: usize = 1;

/// The lower end of each free parameter's range in the fit. Roughness stops at √α_min: below
/// it the GGX width is floored ([`glint_render::bsdf::ggx::MIN_ALPHA`]), every roughness
/// renders alike and the derivative is exactly 0, so a step into that range could never come
/// back out.
pub fn free_lower_bounds() -> [f32; FREE] {
    [0.0, 0.0, glint_render::bsdf::ggx::MIN_ALPHA.sqrt(), 0.0]
}

/// Why a fit could not run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    /// A view's [`FitTarget`] has not one radiance per pixel.
    #[error("view {view}: the target has {pixels} pixels but {values} radiance values")]
    LengthMismatch {
        /// Index of the view in [`FitProblem::views`].
        view: usize,
        /// Its target's pixel count.
        pixels: usize,
        /// Its target's radiance count.
        values: usize,
    },
    /// No target pixel both sees a fitted instance and has a finite, positive target: check
    /// the poses, [`FitProblem::instances`] and the targets.
    #[error(
        "none of the {pixels} target pixels sees instances {instances:?} with a finite, non-zero target"
    )]
    NoPixels {
        /// Target pixels over all views.
        pixels: usize,
        /// The fitted instances (scene indices).
        instances: Vec<u32>,
    },
    /// A fitted instance index is out of the scene's range.
    #[error("instance {instance} is not in the scene ({instances} instances)")]
    NoSuchInstance {
        /// The offending scene index.
        instance: u32,
        /// The scene's instance count.
        instances: usize,
    },
    /// A setting is out of range ([`FitConfig`], its fixed parameters, or no start value); the
    /// message says which.
    #[error("{0}")]
    Config(String),
    /// The progress callback returned `Break`; no result.
    #[error("stopped by its caller after iteration {iteration}")]
    Stopped {
        /// The last iteration run (0-based).
        iteration: usize,
    },
}

/// The object's pixels and their target radiance (same unit as the renderer, W·sr⁻¹·m⁻²).
#[derive(Clone, Debug, Default)]
pub struct FitTarget {
    /// Pixels (column u, row v) of the object.
    pub pixels: Vec<(u32, u32)>,
    /// Target radiance of each pixel, W·sr⁻¹·m⁻²; pixels with a non-finite or non-positive
    /// value are left out of the loss.
    pub radiance: Vec<f32>,
}

/// One view of the fit: the left camera, the projector as it was for that view, and the target.
#[derive(Clone, Debug)]
pub struct FitView {
    /// The left camera, placed in the world.
    pub camera: Camera,
    /// The projector (pose, pattern, intensity) of this view.
    pub projector: Projector,
    /// The pixels to match and their radiance.
    pub target: FitTarget,
}

/// Adam settings and the fixed parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct FitConfig {
    /// Adam steps, ≥ 1.
    pub iterations: usize,
    /// Initial Adam step size; it decays geometrically to `final_learning_rate`.
    pub learning_rate: f32,
    /// Adam step size of the last iteration, > 0.
    pub final_learning_rate: f32,
    /// Adam's decay rate β₁ of the gradient's running mean, in [0, 1).
    pub beta1: f32,
    /// Adam's decay rate β₂ of the squared gradient's running mean, in [0, 1).
    pub beta2: f32,
    /// The starting value of every free parameter (the paper's medium value 0.5).
    pub start: f32,
    /// Values of the parameters that are not free.
    pub fixed: PrincipledParams<f32>,
    /// Fresh random numbers every iteration (seed + k·[`RESEED_STRIDE`]): stochastic gradient
    /// descent, whose Adam averages the Monte Carlo noise of the gradient over iterations.
    /// Without it every iteration reuses the same samples (common random numbers): a
    /// deterministic loss, but one whose noise the optimiser can fit.
    pub reseed: bool,
    /// With a regularised multi-path rendering: the roughness floor of the last iteration.
    /// The floor falls linearly from the rendering's own `min_indirect_roughness` to this
    /// over the iterations — early steps see smooth renders of a blurred scene, the last ones
    /// nearly the camera's own paths, which removes most of the regularisation's bias
    /// (Kaplanyan & Dachsbacher shrink it as the estimate converges, for the same reason).
    /// `None` keeps the floor fixed.
    pub final_min_indirect_roughness: Option<f32>,
    /// The metallic weight, in [0, 1], when the part's finish is known: 1 for bare metal, 0
    /// for a dielectric (paint, plastic). It is then held, not fitted; the other three
    /// parameters are. Bare metal has no diffuse lobe, but a fit left free to add one can
    /// trade it against base colour and specular (both scale F0) and still match the
    /// radiance: the Gear's free fit gives metallic 0.78 for bare steel.
    pub known_metallic: Option<f32>,
}

impl FitConfig {
    /// The free parameter held at a known value, as (index in `[f32; FREE]`, value).
    fn held(&self) -> Option<(usize, f32)> {
        self.known_metallic.map(|m| (METALLIC, m))
    }

    /// Names of the parameters the fit changes: [`FREE_NAMES`] but the held one.
    pub fn fitted_names(&self) -> Vec<&'static str> {
        let held = self.held().map(|(i, _)| i);
        (0..FREE)
            .filter(|&i| Some(i) != held)
            .map(|i| FREE_NAMES[i])
            .collect()
    }
}

/// Seed step between iterations with [`FitConfig::reseed`].
pub const RESEED_STRIDE: u64 = 0x9E37_79B9;

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            iterations: 300,
            learning_rate: 0.03,
            final_learning_rate: 0.002,
            beta1: 0.9,
            beta2: 0.999,
            start: 0.5,
            // The default material with metallic 0.5, the paper's start.
            fixed: PrincipledParams {
                metallic: 0.5,
                ..PrincipledParams::default()
            },
            reseed: false,
            final_min_indirect_roughness: None,
            known_metallic: None,
        }
    }
}

/// A fit's outcome.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FitResult {
    /// The fitted parameters (free ones fitted, the others as fixed).
    #[serde(skip)]
    pub params: PrincipledParams<f32>,
    /// Loss before each step and after the last (iterations + 1 values), each with its own
    /// step's regularisation ([`FitConfig::final_min_indirect_roughness`]).
    pub loss: Vec<f64>,
    /// Free parameters before each step and after the last.
    pub trajectory: Vec<[f32; FREE]>,
    /// Pixels that entered the loss, all views.
    pub pixels: usize,
    /// Wall time of the fit, seconds.
    pub elapsed_s: f64,
}

/// Seed of the renders that judge fits from several starts (no fit's own).
pub const JUDGE_SEED: u64 = 0x00D6_E5EE;

/// One of [`FitProblem::fit_from_starts`]' fits.
#[derive(Clone, Debug)]
pub struct StartFit {
    /// The start value of every free parameter, in [0, 1].
    pub start: f32,
    /// The fit from that start.
    pub result: FitResult,
    /// Its unbiased L2 under the common judging render (NaN with a single start).
    pub judged_l2: f64,
}

/// The fits of [`FitProblem::fit_from_starts`], in the order of the starts, and the index of
/// the one with the lowest judged loss.
#[derive(Clone, Debug)]
pub struct StartFits {
    /// One fit per start, in the order of the starts.
    pub fits: Vec<StartFit>,
    /// Index in `fits` of the lowest [`StartFit::judged_l2`] (0 with a single start).
    pub best: usize,
}

/// What the fit renders: the scene (other instances keep their own, known materials), the
/// views with their targets, the instances whose (shared) material is fitted — every copy of
/// the part in a bin has the same material — and how pixels are rendered. The loss sums over
/// all views (one normalisation, so each pixel weighs the same whichever view it is in).
pub struct FitProblem<'a> {
    /// The scene; the fitted instances' own materials in it are not used.
    pub scene: &'a Scene,
    /// The views and their targets.
    pub views: &'a [FitView],
    /// Scene indices of the instances whose material is fitted.
    pub instances: &'a [u32],
    /// How a pixel is rendered.
    pub rendering: PixelRendering,
    /// How the gradient's residual is estimated (matters with multi-path only).
    pub residual: Residual,
    /// The per-pixel loss.
    pub loss: Loss,
    /// Side of the square pixel blocks the loss compares, pixels: 1 compares pixels; b > 1
    /// compares each b × b block's mean radiance (rendered against measured, over the block's
    /// target pixels), which averages the Monte Carlo noise of both by the block's pixel
    /// count, at the price of detail. Each block weighs by its pixel count.
    pub block_px: u32,
}

/// The per-pixel loss ℓ(r, t) summed over the target pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Loss {
    /// L = Σ (r − t)² / Σ t²: the paper's L2, scale-free. Bright glints dominate it.
    L2,
    /// L = Σ (ln(r + ε) − ln(t + ε))² / N, ε = `floor` (W·sr⁻¹·m⁻²): every pixel weighs
    /// alike whatever its brightness, relative errors count.
    LnRadiance {
        /// ε, W·sr⁻¹·m⁻², > 0.
        floor: f32,
    },
    /// Huber: (r − t)² within ±δ, 2δ|r − t| − δ² beyond (δ = `delta`, W·sr⁻¹·m⁻²), over
    /// Σ t²: L2 for ordinary pixels, a bounded slope for Monte Carlo fireflies (in the render
    /// or the capture) that would otherwise dominate.
    Huber {
        /// δ, W·sr⁻¹·m⁻², > 0.
        delta: f32,
    },
}

impl Loss {
    /// (ℓ(r, t), ∂ℓ/∂r at r, this pixel's share of the normalisation).
    fn pixel(self, r: f64, t: f64) -> (f64, f64, f64) {
        match self {
            Loss::L2 => ((r - t).powi(2), 2.0 * (r - t), t * t),
            Loss::LnRadiance { floor } => {
                let e = floor as f64;
                let d = (r.max(0.0) + e).ln() - (t + e).ln();
                (d * d, 2.0 * d / (r.max(0.0) + e), 1.0)
            }
            Loss::Huber { delta } => {
                let (d, delta) = (r - t, delta as f64);
                if d.abs() <= delta {
                    (d * d, 2.0 * d, t * t)
                } else {
                    (
                        2.0 * delta * d.abs() - delta * delta,
                        2.0 * delta * d.signum(),
                        t * t,
                    )
                }
            }
        }
    }
}

/// The residual r̂ − t in the gradient 2 Σ (r̂ − t) ∂r̂ of a Monte Carlo render r̂.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Residual {
    /// From the same samples as ∂r̂. E[(r̂ − t)²] = (r − t)² + Var r̂, so the gradient is that
    /// of the loss plus ∂Var r̂: a bias towards parameters whose renders are less noisy.
    SameSamples,
    /// From a second, independent estimate r̂' (seed + [`DECORRELATED_SEED_OFFSET`]):
    /// E[2 (r̂' − t) ∂r̂] = ∂(r − t)², unbiased, for one more f32 render per pixel.
    Decorrelated,
}

/// Seed offset of the independent residual estimate of [`Residual::Decorrelated`].
pub const DECORRELATED_SEED_OFFSET: u64 = 0x5DEE_CE66;

/// `fixed` with the free parameters replaced by `free`.
pub fn with_free<T: Copy>(fixed: PrincipledParams<T>, free: [T; FREE]) -> PrincipledParams<T> {
    PrincipledParams {
        base_color: free[0],
        metallic: free[1],
        roughness: free[2],
        specular: free[3],
        ..fixed
    }
}

/// The free parameters of `p`.
pub fn free_of<T: Copy>(p: &PrincipledParams<T>) -> [T; FREE] {
    [p.base_color, p.metallic, p.roughness, p.specular]
}

/// A target pixel in the loss: view index, pixel (u, v), target radiance.
type LossPixel = (usize, (u32, u32), f32);

/// Sums of a loss pass: loss, its gradient, normalisation, pixels.
type Sums = (f64, [f64; FREE], f64, usize);

fn add_sums(a: Sums, b: Sums) -> Sums {
    (
        a.0 + b.0,
        std::array::from_fn(|i| a.1[i] + b.1[i]),
        a.2 + b.2,
        a.3 + b.3,
    )
}

impl FitProblem<'_> {
    fn check(&self) -> Result<(), FitError> {
        for (view, v) in self.views.iter().enumerate() {
            let t = &v.target;
            if t.pixels.len() != t.radiance.len() {
                return Err(FitError::LengthMismatch {
                    view,
                    pixels: t.pixels.len(),
                    values: t.radiance.len(),
                });
            }
        }
        let instances = self.scene.instances().len();
        if let Some(&instance) = self.instances.iter().find(|&&i| i as usize >= instances) {
            return Err(FitError::NoSuchInstance {
                instance,
                instances,
            });
        }
        Ok(())
    }

    fn is_fitted(&self, instance: u32) -> bool {
        self.instances.contains(&instance)
    }

    /// Pixel (u, v) of view `k` rendered with `params` on the fitted instances (and the
    /// scene's materials elsewhere); `None` unless its centre ray hits a fitted instance.
    /// With `sampling`, every random decision uses it instead of `params`' real part
    /// ([`path_pixel_frozen_sampling`]).
    fn shade<T: glint_render::bsdf::BsdfScalar>(
        &self,
        k: usize,
        (u, v): (u32, u32),
        params: &PrincipledParams<T>,
        sampling: Option<&PrincipledParams<f32>>,
    ) -> Option<T> {
        self.shade_seeded(k, (u, v), params, sampling, 0)
    }

    /// [`FitProblem::shade`] with the seed offset by `seed_offset`.
    fn shade_seeded<T: glint_render::bsdf::BsdfScalar>(
        &self,
        k: usize,
        (u, v): (u32, u32),
        params: &PrincipledParams<T>,
        sampling: Option<&PrincipledParams<f32>>,
        seed_offset: u64,
    ) -> Option<T> {
        let r = &self.rendering;
        let view = &self.views[k];
        let seed = r.seed.wrapping_add(k as u64).wrapping_add(seed_offset);
        let material = |i: u32| {
            if self.is_fitted(i) {
                *params
            } else {
                self.scene.material_of(i).map(|x| T::from(x))
            }
        };
        let frozen = |i: u32| match sampling {
            Some(s) if self.is_fitted(i) => *s,
            _ => *self.scene.material_of(i),
        };
        let sample = path_pixel_frozen_sampling(
            self.scene,
            &view.camera,
            &view.projector,
            (u, v),
            &PixelRendering { seed, ..*r },
            material,
            sampling.map(|_| &frozen as &dyn Fn(u32) -> PrincipledParams<f32>),
        );
        sample
            .filter(|s| self.is_fitted(s.instance))
            .map(|s| s.radiance)
    }

    /// Every view's target pixels with a usable (finite, positive) target, grouped into the
    /// loss's blocks ([`FitProblem::block_px`]).
    fn loss_groups(&self) -> Vec<Vec<LossPixel>> {
        let b = self.block_px.max(1);
        let mut groups = Vec::new();
        for (k, view) in self.views.iter().enumerate() {
            let mut blocks: std::collections::BTreeMap<(u32, u32), Vec<_>> = Default::default();
            for (&(u, v), &t) in view.target.pixels.iter().zip(&view.target.radiance) {
                if t.is_finite() && t > 0.0 {
                    blocks
                        .entry((u / b, v / b))
                        .or_default()
                        .push((k, (u, v), t));
                }
            }
            groups.extend(blocks.into_values());
        }
        groups
    }

    /// The rendered radiance of every view's target pixels for `params` (NaN where the pixel
    /// does not see a fitted instance).
    pub fn render(&self, params: &PrincipledParams<f32>) -> Vec<Vec<f32>> {
        self.views
            .iter()
            .enumerate()
            .map(|(k, view)| {
                view.target
                    .pixels
                    .par_iter()
                    .map(|&p| self.shade(k, p, params, None).unwrap_or(f32::NAN))
                    .collect()
            })
            .collect()
    }

    /// The loss and its gradient with respect to the free parameters at `free` (others fixed),
    /// and the number of pixels that entered it.
    pub fn loss_and_gradient(
        &self,
        fixed: &PrincipledParams<f32>,
        free: [f32; FREE],
    ) -> (f64, [f64; FREE], usize) {
        // One material per free parameter, each carrying ∂/∂(that parameter).
        let seeded: [PrincipledParams<Dual32>; FREE] = std::array::from_fn(|i| {
            let lifted = std::array::from_fn(|j| {
                if i == j {
                    Dual32::new(free[j], 1.0)
                } else {
                    Dual32::from_re(free[j])
                }
            });
            with_free(fixed.map(Dual32::from_re), lifted)
        });
        let decorrelated = self.residual == Residual::Decorrelated
            && self.rendering.transport != LightTransport::SinglePath;
        let plain = with_free(*fixed, free);
        let zero = || (0.0f64, [0.0f64; FREE], 0.0f64, 0usize);
        let (sse, grad, norm, n) = self
            .loss_groups()
            .par_iter()
            .fold(zero, |(mut sse, mut grad, mut norm, mut n), group| {
                // Sums over the group's pixels that see a fitted instance.
                let (mut r, mut r_other, mut t, mut d, mut m) = (0.0, 0.0, 0.0, [0.0; FREE], 0);
                for &(k, p, tp) in group {
                    let Some(radiance) = self.shade(k, p, &seeded[0], None) else {
                        continue;
                    };
                    r += radiance.re as f64;
                    d[0] += radiance.eps as f64;
                    for (i, s) in seeded.iter().enumerate().skip(1) {
                        // Same rays, same random numbers: only the seeded derivative differs.
                        d[i] += self.shade(k, p, s, None).map_or(0.0, |s| s.eps) as f64;
                    }
                    if decorrelated {
                        let other = self.shade_seeded(k, p, &plain, None, DECORRELATED_SEED_OFFSET);
                        r_other += other.unwrap_or(0.0) as f64;
                    }
                    t += tp as f64;
                    m += 1;
                }
                if m > 0 {
                    let mf = m as f64;
                    let (value, mut slope, weight) = self.loss.pixel(r / mf, t / mf);
                    if decorrelated {
                        slope = self.loss.pixel(r_other / mf, t / mf).1;
                    }
                    // m·ℓ(r̄, t̄): its derivative is m·ℓ'·Σ∂r/m = ℓ'·Σ∂r.
                    sse += mf * value;
                    for (g, di) in grad.iter_mut().zip(d) {
                        *g += slope * di;
                    }
                    norm += mf * weight;
                    n += m;
                }
                (sse, grad, norm, n)
            })
            .reduce(zero, add_sums);
        if n == 0 || norm <= 0.0 {
            return (f64::NAN, [0.0; FREE], 0);
        }
        (sse / norm, grad.map(|g| g / norm), n)
    }

    /// An unbiased estimate of the L2 loss Σ (r − t)² / Σ t² of the fitted material at
    /// `params`, from two independent renders r̂, r̂' of every block:
    /// E[(r̂ − t)(r̂' − t)] = (r − t)², where the plain (r̂ − t)² would add Var r̂ — a penalty
    /// on sharp, noisy materials that would bias any comparison towards rough ones. For
    /// choosing between fits; single-path renders are exact and give the plain L2.
    pub fn unbiased_l2(&self, params: &PrincipledParams<f32>) -> f64 {
        let zero = || (0.0f64, 0.0f64);
        let (cross, norm) = self
            .loss_groups()
            .par_iter()
            .fold(zero, |(mut cross, mut norm), group| {
                let (mut r, mut r_other, mut t, mut m) = (0.0, 0.0, 0.0, 0);
                for &(k, p, tp) in group {
                    let Some(radiance) = self.shade(k, p, params, None) else {
                        continue;
                    };
                    r += radiance as f64;
                    r_other += self
                        .shade_seeded(k, p, params, None, DECORRELATED_SEED_OFFSET)
                        .unwrap_or(0.0) as f64;
                    t += tp as f64;
                    m += 1;
                }
                if m > 0 {
                    let mf = m as f64;
                    let (r, r_other, t) = (r / mf, r_other / mf, t / mf);
                    cross += mf * (r - t) * (r_other - t);
                    norm += mf * t * t;
                }
                (cross, norm)
            })
            .reduce(zero, |a, b| (a.0 + b.0, a.1 + b.1));
        if norm > 0.0 { cross / norm } else { f64::NAN }
    }

    /// The loss with the fitted material at `free` but every random decision of every path
    /// made with the material at `sampled_at` (frozen sampling,
    /// [`path_pixel_frozen_sampling`]): a smooth function of `free` for fixed `sampled_at`,
    /// whose gradient at `free = sampled_at` is what [`FitProblem::loss_and_gradient`]
    /// computes. For checking that gradient by finite differences.
    pub fn loss_with_frozen_sampling(
        &self,
        fixed: &PrincipledParams<f32>,
        free: [f32; FREE],
        sampled_at: [f32; FREE],
    ) -> f64 {
        let params = with_free(*fixed, free);
        let sampling = with_free(*fixed, sampled_at);
        let zero = || (0.0f64, [0.0f64; FREE], 0.0f64, 0usize);
        let (sse, _, norm, n) = self
            .loss_groups()
            .par_iter()
            .fold(zero, |(mut sse, g, mut norm, mut n), group| {
                let (mut r, mut t, mut m) = (0.0, 0.0, 0);
                for &(k, p, tp) in group {
                    if let Some(radiance) = self.shade(k, p, &params, Some(&sampling)) {
                        r += radiance as f64;
                        t += tp as f64;
                        m += 1;
                    }
                }
                if m > 0 {
                    let mf = m as f64;
                    let (value, _, weight) = self.loss.pixel(r / mf, t / mf);
                    sse += mf * value;
                    norm += mf * weight;
                    n += m;
                }
                (sse, g, norm, n)
            })
            .reduce(zero, add_sums);
        if n == 0 || norm <= 0.0 {
            f64::NAN
        } else {
            sse / norm
        }
    }

    /// The light transport of iteration `k`: the rendering's, with the regularisation floor
    /// moved towards [`FitConfig::final_min_indirect_roughness`].
    fn transport_at(&self, config: &FitConfig, k: usize) -> LightTransport {
        let transport = self.rendering.transport;
        match (transport, config.final_min_indirect_roughness) {
            (
                LightTransport::MultiPath {
                    min_indirect_roughness: start,
                    ..
                },
                Some(end),
            ) => {
                let f = k as f32 / (config.iterations.max(2) - 1) as f32;
                transport.regularised(start + (end - start) * f)
            }
            _ => transport,
        }
    }

    /// One fit from each of `starts` (the start value of every free parameter; `config.start`
    /// is ignored), judged alike: the [`FitProblem::unbiased_l2`] of each result, rendered as
    /// the last iteration renders (final regularisation floor) but with seed [`JUDGE_SEED`]
    /// and, for multi-path, 4× the samples. A single start needs no judging (its `judged_l2` is NaN).
    /// `progress(iteration, loss, params)` is called after every step of every fit, as in
    /// [`FitProblem::fit_with_progress`]; a `Break` stops all fits ([`FitError::Stopped`]).
    pub fn fit_from_starts(
        &self,
        config: &FitConfig,
        starts: &[f32],
        mut progress: impl FnMut(usize, f64, &PrincipledParams<f32>) -> ControlFlow<()>,
    ) -> Result<StartFits, FitError> {
        if starts.is_empty() {
            return Err(FitError::Config("no start values given".into()));
        }
        let mut fits = Vec::with_capacity(starts.len());
        for &start in starts {
            let config = FitConfig {
                start,
                ..config.clone()
            };
            fits.push(StartFit {
                start,
                result: self.fit_with_progress(&config, &mut progress)?,
                judged_l2: f64::NAN,
            });
        }
        if fits.len() > 1 {
            let transport = self.transport_at(config, config.iterations - 1);
            let judge = FitProblem {
                rendering: PixelRendering {
                    transport,
                    // Single-path renders are the exact centre ray: nothing to add.
                    samples_per_pixel: match transport {
                        LightTransport::SinglePath => self.rendering.samples_per_pixel,
                        LightTransport::MultiPath { .. } => {
                            (self.rendering.samples_per_pixel * 4).min(256)
                        }
                    },
                    seed: JUDGE_SEED,
                },
                ..*self
            };
            for fit in &mut fits {
                fit.judged_l2 = judge.unbiased_l2(&fit.result.params);
            }
        }
        let best = (0..fits.len())
            .min_by(|&a, &b| fits[a].judged_l2.total_cmp(&fits[b].judged_l2))
            .unwrap_or(0);
        Ok(StartFits { fits, best })
    }

    /// Runs Adam from `config.start` (see the module doc).
    pub fn fit(&self, config: &FitConfig) -> Result<FitResult, FitError> {
        self.fit_with_progress(config, |_, _, _| ControlFlow::Continue(()))
    }

    /// [`FitProblem::fit`], calling `progress(iteration, loss, params)` after every step with
    /// the loss before the step and the parameters it was evaluated at; a `Break` stops the fit
    /// ([`FitError::Stopped`]: the caller no longer wants it, say a client that went away).
    pub fn fit_with_progress(
        &self,
        config: &FitConfig,
        mut progress: impl FnMut(usize, f64, &PrincipledParams<f32>) -> ControlFlow<()>,
    ) -> Result<FitResult, FitError> {
        self.check()?;
        let valid = config.iterations > 0
            && config.learning_rate > 0.0
            && config.final_learning_rate > 0.0
            && (0.0..1.0).contains(&config.beta1)
            && (0.0..1.0).contains(&config.beta2)
            && (0.0..=1.0).contains(&config.start)
            && config
                .final_min_indirect_roughness
                .is_none_or(|r| (0.0..=1.0).contains(&r))
            && config
                .known_metallic
                .is_none_or(|m| (0.0..=1.0).contains(&m));
        if !valid {
            return Err(FitError::Config(format!(
                "iterations must be ≥ 1, learning rates > 0, betas in [0, 1), start, final_min_indirect_roughness and known_metallic in [0, 1]; got {config:?}"
            )));
        }
        config
            .fixed
            .validated()
            .map_err(|e| FitError::Config(format!("fixed parameters: {e}")))?;
        let started = Instant::now();
        let lower = free_lower_bounds();
        let mut x: [f32; FREE] = std::array::from_fn(|i| config.start.max(lower[i]));
        let held = config.held();
        if let Some((i, value)) = held {
            x[i] = value;
        }
        let (mut m, mut v) = ([0f64; FREE], [0f64; FREE]);
        let mut loss = Vec::with_capacity(config.iterations + 1);
        let mut trajectory = Vec::with_capacity(config.iterations + 1);
        let decay = (config.final_learning_rate / config.learning_rate) as f64;
        let mut pixels = 0;
        for k in 0..config.iterations {
            let seed_offset = if config.reseed {
                (k as u64).wrapping_mul(RESEED_STRIDE)
            } else {
                0
            };
            let this_step = FitProblem {
                rendering: PixelRendering {
                    seed: self.rendering.seed.wrapping_add(seed_offset),
                    transport: self.transport_at(config, k),
                    ..self.rendering
                },
                ..*self
            };
            let (l, g, n) = this_step.loss_and_gradient(&config.fixed, x);
            if n == 0 {
                return Err(FitError::NoPixels {
                    pixels: self.views.iter().map(|v| v.target.pixels.len()).sum(),
                    instances: self.instances.to_vec(),
                });
            }
            pixels = n;
            loss.push(l);
            trajectory.push(x);
            let evaluated = with_free(config.fixed, x);
            let lr = config.learning_rate as f64
                * decay.powf(k as f64 / (config.iterations.max(2) - 1) as f64);
            let (b1, b2) = (config.beta1 as f64, config.beta2 as f64);
            for i in (0..FREE).filter(|&i| held.is_none_or(|(h, _)| h != i)) {
                m[i] = b1 * m[i] + (1.0 - b1) * g[i];
                v[i] = b2 * v[i] + (1.0 - b2) * g[i] * g[i];
                let m_hat = m[i] / (1.0 - b1.powi(k as i32 + 1));
                let v_hat = v[i] / (1.0 - b2.powi(k as i32 + 1));
                let step = lr * m_hat / (v_hat.sqrt() + 1e-10);
                x[i] = ((x[i] as f64 - step).clamp(lower[i] as f64, 1.0)) as f32;
            }
            if progress(k, l, &evaluated).is_break() {
                return Err(FitError::Stopped { iteration: k });
            }
        }
        let last = FitProblem {
            rendering: PixelRendering {
                transport: self.transport_at(config, config.iterations - 1),
                ..self.rendering
            },
            ..*self
        };
        let (l, _, _) = last.loss_and_gradient(&config.fixed, x);
        loss.push(l);
        trajectory.push(x);
        Ok(FitResult {
            params: with_free(config.fixed, x),
            loss,
            trajectory,
            pixels,
            elapsed_s: started.elapsed().as_secs_f64(),
        })
    }
}

#[cfg(test)]
mod tests;
