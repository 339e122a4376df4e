//! The principled BSDF: Mitsuba 3's `principled` plugin (Burley 2012/2015, "Physically Based
//! Shading at Disney" and "Extending the Disney BRDF to a BSDF with Integrated Subsurface
//! Scattering") without its transmission, monochrome, and generic over the parameter scalar so
//! that forward-mode dual numbers give exact parameter derivatives of the radiance.
//!
//! # Conventions
//! - Directions are unit `f32` vectors in the local [`ShadingFrame`] (z = normal). They are
//!   never differentiated; the parameters may be (`T: `[`BsdfScalar`]).
//! - `wi` is the fixed direction, towards where the path came from: the camera side when paths
//!   are traced from the camera (Mitsuba's `si.wi`). `wo` is the other direction — the one
//!   [`sample`] draws — towards the next vertex, e.g. the projector for next-event estimation.
//! - [`eval`] returns f(wi, wo) · cos θo, Mitsuba's convention: with paths traced from the camera
//!   the cosine is that of the light's direction, as the rendering equation wants. f itself is
//!   reciprocal (f(wi, wo) = f(wo, wi)): every lobe below is symmetric in wi and wo.
//! - One-sided, like Mitsuba's principled without transmission: 0 unless wi.z > 0 and wo.z > 0.
//!
//! # The model (value = f · cos θo), h = normalize(wi + wo), cos θd = wi·h = wo·h
//! - specular: F · D(h) · G(wi, wo, h) / (4 cos θi), with anisotropic GGX `D` and separable
//!   Smith `G` = G1(wi) G1(wo) ([`ggx`]; Mitsuba's `MicrofacetDistribution::G`), and the
//!   principled Fresnel blend (Mitsuba's `principled_fresnel`)
//!   F = (1 − metallic)(1 − spec_tint) F_dielectric(cos θd, η(specular))
//!   \+ metallic · Schlick(base_color, cos θd)
//!   \+ (1 − metallic) spec_tint · Schlick(0.08 specular, cos θd),
//!   where F_dielectric is the *exact* dielectric Fresnel with η = 2/(1 − √(0.08 specular)) − 1,
//!   i.e. F0 = 0.08 · specular, as Mitsuba does ([`fresnel`]).
//! - diffuse with retro-reflection (Burley 2015, Mitsuba's split form): (1 − metallic) ·
//!   base_color/π · (f_diff + f_retro) · cos θo, with F_L = (1 − cos θ)⁵ per direction,
//!   f_diff = (1 − F_i/2)(1 − F_o/2), R_R = 2 · roughness · cos²θd,
//!   f_retro = R_R (F_o + F_i + F_o F_i (R_R − 1)).
//! - sheen: sheen · (1 − metallic) · (1 − cos θd)⁵ · cos θo (no 1/π, as Burley and Mitsuba).
//! - clearcoat: clearcoat/4 · Schlick(0.04, cos θd) · D_GTR1(h) · G1(wi) G1(wo)|_{α = 0.25} · cos θo,
//!   with α_GTR1 = lerp(0.1, 0.001, clearcoat_gloss) ([`gtr1`]). This is Mitsuba's formula; it
//!   lacks the 1/(4 cos θi cos θo) of a microfacet lobe that Burley's reference code carries
//!   inside its G, so Mitsuba's coat is Disney's times 4 cos θi cos θo (4× at normal incidence
//!   and exitance, dimmer towards grazing).
//!
//! # Sampling (Mitsuba's, with its default sampling rates of 1)
//! A lobe is chosen with probabilities ∝ (1 − metallic) : clearcoat/4 : 1 for the cosine
//! hemisphere, the GTR1 normals and the GGX visible normals (Heitz 2018), in that order along
//! `u_lobe`; the returned density is the whole mixture's (one-sample MIS), and weight =
//! [`eval`] / [`pdf`].
//!
//! # Differences from Mitsuba, on purpose
//! - No `m_has_*` switches: every lobe is always evaluated, so no parameter's derivative
//!   vanishes because it sits at exactly 0 (DESIGN.md). With plain `f32` (no derivatives) a lobe
//!   whose weight is exactly 0 is skipped, which changes nothing but time.
//! - Mitsuba drops the whole specular lobe, metallic part included, when `specular` is exactly 0
//!   (η = 1 makes F_dielectric = 0 and its mask `F_spec_dielectric > 0` fails) until a parameter
//!   update nudges specular to 1e-3. Here specular = 0 only zeroes the dielectric Fresnel, which
//!   is evaluated in a form that stays accurate, with a finite derivative, down to 0.
//! - cos θd is the mean of wi·h and wo·h (equal in exact arithmetic), so every term is
//!   symmetric in wi and wo and reciprocity holds to f32 rounding.
//! - Monochrome: see [`PrincipledParams`] for what becomes of `spec_tint` and `sheen_tint`.

mod frame;
pub mod fresnel;
pub mod ggx;
pub mod gtr1;
mod params;
pub mod warp;

#[cfg(test)]
mod tests;

pub use frame::ShadingFrame;
pub use ggx::Ggx;
pub use gtr1::Gtr1;
pub use params::{BsdfScalar, InvalidParameter, PARAMETER_COUNT, PrincipledParams};

use glam::Vec3;
use std::f32::consts::FRAC_1_PI;

/// Width of the clearcoat's Smith masking, fixed by Burley and Mitsuba.
const CLEARCOAT_MASKING_ALPHA: f32 = 0.25;
/// Normal-incidence reflectance of the clearcoat (IOR 1.5).
const CLEARCOAT_F0: f32 = 0.04;

/// Which lobe [`sample`] drew a direction from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampledLobe {
    /// Cosine-weighted hemisphere (diffuse, retro-reflection, sheen).
    Diffuse,
    /// GTR1 normals (clearcoat).
    Clearcoat,
    /// GGX visible normals (main specular).
    Specular,
}

/// A direction drawn by [`sample`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// The sampled direction in the local frame, above the horizon (wo.z > 0).
    pub wo: Vec3,
    /// The mixture's density of `wo`, per steradian.
    pub pdf: f32,
    /// eval(wi, wo) / pdf: the path throughput factor (f · cos θo / pdf).
    pub weight: f32,
    /// The lobe that proposed `wo` (the weight does not depend on it).
    pub lobe: SampledLobe,
}

/// f(wi, wo) · cos θo: the principled BSDF times the cosine of `wo`, 0 unless both directions
/// are above the horizon. Local frame; see the module doc for conventions and formulas.
#[inline]
pub fn eval<T: BsdfScalar>(p: &PrincipledParams<T>, wi: Vec3, wo: Vec3) -> T {
    evaluate::<T, true, false>(p, wi, wo).0
}

/// The density (per steradian) with which [`sample`] proposes `wo` given `wi`.
#[inline]
pub fn pdf<T: BsdfScalar>(p: &PrincipledParams<T>, wi: Vec3, wo: Vec3) -> T {
    evaluate::<T, false, true>(p, wi, wo).1
}

/// ([`eval`], [`pdf`]) in one pass, sharing the microfacet terms (for MIS).
#[inline]
pub fn eval_and_pdf<T: BsdfScalar>(p: &PrincipledParams<T>, wi: Vec3, wo: Vec3) -> (T, T) {
    evaluate::<T, true, true>(p, wi, wo)
}

/// Draws `wo` given `wi` (wi.z > 0) from the lobe mixture, with `u_lobe` choosing the lobe and
/// `u` driving the lobe's warp (all uniform in [0, 1)). `None` when wi is below the horizon or
/// the proposal falls below it (a GGX or GTR1 reflection can): the path ends there, as a zero
/// weight would end it in Mitsuba.
#[inline]
pub fn sample(p: &PrincipledParams<f32>, wi: Vec3, u_lobe: f32, u: [f32; 2]) -> Option<BsdfSample> {
    if !is_positive(wi.z) {
        return None;
    }
    let weights = LobeWeights::new(p);
    let (wo, lobe) = if u_lobe < weights.diffuse {
        (warp::square_to_cosine_hemisphere(u), SampledLobe::Diffuse)
    } else {
        let (m, lobe) = if u_lobe < weights.diffuse + weights.clearcoat {
            let m = Gtr1::from_clearcoat_gloss(p.clearcoat_gloss).sample(u);
            (m, SampledLobe::Clearcoat)
        } else {
            let m = Ggx::from_roughness(p.roughness, p.anisotropic).sample_visible_normal(wi, u);
            (m, SampledLobe::Specular)
        };
        let cos_im = wi.dot(m);
        if !is_positive(cos_im) {
            return None;
        }
        (m * (2.0 * cos_im) - wi, lobe)
    };
    if !is_positive(wo.z) {
        return None;
    }
    let (value, pdf) = evaluate::<f32, true, true>(p, wi, wo);
    if !is_positive(pdf) {
        return None;
    }
    Some(BsdfSample {
        wo,
        pdf,
        weight: value / pdf,
        lobe,
    })
}

/// `x > 0`, false for NaN: the guard for directions and densities.
#[inline(always)]
pub(crate) fn is_positive(x: f32) -> bool {
    x > 0.0
}

/// Lobe selection probabilities, Mitsuba's `prob_*` normalised: (1 − metallic) : clearcoat/4 : 1.
struct LobeWeights<T> {
    diffuse: T,
    clearcoat: T,
    specular: T,
}

impl<T: BsdfScalar> LobeWeights<T> {
    #[inline]
    fn new(p: &PrincipledParams<T>) -> Self {
        let diffuse = -p.metallic + 1.0;
        let clearcoat = p.clearcoat * 0.25;
        let inv_total = (diffuse + clearcoat + 1.0).recip();
        Self {
            diffuse: diffuse * inv_total,
            clearcoat: clearcoat * inv_total,
            specular: inv_total,
        }
    }
}

/// Whether a lobe with weight `w` must be evaluated: always with derivatives (its derivative is
/// not 0 even when its value is), otherwise only if its weight is not exactly 0.
#[inline(always)]
fn lobe_is_live<T: BsdfScalar>(w: T) -> bool {
    T::NDERIV > 0 || w.re() != 0.0
}

/// The shared evaluation behind [`eval`], [`pdf`] and [`sample`]; the const flags let the
/// compiler drop what the caller does not need.
#[inline(always)]
fn evaluate<T: BsdfScalar, const VALUE: bool, const PDF: bool>(
    p: &PrincipledParams<T>,
    wi: Vec3,
    wo: Vec3,
) -> (T, T) {
    let zero = T::from(0.0);
    let (cos_i, cos_o) = (wi.z, wo.z);
    if !(is_positive(cos_i) && is_positive(cos_o)) {
        return (zero, zero);
    }
    // Both above the horizon: wi + wo ≠ 0 and h is above it too.
    let h = (wi + wo).normalize();
    let cos_d = (0.5 * (wi.dot(h) + wo.dot(h))).min(1.0);
    let dielectric = -p.metallic + 1.0;

    let ggx = Ggx::from_roughness(p.roughness, p.anisotropic);
    let d = ggx.d(h);
    let g1_i = ggx.smith_g1(wi, h);
    let coat_live = lobe_is_live(p.clearcoat);
    let coat_d = if coat_live {
        Gtr1::from_clearcoat_gloss(p.clearcoat_gloss).d(h)
    } else {
        zero
    };

    let mut value = zero;
    if VALUE {
        // Main specular.
        let f_spec = fresnel::dielectric_from_specular(p.specular, cos_d)
            * dielectric
            * (-p.spec_tint + 1.0)
            + fresnel::schlick(p.base_color, cos_d) * p.metallic
            + fresnel::schlick(p.specular * fresnel::F0_PER_SPECULAR, cos_d)
                * dielectric
                * p.spec_tint;
        let g1_o = ggx.smith_g1(wo, h);
        value = f_spec * d * g1_i * g1_o * (0.25 / cos_i);

        // Diffuse with retro-reflection.
        let (f_i, f_o) = (
            fresnel::schlick_weight(cos_i),
            fresnel::schlick_weight(cos_o),
        );
        let f_diff = (1.0 - 0.5 * f_i) * (1.0 - 0.5 * f_o);
        let retro = p.roughness * (2.0 * cos_d * cos_d);
        let f_retro = retro * ((retro - 1.0) * (f_o * f_i) + (f_o + f_i));
        value += dielectric * p.base_color * (f_retro + f_diff) * (cos_o * FRAC_1_PI);

        // Sheen (its tint is 1 in monochrome).
        if lobe_is_live(p.sheen) {
            value += p.sheen * dielectric * (fresnel::schlick_weight(cos_d) * cos_o);
        }

        // Clearcoat.
        if coat_live {
            let coat_masking = Ggx {
                alpha_x: CLEARCOAT_MASKING_ALPHA,
                alpha_y: CLEARCOAT_MASKING_ALPHA,
            }
            .smith_g(wi, wo, h);
            let coat_fresnel = fresnel::schlick(CLEARCOAT_F0, cos_d);
            value += p.clearcoat * coat_d * (0.25 * coat_fresnel * coat_masking * cos_o);
        }
    }

    let mut density = zero;
    if PDF {
        let weights = LobeWeights::new(p);
        // GGX visible normals: D_wi(h) / (4 wo·h) = D G1(wi) (wi·h) / cos θi / (4 wo·h),
        // and wi·h = wo·h for a reflection.
        density =
            weights.specular * d * g1_i * (0.25 / cos_i) + weights.diffuse * (cos_o * FRAC_1_PI);
        if coat_live {
            density += weights.clearcoat * coat_d * (h.z * 0.25 / cos_d);
        }
    }
    (value, density)
}
