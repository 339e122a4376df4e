//! The path tracer every integrator shares: next-event estimation towards the projector at
//! every vertex, BSDF importance sampling between vertices, Russian roulette.

use glam::Vec3A;
use rand::Rng;

use super::LightTransport;
use super::pixel::direct_light;
use crate::bsdf::{self, BsdfScalar, PrincipledParams, ShadingFrame};
use crate::projector::Projector;
use crate::scene::{RAY_EPSILON_M, Scene};

pub(super) struct PathResult<T> {
    pub(super) radiance: T,
    /// The first vertex's next-event term alone: what the single-path transport estimates
    /// from the same camera ray (the paper's I_single), a part of `radiance`.
    pub(super) single_path_radiance: T,
    /// Distance along the camera ray and instance of the first hit.
    pub(super) first_hit: Option<(f32, u32)>,
    pub(super) rays: u64,
}

/// One camera path.
///
/// Generic over the BSDF scalar, with `material(instance)` shading each hit: directions are
/// sampled from the real parts of the materials and the throughput is f·cos / pdf with the pdf
/// held constant, so with dual numbers the derivative of the estimate is an unbiased estimate of
/// the radiance's derivative (the sampling density is detached, as in differentiable path
/// tracers). With `f32` the throughput factor is the sample's own weight, as always.
/// `sampling`, when given, replaces the real part of the material in every random decision
/// (see [`super::path_pixel_frozen_sampling`]); Russian roulette always uses the sampling side's
/// throughput, so it is detached like the density. `on_direct(point, contribution)` sees every
/// vertex's next-event term (throughput × direct light) as it is added; no random decision
/// depends on the projector's pattern, so the same seed traces the same paths under any pattern.
#[inline]
#[allow(clippy::too_many_arguments)]
pub(super) fn trace<T: BsdfScalar>(
    scene: &Scene,
    projector: &Projector,
    origin: Vec3A,
    direction: Vec3A,
    transport: LightTransport,
    rng: &mut impl Rng,
    material: &impl Fn(u32) -> PrincipledParams<T>,
    sampling: Option<&dyn Fn(u32) -> PrincipledParams<f32>>,
    on_direct: &mut impl FnMut(Vec3A, T),
) -> PathResult<T> {
    let (max_bounces, roulette_after, min_indirect_roughness) = match transport {
        LightTransport::SinglePath => (1, u32::MAX, 0.0),
        LightTransport::MultiPath {
            max_bounces,
            roulette_after,
            min_indirect_roughness,
        } => (max_bounces.max(1), roulette_after, min_indirect_roughness),
    };
    let mut result = PathResult {
        radiance: T::from(0.0),
        single_path_radiance: T::from(0.0),
        first_hit: None,
        rays: 0,
    };
    let mut throughput = T::from(1.0);
    // The throughput of the sampling material alone (equal to `throughput.re()` unless the
    // sampling is frozen): what Russian roulette looks at.
    let mut sampled_throughput = 1.0f32;
    let (mut origin, mut direction) = (origin, direction);
    for bounce in 0..max_bounces {
        result.rays += 1;
        let Some(hit) = scene.intersect(origin, direction, f32::INFINITY) else {
            break;
        };
        if bounce == 0 {
            result.first_hit = Some((hit.t, hit.instance));
        }
        let mut material = material(hit.instance);
        if bounce > 0 && material.roughness.re() < min_indirect_roughness {
            // Regularised vertex: a constant roughness, so no derivative flows through it.
            material.roughness = T::from(min_indirect_roughness);
        }
        let frame = ShadingFrame::from_normal(hit.normal.into());
        let towards_previous = frame.to_local((-direction).into());
        let lifted = hit.point + hit.normal * RAY_EPSILON_M;

        // Next-event estimation: the projector is a point, so this is its only contribution.
        let (direct, shadow_rays) =
            direct_light(scene, projector, &hit, &frame, towards_previous, &material);
        result.rays += shadow_rays;
        let contribution = throughput * direct;
        on_direct(hit.point, contribution);
        if bounce == 0 {
            result.single_path_radiance = contribution;
        }
        result.radiance += contribution;
        if bounce + 1 == max_bounces {
            break;
        }
        let sampling_material = match sampling {
            None => material.re(),
            Some(frozen) => {
                // Regularised like the shaded material.
                let mut m = frozen(hit.instance);
                if bounce > 0 {
                    m.roughness = m.roughness.max(min_indirect_roughness);
                }
                m
            }
        };
        let Some(sample) = bsdf::sample(
            &sampling_material,
            towards_previous,
            rng.random(),
            [rng.random(), rng.random()],
        ) else {
            break;
        };
        throughput *= if T::NDERIV == 0 && sampling.is_none() {
            T::from(sample.weight)
        } else {
            bsdf::eval(&material, towards_previous, sample.wo) * sample.pdf.recip()
        };
        sampled_throughput *= sample.weight;
        if bounce + 1 >= roulette_after {
            let survive = sampled_throughput.min(0.95);
            if survive <= 0.0 || rng.random::<f32>() >= survive {
                break;
            }
            throughput *= survive.recip();
            sampled_throughput *= survive.recip();
        }
        if !(throughput.re() > 0.0 && throughput.re().is_finite()) {
            break;
        }
        direction = Vec3A::from(frame.to_world(sample.wo));
        origin = if sample.wo.z > 0.0 {
            lifted
        } else {
            hit.point - hit.normal * RAY_EPSILON_M
        };
    }
    result
}
