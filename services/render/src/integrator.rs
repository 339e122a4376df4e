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

use glam::Vec3A;
use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::{Image, PixelRect};
use nalgebra::{Isometry3, Vector3};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use crate::bsdf::{self, BsdfScalar, PrincipledParams, ShadingFrame};
use crate::projector::Projector;
use crate::scene::{Hit, RAY_EPSILON_M, Scene};

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

/// What a render produces, all full-size images (pixels outside the ROI untouched).
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Mean radiance per pixel, W·sr⁻¹·m⁻².
    pub radiance: Image<f32>,
    /// Depth z of the first surface through the pixel centre, metres; NaN where nothing is hit.
    pub depth_m: Image<f32>,
    /// Label of the instance hit through the pixel centre; 0 where nothing is hit.
    pub label: Image<u16>,
    /// Rays traced (camera, shadow and bounce rays), for throughput figures.
    pub rays_traced: u64,
}

/// A camera placed in the world.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    /// Pinhole intrinsics (focal lengths and principal point in px, image size).
    pub intrinsics: PinholeIntrinsics,
    /// Camera → world.
    pub t_w_c: Isometry3<f64>,
}

impl Camera {
    /// R_w_c and the camera centre in the world, in the renderer's f32.
    fn rotation_and_origin(&self) -> (nalgebra::Matrix3<f32>, Vec3A) {
        let rotation = self
            .t_w_c
            .rotation
            .to_rotation_matrix()
            .matrix()
            .cast::<f32>();
        let origin = self.t_w_c.translation.vector.cast::<f32>();
        (rotation, Vec3A::new(origin.x, origin.y, origin.z))
    }
}

/// Renders what `camera` sees of `scene` under `projector`.
///
/// # Panics
/// When the camera's intrinsics have a zero side (see [`PinholeIntrinsics::new`]).
pub fn render(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    settings: &RenderSettings,
) -> RenderOutput {
    let mut sinks = vec![(); camera.intrinsics.height_px as usize];
    render_with_sinks(scene, camera, projector, settings, &mut sinks)
}

/// Receives every next-event contribution of a render, one sink per image row: what
/// [`crate::pattern_record`] records to evaluate other projector patterns without tracing again.
pub(crate) trait DirectSink: Send {
    /// Column `u` of the sink's row received `radiance` (the path throughput × the projector's
    /// direct light, W·sr⁻¹·m⁻², not yet divided by the samples per pixel) from the surface
    /// point `point_w` (world). Called in the order the samples are traced.
    fn direct(&mut self, u: u32, point_w: Vec3A, radiance: f32);
}

impl DirectSink for () {
    #[inline]
    fn direct(&mut self, _: u32, _: Vec3A, _: f32) {}
}

/// [`render`], handing every next-event contribution of row v to `sinks[v]` (`sinks` has one
/// entry per image row; rows without one are not rendered).
pub(crate) fn render_with_sinks<S: DirectSink>(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    settings: &RenderSettings,
    sinks: &mut [S],
) -> RenderOutput {
    let k = &camera.intrinsics;
    let (w, h) = (k.width_px, k.height_px);
    let roi = settings
        .roi
        .and_then(|r| r.clipped_to(w, h))
        .unwrap_or(PixelRect::full(w, h));
    let mut radiance = camera_image(k, 0f32);
    let mut depth = Image::filled_like(&radiance, f32::NAN);
    let mut label = Image::filled_like(&radiance, 0u16);
    let (rotation, origin) = camera.rotation_and_origin();
    let spp = settings.samples_per_pixel.max(1);
    let rows = radiance
        .data_mut()
        .par_chunks_mut(w as usize)
        .zip(depth.data_mut().par_chunks_mut(w as usize))
        .zip(label.data_mut().par_chunks_mut(w as usize))
        .zip(sinks.par_iter_mut());
    let rays_traced: u64 = rows
        .enumerate()
        .filter(|(v, _)| (roi.v_min..roi.v_min + roi.height).contains(&(*v as u32)))
        .map(|(v, (((radiance_row, depth_row), label_row), sink))| {
            let mut rng = rand_pcg::Pcg32::seed_from_u64(
                settings.seed ^ (v as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            let mut rays = 0u64;
            for u in roi.u_min..roi.u_min + roi.width {
                let mut sum = 0.0f32;
                for s in 0..spp {
                    let (ju, jv) = if s == 0 {
                        (0.5, 0.5)
                    } else {
                        (rng.random::<f32>(), rng.random::<f32>())
                    };
                    let (d_c, direction) = camera_ray(k, &rotation, u as f32 + ju, v as f32 + jv);
                    let path = trace(
                        scene,
                        projector,
                        origin,
                        direction,
                        settings.transport,
                        &mut rng,
                        &|i| *scene.material_of(i),
                        None,
                        &mut |point, radiance| sink.direct(u, point, radiance),
                    );
                    rays += path.rays;
                    sum += path.radiance;
                    if s == 0
                        && let Some((t, instance)) = path.first_hit
                    {
                        depth_row[u as usize] = t * d_c.z; // ray length → z
                        label_row[u as usize] = scene.instances()[instance as usize].label;
                    }
                }
                radiance_row[u as usize] = sum / spp as f32;
            }
            rays
        })
        .sum();
    RenderOutput {
        radiance,
        depth_m: depth,
        label,
        rays_traced,
    }
}

/// A blank image of the camera's size, every pixel `value`.
///
/// # Panics
/// When `k` has a zero side, which no constructor of [`PinholeIntrinsics`] (`new`, `resized`,
/// `cropped`) nor Glint's rig and camera readers let through: only a hand-built value can.
fn camera_image<T: Copy>(k: &PinholeIntrinsics, value: T) -> Image<T> {
    // A zero side breaks the invariant every `PinholeIntrinsics` constructor checks; a render
    // has no image to return for it (`par_chunks_mut(0)` would panic too).
    #[allow(clippy::expect_used)]
    Image::filled(k.width_px, k.height_px, value).expect("intrinsics have non-zero sides")
}

/// The camera ray through continuous pixel coordinates (u, v) (pixel centres at +0.5): its unit
/// direction in the camera frame and in the world (`rotation` = R_w_c).
#[inline]
fn camera_ray(
    k: &PinholeIntrinsics,
    rotation: &nalgebra::Matrix3<f32>,
    u: f32,
    v: f32,
) -> (Vector3<f32>, Vec3A) {
    let x = (u - k.cx_px as f32) / k.fx_px as f32;
    let y = (v - k.cy_px as f32) / k.fy_px as f32;
    let d_c = Vector3::new(x, y, 1.0).normalize();
    let d_w = rotation * d_c;
    (d_c, Vec3A::new(d_w.x, d_w.y, d_w.z))
}

/// The label of the first surface through each pixel centre (0 where nothing is hit): primary
/// rays only, no shading. With `only_instance`, every other instance is transparent, which
/// gives that instance's whole (amodal) silhouette. Pixels outside `roi` stay 0.
///
/// # Panics
/// When the camera's intrinsics have a zero side (see [`PinholeIntrinsics::new`]).
pub fn render_labels(
    scene: &Scene,
    camera: &Camera,
    roi: Option<PixelRect>,
    only_instance: Option<u32>,
) -> Image<u16> {
    let k = &camera.intrinsics;
    let (w, h) = (k.width_px, k.height_px);
    let mut label = camera_image(k, 0u16);
    let Some(roi) = roi.map_or(Some(PixelRect::full(w, h)), |r| r.clipped_to(w, h)) else {
        return label;
    };
    let (rotation, origin) = camera.rotation_and_origin();
    label
        .data_mut()
        .par_chunks_mut(w as usize)
        .enumerate()
        .filter(|(v, _)| (roi.v_min..roi.v_min + roi.height).contains(&(*v as u32)))
        .for_each(|(v, row)| {
            for u in roi.u_min..roi.u_min + roi.width {
                let (_, direction) = camera_ray(k, &rotation, u as f32 + 0.5, v as f32 + 0.5);
                let hit = match only_instance {
                    None => scene.intersect(origin, direction, f32::INFINITY),
                    Some(i) => scene.intersect_instance(origin, direction, f32::INFINITY, i),
                };
                if let Some(hit) = hit {
                    row[u as usize] = scene.instances()[hit.instance as usize].label;
                }
            }
        });
    label
}

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
/// intersection and [`direct_light`] as [`render`] with [`LightTransport::SinglePath`] (which
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

struct PathResult<T> {
    radiance: T,
    /// Distance along the camera ray and instance of the first hit.
    first_hit: Option<(f32, u32)>,
    rays: u64,
}

/// The radiance through pixel (u, v) with `transport` and `samples_per_pixel` (the first
/// through the centre, the rest jittered; the pixel's own RNG stream from `seed`), shading each
/// hit with `material(instance)`: the estimator of [`render`], generic so that dual-number
/// materials give derivatives (see `trace` for the detached sampling density). `instance` and
/// `depth_m` are the centre ray's; `None` if the centre ray hits nothing.
#[allow(clippy::too_many_arguments)]
pub fn path_pixel<T: BsdfScalar>(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    u: u32,
    v: u32,
    transport: LightTransport,
    samples_per_pixel: u32,
    seed: u64,
    material: impl Fn(u32) -> PrincipledParams<T>,
) -> Option<SinglePathSample<T>> {
    path_pixel_frozen_sampling(
        scene,
        camera,
        projector,
        (u, v),
        transport,
        samples_per_pixel,
        seed,
        material,
        None,
    )
}

/// [`path_pixel`] with the sampling frozen when `sampling` is given: every random decision of
/// the path (BSDF lobe and direction, Russian roulette) is made with `sampling(instance)`,
/// while the hits are shaded with `material(instance)` (throughput f(material)·cos /
/// pdf(sampling)). For the same seed and `sampling`, the paths are then identical whatever
/// `material` is, so the estimate is a smooth function of `material` whose derivative is
/// exactly what dual-number materials with real part `sampling` compute: the basis of a
/// finite-difference check of the multi-path gradient. With `sampling = material` this is
/// [`path_pixel`] (up to f32 rounding); with `None` it is [`path_pixel`].
#[allow(clippy::too_many_arguments)]
pub fn path_pixel_frozen_sampling<T: BsdfScalar>(
    scene: &Scene,
    camera: &Camera,
    projector: &Projector,
    (u, v): (u32, u32),
    transport: LightTransport,
    samples_per_pixel: u32,
    seed: u64,
    material: impl Fn(u32) -> PrincipledParams<T>,
    sampling: Option<&dyn Fn(u32) -> PrincipledParams<f32>>,
) -> Option<SinglePathSample<T>> {
    let (rotation, origin) = camera.rotation_and_origin();
    let pixel = v as u64 * camera.intrinsics.width_px as u64 + u as u64;
    let mut rng = rand_pcg::Pcg32::seed_from_u64(seed ^ pixel.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let spp = samples_per_pixel.max(1);
    let mut sum = T::from(0.0);
    let mut centre = None;
    for s in 0..spp {
        let (ju, jv) = if s == 0 {
            (0.5, 0.5)
        } else {
            (rng.random::<f32>(), rng.random::<f32>())
        };
        let (d_c, direction) =
            camera_ray(&camera.intrinsics, &rotation, u as f32 + ju, v as f32 + jv);
        let path = trace(
            scene,
            projector,
            origin,
            direction,
            transport,
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

/// One camera path.
#[inline]
///
/// Generic over the BSDF scalar, with `material(instance)` shading each hit: directions are
/// sampled from the real parts of the materials and the throughput is f·cos / pdf with the pdf
/// held constant, so with dual numbers the derivative of the estimate is an unbiased estimate of
/// the radiance's derivative (the sampling density is detached, as in differentiable path
/// tracers). With `f32` the throughput factor is the sample's own weight, as always.
/// `sampling`, when given, replaces the real part of the material in every random decision
/// (see [`path_pixel_frozen_sampling`]); Russian roulette always uses the sampling side's
/// throughput, so it is detached like the density. `on_direct(point, contribution)` sees every
/// vertex's next-event term (throughput × direct light) as it is added; no random decision
/// depends on the projector's pattern, so the same seed traces the same paths under any pattern.
#[allow(clippy::too_many_arguments)]
fn trace<T: BsdfScalar>(
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::projector::Pattern;
    use crate::scene::SceneInstance;
    use glint_geometry::TriMesh;
    use nalgebra::{Point3, Translation3, UnitQuaternion};

    /// A square of half-size `half_m` in the z = 0 plane, facing +z.
    fn square(half_m: f32) -> TriMesh {
        let h = half_m;
        TriMesh::new(
            vec![
                Point3::new(-h, -h, 0.0),
                Point3::new(h, -h, 0.0),
                Point3::new(h, h, 0.0),
                Point3::new(-h, h, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    fn small_camera() -> Camera {
        Camera {
            intrinsics: PinholeIntrinsics::ensenso_n35().resized(160, 128).unwrap(),
            t_w_c: Isometry3::identity(),
        }
    }

    fn projector_at(x_m: f64) -> Projector {
        Projector {
            t_w_p: Isometry3::translation(x_m, 0.0, 0.0),
            intrinsics: PinholeIntrinsics::ensenso_n35().resized(64, 64).unwrap(),
            pattern: Pattern::White,
            intensity_w_per_sr: 1.0,
        }
    }

    /// A diffuse principled material: no specular lobe, roughness 1.
    fn diffuse(albedo: f32) -> PrincipledParams<f32> {
        PrincipledParams::new(albedo, 0.0, 1.0, 0.0).unwrap()
    }

    /// The plane z = 0.6 m in front of the camera, facing it.
    fn plane_scene(material: PrincipledParams<f32>) -> Scene {
        let facing_camera =
            UnitQuaternion::from_axis_angle(&nalgebra::Vector3::x_axis(), std::f64::consts::PI);
        let instance = SceneInstance {
            mesh: 0,
            t_w_o: Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.6), facing_camera),
            material: 0,
            label: 1,
        };
        Scene::build(&[square(1.0)], vec![instance], vec![material]).unwrap()
    }

    #[test]
    fn single_path_lambertian_plane_matches_analytic_radiance() {
        let albedo = 0.5;
        let scene = plane_scene(diffuse(albedo));
        let camera = small_camera();
        let projector = projector_at(0.05);
        let settings = RenderSettings {
            transport: LightTransport::SinglePath,
            samples_per_pixel: 1,
            roi: None,
            seed: 1,
        };
        let out = render(&scene, &camera, &projector, &settings);
        let k = &camera.intrinsics;
        let mut worst: f64 = 0.0;
        // Central pixels: camera and light within ~10° of the normal, where the principled
        // diffuse (Burley, with retro-reflection) is within 0.3 % of Lambert.
        for v in 44..84 {
            for u in 60..100 {
                let p = k.unproject(&PinholeIntrinsics::pixel_centre(u, v), 0.6);
                let to_light = nalgebra::Vector3::new(0.05, 0.0, 0.0) - p.coords;
                let r2 = to_light.norm_squared();
                let cos_light = 0.6 / r2.sqrt();
                let analytic = albedo as f64 / std::f64::consts::PI * cos_light / r2;
                let rendered = out.radiance.get(u, v).unwrap() as f64;
                worst = worst.max((rendered / analytic - 1.0).abs());
                assert!((out.depth_m.get(u, v).unwrap() - 0.6).abs() < 1e-5);
                assert_eq!(out.label.get(u, v), Some(1));
            }
        }
        assert!(worst < 0.01, "worst relative error {worst}");
    }

    #[test]
    fn single_path_pixel_is_the_renderers_single_path() {
        let (scene, camera, projector) = corner_scene();
        let settings = RenderSettings {
            transport: LightTransport::SinglePath,
            samples_per_pixel: 1,
            roi: None,
            seed: 1,
        };
        let out = render(&scene, &camera, &projector, &settings);
        let mut hits = 0;
        for v in (0..128).step_by(7) {
            for u in (0..160).step_by(7) {
                let own = |i: u32| *scene.material_of(i);
                match single_path_pixel(&scene, &camera, &projector, u, v, own) {
                    Some(s) => {
                        hits += 1;
                        assert_eq!(s.radiance, out.radiance.get(u, v).unwrap(), "({u}, {v})");
                        assert_eq!(s.depth_m, out.depth_m.get(u, v).unwrap());
                    }
                    None => assert!(out.depth_m.get(u, v).unwrap().is_nan()),
                }
            }
        }
        assert!(hits > 50, "{hits}");
        // With dual numbers the value is the same and the derivative is the BSDF's.
        let lift = |i: u32| scene.material_of(i).map(num_dual::Dual32::from_re);
        let s = single_path_pixel(&scene, &camera, &projector, 80, 64, lift).unwrap();
        assert_eq!(s.radiance.re, out.radiance.get(80, 64).unwrap());
    }

    #[test]
    fn path_pixel_estimates_what_render_estimates() {
        let (scene, camera, projector) = corner_scene();
        let transport = LightTransport::MULTI_PATH_DEFAULT;
        let roi = PixelRect {
            u_min: 48,
            v_min: 32,
            width: 64,
            height: 64,
        };
        let settings = RenderSettings {
            transport,
            samples_per_pixel: 16,
            roi: Some(roi),
            seed: 3,
        };
        let out = render(&scene, &camera, &projector, &settings);
        // Independent streams: per pixel the difference has mean 0 if both estimate the same
        // radiance. Its mean over 4096 pixels is within a few standard errors of 0; the paths'
        // throughputs (Russian roulette, glossy bounces) are heavy-tailed, so the bound is 6
        // standard errors rather than a Gaussian 4.
        let mut d = Vec::new();
        for v in roi.v_min..roi.v_min + roi.height {
            for u in roi.u_min..roi.u_min + roi.width {
                let own = |i: u32| *scene.material_of(i);
                let s = path_pixel(&scene, &camera, &projector, u, v, transport, 16, 9, own);
                let a = s.map_or(0.0, |s| s.radiance) as f64;
                d.push(a - out.radiance.get(u, v).unwrap() as f64);
            }
        }
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n;
        let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert!(
            mean.abs() < 6.0 * sd / n.sqrt(),
            "mean difference {mean}, sd {sd}"
        );
        // Single-path through path_pixel is single_path_pixel.
        let own = |i: u32| *scene.material_of(i);
        let a = path_pixel(
            &scene,
            &camera,
            &projector,
            80,
            64,
            LightTransport::SinglePath,
            1,
            0,
            own,
        );
        let b = single_path_pixel(&scene, &camera, &projector, 80, 64, own);
        assert_eq!(a.map(|s| s.radiance), b.map(|s| s.radiance));
    }

    #[test]
    fn shadows_block_the_projector() {
        // A small occluder between the projector and the plane casts a shadow on it.
        let scene_meshes = [square(1.0), square(0.01)];
        let facing_camera =
            UnitQuaternion::from_axis_angle(&nalgebra::Vector3::x_axis(), std::f64::consts::PI);
        let instances = vec![
            SceneInstance {
                mesh: 0,
                t_w_o: Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.6), facing_camera),
                material: 0,
                label: 1,
            },
            // Occluder at z = 0.3 on the projector's axis, off the camera's central ray.
            SceneInstance {
                mesh: 1,
                t_w_o: Isometry3::from_parts(Translation3::new(0.05, 0.0, 0.3), facing_camera),
                material: 0,
                label: 2,
            },
        ];
        let scene = Scene::build(&scene_meshes, instances, vec![diffuse(0.5)]).unwrap();
        let camera = small_camera();
        let projector = projector_at(0.05);
        let settings = RenderSettings {
            transport: LightTransport::SinglePath,
            samples_per_pixel: 1,
            roi: None,
            seed: 1,
        };
        let out = render(&scene, &camera, &projector, &settings);
        // The projector looks along +z from x = 5 cm, so the shadow centre is (0.05, 0, 0.6); the
        // camera's ray to it passes the occluder's plane at x = 2.5 cm, beside it.
        let shadow = camera
            .intrinsics
            .project(&Point3::new(0.05, 0.0, 0.6))
            .unwrap();
        assert_eq!(out.label.get(shadow.x as u32, shadow.y as u32), Some(1));
        assert_eq!(
            out.radiance.get(shadow.x as u32, shadow.y as u32),
            Some(0.0)
        );
        assert!(out.radiance.get(80, 64).unwrap() > 0.0);
    }

    /// A floor and a wall meeting at a right angle, seen from above at 45°: light reflected by
    /// the wall reaches the floor, so multi-path exceeds single-path near the corner.
    fn corner_scene() -> (Scene, Camera, Projector) {
        let floor = Isometry3::translation(0.0, 0.0, 0.0);
        let wall = Isometry3::from_parts(
            Translation3::new(0.0, 0.1, 0.1),
            UnitQuaternion::from_axis_angle(
                &nalgebra::Vector3::x_axis(),
                std::f64::consts::FRAC_PI_2,
            ),
        );
        let instances = vec![
            SceneInstance {
                mesh: 0,
                t_w_o: floor,
                material: 0,
                label: 1,
            },
            SceneInstance {
                mesh: 0,
                t_w_o: wall,
                material: 0,
                label: 2,
            },
        ];
        let scene = Scene::build(&[square(0.1)], instances, vec![diffuse(0.8)]).unwrap();
        let eye = Point3::new(0.0, -0.35, 0.45);
        let t_w_c =
            Isometry3::face_towards(&eye, &Point3::new(0.0, 0.05, 0.0), &-nalgebra::Vector3::z());
        let camera = Camera {
            intrinsics: small_camera().intrinsics,
            t_w_c,
        };
        let projector = Projector {
            t_w_p: t_w_c,
            ..projector_at(0.0)
        };
        (scene, camera, projector)
    }

    #[test]
    fn multi_path_adds_inter_reflections_and_its_variance_falls_as_one_over_n() {
        let (scene, camera, projector) = corner_scene();
        let roi = Some(PixelRect {
            u_min: 48,
            v_min: 32,
            width: 64,
            height: 64,
        });
        let run = |transport, spp, seed| {
            render(
                &scene,
                &camera,
                &projector,
                &RenderSettings {
                    transport,
                    samples_per_pixel: spp,
                    roi,
                    seed,
                },
            )
        };
        let single = run(LightTransport::SinglePath, 1, 1);
        let multi = run(LightTransport::MULTI_PATH_DEFAULT, 64, 1);
        let mean =
            |img: &Image<f32>| img.data().iter().map(|&x| x as f64).sum::<f64>() / (64.0 * 64.0);
        // Diffuse albedo 0.8 walls: the indirect share is a sizeable fraction of the direct light.
        assert!(
            mean(&multi.radiance) > 1.1 * mean(&single.radiance),
            "{} vs {}",
            mean(&multi.radiance),
            mean(&single.radiance)
        );

        // E[(a − b)²] = 2σ²/N for two independent N-sample estimates.
        let mse = |spp: u32| {
            let (a, b) = (
                run(LightTransport::MULTI_PATH_DEFAULT, spp, 11),
                run(LightTransport::MULTI_PATH_DEFAULT, spp, 12),
            );
            a.radiance
                .data()
                .iter()
                .zip(b.radiance.data())
                .map(|(x, y)| ((x - y) as f64).powi(2))
                .sum::<f64>()
        };
        let ratio = mse(2) / mse(8);
        // 4096 pixels: the ratio of two variance estimates is within ~±15 % of 4 at 2σ.
        assert!(
            (3.0..5.3).contains(&ratio),
            "variance ratio for 4× the samples: {ratio}"
        );
    }

    /// The corner of [`corner_scene`] in polished metal (roughness 0.1, α = 0.01).
    fn glossy_corner_scene() -> (Scene, Camera, Projector) {
        let (scene, camera, projector) = corner_scene();
        let metal = PrincipledParams::new(0.9, 1.0, 0.1, 0.5).unwrap();
        let meshes = [square(0.1)];
        let glossy = Scene::build(&meshes, scene.instances().to_vec(), vec![metal]).unwrap();
        (glossy, camera, projector)
    }

    #[test]
    fn regularisation_keeps_the_first_vertex_and_rough_scenes_exact() {
        let (scene, camera, projector) = glossy_corner_scene();
        let run = |transport, scene: &Scene| {
            let settings = RenderSettings {
                transport,
                samples_per_pixel: 4,
                roi: None,
                seed: 3,
            };
            render(scene, &camera, &projector, &settings).radiance
        };
        let one_bounce = LightTransport::MultiPath {
            max_bounces: 1,
            roulette_after: 3,
            min_indirect_roughness: 0.0,
        };
        // Only the first vertex: nothing to regularise, bit for bit.
        assert_eq!(
            run(one_bounce, &scene).data(),
            run(one_bounce.regularised(0.6), &scene).data()
        );
        // A floor at or below every roughness changes nothing either.
        let exact = LightTransport::MULTI_PATH_DEFAULT;
        assert_eq!(
            run(exact, &scene).data(),
            run(exact.regularised(0.1), &scene).data()
        );
        assert_eq!(
            LightTransport::SinglePath.regularised(0.6),
            LightTransport::SinglePath
        );
    }

    #[test]
    fn regularisation_removes_the_variance_of_glossy_inter_reflections() {
        let (scene, camera, projector) = glossy_corner_scene();
        let roi = Some(PixelRect {
            u_min: 32,
            v_min: 16,
            width: 96,
            height: 96,
        });
        let run = |transport, seed| {
            let settings = RenderSettings {
                transport,
                samples_per_pixel: 4,
                roi,
                seed,
            };
            render(&scene, &camera, &projector, &settings).radiance
        };
        // Σ (a − b)² of two independent renders: 2 × the summed per-pixel variance.
        let spread = |transport| {
            let (a, b) = (run(transport, 21), run(transport, 22));
            a.data()
                .iter()
                .zip(b.data())
                .map(|(x, y)| ((x - y) as f64).powi(2))
                .sum::<f64>()
        };
        let exact = LightTransport::MULTI_PATH_DEFAULT;
        let regularised = exact.regularised(0.5);
        // The second vertex's next-event estimate is f·cos ∝ D ≤ 1/(π α²): its second moment
        // scales like 1/α², so α 0.01 → 0.25 divides that term's variance by up to 625. The
        // direct light (exact in both) adds none: the ratio must be far above 1.
        let ratio = spread(exact) / spread(regularised);
        assert!(ratio > 10.0, "variance ratio exact / regularised: {ratio}");
    }
}
