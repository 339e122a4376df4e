//! The estimation stage over real gRPC on loopback: `RemoteEstimation` against the estimation
//! server gives what `LocalEstimation` gives in-process on the same captured views of a small
//! mock bin (the refined pose, its information, the plan, the entropy), registering the mesh
//! on the first NOT_FOUND. Bad input answers INVALID_ARGUMENT naming the field, an unknown
//! mesh NOT_FOUND naming its hash, views without the part's points FAILED_PRECONDITION.
//!
//! Tolerances. Both sides run `glint_estimation::multiview::refine_views` on the same inputs:
//! the views travel bit-exact (u16 shots as MONO16, f32 depth as FLOAT32 with NaN kept, the
//! mesh's f32 vertices as binary PLY in metres, f64 settings and matrices), so what may differ
//! is (a) the poses' unit quaternions, re-normalised on receipt (a few ulp, ~1e-16), (b) the
//! order in which rayon reduces the normal equations' partial sums (`refine::accumulate`),
//! which changes from run to run at ~1e-16 relative, as between two local runs, and (c) the
//! response's matrices, symmetrised as (M + Mᵀ)/2 (exact for the information, assembled
//! symmetric; ~1e-16 for the covariance). Gauss–Newton carries such perturbations to the pose
//! scaled by the normal equations' condition number (≲ 1e6 here), ≲ 1e-10; a discrete change
//! (a pixel across a mask edge, a point across a gate) would need a value within ~1e-16 of its
//! threshold. So 1e-9 (m, rad, relative for the information) fails only if the paths differ.

use glint_e2e::TestServer;
use std::time::Duration;

use glint_estimation::correlated_error::CorrelatedDepthError;
use glint_estimation::pose_error_model::PoseErrorModel;
use glint_estimation::server::{
    Estimation, SERVICE_NAME, mesh_file, refine_chunks, refine_header, view_arrays,
};
use glint_estimation::view::ViewMeasurement;
use glint_estimation::view_bias::ViewPoseBias;
use glint_eval::active::{ActiveSceneSpec, Masking, session_config, set_up};
use glint_geometry::Part;
use glint_geometry::image::Image;
use glint_orchestrator::local::LocalEstimation;
use glint_orchestrator::remote::Endpoint;
use glint_orchestrator::remote::estimation::RemoteEstimation;
use glint_orchestrator::session::ViewPolicy;
use glint_orchestrator::stages::{
    CameraStage, EstimationStage, RefineSettings, RefineSigma, Refinement, StageError,
};
use glint_proto::v1;
use glint_proto::v1::estimation_service_client::EstimationServiceClient;
use nalgebra::{Isometry3, Matrix6, Vector6};
use tonic::Code;

const TOLERANCE: f64 = 1e-9;

fn assert_same(remote: &Refinement, local: &Refinement, what: &str) {
    let dt = (remote.t_w_o.translation.vector - local.t_w_o.translation.vector).norm();
    let dr = (remote.t_w_o.rotation.inverse() * local.t_w_o.rotation).angle();
    assert!(
        dt < TOLERANCE && dr < TOLERANCE,
        "{what}: pose off by {dt} m, {dr} rad"
    );
    let scale = local.information.amax();
    let di = (remote.information - local.information).amax();
    assert!(
        di <= TOLERANCE * scale,
        "{what}: information off by {di} of {scale}"
    );
    match (&remote.covariance, &local.covariance) {
        (Some(a), Some(b)) => assert!((a - b).amax() <= TOLERANCE * b.amax(), "{what}"),
        (None, None) => {}
        other => panic!("{what}: covariances {other:?}"),
    }
    assert_eq!(remote.view_points, local.view_points, "{what}");
    assert_eq!(
        (remote.inliers, remote.iterations, &remote.status),
        (local.inliers, local.iterations, &local.status),
        "{what}"
    );
}

/// The in-process results and the views the raw-request checks reuse.
struct Captured {
    views: Vec<ViewMeasurement>,
    settings: RefineSettings,
    t_w_o: Isometry3<f64>,
    mesh_sha256_hex: String,
    mesh: std::sync::Arc<glint_geometry::TriMesh>,
}

/// RemoteEstimation against LocalEstimation: on a blocking thread, as a session runs it.
fn remote_equals_local(target: &str, handle: tokio::runtime::Handle) -> Captured {
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
    let settings = session_config(
        &scene,
        ViewPolicy::Random,
        3,
        None,
        9,
        &Masking::default(),
        None,
    )
    .unwrap()
    .refine;
    let captured: Vec<_> = [0, 1]
        .iter()
        .map(|&i| {
            scene
                .camera
                .capture(&scene.candidates[i], 7 + i as u64)
                .unwrap()
        })
        .collect();
    let views: Vec<_> = captured.iter().collect();
    let local = LocalEstimation::default();
    let remote =
        RemoteEstimation::new(handle, Endpoint::new(target, Duration::from_secs(120))).unwrap();
    let t_w_o = scene.initial_t_w_o;

    // The first call registers the mesh (NOT_FOUND, then once more).
    let l = local
        .refine(&scene.object, &views, &t_w_o, &settings)
        .unwrap();
    let r = remote
        .refine(&scene.object, &views, &t_w_o, &settings)
        .unwrap();
    assert!(
        l.view_points.iter().all(|&n| n > 30) && l.status != "diverged",
        "the small bin must still give points: {l:?}"
    );
    assert_same(&r, &l, "σ from pattern images, two views");

    // Under an error model (it crosses the wire): the same pose, eq 18's information kept
    // beside, and the model's no larger in any direction — a cell's shared depth bias only
    // subtracts (Sherman–Morrison) and M ⪰ I makes I M⁺ I ⪯ I — and far smaller: a view adds
    // at most about B⁻¹ (4e6 m⁻² per lateral axis here) where eq 18 claims about n/σ_z², above
    // 1e8 m⁻² for the n > 30 points of σ_z ≲ 0.5 mm each view holds (the trace, dominated by
    // the translation entries, at least halves).
    let model = PoseErrorModel {
        depth_error: CorrelatedDepthError {
            cell_m: 2e-3,
            bias_sigma_m: 0.5e-3,
        },
        view_bias: ViewPoseBias {
            covariance_v: Matrix6::from_diagonal(&Vector6::new(
                0.5e-3f64.powi(2),
                0.5e-3f64.powi(2),
                1e-3f64.powi(2),
                0.5f64.to_radians().powi(2),
                0.5f64.to_radians().powi(2),
                1f64.to_radians().powi(2),
            )),
        },
    };
    let modelled = RefineSettings {
        error_model: Some(model),
        ..settings
    };
    let lm = local
        .refine(&scene.object, &views, &t_w_o, &modelled)
        .unwrap();
    let rm = remote
        .refine(&scene.object, &views, &t_w_o, &modelled)
        .unwrap();
    assert_same(&rm, &lm, "with an error model, two views");
    let scale = l.information.amax();
    assert!((rm.pixel_information - lm.pixel_information).amax() <= TOLERANCE * scale);
    assert!(
        (lm.pixel_information - l.information).amax() <= TOLERANCE * scale,
        "eq 18's information does not depend on the model"
    );
    assert!((lm.t_w_o.translation.vector - l.t_w_o.translation.vector).norm() < TOLERANCE);
    let lowest = (lm.pixel_information - lm.information)
        .symmetric_eigenvalues()
        .min();
    assert!(
        lowest >= -TOLERANCE * scale,
        "the model adds information: {lowest}"
    );
    assert!(
        lm.information.trace() < 0.5 * lm.pixel_information.trace(),
        "the model claims what eq 18 claims: {} vs {}",
        lm.information.trace(),
        lm.pixel_information.trace()
    );

    // A constant σ sends depth only.
    let constant = RefineSettings {
        sigma: RefineSigma::Constant { sigma_z_m: 0.5e-3 },
        final_mask_margin_m: None,
        ..settings
    };
    let l = local
        .refine(&scene.object, &views[..1], &t_w_o, &constant)
        .unwrap();
    let r = remote
        .refine(&scene.object, &views[..1], &t_w_o, &constant)
        .unwrap();
    assert_same(&r, &l, "constant σ, one view");

    // Plan and entropy: the same prior, the same numbers.
    let collected = l.information;
    let spd = |d: [f64; 6]| Matrix6::from_diagonal(&Vector6::from_row_slice(&d));
    let candidates = vec![
        collected * 0.5,
        spd([1e6, 1e6, 1e6, 1e3, 1e3, 1e3]),
        spd([1e7, 1e5, 1e5, 1e4, 1e2, 1e2]),
        collected * 2.0 + spd([0.0, 0.0, 1e6, 0.0, 0.0, 0.0]),
    ];
    let taken = [3];
    let lp = local.plan(&collected, &candidates, &taken).unwrap();
    let rp = remote.plan(&collected, &candidates, &taken).unwrap();
    assert_eq!(rp.chosen, lp.chosen);
    assert_eq!(rp.entropies_nats[3], None, "a taken view has no entropy");
    for (a, b) in rp.entropies_nats.iter().zip(&lp.entropies_nats) {
        match (a, b) {
            (Some(a), Some(b)) => assert!((a - b).abs() <= 1e-12 * b.abs(), "{a} vs {b}"),
            (None, None) => {}
            other => panic!("{other:?}"),
        }
    }
    let (le, re) = (
        local.entropy_nats(&collected).unwrap(),
        remote.entropy_nats(&collected).unwrap(),
    );
    assert!((le - re).abs() <= 1e-12 * le.abs(), "{le} vs {re}");

    // Refused alike: an asymmetric candidate (refused before the wire, which holds upper
    // triangles), and a hypothesis whose silhouette holds no points.
    let mut asymmetric = candidates.clone();
    asymmetric[2][(0, 1)] = 1.0;
    let field = |e: StageError| match e {
        StageError::InvalidArgument { field, .. } => field,
        other => panic!("{other:?}"),
    };
    assert_eq!(
        field(remote.plan(&collected, &asymmetric, &[]).unwrap_err()),
        "candidates[2]"
    );
    assert_eq!(
        field(local.plan(&collected, &asymmetric, &[]).unwrap_err()),
        "candidates[2]"
    );
    let far = Isometry3::translation(5.0, 0.0, 0.0) * t_w_o;
    for e in [
        remote.refine(&scene.object, &views, &far, &settings),
        local.refine(&scene.object, &views, &far, &settings),
    ] {
        assert!(matches!(e, Err(StageError::FailedPrecondition(_))), "{e:?}");
    }

    Captured {
        views: captured.into_iter().map(|c| c.measurement).collect(),
        settings,
        t_w_o,
        mesh_sha256_hex: scene.object.mesh_sha256_hex.clone(),
        mesh: scene.object.mesh.clone(),
    }
}

/// A raw `Refine` call's status.
async fn refine_status(
    client: &mut EstimationServiceClient<tonic::transport::Channel>,
    chunks: Vec<v1::RefineChunk>,
) -> tonic::Status {
    client
        .refine(tokio_stream::iter(chunks))
        .await
        .expect_err("the request is bad")
}

fn assert_invalid(status: &tonic::Status, field: &str) {
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(
        status.message().starts_with(&format!("{field}: ")),
        "expected {field}: {status:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn remote_estimation_equals_local_and_names_bad_fields() {
    let server = TestServer::start(
        tonic::service::Routes::new(Estimation::default().into_service()),
        SERVICE_NAME,
    )
    .await;
    let target = server.target.clone();
    let handle = tokio::runtime::Handle::current();
    let c = tokio::task::spawn_blocking(move || remote_equals_local(&target, handle))
        .await
        .unwrap();
    let mut client = EstimationServiceClient::connect(server.target.clone())
        .await
        .unwrap();
    // The service keys the mesh as the session does: the content hash survives the PLY file.
    let key = client
        .register_mesh(mesh_file(&c.mesh, "zigzag"))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(key.sha256_hex, c.mesh_sha256_hex);
    let views: Vec<&ViewMeasurement> = c.views.iter().collect();
    let good = refine_chunks(&c.mesh_sha256_hex, &c.t_w_o, &c.settings, &views);

    // A NaN pose names its coordinate.
    let mut nan = c.t_w_o;
    nan.translation.vector.x = f64::NAN;
    let mut chunks = good.clone();
    chunks[0].part = Some(v1::refine_chunk::Part::Header(refine_header(
        &c.mesh_sha256_hex,
        &nan,
        &c.settings,
        2,
    )));
    assert_invalid(
        &refine_status(&mut client, chunks).await,
        "header.initial_t_w_o.translation_m.x",
    );

    // A non-unit quaternion in the second view's pose.
    let mut chunks = good.clone();
    let second = chunks
        .iter()
        .enumerate()
        .filter(|(_, c)| matches!(c.part, Some(v1::refine_chunk::Part::View(_))))
        .nth(1)
        .map(|(i, _)| i)
        .unwrap();
    if let Some(v1::refine_chunk::Part::View(h)) = &mut chunks[second].part
        && let Some(q) = h.t_w_c.as_mut().and_then(|p| p.rotation.as_mut())
    {
        q.w *= 1.5;
    }
    assert_invalid(
        &refine_status(&mut client, chunks).await,
        "views[1].t_w_c.rotation",
    );

    // A pattern shot of the wrong size: "left_003" is the view's fifth array (after "depth").
    let mut small = c.views[0].clone();
    small.left[3] = Image::new(16, 16, vec![0u16; 256]).unwrap();
    let (header, arrays) = view_arrays(&small, &c.settings.sigma);
    assert_eq!(header.arrays[4].name, "left_003");
    let mut chunks = refine_chunks(&c.mesh_sha256_hex, &c.t_w_o, &c.settings, &[&small]);
    assert_eq!(arrays.len(), header.arrays.len());
    chunks[0].part = Some(v1::refine_chunk::Part::Header(refine_header(
        &c.mesh_sha256_hex,
        &c.t_w_o,
        &c.settings,
        1,
    )));
    assert_invalid(
        &refine_status(&mut client, chunks).await,
        "views[0].arrays[4]",
    );

    // An unknown mesh: NOT_FOUND naming its hash, before the views are read.
    let unknown = "0123456789abcdef".repeat(4);
    let status = refine_status(
        &mut client,
        refine_chunks(&unknown, &c.t_w_o, &c.settings, &views),
    )
    .await;
    assert_eq!(status.code(), Code::NotFound, "{status:?}");
    assert!(status.message().contains(&unknown), "{status:?}");

    // Plans: no candidates; a candidate that is not 21 upper-triangle entries (a full,
    // asymmetric 6×6 sent as 36 values).
    let identity = v1::SymmetricMatrix6::from(&Matrix6::<f64>::identity());
    let status = client
        .plan_next_view(v1::PlanNextViewRequest {
            collected: Some(identity.clone()),
            candidates: vec![],
            taken: vec![],
        })
        .await
        .unwrap_err();
    assert_invalid(&status, "candidates");
    let full = v1::SymmetricMatrix6 {
        upper: (0..36).map(f64::from).collect(),
    };
    let status = client
        .plan_next_view(v1::PlanNextViewRequest {
            collected: Some(identity.clone()),
            candidates: vec![identity.clone(), identity.clone(), full],
            taken: vec![],
        })
        .await
        .unwrap_err();
    assert_invalid(&status, "candidates[2].upper");
    let status = client
        .pose_entropy(v1::PoseEntropyRequest { information: None })
        .await
        .unwrap_err();
    assert_invalid(&status, "information");
    // A taken index past the candidates.
    let status = client
        .plan_next_view(v1::PlanNextViewRequest {
            collected: Some(identity.clone()),
            candidates: vec![identity],
            taken: vec![4],
        })
        .await
        .unwrap_err();
    assert_invalid(&status, "taken");

    drop(client);
    server.stop().await.unwrap().unwrap();
}
