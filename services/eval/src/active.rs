//! An active session on a mock bin, as the demo and the end-to-end tests run it: the bin
//! set-up, the target instance, a stand-in detector's initial pose, and each step's pose error
//! against the truth. Evaluation code: it reads ground truth to place the detector's guess and
//! to score the steps; the session itself (in `glint-orchestrator`) never sees it.

use anyhow::Context;
use glint_camera::setup::{BinSetup, BinSetupSpec};
use glint_estimation::multiview::RefineSettings;
use glint_estimation::pose_error_model::PoseErrorModel;
use glint_geometry::image::Image;
use glint_geometry::pose_deviation::{PoseDeviation, pose_deviation};
use glint_geometry::{Part, Symmetry};
use glint_orchestrator::local::MockCamera;
use glint_orchestrator::session::StepRecord;
use glint_orchestrator::stages::SessionObject;
use nalgebra::Isometry3;
use rand::SeedableRng;

use crate::initial_pose::InitialPoseNoise;
use glint_orchestrator::session::{Cell, SessionConfig, ViewPolicy};
use glint_orchestrator::stages::{CameraStage, PartCalibration, PredictionObject, calibrate_noise};
use glint_uncertainty::predict::PixelCause;
use std::path::Path;

/// How the demo's bin is made.
#[derive(Clone, Debug)]
pub struct ActiveSceneSpec {
    /// The part dropped into the bin.
    pub part: Part,
    /// Number of parts dropped into the bin.
    pub instances: u32,
    /// Seed of the drop and of the detector's error.
    pub seed: u64,
    /// Width of the mock camera's images, px.
    pub width_px: u32,
    /// Height of the mock camera's images, px.
    pub height_px: u32,
    /// Samples per pixel of the mock camera's renders.
    pub samples_per_pixel: u32,
    /// Candidate views on the cap above the bin.
    pub candidates: usize,
}

/// The bin, the part to refine and the stand-in detector's guess.
pub struct ActiveScene {
    /// The mock camera over the dropped bin.
    pub camera: MockCamera,
    /// The part as the session knows it: name and mesh (metres, object frame).
    pub object: SessionObject,
    /// The part's symmetry, used to score pose errors.
    pub symmetry: Symmetry,
    /// Candidate views `t_w_c` (left camera → world) on the cap above the bin.
    pub candidates: Vec<Isometry3<f64>>,
    /// The candidate the detector looked from (the session's first view).
    pub first_view: usize,
    /// Index of the target among the bin's instances: the most visible one from the first view.
    pub target: usize,
    /// Ground truth of the target, evaluation only.
    pub gt_t_w_o: Isometry3<f64>,
    /// The stand-in detector's pose: the truth perturbed as `glint eval refine` perturbs it
    /// ([`InitialPoseNoise`], within 30 mm/30°).
    pub initial_t_w_o: Isometry3<f64>,
    /// Share of the target's silhouette visible from the first view.
    pub target_visib_fract: f64,
}

/// Drops the bin, picks the target and draws the detector's guess.
pub fn set_up(spec: &ActiveSceneSpec) -> anyhow::Result<ActiveScene> {
    let mesh = spec.part.mesh();
    let setup = BinSetup::new(
        &mesh,
        glint_camera::materials::ground_truth(spec.part),
        &BinSetupSpec {
            instances: spec.instances,
            seed: spec.seed,
            width_px: spec.width_px,
            height_px: spec.height_px,
            samples_per_pixel: spec.samples_per_pixel,
        },
    )
    .context("setting up the mock bin")?;
    anyhow::ensure!(spec.candidates >= 2, "candidates: at least 2 views");
    let candidates = setup.views(spec.candidates);
    let first_view = 0;
    let visibility: Vec<(f64, f64)> = setup
        .instance_visibility(&candidates[first_view])
        .iter()
        .map(|v| (v.visib_fract, v.px_count_all as f64))
        .collect();
    let symmetry = spec.part.symmetry();
    let guess = stand_in_detector(
        &setup.poses,
        &visibility,
        &candidates[first_view],
        &symmetry,
        spec.seed,
    )
    .context("the bin holds no instance")?;
    let (target, target_visib_fract, initial_t_w_o) =
        (guess.target, guess.visib_fract, guess.initial_t_w_o);
    let gt_t_w_o = setup.poses[target];
    let object = SessionObject::new(spec.part.name(), mesh);
    Ok(ActiveScene {
        camera: MockCamera { setup },
        object,
        symmetry,
        candidates,
        first_view,
        target,
        gt_t_w_o,
        initial_t_w_o,
        target_visib_fract,
    })
}

/// What the stand-in detector reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectorGuess {
    /// The instance it detected: the most visible one (most visible pixels) from its view.
    pub target: usize,
    /// Share of that instance's silhouette visible from the view.
    pub visib_fract: f64,
    /// Its pose guess, object → world: the truth perturbed in the view's camera frame as
    /// `glint eval refine` perturbs it ([`InitialPoseNoise`], within 30 mm/30°).
    pub initial_t_w_o: Isometry3<f64>,
}

/// A stand-in for a real detector, for the demo and the tests (it reads ground truth, so
/// evaluation code only): given every instance's true pose and `(visible fraction, silhouette
/// pixels)` from the view `t_w_c`, it picks the most visible instance and guesses its pose
/// with a detector's error, seeded by `seed`. `None` for an empty bin.
pub fn stand_in_detector(
    gt_t_w_o: &[Isometry3<f64>],
    visibility: &[(f64, f64)],
    t_w_c: &Isometry3<f64>,
    symmetry: &Symmetry,
    seed: u64,
) -> Option<DetectorGuess> {
    let (target, visib_fract) = visibility
        .iter()
        .enumerate()
        .take(gt_t_w_o.len())
        .map(|(i, &(fract, all_px))| (i, fract * all_px, fract))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _, f)| (i, f))?;
    // The detector's error lives in its camera's frame (lateral vs depth).
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0xDE7E_C70B);
    let t_c_o =
        InitialPoseNoise::default().draw(&(t_w_c.inverse() * gt_t_w_o[target]), symmetry, &mut rng);
    Some(DetectorGuess {
        target,
        visib_fract,
        initial_t_w_o: t_w_c * t_c_o,
    })
}

impl ActiveScene {
    /// The bin's floor (world z = 0, parts above) as the cell's calibration knows it, with
    /// `clearance_m`.
    pub fn background(&self, clearance_m: f64) -> glint_estimation::view::BackgroundPlane {
        glint_estimation::view::BackgroundPlane {
            normal_w: nalgebra::Vector3::z_axis(),
            offset_m: 0.0,
            clearance_m,
        }
    }
}

pub use glint_calibration::shipped::Calibration;

/// What the render workers know of `scene`'s part and camera: the calibrated material,
/// response and radiometric scale, the rig, the camera's shots and window, and the sensor's
/// noise fitted from two read-outs of one shot at the first view (a capture of its own) —
/// never the simulator's truth.
pub fn prediction_object(
    scene: &ActiveScene,
    calibration: &Calibration,
    with_bin: bool,
) -> anyhow::Result<PredictionObject> {
    prediction_object_for(
        &scene.camera,
        &scene.candidates[scene.first_view],
        &scene.object,
        calibration,
        with_bin,
    )
}

/// [`prediction_object`] for any bin set-up, the noise calibrated from `noise_t_w_c`; with
/// `with_bin` the workers render the bin too (its geometry and its reference material, which
/// the cell's calibration knows), beyond the paper.
pub fn prediction_object_for(
    camera: &MockCamera,
    noise_t_w_c: &Isometry3<f64>,
    object: &SessionObject,
    calibration: &Calibration,
    with_bin: bool,
) -> anyhow::Result<PredictionObject> {
    let noise = calibrate_noise(camera, noise_t_w_c)?;
    let surroundings = if with_bin {
        Cell::standard_bin().surroundings
    } else {
        Vec::new()
    };
    Ok(PredictionObject::calibrated(
        object.clone(),
        &PartCalibration::from_files(calibration)?,
        &camera.info()?,
        noise,
        surroundings,
    )?)
}

pub use glint_orchestrator::session::{CONST_SIGMA_Z_M, Masking};

/// A session on `scene` with `policy`: from the stand-in detector's pose, σ_z from the pattern
/// images, the part's pixels by `masking`, its information under `error_model` (eq 18's
/// without one).
pub fn session_config(
    scene: &ActiveScene,
    policy: ViewPolicy,
    max_views: usize,
    entropy_threshold_nats: Option<f64>,
    seed: u64,
    masking: &Masking,
    error_model: Option<PoseErrorModel>,
) -> anyhow::Result<SessionConfig> {
    let info = scene.camera.info().map_err(anyhow::Error::msg)?;
    Ok(SessionConfig {
        initial_t_w_o: scene.initial_t_w_o,
        candidates: scene.candidates.clone(),
        first_view: scene.first_view,
        policy,
        max_views,
        entropy_threshold_nats,
        seed,
        refine: RefineSettings {
            error_model,
            ..masking.refine_settings(&info, Some(&Cell::standard_bin()))
        },
        const_sigma_z_m: CONST_SIGMA_Z_M,
    })
}

/// Colours of the predicted-σ map's missing pixels, by cause: the ratio test (eq 16) red, the σ
/// test (eq 17) magenta, not seen by the right camera orange, not the part black.
pub const MISSING_RGB: [(PixelCause, [u8; 3]); 4] = [
    (PixelCause::Ratio, [220, 40, 40]),
    (PixelCause::Sigma, [230, 60, 230]),
    (PixelCause::RightOccluded, [250, 150, 30]),
    (PixelCause::NotPart, [0, 0, 0]),
];

/// Writes a candidate's predicted σ̌_z over its crop as `<stem>.exr` (channel `sigma_z_m`,
/// metres, NaN off the part) and `<stem>.png` (kept pixels on the colour ramp from 0 to
/// `scale_max_m`, missing ones in [`MISSING_RGB`] by `cause`, a [`PixelCause`] per pixel).
pub fn write_prediction_maps(
    sigma: &Image<f32>,
    cause: &Image<u8>,
    stem: &Path,
    scale_max_m: f64,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        (sigma.width(), sigma.height()) == (cause.width(), cause.height()),
        "the σ̌_z map is {}×{} px and its cause map {}×{}",
        sigma.width(),
        sigma.height(),
        cause.width(),
        cause.height()
    );
    glint_render::exr_io::write_exr(&stem.with_extension("exr"), &[("sigma_z_m", sigma)])?;
    let rgb: Vec<u8> = sigma
        .data()
        .iter()
        .zip(cause.data())
        .flat_map(|(&s, &c)| {
            MISSING_RGB
                .iter()
                .find(|(k, _)| *k as u8 == c)
                .map(|(_, rgb)| *rgb)
                .unwrap_or_else(|| glint_plot::ramp_rgb(f64::from(s) / scale_max_m))
        })
        .collect();
    let png = glint_plot::encode_rgb_png(&rgb, sigma.width(), sigma.height())?;
    glint_geometry::io::write_file_atomically(&stem.with_extension("png"), &png)?;
    Ok(())
}

/// Each step's pose error against the truth (symmetry-aware), the initial guess first.
pub fn deviations(
    scene: &ActiveScene,
    steps: &[StepRecord],
) -> (PoseDeviation, Vec<PoseDeviation>) {
    let of = |t_w_o: &Isometry3<f64>| pose_deviation(t_w_o, &scene.gt_t_w_o, &scene.symmetry);
    (
        of(&scene.initial_t_w_o),
        steps.iter().map(|s| of(&s.t_w_o)).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glint_estimation::view::{SigmaSource, ViewMeasurement, hypothesis_mask, view_points};
    use glint_geometry::image::DepthMap;
    use glint_orchestrator::local::LocalEstimation;
    use glint_orchestrator::session::{self, Session, SessionState, Stages};
    use glint_orchestrator::stages::StageError;

    /// Median |SDF| (m) of `view`'s points in the silhouette of the truth.
    fn median_sdf_at_truth(scene: &ActiveScene, view: &ViewMeasurement) -> (usize, f64) {
        let mask = hypothesis_mask(
            &scene.object.mesh,
            &view.stereo,
            &view.t_w_c,
            &scene.gt_t_w_o,
            0.0,
        );
        let sigma = SigmaSource::Constant { sigma_z_m: 1e-3 };
        let points = view_points(view, &mask, &sigma, 0).unwrap().points;
        let sdf =
            glint_geometry::sdf::SdfGrid::build(&scene.object.mesh, &Default::default()).unwrap();
        let t_o_w = scene.gt_t_w_o.inverse();
        let mut d: Vec<f64> = points
            .iter()
            .map(|p| sdf.sample(&(t_o_w * p.p_w)).distance_m.abs())
            .collect();
        d.sort_by(f64::total_cmp);
        (d.len(), d[d.len() / 2])
    }

    #[test]
    fn the_silhouette_of_the_truth_selects_the_parts_depth() {
        let scene = set_up(&ActiveSceneSpec {
            part: Part::Zigzag,
            instances: 4,
            seed: 3,
            width_px: 320,
            height_px: 256,
            samples_per_pixel: 1,
            candidates: 6,
        })
        .unwrap();
        let t_w_c = scene.candidates[scene.first_view];
        let view = scene.camera.capture(&t_w_c, 7).unwrap().measurement;
        // The renderer's true depth through the silhouette lies on the mesh up to the 1 mm
        // SDF grid's trilinear error (a quarter voxel): the silhouette, the back-projection and
        // the frames agree with the renderer's.
        let rendered = scene.camera.setup.camera().render_shots(&t_w_c, 7);
        let truth = ViewMeasurement {
            depth: DepthMap::new(rendered.truth.depth_m),
            ..view.clone()
        };
        let (n, median) = median_sdf_at_truth(&scene, &truth);
        assert!(
            n > 30 && median < 0.25e-3,
            "{n} points, median |SDF| {median} m"
        );
        // The camera's matched depth there: the Zigzag's matte-ish strip matches within a few
        // σ_z (≈ 0.3 mm here), not the centimetres of a wrong frame or a mirror match.
        let (n, median) = median_sdf_at_truth(&scene, &view);
        assert!(
            n > 30 && median < 1.5e-3,
            "{n} points, median |SDF| {median} m"
        );
    }

    fn small_scene() -> ActiveScene {
        set_up(&ActiveSceneSpec {
            part: Part::Zigzag,
            instances: 3,
            seed: 5,
            width_px: 640,
            height_px: 512,
            samples_per_pixel: 1,
            candidates: 8,
        })
        .unwrap()
    }

    fn config(scene: &ActiveScene, policy: ViewPolicy, max_views: usize) -> SessionConfig {
        session_config(scene, policy, max_views, None, 9, &Masking::default(), None).unwrap()
    }

    /// What a broken camera does from its second capture on.
    #[derive(Clone, Copy, Debug)]
    enum CameraFault {
        /// Depth NaN, infinite or negative everywhere.
        BadDepth,
        /// No pattern shots, no noise shots, no depth.
        EmptyCapture,
        /// No answer in time.
        Timeout,
    }

    struct FaultyCamera<'a> {
        inner: &'a dyn CameraStage,
        fault: CameraFault,
        captures: std::sync::atomic::AtomicUsize,
    }

    impl CameraStage for FaultyCamera<'_> {
        fn info(&self) -> Result<glint_orchestrator::stages::CameraInfo, StageError> {
            self.inner.info()
        }
        fn candidate_views(&self, count: usize) -> Result<Vec<Isometry3<f64>>, StageError> {
            self.inner.candidate_views(count)
        }
        fn capture(
            &self,
            t_w_c: &Isometry3<f64>,
            seed: u64,
        ) -> Result<glint_orchestrator::stages::CapturedView, StageError> {
            let n = self
                .captures
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if n == 0 {
                return self.inner.capture(t_w_c, seed);
            }
            match self.fault {
                CameraFault::Timeout => Err(StageError::Unavailable(
                    "the camera did not answer within 5 s".into(),
                )),
                CameraFault::BadDepth => {
                    let mut view = self.inner.capture(t_w_c, seed)?;
                    let bad = [f32::NAN, f32::INFINITY, -0.5, f32::NEG_INFINITY];
                    for (i, z) in view
                        .measurement
                        .depth
                        .depth_m
                        .data_mut()
                        .iter_mut()
                        .enumerate()
                    {
                        *z = bad[i % bad.len()];
                    }
                    Ok(view)
                }
                CameraFault::EmptyCapture => {
                    let mut view = self.inner.capture(t_w_c, seed)?;
                    let m = &mut view.measurement;
                    m.left.clear();
                    m.right.clear();
                    m.noise_shots = None;
                    m.depth.depth_m.data_mut().fill(f32::NAN);
                    Ok(view)
                }
            }
        }
    }

    #[test]
    fn a_broken_camera_fails_or_adds_nothing_never_panics_and_the_steps_before_are_kept() {
        let scene = small_scene();
        let estimation = LocalEstimation::default();
        for fault in [
            CameraFault::BadDepth,
            CameraFault::EmptyCapture,
            CameraFault::Timeout,
        ] {
            let camera = FaultyCamera {
                inner: &scene.camera,
                fault,
                captures: Default::default(),
            };
            let stages = Stages::without_prediction(&camera, &estimation);
            let mut session =
                Session::new("t".into(), config(&scene, ViewPolicy::MaxDistance, 2)).unwrap();
            let result = session::run(&mut session, &scene.object, &stages, |_| {}, || false);
            let first = &session.steps[0];
            match fault {
                // Depth that is not a finite positive number is missing depth: the view adds
                // no point, the pose and its information stay those of the first view.
                CameraFault::BadDepth => {
                    assert!(result.is_ok(), "{fault:?}: {result:?}");
                    let second = &session.steps[1];
                    assert_eq!(second.view_points, 0, "{fault:?}");
                    assert_eq!(second.total_points, first.total_points, "{fault:?}");
                    assert!(second.entropy_nats.is_finite());
                }
                // The rest end the session FAILED with the reason; step 0 is kept.
                CameraFault::EmptyCapture | CameraFault::Timeout => {
                    let error = result.unwrap_err().to_string();
                    assert_eq!(session.state, SessionState::Failed, "{fault:?}");
                    assert_eq!(session.steps.len(), 1, "{fault:?}");
                    assert_eq!(session.error.as_deref(), Some(error.as_str()));
                    let expected = match fault {
                        CameraFault::Timeout => "did not answer",
                        _ => "views[1]",
                    };
                    assert!(error.contains(expected), "{fault:?}: {error}");
                }
            }
        }
    }

    #[test]
    fn a_session_takes_distinct_views_until_its_budget_and_resumes_identically() {
        let scene = small_scene();
        let estimation = LocalEstimation::default();
        let stages = Stages::without_prediction(&scene.camera, &estimation);
        let mut session =
            Session::new("t".into(), config(&scene, ViewPolicy::MaxDistance, 3)).unwrap();
        let mut seen = Vec::new();
        session::run(
            &mut session,
            &scene.object,
            &stages,
            |s| seen.push(s.step),
            || false,
        )
        .unwrap();
        assert_eq!(session.state, SessionState::BudgetSpent);
        assert_eq!(seen, [0, 1, 2]);
        let views: Vec<usize> = session.steps.iter().map(|s| s.view).collect();
        assert_eq!(views[0], scene.first_view);
        assert!(views[0] != views[1] && views[1] != views[2] && views[0] != views[2]);
        for pair in session.steps.windows(2) {
            assert_eq!(pair[0].next_view, Some(pair[1].view));
        }
        assert_eq!(session.steps[2].next_view, None);
        // Points accumulate view by view.
        let totals: Vec<usize> = session.steps.iter().map(|s| s.total_points).collect();
        assert!(totals[0] > 0 && totals[1] > totals[0] && totals[2] > totals[1]);
        // A session resumed after its second step (a restart that kept steps and captures)
        // completes with the same third step: every stage is seeded by the step.
        let mut resumed = session.clone();
        resumed.steps.truncate(2);
        resumed.views.truncate(2);
        resumed.state = SessionState::Running;
        session::run(&mut resumed, &scene.object, &stages, |_| {}, || false).unwrap();
        assert_eq!(resumed.steps[2].view, session.steps[2].view);
        assert_eq!(resumed.steps[2].t_w_o, session.steps[2].t_w_o);
    }

    #[test]
    fn sessions_stop_at_the_threshold_and_refuse_what_they_cannot_run() {
        let scene = small_scene();
        let estimation = LocalEstimation::default();
        let stages = Stages::without_prediction(&scene.camera, &estimation);
        // Any pose entropy is below +10⁶ nats: one view and the session has converged.
        let mut c = config(&scene, ViewPolicy::Random, 5);
        c.entropy_threshold_nats = Some(1e6);
        let mut session = Session::new("t".into(), c).unwrap();
        session::run(&mut session, &scene.object, &stages, |_| {}, || false).unwrap();
        assert_eq!(session.state, SessionState::Converged);
        assert_eq!(session.steps.len(), 1);
        // An entropy policy without render workers fails with a reason, after its first step.
        let mut session = Session::new("t".into(), config(&scene, ViewPolicy::Nbv, 3)).unwrap();
        let err = session::run(&mut session, &scene.object, &stages, |_| {}, || false).unwrap_err();
        assert!(
            matches!(err, StageError::FailedPrecondition(ref m) if m.contains("render workers"))
        );
        assert_eq!(session.state, SessionState::Failed);
        // Cancelled before the first capture: nothing taken.
        let mut session = Session::new("t".into(), config(&scene, ViewPolicy::Random, 3)).unwrap();
        let err = session::run(&mut session, &scene.object, &stages, |_| {}, || true).unwrap_err();
        assert_eq!(err, StageError::Cancelled);
        assert_eq!(
            (session.state, session.views.len()),
            (SessionState::Cancelled, 0)
        );
        // Bad configurations name their field.
        let mut c = config(&scene, ViewPolicy::Random, 0);
        assert!(
            matches!(Session::new("t".into(), c.clone()), Err(StageError::InvalidArgument { ref field, .. }) if field == "max_views")
        );
        c.max_views = 2;
        c.first_view = 99;
        assert!(
            matches!(Session::new("t".into(), c.clone()), Err(StageError::InvalidArgument { ref field, .. }) if field == "first_view")
        );
        c.first_view = 0;
        c.candidates[3].translation.vector.x = f64::NAN;
        assert!(
            matches!(Session::new("t".into(), c), Err(StageError::InvalidArgument { ref field, .. }) if field == "candidates_t_w_c[3]")
        );
    }

    #[test]
    fn the_nbv_policy_takes_the_candidate_of_least_predicted_entropy() {
        use glint_orchestrator::local::LocalPrediction;
        let scene = small_scene();
        let calibration = Calibration::embedded(Part::Zigzag).unwrap();
        let object = prediction_object(&scene, &calibration, false).unwrap();
        let estimation = LocalEstimation::default();
        let workers = LocalPrediction::default();
        let stages = Stages {
            camera: &scene.camera,
            estimation: &estimation,
            prediction: Some((&workers, &object)),
        };
        for policy in [ViewPolicy::Nbv, ViewPolicy::NbvConstSigma] {
            let mut session = Session::new("t".into(), config(&scene, policy, 2)).unwrap();
            session::run(&mut session, &scene.object, &stages, |_| {}, || false).unwrap();
            let first = &session.steps[0];
            let h = &first.candidate_entropies_nats;
            assert_eq!(h.len(), scene.candidates.len());
            assert_eq!(
                h[first.view], None,
                "the view taken is not a candidate again"
            );
            let (best, best_h) = h
                .iter()
                .enumerate()
                .filter_map(|(i, h)| Some((i, (*h)?)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert_eq!(first.next_view, Some(best), "{policy:?}: {h:?}");
            assert_eq!(session.steps[1].view, best);
            assert_eq!(session.steps[1].predicted_entropy_nats, Some(best_h));
            // Every candidate's prediction adds information: entropies below the current one.
            assert!(h.iter().flatten().all(|&x| x <= first.entropy_nats + 1e-9));
        }
    }

    #[test]
    fn prediction_maps_are_written_as_exr_and_png() {
        let scene = small_scene();
        let calibration = Calibration::embedded(Part::Zigzag).unwrap();
        let object = prediction_object(&scene, &calibration, true).unwrap();
        let sdf = glint_orchestrator::local::SdfCache::with_config(
            glint_uncertainty::predict::prediction_grid_config(),
        )
        .grid(&object.object)
        .unwrap();
        let settings = glint_uncertainty::PredictionSettings {
            with_maps: true,
            ..Default::default()
        };
        let p = glint_uncertainty::predict_candidate(
            &object.predictor(sdf),
            &scene.gt_t_w_o,
            &scene.candidates[1],
            &settings,
            1,
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let stem = dir.path().join("map");
        let sigma = p.sigma_z_m.as_ref().unwrap();
        let cause = p.cause.as_ref().unwrap();
        write_prediction_maps(sigma, cause, &stem, 0.1e-3).unwrap();
        let channels = glint_render::exr_io::read_exr(&stem.with_extension("exr")).unwrap();
        assert_eq!(channels[0].0, "sigma_z_m");
        let read = &channels[0].1;
        assert_eq!(
            (read.width(), read.height()),
            (sigma.width(), sigma.height())
        );
        assert!(
            read.data()
                .iter()
                .zip(sigma.data())
                .all(|(a, b)| a == b || (a.is_nan() && b.is_nan()))
        );
        let png = image::open(stem.with_extension("png")).unwrap();
        assert_eq!((png.width(), png.height()), (sigma.width(), sigma.height()));
        // Maps of different sizes are refused, and nothing is written.
        let other = dir.path().join("other");
        let small = Image::new(1, 1, vec![0u8]).unwrap();
        assert!(write_prediction_maps(sigma, &small, &other, 0.1e-3).is_err());
        assert!(!other.with_extension("png").exists());
    }
}
