//! `glint eval …` end to end on small scenes: the files a user audits, and clear errors.

mod common;

use common::{argv, glint, printed as text};

/// `part,views,method` → (n, rate 5/5, rate 2/2).
fn results(csv: &str) -> std::collections::HashMap<(String, u32, String), (usize, f64, f64)> {
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("part,views,method,n,rate_5mm5deg,rate_2mm2deg")
    );
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 6, "{l}");
            (
                (f[0].to_owned(), f[1].parse().unwrap(), f[2].to_owned()),
                (
                    f[3].parse().unwrap(),
                    f[4].parse().unwrap(),
                    f[5].parse().unwrap(),
                ),
            )
        })
        .collect()
}

#[test]
fn eval_refine_writes_auditable_results() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("table");
    let args = argv(
        "eval refine --parts eye-bolt --scenes 1 --views-per-scene 2 --views 1,2 --instances 4 \
        --spp 1 --tune-scenes 1 --view-bias-scenes 1 --icp-distances-mm 5,10 --out {}",
        &[out.to_str().unwrap()],
    );
    let o = glint(&args);
    assert!(o.status.success(), "{}", text(&o));
    let rows = results(&std::fs::read_to_string(out.join("results.csv")).unwrap());
    // Every group × view count × method is there, with the same trials for each method.
    for group in ["eye-bolt", "all"] {
        for k in [1, 2] {
            let n: Vec<usize> = ["initial", "aligned", "sdf", "icp", "icp_plane"]
                .iter()
                .map(|m| rows[&(group.to_owned(), k, m.to_string())].0)
                .collect();
            assert!(
                n[0] > 0 && n.iter().all(|&x| x == n[0]),
                "{group} {k}: {n:?}"
            );
        }
    }
    for (key, (_, r5, r2)) in &rows {
        assert!((0.0..=1.0).contains(r5) && r2 <= r5, "{key:?}: {r5} {r2}");
    }
    // trials.csv: one row per trial and method; initial poses within the 30 mm/30° test.
    let trials = std::fs::read_to_string(out.join("trials.csv")).unwrap();
    let header: Vec<&str> = trials.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (method, te, re) = (
        col("method"),
        col("translation_error_mm"),
        col("rotation_error_deg"),
    );
    let mut count = 0;
    let (mut initial_t, mut sdf_t) = (Vec::new(), Vec::new());
    for line in trials.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (t, r): (f64, f64) = (f[te].parse().unwrap(), f[re].parse().unwrap());
        match f[method] {
            "initial" => {
                count += 1;
                assert!(t < 30.0 && r < 30.0, "{line}");
                initial_t.push(t);
            }
            "sdf" => sdf_t.push(t),
            _ => {}
        }
    }
    // Refinement helps: the SDF refiner's median translation error is below the initial one.
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (mi, ms) = (median(&mut initial_t), median(&mut sdf_t));
    assert!(
        ms < mi,
        "median translation error: sdf {ms} mm vs initial {mi} mm"
    );
    let n1 = rows[&("all".to_owned(), 1, "initial".to_owned())].0;
    let n2 = rows[&("all".to_owned(), 2, "initial".to_owned())].0;
    assert_eq!(count, n1 + n2);
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(
        table.contains("| initial pose |") && table.contains("2 views — ICP"),
        "{table}"
    );
    let nees = std::fs::read_to_string(out.join("nees.csv")).unwrap();
    assert!(
        nees.lines()
            .next()
            .is_some_and(|h| h.ends_with("mean_nees_view_bias,median_nees_view_bias")),
        "{nees}"
    );
    // The refiner's own verdict is tallied per part and view count, flagged ≤ all trials.
    let notice = std::fs::read_to_string(out.join("notice.csv")).unwrap();
    let all_1 = notice
        .lines()
        .find(|l| l.starts_with("all,1,"))
        .expect("notice.csv has the all/1-view row");
    let f: Vec<usize> = all_1
        .split(',')
        .skip(2)
        .take(5)
        .map(|x| x.parse().unwrap())
        .collect();
    // n, flagged, worse, caught, false alarms: caught + false alarms = flagged.
    assert!(
        f[1] <= f[0] && f[3] + f[4] == f[1] && f[3] <= f[2],
        "{all_1}"
    );

    // A rerun reads the cached scenes back and reproduces the same numbers.
    let again = glint(&args);
    assert!(again.status.success(), "{}", text(&again));
    let rerun = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(results(&rerun), rows);
}

#[test]
fn eval_refine_rejects_bad_arguments_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    for (flag, value, needle) in [
        ("--views", "1,9", "--views"),
        ("--icp-distances-mm", "0,-1", "--icp-distances-mm"),
        ("--parts", "gear,spanner", "spanner"),
        ("--window-radius-px", "0", "--window-radius-px"),
        ("--sdf-gates-mm", "10,40", "--sdf-gates-mm"),
    ] {
        let mut args = vec!["eval", "refine", "--views-per-scene", "4", "--out"];
        args.push(out.to_str().unwrap());
        args.extend([flag, value]);
        let o = glint(&args);
        let err = text(&o);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(needle) && !err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{flag} {value} left output behind");
    }
}

#[test]
fn eval_initial_poses_rejects_a_ratio_it_cannot_fit_at() {
    for ratio in ["0", "-2", "nan"] {
        let flag = format!("--depth-to-lateral={ratio}");
        let o = glint(argv("eval initial-poses --samples 100 {}", &[&flag]));
        let err = text(&o);
        assert_ne!(o.status.code(), Some(0), "{ratio}: {err}");
        assert!(
            err.contains("--depth-to-lateral") && !err.contains("panicked"),
            "{err}"
        );
    }
}

#[test]
fn eval_uncertainty_writes_the_scatter() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("unc");
    let o = glint(argv(
        "eval uncertainty --part gear --repeats 4 --spp 1 --out {}",
        &[out.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", text(&o));
    let csv = std::fs::read_to_string(out.join("scatter.csv")).unwrap();
    let values: Vec<(f64, f64)> = csv
        .lines()
        .skip(1)
        .map(|l| {
            let (a, b) = l.split_once(',').unwrap();
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect();
    assert!(values.len() >= 100);
    assert!(values.iter().all(|&(p, m)| p > 0.0 && m >= 0.0));
    // The predicted scale is right to within an order of magnitude: eq 1–5 with a measured
    // noise model, against the spread of real matches.
    let mut ratios: Vec<f64> = values.iter().map(|(p, m)| m / p).collect();
    ratios.sort_by(f64::total_cmp);
    let median = ratios[ratios.len() / 2];
    assert!(
        (0.1..10.0).contains(&median),
        "median measured/predicted {median}"
    );
    assert!(out.join("scatter.png").exists() && out.join("report.md").exists());
}

#[test]
fn eval_refine_runs_on_a_user_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("bracket.ply");
    let o = glint(argv(
        "mesh export --part zigzag --unit mm --out {}",
        &[mesh.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", text(&o));
    let out = dir.path().join("table");
    let run = |symmetry: &str, out: &std::path::Path| {
        glint(argv(
            "eval refine --mesh {} --unit mm --symmetry {} --scenes 1 \
            --views-per-scene 1 --views 1 --instances 4 --spp 1 \
            --tune-scenes 1 --icp-distances-mm 10 --out {}",
            &[mesh.to_str().unwrap(), symmetry, out.to_str().unwrap()],
        ))
    };
    let o = run("discrete:z:2", &out);
    assert!(o.status.success(), "{}", text(&o));
    // The mesh replaces the five parts: its file stem names its rows, and `all` is just it.
    let rows = results(&std::fs::read_to_string(out.join("results.csv")).unwrap());
    let mut groups: Vec<&str> = rows.keys().map(|(g, _, _)| g.as_str()).collect();
    groups.sort();
    groups.dedup();
    assert_eq!(groups, ["all", "bracket"]);
    for m in ["initial", "sdf", "icp"] {
        let own = rows[&("bracket".to_owned(), 1, m.to_owned())];
        assert!(own.0 > 0, "{m}: no trials");
        assert_eq!(own, rows[&("all".to_owned(), 1, m.to_owned())], "{m}");
    }
    let trials = std::fs::read_to_string(out.join("trials.csv")).unwrap();
    assert!(
        trials.lines().skip(1).all(|l| l.starts_with("bracket,")),
        "{trials}"
    );

    // A symmetry the mesh frame cannot have is a usage error (clap's exit code 2), a mesh
    // that is not there names its path; neither writes anything.
    let never = dir.path().join("never");
    let o = run("discrete:w:2", &never);
    let err = text(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("--symmetry") && err.contains("\"w\""), "{err}");
    std::fs::remove_file(&mesh).unwrap();
    let o = run("discrete:z:2", &never);
    let err = text(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("bracket.ply") && !err.contains("panicked"),
        "{err}"
    );
    assert!(!never.exists());
}

/// `glint eval COMMAND --out DIR` with each case's flags exits 1 or 2 with an error holding
/// the case's needle, no panic, and writes nothing; the calibration cases every
/// multi-part experiment shares are added.
fn rejects_before_writing(command: &str, cases: &[(Vec<&str>, &str)]) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let missing = dir.path().join("missing.json");
    let missing = missing.to_str().unwrap();
    let calibration_cases = [
        (vec!["--parts", "gear,spanner"], "spanner"),
        (
            vec![
                "--parts",
                "gear,zigzag",
                "--material",
                missing,
                "--response",
                missing,
            ],
            "one part",
        ),
        (
            vec![
                "--parts",
                "gear",
                "--material",
                missing,
                "--response",
                missing,
            ],
            "missing.json",
        ),
    ];
    for (extra, needle) in cases.iter().chain(&calibration_cases) {
        let mut args = vec!["eval", command, "--out", out.to_str().unwrap()];
        args.extend(extra.iter().copied());
        let o = glint(&args);
        let err = text(&o);
        assert!(matches!(o.status.code(), Some(1 | 2)), "{extra:?}: {err}");
        assert!(
            err.contains(needle) && !err.contains("panicked"),
            "{extra:?}: {err}"
        );
        assert!(!out.exists(), "{extra:?} left output behind");
    }
}

#[test]
fn eval_nbv_rejects_bad_arguments_before_writing() {
    rejects_before_writing(
        "nbv",
        &[
            (
                vec!["--parts", "zigzag", "--min-visib-fract", "2"],
                "--min-visib-fract",
            ),
            (
                vec!["--parts", "zigzag", "--max-views", "9", "--candidates", "4"],
                "max_views",
            ),
        ],
    );
}

#[test]
fn eval_nbv_writes_rates_that_follow_from_its_trials() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fig9");
    let o = glint(argv(
        "eval nbv --parts zigzag --scenes 1 --detection-views 1 \
        --candidates 5 --max-views 2 --instances 3 --resolution 320x256 \
        --spp 1 --random-draws 2 --min-visib-fract 0.5 --nbv-error-model shipped --out {}",
        &[out.to_str().unwrap()],
    ));
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    for file in [
        "results.csv",
        "trials.csv",
        "paired.csv",
        "table.md",
        "fig9.png",
        "index.html",
    ] {
        assert!(out.join(file).is_file(), "{file}");
    }
    let trials = std::fs::read_to_string(out.join("trials.csv")).unwrap();
    let mut lines = trials.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    let trials_n = rows
        .iter()
        .filter(|r| r[col("policy")] == "max_distance" && r[col("views")] == "1")
        .count();
    assert!(trials_n >= 1, "{trials}");
    // Every run takes distinct views, one per step.
    let mut runs: std::collections::HashMap<(String, String, String), Vec<String>> =
        Default::default();
    for r in &rows {
        let key = (
            r[col("instance")].clone(),
            r[col("policy")].clone(),
            r[col("draw")].clone(),
        );
        runs.entry(key).or_default().push(r[col("view")].clone());
    }
    assert_eq!(
        runs.len(),
        trials_n * 6,
        "4 policies, Random twice, NBV under the error model"
    );
    for (key, views) in &runs {
        assert_eq!(views.len(), 2, "{key:?}");
        assert_ne!(views[0], views[1], "{key:?}");
    }
    // Where NBV under the error model took NBV's views it holds NBV's pose, and the
    // information that survives the model is at most eq 18's (the sandwich I M⁺ I ⪯ I, the
    // per-view bias only adds covariance): its entropy is higher.
    let step = |policy: &str, instance: &str, views: &str| {
        rows.iter()
            .find(|r| {
                r[col("policy")] == policy
                    && r[col("instance")] == instance
                    && r[col("views")] == views
            })
            .unwrap()
    };
    let mut same = 0;
    for r in rows
        .iter()
        .filter(|r| r[col("policy")] == "nbv_error_model")
    {
        assert!(!r[col("predicted_entropy_nats")].is_empty(), "{r:?}");
        let instance = &r[col("instance")];
        let views = &r[col("views")];
        let taken = |p: &str| runs[&(instance.clone(), p.to_string(), "0".to_string())].clone();
        let n: usize = views.parse().unwrap();
        if taken("nbv")[..n] != taken("nbv_error_model")[..n] {
            continue;
        }
        same += 1;
        let nbv = step("nbv", instance, views);
        for c in ["err_mm", "err_deg"] {
            assert_eq!(r[col(c)], nbv[col(c)], "{c}: {r:?}");
        }
        let h = |r: &Vec<String>| r[col("entropy_nats")].parse::<f64>().unwrap();
        if r[col("status")].starts_with("error") {
            // Not refined this step: each keeps what it had, the prior's alone if nothing.
            assert!(h(r) >= h(nbv), "{r:?} against {nbv:?}");
        } else {
            assert!(h(r) > h(nbv), "{r:?} against {nbv:?}");
        }
    }
    assert!(same >= 1, "no step where the two NBVs agree: {trials}");
    // results.csv's rates are the trials' own: Random's the mean of its draws.
    let results = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert!(results.starts_with("part,policy,views,n,rate_5mm5deg,rate_2mm2deg\n"));
    for line in results.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (policy, views): (&str, &str) = (f[1], f[2]);
        let hits: Vec<f64> = rows
            .iter()
            .filter(|r| r[col("policy")] == policy && r[col("views")] == views)
            .map(|r| {
                let (mm, deg): (f64, f64) = (
                    r[col("err_mm")].parse().unwrap(),
                    r[col("err_deg")].parse().unwrap(),
                );
                f64::from(u8::from(mm < 5.0 && deg < 5.0))
            })
            .collect();
        let expected = hits.iter().sum::<f64>() / hits.len() as f64;
        assert_eq!(f[3].parse::<usize>().unwrap(), trials_n, "{line}");
        // results.csv rounds to 4 decimals; errors are printed to 4 decimals too, so a trial
        // exactly at the threshold could differ: none is, at this precision.
        assert!(
            (f[4].parse::<f64>().unwrap() - expected).abs() < 1e-4,
            "{line}"
        );
    }
}

#[test]
fn eval_prediction_rejects_bad_arguments_before_writing() {
    rejects_before_writing(
        "prediction",
        &[
            (vec!["--good-depth-mm=-1"], "--good-depth-mm"),
            (vec!["--candidates", "1"], "--candidates"),
            (vec!["--min-visib-fract", "1.5"], "--min-visib-fract"),
        ],
    );
}

#[test]
fn eval_prediction_ranks_every_candidate_of_every_bin() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("prediction");
    let o = glint(argv(
        "eval prediction --parts zigzag --scenes 2 --candidates 3 \
        --instances 3 --resolution 320x256 --spp 1 --out {}",
        &[out.to_str().unwrap()],
    ));
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let csv = std::fs::read_to_string(out.join("prediction.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "part,scene,view,iou_missing,spearman_sigma,logdet_ratio,predicted_rank,oracle_rank,\
         instance"
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // Every ranking (bin, instance) ranks the 3 candidates 1, 2, 3 both ways.
    let mut rankings: std::collections::BTreeMap<(&str, &str), [Vec<&str>; 2]> = Default::default();
    for r in &rows {
        let entry = rankings.entry((r[1], r[8])).or_default();
        entry[0].push(r[6]);
        entry[1].push(r[7]);
    }
    assert!(rankings.len() >= 2, "{csv}");
    assert!(
        rankings.keys().any(|k| k.0 == "1"),
        "both bins judged: {csv}"
    );
    for (key, mut columns) in rankings {
        for ranks in &mut columns {
            ranks.sort_unstable();
            assert_eq!(ranks, &["1", "2", "3"], "{key:?}: {csv}");
        }
    }
    for r in &rows {
        let iou: f64 = r[3].parse().unwrap();
        assert!(iou.is_nan() || (0.0..=1.0).contains(&iou), "{r:?}");
        assert!(r[5].parse::<f64>().unwrap().is_finite(), "{r:?}");
    }
    let summary = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    let parts: Vec<&str> = summary
        .lines()
        .skip(1)
        .map(|l| &l[..l.find(',').unwrap()])
        .collect();
    assert_eq!(parts, ["zigzag", "all"]);
    for file in ["summary.md", "fig8_zigzag.png", "index.html"] {
        assert!(out.join(file).is_file(), "{file}");
    }
}
