//! A render worker that answers garbage (a Fisher information that is not positive
//! semi-definite, or other candidates than asked) or answers too slowly does not decide the
//! view: the orchestrator's pool refuses its answers (or gives up on them at the call's
//! deadline), re-sends those candidates to a sound worker, and the decision equals one made
//! by the sound worker alone.

use glint_e2e::TestServer;
use glint_eval::active::{ActiveSceneSpec, Calibration, prediction_object, set_up};
use glint_geometry::Part;
use glint_orchestrator::remote::prediction::{
    PoolConfig, PoolStats, RemotePrediction, WorkerSource,
};
use glint_orchestrator::stages::{
    CandidateInformation, PredictionObject, PredictionRequest, PredictionSigma, PredictionStage,
};
use glint_proto::v1;
use glint_proto::v1::uncertainty_service_server::{UncertaintyService, UncertaintyServiceServer};
use tonic::{Request, Response, Status};

/// How the bad worker lies.
#[derive(Clone, Copy)]
enum Lie {
    /// Information with a negative eigenvalue.
    NotPsd,
    /// Answers for a candidate it was not asked about.
    WrongCandidate,
    /// Answers nothing for 30 s (slow, not dead).
    Slow,
}

struct LyingWorker(Lie);

#[tonic::async_trait]
impl UncertaintyService for LyingWorker {
    async fn register_object(
        &self,
        _: Request<v1::RegisterObjectRequest>,
    ) -> Result<Response<v1::RegisterObjectResponse>, Status> {
        Err(Status::unimplemented("a lying worker registers nothing"))
    }

    async fn predict_candidates(
        &self,
        request: Request<v1::PredictCandidatesRequest>,
    ) -> Result<Response<v1::PredictCandidatesResponse>, Status> {
        if let Lie::Slow = self.0 {
            tokio::time::sleep(std::time::Duration::from_secs(30)).await;
        }
        let mut upper = vec![0.0; 21];
        upper[0] = -1.0; // (0,0) < 0: not positive semi-definite
        let predictions = request
            .get_ref()
            .candidate_indices
            .iter()
            .map(|&i| v1::CandidatePrediction {
                candidate_index: match self.0 {
                    Lie::NotPsd | Lie::Slow => i,
                    Lie::WrongCandidate => i + 1000,
                },
                information: Some(v1::SymmetricMatrix6 {
                    upper: match self.0 {
                        Lie::NotPsd | Lie::Slow => upper.clone(),
                        Lie::WrongCandidate => vec![0.0; 21],
                    },
                }),
                ..Default::default()
            })
            .collect();
        Ok(Response::new(v1::PredictCandidatesResponse { predictions }))
    }
}

/// One decision by `pool` on the blocking pool (it blocks on the runtime): its answers and
/// what the pool did.
async fn decide(
    pool: RemotePrediction,
    object: &PredictionObject,
    request: &PredictionRequest,
) -> (Vec<CandidateInformation>, PoolStats) {
    let (object, request) = (object.clone(), request.clone());
    let (answers, stats) = tokio::task::spawn_blocking(move || {
        let answers = pool.predict(&object, &request);
        (answers, pool.stats())
    })
    .await
    .unwrap();
    (answers.unwrap(), stats)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn garbage_from_one_worker_is_refused_and_its_candidates_go_to_another() {
    let scene = set_up(&ActiveSceneSpec {
        part: Part::Zigzag,
        instances: 2,
        seed: 4,
        width_px: 320,
        height_px: 256,
        samples_per_pixel: 1,
        candidates: 6,
    })
    .unwrap();
    let calibration = Calibration::embedded(Part::Zigzag).unwrap();
    let object = prediction_object(&scene, &calibration, false).unwrap();
    let request = PredictionRequest {
        t_w_o: scene.initial_t_w_o,
        candidates: (1..6).map(|i| (i, scene.candidates[i as usize])).collect(),
        sigma: PredictionSigma::Rendered,
        seed: 9,
        with_maps: false,
    };
    let sound = TestServer::start(
        tonic::service::Routes::new(
            glint_uncertainty::server::Uncertainty::default().into_service(),
        ),
        glint_uncertainty::server::SERVICE_NAME,
    )
    .await;
    let config = PoolConfig {
        in_flight_per_worker: 1,
        retry_after: std::time::Duration::from_millis(100),
        ..PoolConfig::default()
    };
    let handle = tokio::runtime::Handle::current();
    // The reference: the sound worker alone.
    let reference = RemotePrediction::new(
        handle.clone(),
        WorkerSource::Static(vec![sound.target.clone()]),
        config,
    );
    let (reference, _) = decide(reference, &object, &request).await;
    for lie in [Lie::NotPsd, Lie::WrongCandidate] {
        let liar = TestServer::start(
            tonic::service::Routes::new(UncertaintyServiceServer::new(LyingWorker(lie))),
            "glint.v1.UncertaintyService",
        )
        .await;
        // The liar first, so it is asked before the sound worker.
        let pool = RemotePrediction::new(
            handle.clone(),
            WorkerSource::Static(vec![liar.target.clone(), sound.target.clone()]),
            config,
        );
        let (answers, stats) = decide(pool, &object, &request).await;
        assert!(stats.rejected >= 1, "{stats:?}");
        assert_eq!(stats.answered_by.get(&liar.target), None, "{stats:?}");
        assert_eq!(answers.len(), reference.len());
        for (a, r) in answers.iter().zip(&reference) {
            assert_eq!(a.index, r.index);
            assert_eq!(a.information, r.information, "candidate {}", r.index);
        }
        let _ = liar.stop().await;
    }
    // A slow worker: its call passes its deadline (DEADLINE_EXCEEDED), its candidate goes to
    // the sound worker, and the decision does not wait the 30 s out.
    let slow = TestServer::start(
        tonic::service::Routes::new(UncertaintyServiceServer::new(LyingWorker(Lie::Slow))),
        "glint.v1.UncertaintyService",
    )
    .await;
    let pool = RemotePrediction::new(
        handle.clone(),
        WorkerSource::Static(vec![slow.target.clone(), sound.target.clone()]),
        PoolConfig {
            call_deadline: std::time::Duration::from_millis(500),
            ..config
        },
    );
    let started = std::time::Instant::now();
    let (answers, stats) = decide(pool, &object, &request).await;
    assert!(stats.resent >= 1, "{stats:?}");
    assert!(
        started.elapsed() < std::time::Duration::from_secs(20),
        "the decision waited for the slow worker: {:?}",
        started.elapsed()
    );
    for (a, r) in answers.iter().zip(&reference) {
        assert_eq!(a.information, r.information, "candidate {}", r.index);
    }
    let _ = slow.stop().await;
    let _ = sound.stop().await;
}
