use super::*;
use glint_geometry::pose_deviation::pose_deviation;
use glint_geometry::{Part, Symmetry};
use rand::{Rng, SeedableRng};

const MODEL_SAMPLES: usize = 20_000;

/// A pose perturbed by exactly `translation_m` and `angle_rad` about random directions, on the
/// left like every optimiser here.
fn perturbed(t: &Isometry3<f64>, translation_m: f64, angle_rad: f64, seed: u64) -> Isometry3<f64> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut unit = || {
        Vector3::from_fn(|_, _| rng.random::<f64>() - 0.5)
            .try_normalize(1e-6)
            .unwrap_or_else(Vector3::z)
    };
    let (dt, axis) = (unit() * translation_m, unit() * angle_rad);
    let delta = Isometry3::from_parts(
        Translation3::from(dt),
        UnitQuaternion::from_scaled_axis(axis),
    );
    delta * t
}

/// Object → world of the test scenes: 0.6 m in front of the origin, turned.
fn t_w_o_true() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.05, -0.02, 0.6),
        UnitQuaternion::from_euler_angles(0.4, -0.3, 1.1),
    )
}

/// Mean spacing of `n` area-uniform samples on `mesh`: √(area / n).
fn spacing_m(mesh: &TriMesh, n: usize) -> f64 {
    (mesh.area() / n as f64).sqrt()
}

/// RMS distance of the samples from their centroid: the lever arm that turns a rotation error
/// into surface displacement.
fn gyration_radius_m(samples: &[SurfaceSample]) -> f64 {
    let c = samples.iter().map(|s| s.point.coords).sum::<Vector3<f64>>() / samples.len() as f64;
    (samples
        .iter()
        .map(|s| (s.point.coords - c).norm_squared())
        .sum::<f64>()
        / samples.len() as f64)
        .sqrt()
}

fn to_world(samples: &[SurfaceSample], t_w_o: &Isometry3<f64>) -> Vec<Point3<f64>> {
    samples.iter().map(|s| t_w_o * s.point).collect()
}

#[test]
fn point_to_point_recovers_a_small_perturbation_exactly_on_the_model_samples() {
    // The points are the model samples themselves: once every pair is the right one the
    // Kabsch step is exact, so only rounding remains.
    for part in Part::ALL {
        let mesh = part.mesh();
        let samples = surface_samples(&mesh, MODEL_SAMPLES, 1);
        let model = IcpModel::new(&samples).unwrap();
        let t_w_o = t_w_o_true();
        let points_w = to_world(&samples[..5_000], &t_w_o);
        let init = perturbed(&t_w_o.inverse(), 2e-3, 2f64.to_radians(), part as u64);
        let config = IcpConfig {
            max_iterations: 60,
            ..IcpConfig::default()
        };
        let result = refine_icp(&model, &points_w, &init, &config).unwrap();
        let err = pose_deviation(&result.t_o_w.inverse(), &t_w_o, &Symmetry::none());
        assert!(result.converged, "{part:?}: {result:?}");
        assert!(
            err.translation_m < 1e-9 && err.rotation_rad < 1e-9,
            "{part:?}: {err:?}"
        );
        assert_eq!(result.inliers, points_w.len());
        assert!(result.rms_m < 1e-9, "{part:?}: rms {}", result.rms_m);
    }
}

#[test]
fn both_metrics_recover_a_perturbation_within_the_sample_spacing_on_independent_samples() {
    // Points drawn independently of the model samples, so every pair is off by up to about one
    // sample spacing s. Point-to-point stops once no pair changes any more, i.e. while every
    // point has moved less than ~s/2 against the samples: translation < s/2 and rotation
    // < (s/2)/lever arm. Point-to-plane has no such sliding; its pose is the average of N pair
    // offsets of size ≲ s, so it must lie within 3 standard errors, 3 s/√N (and 3 s/√N/lever).
    let n_points = 5_000;
    for part in Part::ALL {
        let mesh = part.mesh();
        let samples = surface_samples(&mesh, MODEL_SAMPLES, 1);
        let model = IcpModel::new(&samples).unwrap();
        let s = spacing_m(&mesh, MODEL_SAMPLES);
        let lever = gyration_radius_m(&samples);
        let t_w_o = t_w_o_true();
        let points_w = to_world(&surface_samples(&mesh, n_points, 99), &t_w_o);
        let init = perturbed(&t_w_o.inverse(), 2e-3, 2f64.to_radians(), 7 + part as u64);
        for method in [IcpMethod::PointToPoint, IcpMethod::PointToPlane] {
            let config = IcpConfig {
                max_iterations: 100,
                ..IcpConfig::with_method(method)
            };
            let result = refine_icp(&model, &points_w, &init, &config).unwrap();
            let err = pose_deviation(&result.t_o_w.inverse(), &t_w_o, &part.symmetry());
            let bound_m = match method {
                IcpMethod::PointToPoint => s / 2.0,
                IcpMethod::PointToPlane => 3.0 * s / (n_points as f64).sqrt(),
            };
            assert!(
                err.translation_m < bound_m && err.rotation_rad < bound_m / lever,
                "{part:?} {method:?}: {err:?}, bound {bound_m} m, lever {lever} m"
            );
            assert!(result.converged, "{part:?} {method:?}");
            // Distances to the nearest of area-uniform samples: RMS below the spacing.
            assert!(
                result.rms_m < s,
                "{part:?} {method:?}: rms {}",
                result.rms_m
            );
            assert_eq!(result.inliers, points_w.len(), "{part:?} {method:?}");
        }
    }
}

#[test]
fn outliers_beyond_the_correspondence_distance_change_nothing() {
    let mesh = Part::Gear.mesh();
    let samples = surface_samples(&mesh, MODEL_SAMPLES, 1);
    let model = IcpModel::new(&samples).unwrap();
    let t_w_o = t_w_o_true();
    let clean = to_world(&surface_samples(&mesh, 4_000, 5), &t_w_o);
    // Clutter: as many points again, uniformly in a shell 5–20 max-distances outside the part's
    // bounding sphere (in the object frame), so no pose near the start can reach them.
    let config = IcpConfig::default();
    let d = config.max_correspondence_distance_m;
    let (lo, hi) = mesh.aabb().unwrap();
    let radius = (hi - lo).cast::<f64>().norm() / 2.0;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
    let mut noisy = clean.clone();
    for _ in 0..clean.len() {
        let dir = Vector3::from_fn(|_, _| rng.random::<f64>() - 0.5).normalize();
        let r = radius + d * rng.random_range(5.0..20.0);
        noisy.push(t_w_o * Point3::from(dir * r));
    }
    // Interleave so every parallel chunk gets some.
    noisy.swap(1, clean.len() + 1);
    noisy.swap(1000, clean.len() + 2);
    for method in [IcpMethod::PointToPoint, IcpMethod::PointToPlane] {
        let config = IcpConfig::with_method(method);
        let init = perturbed(&t_w_o.inverse(), 3e-3, 3f64.to_radians(), 3);
        let a = refine_icp(&model, &clean, &init, &config).unwrap();
        let b = refine_icp(&model, &noisy, &init, &config).unwrap();
        // The clutter never pairs, so the sums are the same up to summation order.
        assert_eq!(a.inliers, b.inliers, "{method:?}");
        assert_eq!(a.iterations, b.iterations, "{method:?}");
        let e = pose_deviation(&a.t_o_w, &b.t_o_w, &Symmetry::none());
        assert!(e.translation_m < 1e-12 && e.rotation_rad < 1e-12, "{e:?}");
    }
}

#[test]
fn non_finite_points_are_skipped_and_counted() {
    let mesh = Part::Zigzag.mesh();
    let samples = surface_samples(&mesh, MODEL_SAMPLES, 1);
    let model = IcpModel::new(&samples).unwrap();
    let t_w_o = t_w_o_true();
    let clean = to_world(&samples[..2_000], &t_w_o);
    let mut holey = clean.clone();
    holey.insert(0, Point3::new(f64::NAN, 0.0, 0.0));
    holey.insert(700, Point3::new(0.0, f64::INFINITY, 0.0));
    let init = perturbed(&t_w_o.inverse(), 1e-3, 1f64.to_radians(), 1);
    let config = IcpConfig::default();
    let a = refine_icp(&model, &clean, &init, &config).unwrap();
    let b = refine_icp(&model, &holey, &init, &config).unwrap();
    assert_eq!((a.non_finite_skipped, b.non_finite_skipped), (0, 2));
    assert_eq!(a.inliers, b.inliers);
    let e = pose_deviation(&a.t_o_w, &b.t_o_w, &Symmetry::none());
    assert!(e.translation_m < 1e-12 && e.rotation_rad < 1e-12, "{e:?}");
}

#[test]
fn kabsch_returns_a_proper_rotation_when_the_best_orthogonal_fit_is_a_reflection() {
    // Mirror images of a non-planar set: the unconstrained orthogonal fit is the mirror
    // (det −1); the step must fold it back into SO(3).
    let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
    let mut sums = PointSums::default();
    for _ in 0..50 {
        let m = Point3::from(Vector3::from_fn(|_, _| rng.random::<f64>() - 0.5) * 0.04);
        let q = Vector3::new(m.x, m.y, -m.z);
        sums.add(&q, &m, &Vector3::z(), 0.0);
    }
    let step = kabsch_step(&sums).unwrap();
    let r = step.rotation.to_rotation_matrix().into_inner();
    assert!((r.determinant() - 1.0).abs() < 1e-12);
    assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
}

#[test]
fn kabsch_recovers_a_known_motion_of_planar_points() {
    // Coplanar points have a zero singular value: the determinant fix picks the proper motion.
    let motion = Isometry3::from_parts(
        Translation3::new(0.003, -0.001, 0.002),
        UnitQuaternion::from_euler_angles(0.2, -0.1, 0.7),
    );
    let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
    let mut sums = PointSums::default();
    for _ in 0..40 {
        let q = Vector3::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5, 0.0) * 0.03;
        sums.add(&q, &(motion * Point3::from(q)), &Vector3::z(), 0.0);
    }
    let step = kabsch_step(&sums).unwrap();
    let e = pose_deviation(&step, &motion, &Symmetry::none());
    assert!(e.translation_m < 1e-12 && e.rotation_rad < 1e-12, "{e:?}");
}

#[test]
fn point_to_plane_leaves_directions_a_plane_cannot_see_and_says_so() {
    // Points on the interior of a box's top face: the face fixes z and the tilts, not the
    // in-plane shift or the turn about z, so those must keep their initial values exactly.
    let mesh = TriMesh::cuboid([0.0; 3], [0.03, 0.03, 0.01]);
    let model = IcpModel::from_mesh(&mesh, MODEL_SAMPLES, 1).unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(6);
    let points_o: Vec<Point3<f64>> = (0..2_000)
        .map(|_| {
            Point3::new(
                rng.random_range(-0.015..0.015),
                rng.random_range(-0.015..0.015),
                0.01,
            )
        })
        .collect();
    let offset = Vector3::new(0.001, -0.0005, 0.002);
    let init = Isometry3::from_parts(Translation3::from(offset), UnitQuaternion::identity());
    let config = IcpConfig::with_method(IcpMethod::PointToPlane);
    let result = refine_icp(&model, &points_o, &init, &config).unwrap();
    assert_eq!(result.unobservable_dofs, 3);
    let t = result.t_o_w.translation.vector;
    assert!(
        (t.x - offset.x).abs() < 1e-12 && (t.y - offset.y).abs() < 1e-12,
        "{t}"
    );
    // f32 mesh vertices: the face sits at 0.01 m to ~1e-9 m.
    assert!(t.z.abs() < 1e-8, "{t}");
    assert!(result.t_o_w.rotation.angle() < 1e-9);
}

#[test]
fn bad_input_is_a_clear_error() {
    let mesh = Part::Gear.mesh();
    let samples = surface_samples(&mesh, 5_000, 1);
    let model = IcpModel::new(&samples).unwrap();
    let near: Vec<Point3<f64>> = samples[..100].iter().map(|s| s.point).collect();
    let id = Isometry3::identity();
    let config = IcpConfig::default();

    assert_eq!(
        refine_icp(&model, &[], &id, &config),
        Err(IcpError::NoPoints)
    );
    let nan = vec![Point3::new(f64::NAN, 0.0, 0.0); 4];
    assert_eq!(
        refine_icp(&model, &nan, &id, &config),
        Err(IcpError::NoFinitePoints { count: 4 })
    );
    let mut bad_pose = id;
    bad_pose.translation.vector.x = f64::NAN;
    assert_eq!(
        refine_icp(&model, &near, &bad_pose, &config),
        Err(IcpError::NonFiniteInitialPose)
    );
    for bad in [
        IcpConfig {
            max_correspondence_distance_m: -1.0,
            ..config
        },
        IcpConfig {
            max_correspondence_distance_m: f64::NAN,
            ..config
        },
        IcpConfig {
            max_iterations: 0,
            ..config
        },
    ] {
        assert!(matches!(
            refine_icp(&model, &near, &id, &bad),
            Err(IcpError::InvalidConfig { .. })
        ));
    }

    // Far from the model: nothing pairs.
    let far: Vec<Point3<f64>> = near
        .iter()
        .map(|p| p + Vector3::new(1.0, 0.0, 0.0))
        .collect();
    assert_eq!(
        refine_icp(&model, &far, &id, &config),
        Err(IcpError::TooFewCorrespondences {
            iteration: 0,
            found: 0,
            required: 3,
            max_distance_m: config.max_correspondence_distance_m,
            method: IcpMethod::PointToPoint,
        })
    );
    // Five pairs are enough for point-to-point but not for point-to-plane.
    let plane = IcpConfig::with_method(IcpMethod::PointToPlane);
    assert!(matches!(
        refine_icp(&model, &near[..5], &id, &plane),
        Err(IcpError::TooFewCorrespondences {
            found: 5,
            required: 6,
            ..
        })
    ));
    // Collinear points leave the rotation about their line free; coincident ones everything.
    for spacing_m in [1e-3, 0.0] {
        let line: Vec<Point3<f64>> = (0..10)
            .map(|i| samples[0].point + Vector3::x() * (i as f64 * spacing_m))
            .collect();
        assert!(matches!(
            refine_icp(&model, &line, &id, &config),
            Err(IcpError::Degenerate { iteration: 0, .. })
        ));
    }
    // A pose that runs away is an error, not a result (a tight leash provokes one).
    let leash = IcpConfig {
        max_displacement_m: 1e-4,
        ..config
    };
    let shifted = Isometry3::translation(0.003, 0.0, 0.0);
    assert!(matches!(
        refine_icp(&model, &near, &shifted, &leash),
        Err(IcpError::Diverged { iteration: 1, .. })
    ));

    assert!(matches!(IcpModel::new(&[]), Err(IcpError::EmptyModel)));
    let mut broken = samples[..10].to_vec();
    broken[3].normal = Vector3::zeros();
    assert!(matches!(
        IcpModel::new(&broken),
        Err(IcpError::NonFiniteModelSample { index: 3 })
    ));
    broken[3].normal = Vector3::z();
    broken[5].point.y = f64::NAN;
    assert!(matches!(
        IcpModel::new(&broken),
        Err(IcpError::NonFiniteModelSample { index: 5 })
    ));
}
