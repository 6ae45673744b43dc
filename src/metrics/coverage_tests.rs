//! Tests of [`super`]: coverage, the reliability diagram and the calibration fit against analytic truths.

use super::*;
use crate::pose::posterior::ModeEvidence;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// The Hessian of evidence that says σ = `sp` m in x and y and `st` rad in θ, independently.
fn diagonal_hessian(sp: f64, st: f64) -> [[f64; 3]; 3] {
    [
        [1.0 / (sp * sp), 0.0, 0.0],
        [0.0, 1.0 / (sp * sp), 0.0],
        [0.0, 0.0, 1.0 / (st * st)],
    ]
}

/// One posterior per truth whose evidence says σ = `sp` m and `st` rad about the origin (raw: τ = 1, no
/// floors or tails), with its truth.
fn raw_posteriors(truths: &[Se2], sp: f64, st: f64) -> Vec<(PosePosterior, Se2)> {
    let hessian = diagonal_hessian(sp, st);
    let evidence = ModeEvidence {
        pose: Se2::default(),
        nats: 0.0,
        hessian,
    };
    truths
        .iter()
        .map(|&t| {
            let raw = PosteriorConfig::untempered();
            (
                PosePosterior::from_evidence(&[evidence], 300, &Symmetry::default(), &raw),
                t,
            )
        })
        .collect()
}

/// The pairs to score: each truth against its posterior, the estimate at the origin.
fn scored_of(posteriors: &[(PosePosterior, Se2)], contact_pixels: usize) -> Vec<Scored<'_>> {
    posteriors
        .iter()
        .map(|(p, t)| Scored {
            posterior: p,
            truth: *t,
            symmetry: Symmetry::default(),
            position_mm: t.x.hypot(t.y) * 1e3,
            theta_rad: Some(t.theta.abs()),
            contact_pixels,
            prior: None,
        })
        .collect()
}

#[test]
fn coverage_counts_levels_and_confident_misses() {
    let c = Coverage::of(
        [
            (0.1, 1.0),
            (0.6, 2.0),
            (0.93, 9.0),
            (0.99, 7.0),
            (0.99, 1.0),
        ]
        .into_iter(),
    )
    .unwrap();
    assert_eq!(c.pairs, 5);
    assert_eq!(c.inside, [0.2, 0.4, 0.6]);
    assert_eq!(c.confidently_wrong, 1);
    assert!(Coverage::of(std::iter::empty()).is_none());
}

#[test]
fn the_fit_recovers_a_known_error_scale() {
    // Independent truth: estimates off by N(0, 2 mm) in x and y and N(0, 3°) in θ, while every posterior's
    // evidence says σ = 0.2 mm and 0.3° at τ = 1 (a sensor's pixels taken as independent). Fitted, the 90 %
    // region covers about 90 % of the truths, where the raw evidence covers almost none.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let pos = Normal::new(0.0, 0.002).unwrap();
    let rot = Normal::new(0.0, 3f64.to_radians()).unwrap();
    let truths: Vec<Se2> = (0..300)
        .map(|_| {
            Se2::new(
                pos.sample(&mut rng),
                pos.sample(&mut rng),
                rot.sample(&mut rng),
            )
        })
        .collect();
    let raw = PosteriorConfig::untempered();
    let posteriors = raw_posteriors(&truths, 0.0002, 0.3f64.to_radians());
    let scored = scored_of(&posteriors, 500);
    let before = coverage_with(&scored, None, 1000).unwrap();
    assert!(before.inside[1] < 0.1, "{before:?}");
    let fit = fit_posterior(&scored, &raw);
    let after = fit.coverage.unwrap();
    assert!((after.inside[1] - 0.9).abs() <= 0.05, "{fit:?}");
    assert!(after.inside[0] > 0.35 && after.inside[0] < 0.65, "{fit:?}");
}

#[test]
fn the_fit_keeps_a_sharp_core_under_heavy_tails() {
    // Independent truth: 80 % of the estimates off by N(0, 0.3 mm) and N(0, 1°), 20 % by N(0, 4 mm) and a θ
    // anywhere, while every posterior's evidence says σ = 0.1 mm and 0.1°. A calibrated fit covers the truth at
    // 50 % and 90 %, and its top mode's core stays near the 0.3 mm of the bulk where one Gaussian wide enough
    // for the outliers would be several millimetres wide.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let (near_p, near_t) = (
        Normal::new(0.0, 3e-4).unwrap(),
        Normal::new(0.0, 1f64.to_radians()).unwrap(),
    );
    let far_p = Normal::new(0.0, 4e-3).unwrap();
    let truths: Vec<Se2> = (0..400)
        .map(|i| {
            if i % 5 == 0 {
                let theta: f64 =
                    rand::Rng::random_range(&mut rng, -std::f64::consts::PI..std::f64::consts::PI);
                Se2::new(far_p.sample(&mut rng), far_p.sample(&mut rng), theta)
            } else {
                Se2::new(
                    near_p.sample(&mut rng),
                    near_p.sample(&mut rng),
                    near_t.sample(&mut rng),
                )
            }
        })
        .collect();
    let posteriors = raw_posteriors(&truths, 1e-4, 0.1f64.to_radians());
    let scored = scored_of(&posteriors, 300);
    let fit = fit_posterior(&scored, &PosteriorConfig::default());
    let (_, r) = reliability(&scored, Some(&fit.config), 2000).unwrap();
    let at = |level: f64| r.inside[RELIABILITY_LEVELS.iter().position(|&l| l == level).unwrap()];
    assert!((at(0.5) - 0.5).abs() <= 0.08, "{r:?} {fit:?}");
    assert!((at(0.9) - 0.9).abs() <= 0.05, "{r:?} {fit:?}");
    let fitted = posteriors[0]
        .0
        .recalibrated(&Symmetry::default(), &fit.config);
    let core_mm = fitted.modes[0].cov[0][0].sqrt() * 1e3;
    assert!(
        core_mm > 0.15 && core_mm < 0.5,
        "core σ {core_mm} mm, {fit:?}"
    );
    let far = fitted.modes[0].tails.far;
    assert!(far > 0.1 && far < 0.35, "far share {far}, {fit:?}");
}

#[test]
fn a_calibration_replays_a_tracks_fusion_in_frame_order() {
    // Three frames of a track of one object at pose a: the second frame's contact slightly prefers the pose
    // turned by half a turn, the earlier frame says a. The tracker fuses each frame with the one before.
    let a = Se2::new(0.001, -0.002, 0.3);
    let flipped = Se2::new(0.001, -0.002, 0.3 - std::f64::consts::PI);
    let hessian = [[4e6, 0.0, 0.0], [0.0, 4e6, 0.0], [0.0, 0.0, 400.0]];
    let ev = |pose: Se2, nats: f64| ModeEvidence {
        pose,
        nats,
        hessian,
    };
    let symmetry = Symmetry::default();
    let recorded = PosteriorConfig::default();
    let own = |evidence: &[ModeEvidence]| {
        PosePosterior::from_evidence(evidence, 300, &symmetry, &recorded)
    };
    let first = own(&[ev(a, 0.0)]);
    let second = crate::pose::fusion::fuse(
        &own(&[ev(flipped, 0.0), ev(a, 1.0)]),
        &first,
        &symmetry,
        recorded.fusion_weight,
    );
    let third = crate::pose::fusion::fuse(
        &own(&[ev(a, 0.0)]),
        &second,
        &symmetry,
        recorded.fusion_weight,
    );
    assert_eq!(second.modes[0].pose(), a, "the earlier frame decides");
    let frames = [&first, &second, &third];
    let scored: Vec<Scored<'_>> = frames
        .iter()
        .enumerate()
        .map(|(i, p)| Scored {
            posterior: p,
            truth: a,
            symmetry,
            position_mm: 0.0,
            theta_rad: Some(0.0),
            contact_pixels: 300,
            prior: i.checked_sub(1),
        })
        .collect();
    // Under the calibration it was recorded with, the replay gives back what the track reported.
    let replayed = calibrated(&scored, &recorded);
    for (r, f) in replayed.iter().zip(frames) {
        assert_eq!(r.modes.len(), f.modes.len());
        for (m, n) in r.modes.iter().zip(&f.modes) {
            assert_eq!(m.pose(), n.pose());
            assert!((m.weight - n.weight).abs() < 1e-12, "{m:?} vs {n:?}");
        }
    }
    // Without the links each frame is its own again: the second frame's top mode is the flipped pose, and the
    // truth is far less likely under it.
    let alone: Vec<Scored<'_>> = scored
        .iter()
        .map(|s| Scored {
            prior: None,
            ..s.clone()
        })
        .collect();
    let unfused = calibrated(&alone, &recorded);
    assert_eq!(unfused[1].modes[0].pose(), flipped);
    let ones = [1.0; 3];
    assert!(
        mean_nll(&scored, &ones, &recorded, NLL_CAP) + 0.1
            < mean_nll(&alone, &ones, &recorded, NLL_CAP)
    );
}

/// Two-frame tracks whose frames each weigh two poses a radian apart, A and B, by a log-likelihood ratio L of A over
/// B with the consistent law L ~ N(±μ, 2μ) (+ where the truth is A): `log_odds` of one frame is then exactly the
/// posterior log-odds of A at τ = 1. With `independent` each frame draws its own L; without, the second frame
/// repeats the first (the frames share their errors). The second frame is fused with the first.
fn two_frame_tracks(independent: bool, seed: u64) -> Vec<(PosePosterior, Se2, Option<usize>)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mu: f64 = 1.5;
    let spread = Normal::new(0.0, (2.0 * mu).sqrt()).unwrap();
    let (a, b) = (Se2::new(0.0, 0.0, 0.0), Se2::new(0.0, 0.0, 1.0));
    let (sp, st) = (2e-4, 0.01);
    let hessian = diagonal_hessian(sp, st);
    let frame = |log_odds: f64| {
        let evidence = [
            ModeEvidence {
                pose: a,
                nats: (-log_odds).max(0.0),
                hessian,
            },
            ModeEvidence {
                pose: b,
                nats: log_odds.max(0.0),
                hessian,
            },
        ];
        PosePosterior::from_evidence(
            &evidence,
            300,
            &Symmetry::default(),
            &PosteriorConfig::untempered(),
        )
    };
    let mut out = Vec::new();
    for i in 0..300 {
        let truth_a = i % 2 == 0;
        let sign = if truth_a { 1.0 } else { -1.0 };
        let truth = if truth_a { a } else { b };
        let first = sign * mu + spread.sample(&mut rng);
        let second = if independent {
            sign * mu + spread.sample(&mut rng)
        } else {
            first
        };
        out.push((frame(first), truth, None));
        out.push((frame(second), truth, Some(out.len() - 1)));
    }
    out
}

#[test]
fn the_fit_discounts_a_track_whose_frames_repeat_each_other() {
    // Independent truth: Bayes' rule. Frames that repeat one another carry one frame's evidence, so fusing them as
    // independent is overconfident and the fitted fusion weight falls towards 0; independent frames carry twice the
    // evidence, and the fit keeps the weight near 1.
    let fitted = |independent: bool| {
        let tracks = two_frame_tracks(independent, 5);
        let scored: Vec<Scored<'_>> = tracks
            .iter()
            .map(|(p, t, prior)| Scored {
                posterior: p,
                truth: *t,
                symmetry: Symmetry::default(),
                position_mm: 0.0,
                theta_rad: Some(0.0),
                contact_pixels: 300,
                prior: *prior,
            })
            .collect();
        // From full weight, so that a low κ is the fit's doing.
        let base = PosteriorConfig {
            fusion_weight: 1.0,
            ..PosteriorConfig::untempered()
        };
        fit_posterior(&scored, &base).config
    };
    let repeated = fitted(false);
    let independent = fitted(true);
    assert!(repeated.fusion_weight < 0.35, "{repeated:?}");
    assert!(independent.fusion_weight > 0.65, "{independent:?}");
    // Without track frames the weight is not a fitted setting.
    let single = raw_posteriors(&[Se2::default(); 20], 2e-4, 0.01);
    let base = PosteriorConfig {
        fusion_weight: 0.4,
        ..PosteriorConfig::untempered()
    };
    assert_eq!(
        fit_posterior(&scored_of(&single, 300), &base)
            .config
            .fusion_weight,
        0.4
    );
}
