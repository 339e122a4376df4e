//! The orchestrator's worker pool against real `glint serve uncertainty` processes: a decision
//! fanned out over two workers gives exactly the in-process prediction, also when one worker
//! is killed (SIGKILL) in the middle of the decision; a worker that comes back on its address
//! is used again.

use std::time::{Duration, Instant};

mod common;

use common::argv;

use glint_eval::active::{ActiveSceneSpec, Calibration, prediction_object, set_up};
use glint_geometry::Part;
use glint_orchestrator::local::{LocalEstimation, LocalPrediction};
use glint_orchestrator::remote::prediction::{PoolConfig, RemotePrediction, WorkerSource};
use glint_orchestrator::stages::{
    EstimationStage, PredictionRequest, PredictionSigma, PredictionStage,
};
use nalgebra::Matrix6;

#[test]
fn a_decision_survives_a_worker_killed_mid_way_and_a_returning_worker_is_used_again() {
    let scene = set_up(&ActiveSceneSpec {
        part: Part::Zigzag,
        instances: 3,
        seed: 5,
        width_px: 640,
        height_px: 512,
        samples_per_pixel: 1,
        candidates: 16,
    })
    .unwrap();
    let calibration = Calibration::embedded(Part::Zigzag).unwrap();
    let object = prediction_object(&scene, &calibration, true).unwrap();
    // Poses as a worker decodes them (the wire's quaternion is re-normalised), so the
    // in-process reference sees the same bits.
    let wire = |t: &nalgebra::Isometry3<f64>| {
        nalgebra::Isometry3::try_from(&glint_proto::v1::Pose::from(t)).unwrap()
    };
    let request = PredictionRequest {
        t_w_o: wire(&scene.initial_t_w_o),
        candidates: (1..scene.candidates.len() as u32)
            .map(|i| (i, wire(&scene.candidates[i as usize])))
            .collect(),
        sigma: PredictionSigma::Rendered,
        seed: 17,
        with_maps: false,
    };
    let local = LocalPrediction::default()
        .predict(&object, &request)
        .unwrap();

    let a = common::serve(argv("uncertainty --listen 127.0.0.1:0", &[]));
    let b = common::serve(argv("uncertainty --listen 127.0.0.1:0", &[]));
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let pool = RemotePrediction::new(
        runtime.handle().clone(),
        WorkerSource::Static(vec![a.addr.clone(), b.addr.clone()]),
        PoolConfig {
            retry_after: Duration::from_millis(200),
            ..PoolConfig::default()
        },
    );

    // Kill worker a once it has answered a candidate: it has more in flight then.
    let (a_addr, mut a) = (a.addr.clone(), a);
    let remote = std::thread::scope(|s| {
        let decision = s.spawn(|| pool.predict(&object, &request));
        let started = Instant::now();
        while pool
            .stats()
            .answered_by
            .get(&format!("http://{a_addr}"))
            .is_none_or(|&n| n == 0)
        {
            assert!(
                started.elapsed() < Duration::from_secs(120),
                "a never answered"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        a.child.kill().unwrap();
        decision.join().unwrap()
    })
    .unwrap();
    let stats = pool.stats();
    assert!(
        stats.resent >= 1,
        "the kill hit no call in flight: {stats:?}"
    );
    assert!(stats.answered_by[&format!("http://{}", b.addr)] > 0);

    // The same predictions as in-process, bit for bit: each is seeded by its candidate.
    assert_eq!(remote.len(), local.len());
    for (r, l) in remote.iter().zip(&local) {
        assert_eq!(r.index, l.index);
        assert_eq!(r.information, l.information, "candidate {}", l.index);
        assert_eq!(r.predicted_points, l.predicted_points);
    }
    // Hence the same choice and entropies.
    let estimation = LocalEstimation::default();
    let informations = |p: &[glint_orchestrator::stages::CandidateInformation]| {
        let mut all = vec![Matrix6::zeros(); scene.candidates.len()];
        for c in p {
            all[c.index as usize] = c.information;
        }
        all
    };
    let collected = Matrix6::identity() * 1e4;
    let plan_remote = estimation
        .plan(&collected, &informations(&remote), &[0])
        .unwrap();
    let plan_local = estimation
        .plan(&collected, &informations(&local), &[0])
        .unwrap();
    assert_eq!(plan_remote, plan_local);

    // Worker a comes back on its address: the next decision uses it again.
    drop(a);
    let a = common::serve(argv("uncertainty --listen {}", &[&a_addr]));
    std::thread::sleep(Duration::from_millis(300)); // past retry_after
    let before = pool
        .stats()
        .answered_by
        .get(&format!("http://{}", a.addr))
        .copied()
        .unwrap_or(0);
    let again = pool.predict(&object, &request).unwrap();
    let informations_of = |p: &[glint_orchestrator::stages::CandidateInformation]| {
        p.iter()
            .map(|c| (c.index, c.information))
            .collect::<Vec<_>>()
    };
    assert_eq!(informations_of(&again), informations_of(&remote));
    let after = pool.stats().answered_by[&format!("http://{}", a.addr)];
    assert!(after > before, "the returning worker got no work");
}

#[test]
fn a_decision_without_workers_waits_for_one_and_fails_naming_them_when_none_comes() {
    let scene = set_up(&ActiveSceneSpec {
        part: Part::Zigzag,
        instances: 2,
        seed: 6,
        width_px: 320,
        height_px: 256,
        samples_per_pixel: 1,
        candidates: 4,
    })
    .unwrap();
    let calibration = Calibration::embedded(Part::Zigzag).unwrap();
    let object = prediction_object(&scene, &calibration, false).unwrap();
    let request = PredictionRequest {
        t_w_o: scene.initial_t_w_o,
        candidates: (1..4).map(|i| (i, scene.candidates[i as usize])).collect(),
        sigma: PredictionSigma::Rendered,
        seed: 3,
        with_maps: false,
    };
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let config = PoolConfig {
        retry_after: Duration::from_millis(100),
        decision_deadline: Duration::from_secs(60),
        ..PoolConfig::default()
    };

    // A name that resolves to nothing (a worker service scaled to zero): UNAVAILABLE at the
    // decision's deadline, naming the workers and why there were none.
    let none = RemotePrediction::new(
        runtime.handle().clone(),
        WorkerSource::Dns("no-such-worker.invalid:50051".into()),
        PoolConfig {
            decision_deadline: Duration::from_secs(1),
            ..config
        },
    );
    match none.predict(&object, &request) {
        Err(glint_orchestrator::stages::StageError::Unavailable(m)) => {
            assert!(m.contains("dns:no-such-worker.invalid:50051"), "{m}");
            assert!(m.contains("resolving"), "{m}");
        }
        other => panic!("expected UNAVAILABLE, got {other:?}"),
    }

    // A worker that is not up yet: the decision waits and completes once it comes.
    let free = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = free.local_addr().unwrap().to_string();
    drop(free);
    let pool = RemotePrediction::new(
        runtime.handle().clone(),
        WorkerSource::Static(vec![addr.clone()]),
        config,
    );
    let answers = std::thread::scope(|s| {
        let decision = s.spawn(|| pool.predict(&object, &request));
        std::thread::sleep(Duration::from_millis(700));
        let worker = common::serve(argv("uncertainty --listen {}", &[&addr]));
        let answers = decision.join().unwrap();
        drop(worker);
        answers
    })
    .unwrap();
    assert_eq!(answers.len(), 3);
    let local = LocalPrediction::default()
        .predict(&object, &request)
        .unwrap();
    for (r, l) in answers.iter().zip(&local) {
        assert_eq!(r.index, l.index);
    }
}
