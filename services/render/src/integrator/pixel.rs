//! Per-pixel estimators, generic over the BSDF scalar so that dual-number materials give the
//! BSDF fit its derivatives: one shading code path for the camera and the fit.

use rand::SeedableRng;

use super::camera::{camera_ray, pixel_sample_ray};
use super::path::trace;
use super::{Camera, PixelRendering};
use crate::bsdf::{self, BsdfScalar, PrincipledParams, ShadingFrame};
use crate::projector::Projector;
use crate::scene::{Hit, RAY_EPSILON_M, Scene};

/// The projector's direct light reflected at `hit` towards `towards_previous` (local frame): the
/// point emitter's intensity / d² times f·cos θ (the rendering equation's integrand for a point
/// light), 0 where the projector does not light the point, is below the horizon or is shadowed.
/// Returns the radiance and the shadow rays traced (0 or 1).
///
/// This is *the* shading of both integrators, generic over the BSDF scalar: with `f32` for
/// rendering and with dual numbers for the BSDF fit, so that fit and camera share one code path.
#[inline]
pub fn direct_light<T: BsdfScalar>(
    scene: &Scene,
    projector: &Projector,
    hit: &Hit,
    frame: &ShadingFrame,
    towards_previous: glam::Vec3,
    material: &PrincipledParams<T>,
) -> (T, u64) {
    let zero = T::from(0.0);
    let Some(light) = projector.illuminate(hit.point) else {
        return (zero, 0);
    };
    let towards_light = frame.to_local(light.direction.into());
    if towards_light.z <= 0.0 {
        return (zero, 0);
    }
    let lifted = hit.point + hit.normal * RAY_EPSILON_M;
    if scene.occluded(
        lifted,
        light.direction,
        light.distance_m - 2.0 * RAY_EPSILON_M,
    ) {
        return (zero, 1);
    }
    let f_cos = bsdf::eval(material, towards_previous, towards_light);
    (
        f_cos * (light.intensity_w_per_sr / (light.distance_m * light.distance_m)),
        1,
    )
}

/// What one single-path camera ray sees (the paper's I_single): the first surface lit directly
/// by the projector.
#[derive(Clone, Copy, Debug)]
pub struct SinglePathSample<T> {
    /// Radiance, W·sr⁻¹·m⁻².
    pub radiance: T,
    /// Scene index of the instance hit.
    pub instance: u32,
    /// Depth z of the hit in the camera frame, metres.
    pub depth_m: f32,
}

/// The single-path radiance through the centre of pixel (u, v), shading the hit with
/// `material(instance)` instead of the scene's own material: the same ray generation,
/// intersection and [`direct_light`] as [`super::render`] with [`super::LightTransport::SinglePath`] (which
/// gives the same value for `material = |i| scene material`), generic so that the BSDF fit gets
/// exact derivatives from dual-number materials. `None` where the ray hits nothing.
pub fn single_path_pixel<T: BsdfScalar>(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    u: u32,
    v: u32,
    material: impl Fn(u32) -> PrincipledParams<T>,
) -> Option<SinglePathSample<T>> {
    let (rotation, origin) = camera.rotation_and_origin();
    let (d_c, direction) = camera_ray(
        &camera.intrinsics,
        &rotation,
        u as f32 + 0.5,
        v as f32 + 0.5,
    );
    let hit = scene.intersect(origin, direction, f32::INFINITY)?;
    let frame = ShadingFrame::from_normal(hit.normal.into());
    let towards_previous = frame.to_local((-direction).into());
    let (radiance, _) = direct_light(
        scene,
        projector,
        &hit,
        &frame,
        towards_previous,
        &material(hit.instance),
    );
    Some(SinglePathSample {
        radiance,
        instance: hit.instance,
        depth_m: hit.t * d_c.z,
    })
}

/// The radiance through pixel (u, v) rendered as `rendering` says (`samples_per_pixel`
/// samples, the first through the centre, the rest jittered; the pixel's own RNG stream from
/// `seed`), shading each hit with `material(instance)`: the estimator of [`super::render`],
/// generic so that dual-number materials give derivatives (see `trace` for the detached
/// sampling density). `instance` and `depth_m` are the centre ray's; `None` if the centre ray
/// hits nothing.
pub fn path_pixel<T: BsdfScalar>(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    (u, v): (u32, u32),
    rendering: &PixelRendering,
    material: impl Fn(u32) -> PrincipledParams<T>,
) -> Option<SinglePathSample<T>> {
    path_pixel_frozen_sampling(scene, camera, projector, (u, v), rendering, material, None)
}

/// [`path_pixel`] with the sampling frozen when `sampling` is given: every random decision of
/// the path (BSDF lobe and direction, Russian roulette) is made with `sampling(instance)`,
/// while the hits are shaded with `material(instance)` (throughput f(material)·cos /
/// pdf(sampling)). For the same seed and `sampling`, the paths are then identical whatever
/// `material` is, so the estimate is a smooth function of `material` whose derivative is
/// exactly what dual-number materials with real part `sampling` compute: the basis of a
/// finite-difference check of the multi-path gradient. With `sampling = material` this is
/// [`path_pixel`] (up to f32 rounding); with `None` it is [`path_pixel`].
pub fn path_pixel_frozen_sampling<T: BsdfScalar>(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    (u, v): (u32, u32),
    rendering: &PixelRendering,
    material: impl Fn(u32) -> PrincipledParams<T>,
    sampling: Option<&dyn Fn(u32) -> PrincipledParams<f32>>,
) -> Option<SinglePathSample<T>> {
    let (rotation, origin) = camera.rotation_and_origin();
    let pixel = v as u64 * camera.intrinsics.width_px as u64 + u as u64;
    let mut rng =
        rand_pcg::Pcg32::seed_from_u64(rendering.seed ^ pixel.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let spp = rendering.samples_per_pixel.max(1);
    let mut sum = T::from(0.0);
    let mut centre = None;
    for s in 0..spp {
        let (d_c, direction) = pixel_sample_ray(&camera.intrinsics, &rotation, (u, v), s, &mut rng);
        let path = trace(
            scene,
            projector,
            origin,
            direction,
            rendering.transport,
            &mut rng,
            &material,
            sampling,
            &mut |_, _| {},
        );
        if s == 0 {
            centre = path.first_hit.map(|(t, instance)| (t * d_c.z, instance));
        }
        sum += path.radiance;
    }
    let (depth_m, instance) = centre?;
    Some(SinglePathSample {
        radiance: sum * (spp as f32).recip(),
        instance,
        depth_m,
    })
}
