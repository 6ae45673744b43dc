//! The pose posterior end to end: every checked row of the evaluation carries one that holds the truth when the
//! samples are exact, and `tnd posterior` scores and fits it from records files as a user would run it.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::cli_common;

use cli_common::{stderr, tnd_in};
use rand::SeedableRng;
use rand_distr::Distribution;
use tactile_derender::metrics::evaluate::{
    EvalConfig, GroundTruthGenerator, MethodResult, PairRecord,
};
use tactile_derender::metrics::sources::{SimSource, SimSpec};
use tactile_derender::metrics::DepthMetrics;
use tactile_derender::objects::{ObjectSet, Symmetry};
use tactile_derender::pipeline::evaluate::Evaluator;
use tactile_derender::pose::posterior::{
    symmetric_eigen3, ModeEvidence, PosePosterior, PosteriorConfig,
};
use tactile_derender::sensor::Se2;
use tactile_derender::sim::SimConfig;

#[test]
fn exact_samples_give_posteriors_that_hold_the_truth() {
    // Invariants on simulated pairs of the nominal sensor with the true X0 as every sample: each checked row's
    // posterior is a distribution (weights sum to 1, covariances positive definite), its estimate lies in one of
    // its modes, and the truth — under a millimetre away — is inside the 90 % region.
    let specs = vec![
        SimSpec {
            object: "cross_w12_s50".into(),
            pose: Se2::new(0.003, -0.002, 0.4),
            press: 0.006,
            seed: 1,
        },
        SimSpec {
            object: "cylinder_r15".into(),
            pose: Se2::new(-0.002, 0.004, 1.1),
            press: 0.006,
            seed: 2,
        },
    ];
    let src = SimSource::new(SimConfig::default(), ObjectSet::builtin(), specs).unwrap();
    let report = Evaluator::new(EvalConfig::default())
        .evaluate(&src, &GroundTruthGenerator, 3, &mut |_, _| true)
        .unwrap();
    for r in &report.records {
        assert!(
            r.baseline.posterior.is_none(),
            "the paper's baseline has no check"
        );
        for (row, m) in [
            ("model", Some(&r.model)),
            ("combined", r.model_combined.as_ref()),
            ("baseline_checked", r.baseline_checked.as_ref()),
        ] {
            let m = m.unwrap();
            let p = m
                .posterior
                .as_ref()
                .unwrap_or_else(|| panic!("{}: {row}", r.name));
            let total: f64 = p.modes.iter().map(|m| m.weight).sum();
            assert!((total - 1.0).abs() < 1e-9, "{}: {row}: {total}", r.name);
            for mode in &p.modes {
                let (values, _) = symmetric_eigen3(&mode.cov);
                assert!(
                    values.iter().all(|&v| v > 0.0),
                    "{}: {row}: {values:?}",
                    r.name
                );
            }
            assert!(p.mode_of(m.estimate.unwrap(), &r.symmetry).is_some());
            // The contact the best mode predicts is the true contact's size (the estimate is within a millimetre
            // of the truth), where the count on the noisy signature is not held to it.
            let predicted = p.predicted_contact_px.unwrap() as f64;
            let truth = r.contact_pixels as f64;
            assert!(
                (predicted - truth).abs() <= 0.15 * truth + 5.0,
                "{}: {row}: predicted {predicted} px, true {truth}",
                r.name
            );
            if row != "baseline_checked" {
                let region = m.truth_region.unwrap();
                assert!(
                    region <= 0.9,
                    "{}: {row}: truth in the {region} region",
                    r.name
                );
            }
        }
    }
    let coverage = report.model.coverage.unwrap();
    assert_eq!(coverage.pairs, 2);
    assert_eq!(coverage.confidently_wrong, 0);
}

/// A record whose pipeline row is off by `off` (the truth at the origin) with a posterior of σ = 0.5 mm and 2.9°
/// (raw: τ = 1, no floors or tails).
fn record(name: &str, off: Se2) -> PairRecord {
    let hessian = [[4e6, 0.0, 0.0], [0.0, 4e6, 0.0], [0.0, 0.0, 400.0]];
    let raw = PosteriorConfig::untempered();
    let estimate = off;
    let off_m = off.x.hypot(off.y);
    let posterior = PosePosterior::from_evidence(
        &[ModeEvidence {
            pose: estimate,
            nats: 0.0,
            hessian,
        }],
        300,
        &Symmetry::default(),
        &raw,
    );
    let result = MethodResult {
        estimate: Some(estimate),
        pose: Some(tactile_derender::metrics::pose::PoseErrors {
            position_mm: off_m * 1e3,
            position_axis_excluded: false,
            theta_rad: Some(off.theta.abs()),
            chamfer_m2: 0.0,
        }),
        posterior: Some(posterior),
        ..record_base()
    };
    PairRecord {
        name: name.into(),
        object: "part".into(),
        truth: Se2::default(),
        contact_pixels: 300,
        symmetry: Symmetry::default(),
        model: result.clone(),
        model_multi: None,
        model_combined: Some(result),
        baseline: record_base(),
        baseline_checked: None,
    }
}

/// A method's scores with nothing estimated.
fn record_base() -> MethodResult {
    MethodResult {
        depth: DepthMetrics {
            l1_mm: 1.0,
            l1_union_mm: None,
            psnr_db: 20.0,
            ssim: 0.5,
        },
        estimate: None,
        pose: None,
        posterior: None,
        truth_region: None,
    }
}

#[test]
fn tnd_posterior_scores_records_and_fits_a_calibration_that_covers_them() {
    let dir = tempfile::tempdir().unwrap();
    // 120 pairs off by N(0, 1.5 mm) in x and y and N(0, 6°) in θ while each posterior says σ = 0.5 mm and 2.9°:
    // overconfident as recorded.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let (position, theta) = (
        rand_distr::Normal::new(0.0, 0.0015).unwrap(),
        rand_distr::Normal::new(0.0, 6f64.to_radians()).unwrap(),
    );
    let mut offsets = Vec::new();
    let mut text = String::from("{\"settings\":{\"seed\":0}}\n");
    for i in 0..120 {
        let off = Se2::new(
            position.sample(&mut rng),
            position.sample(&mut rng),
            theta.sample(&mut rng),
        );
        offsets.push(off);
        let line = serde_json::json!({"split": "unseen_objects", "index": i,
            "record": record(&format!("p{i}"), off)});
        text.push_str(&format!("{line}\n"));
    }
    std::fs::write(dir.path().join("r.jsonl"), text).unwrap();
    let lines = |o: &std::process::Output| -> Vec<serde_json::Value> {
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    };
    let o = tnd_in(
        dir.path(),
        &["posterior", "--records", "r.jsonl", "--method", "combined"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let before = &lines(&o)[0];
    assert_eq!(before["rows"], "combined");
    assert_eq!(before["coverage"]["pairs"], 120);
    // Independent truth: inside the 90 % region of a 3-D Gaussian means d² ≤ 6.25 (χ²₃), d the Mahalanobis
    // distance of the offset under σ = 0.5 mm, 0.5 mm, 0.05 rad.
    let want = offsets
        .iter()
        .filter(|o| {
            (o.x / 5e-4).powi(2) + (o.y / 5e-4).powi(2) + (o.theta / 0.05).powi(2) <= 6.2514
        })
        .count() as f64
        / 120.0;
    let inside90 = before["coverage"]["inside"][1].as_f64().unwrap();
    assert!((inside90 - want).abs() < 0.03, "{before} vs {want}");
    assert!(inside90 < 0.4, "{before}");
    assert!(
        stderr(&o).contains("| combined | all | 120 |"),
        "{}",
        stderr(&o)
    );
    let o = tnd_in(
        dir.path(),
        &[
            "posterior",
            "--records",
            "r.jsonl",
            "--method",
            "combined",
            "--fit",
            "fit.json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let after = &lines(&o)[0];
    // Fitted by the log density of the truth, the 50 % and 90 % regions hold about that share, and the top mode's σ
    // is near the 1.5 mm the estimates are off by.
    let inside = &after["coverage"]["inside"];
    assert!((inside[0].as_f64().unwrap() - 0.5).abs() <= 0.1, "{after}");
    assert!((inside[1].as_f64().unwrap() - 0.9).abs() <= 0.06, "{after}");
    let sigma = after["reliability"]["median_sigma_position_mm"]
        .as_f64()
        .unwrap();
    assert!(sigma > 1.0 && sigma < 2.2, "{after}");
    // The fitted file is a calibration the other commands take, and scores the same.
    let o = tnd_in(
        dir.path(),
        &[
            "posterior",
            "--records",
            "r.jsonl",
            "--method",
            "combined",
            "--config",
            "fit.json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(lines(&o)[0]["coverage"], after["coverage"]);
    // Bad input: one line naming the file and the problem.
    std::fs::write(dir.path().join("bad.json"), "{\"temperature\": -1}").unwrap();
    let o = tnd_in(
        dir.path(),
        &["posterior", "--records", "r.jsonl", "--config", "bad.json"],
    );
    let err = stderr(&o);
    assert!(
        !o.status.success() && err.contains("bad.json") && err.contains("temperature"),
        "{err}"
    );
    std::fs::write(dir.path().join("notes.txt"), "hello\n").unwrap();
    let o = tnd_in(dir.path(), &["posterior", "--records", "notes.txt"]);
    let err = stderr(&o);
    assert!(
        !o.status.success() && err.contains("notes.txt") && err.lines().count() == 1,
        "{err}"
    );
}
