use super::*;
use crate::bsdf::PrincipledParams;
use crate::projector::Pattern;
use crate::projector::Projector;
use crate::scene::Scene;
use crate::scene::SceneInstance;
use glint_geometry::TriMesh;
use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::Image;
use nalgebra::Isometry3;
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
            let rendering = PixelRendering {
                transport,
                samples_per_pixel: 16,
                seed: 9,
            };
            let s = path_pixel(&scene, &camera, &projector, (u, v), &rendering, own);
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
        (80, 64),
        &PixelRendering::SINGLE_PATH,
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
        UnitQuaternion::from_axis_angle(&nalgebra::Vector3::x_axis(), std::f64::consts::FRAC_PI_2),
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
    let mean = |img: &Image<f32>| img.data().iter().map(|&x| x as f64).sum::<f64>() / (64.0 * 64.0);
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

#[test]
fn one_multi_path_trace_gives_the_single_path_image_too() {
    // With one sample per pixel the first ray goes through the centre and its first vertex's
    // next-event term is drawn before any random number: exactly the single-path render.
    let scene = plane_scene(PrincipledParams::new(0.5, 1.0, 0.3, 0.0).unwrap());
    let (camera, projector) = (small_camera(), projector_at(0.05));
    let settings = |transport, samples_per_pixel| RenderSettings {
        transport,
        samples_per_pixel,
        roi: None,
        seed: 7,
    };
    let single = render(
        &scene,
        &camera,
        &projector,
        &settings(LightTransport::SinglePath, 1),
    );
    let (multi, single_from_multi) = render_with_single_path(
        &scene,
        &camera,
        &projector,
        &settings(LightTransport::MULTI_PATH_DEFAULT, 1),
    );
    assert_eq!(single_from_multi.data(), single.radiance.data());
    assert!(single.radiance.data().iter().any(|&e| e > 0.0));
    // A part of the same samples: never above their total, at any sample count.
    let (multi4, single4) = render_with_single_path(
        &scene,
        &camera,
        &projector,
        &settings(LightTransport::MULTI_PATH_DEFAULT, 4),
    );
    for (total, first) in [
        (&multi.radiance, &single_from_multi),
        (&multi4.radiance, &single4),
    ] {
        assert!(total.data().iter().zip(first.data()).all(|(t, f)| f <= t));
    }
}

#[test]
fn first_surface_render_is_the_shaded_renders_depth_and_label() {
    // The same centre rays: depth and label to the bit (NaN and 0 where the ray misses), at
    // any sample count of the shaded render, whose later samples are jittered.
    let scene = plane_scene(PrincipledParams::new(0.5, 1.0, 0.3, 0.0).unwrap());
    let (camera, projector) = (small_camera(), projector_at(0.05));
    let (depth, label) = render_first_surface(&scene, &camera, None, None);
    let bits = |image: &Image<f32>| image.data().iter().map(|z| z.to_bits()).collect::<Vec<_>>();
    for samples_per_pixel in [1, 3] {
        let shaded = render(
            &scene,
            &camera,
            &projector,
            &RenderSettings {
                transport: LightTransport::MULTI_PATH_DEFAULT,
                samples_per_pixel,
                roi: None,
                seed: 3,
            },
        );
        assert_eq!(bits(&depth), bits(&shaded.depth_m));
        assert_eq!(label.data(), shaded.label.data());
    }
    assert!(label.data().iter().any(|&l| l != 0));
    assert_eq!(
        render_labels(&scene, &camera, None, None).data(),
        label.data()
    );
}

#[test]
fn a_masked_render_shades_only_its_pixels() {
    // An all-true mask draws the full render's random numbers in the same order: the same
    // images to the bit. A partial mask leaves the other pixels as outside an ROI (0, NaN,
    // label 0), shades its own and traces fewer rays; pixels past its extent are rendered.
    let (scene, camera, projector) = corner_scene();
    let settings = RenderSettings {
        transport: LightTransport::MULTI_PATH_DEFAULT,
        samples_per_pixel: 2,
        roi: None,
        seed: 5,
    };
    let (full, full_single) = render_with_single_path(&scene, &camera, &projector, &settings);
    let bits = |image: &Image<f32>| image.data().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let everything = full.label.map(|_| true);
    let (same, same_single) =
        render_with_single_path_where(&scene, &camera, &projector, &settings, &everything);
    assert_eq!(bits(&same.radiance), bits(&full.radiance));
    assert_eq!(bits(&same_single), bits(&full_single));
    assert_eq!(same.rays_traced, full.rays_traced);

    let (w, h) = (full.label.width(), full.label.height());
    let left_half = Image::new(w, h, (0..w * h).map(|i| i % w < w / 2).collect()).unwrap();
    let (half, half_single) =
        render_with_single_path_where(&scene, &camera, &projector, &settings, &left_half);
    let mut shaded = 0;
    for (i, &keep) in left_half.data().iter().enumerate() {
        if keep {
            shaded += usize::from(half.radiance.data()[i] > 0.0);
            assert!(half_single.data()[i] <= half.radiance.data()[i]);
        } else {
            assert_eq!(half.radiance.data()[i], 0.0);
            assert_eq!(half_single.data()[i], 0.0);
            assert!(half.depth_m.data()[i].is_nan());
            assert_eq!(half.label.data()[i], 0);
        }
    }
    assert!(shaded > 0);
    assert!(half.rays_traced < full.rays_traced);

    // A pixel past the mask's extent counts as allowed: an all-false mask as wide as the left
    // half renders the right half alone. The centre ray (sample 0) draws no random numbers, so
    // depth and labels there are the full render's to the bit.
    let narrow = Image::new(w / 2, h, vec![false; (w / 2 * h) as usize]).unwrap();
    let (right, _) = render_with_single_path_where(&scene, &camera, &projector, &settings, &narrow);
    for (i, (&d, &label)) in right
        .depth_m
        .data()
        .iter()
        .zip(right.label.data())
        .enumerate()
    {
        if (i as u32 % w) < w / 2 {
            assert!(d.is_nan() && label == 0);
        } else {
            assert_eq!(d.to_bits(), full.depth_m.data()[i].to_bits());
            assert_eq!(label, full.label.data()[i]);
        }
    }
    assert!(right.label.data().iter().any(|&l| l != 0));
}
