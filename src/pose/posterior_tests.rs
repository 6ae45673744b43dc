//! Tests of [`super`]: eigen-decomposition, the Laplace covariance, region masses against the chi-square law, mode
//! weights and merging, symmetry.
use super::*;
use crate::objects::RotationSymmetry;

fn diag(a: f64, b: f64, c: f64) -> Mat3 {
    [[a, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, c]]
}

#[test]
fn jacobi_eigen_decomposes_a_symmetric_matrix() {
    // Invariant: A v = λ v for each pair, and the vectors orthonormal.
    let a = [[4.0, 1.0, -2.0], [1.0, 3.0, 0.5], [-2.0, 0.5, 1.0]];
    let (values, v) = symmetric_eigen3(&a);
    for k in 0..3 {
        for i in 0..3 {
            let av: f64 = (0..3).map(|j| a[i][j] * v[j][k]).sum();
            assert!((av - values[k] * v[i][k]).abs() < 1e-10);
        }
        for m in 0..3 {
            let dot: f64 = (0..3).map(|i| v[i][k] * v[i][m]).sum();
            assert!((dot - f64::from(u8::from(k == m))).abs() < 1e-10);
        }
    }
    // Trace and determinant are preserved.
    assert!((values.iter().sum::<f64>() - 8.0).abs() < 1e-10);
}

#[test]
#[allow(clippy::needless_range_loop)] // a matrix's indices read best as indices
fn laplace_covariance_inverts_the_tempered_hessian() {
    // Analytic: H = diag(1e6, 4e6, 1e2) nats per (m², m², rad²), τ = 4: variances τ/H, plus the floors squared.
    let config = PosteriorConfig {
        covariance_temperature: 4.0,
        floor_position_m: 0.001,
        floor_theta_rad: 0.01,
        ..PosteriorConfig::default()
    };
    let cov = laplace_covariance(&diag(1e6, 4e6, 1e2), 1.0, &config);
    assert!((cov[0][0] - (4e-6 + 1e-6)).abs() < 1e-15);
    assert!((cov[1][1] - (1e-6 + 1e-6)).abs() < 1e-15);
    assert!((cov[2][2] - (0.04 + 1e-4)).abs() < 1e-12);
    // A flat direction is capped at max_sigma (rotation as arc at the lever).
    let flat = laplace_covariance(&diag(1e6, 0.0, -5.0), 1.0, &config);
    assert!((flat[1][1] - (0.03f64.powi(2) + 1e-6)).abs() < 1e-12);
    assert!((flat[2][2] - ((0.03f64 / 0.02).powi(2) + 1e-4)).abs() < 1e-9);
    // A coupled Hessian gives an exactly symmetric covariance whose inverse (less the floors) is H / τ.
    let h = [[2e6, 3e5, 1e4], [3e5, 1e6, -2e3], [1e4, -2e3, 300.0]];
    let bare = PosteriorConfig {
        floor_position_m: 0.0,
        floor_theta_rad: 0.0,
        ..config.clone()
    };
    let c = laplace_covariance(&h, 1.0, &bare);
    for i in 0..3 {
        for j in 0..3 {
            assert_eq!(c[i][j], c[j][i]);
            let product: f64 =
                (0..3).map(|k| c[i][k] * h[k][j]).sum::<f64>() / bare.covariance_temperature;
            assert!(
                (product - f64::from(u8::from(i == j))).abs() < 1e-9,
                "{i} {j}: {product}"
            );
        }
    }
    // A contact a quarter the reference size with exponent ½ doubles the floors.
    let small = PosePosterior::from_evidence(
        &[ModeEvidence {
            pose: Se2::default(),
            nats: 0.0,
            hessian: diag(1e6, 4e6, 1e2),
        }],
        75,
        &Symmetry::default(),
        &PosteriorConfig {
            floor_exponent: 0.5,
            ..config
        },
    );
    assert!((small.modes[0].cov[0][0] - (4e-6 + 4e-6)).abs() < 1e-15);
}

#[test]
fn the_predicted_contact_scales_the_floors_when_chosen() {
    // Measured 300 px, predicted 75 px, exponent ½: the floors double only when the prediction is chosen, and a
    // posterior without a prediction falls back to the measured count; both counts are kept for recalibration.
    let config = PosteriorConfig {
        floor_position_m: 0.001,
        floor_exponent: 0.5,
        contact_from_prediction: false,
        ..PosteriorConfig::untempered()
    };
    let evidence = [ModeEvidence {
        pose: Se2::default(),
        nats: 0.0,
        hessian: diag(1e12, 1e12, 1e8),
    }];
    let none = Symmetry::default();
    let floor = |p: &PosePosterior| p.modes[0].cov[0][0].sqrt();
    let measured =
        PosePosterior::from_evidence_with(&evidence, 300, Some(75), None, &none, &config);
    assert!((floor(&measured) - 0.001).abs() < 1e-5);
    let chosen = PosteriorConfig {
        contact_from_prediction: true,
        ..config.clone()
    };
    let predicted = measured.recalibrated(&none, &chosen);
    assert!((floor(&predicted) - 0.002).abs() < 1e-5);
    assert_eq!(
        (predicted.contact_px, predicted.predicted_contact_px),
        (300, Some(75))
    );
    let fallback = PosePosterior::from_evidence(&evidence, 300, &none, &chosen);
    assert!((floor(&fallback) - 0.001).abs() < 1e-5);
}

#[test]
fn a_frame_half_as_noisy_weighs_its_evidence_as_four_times_the_nats() {
    // Invariant: with the frame's noise σ₀/2 and no floor, the evidence counts 4x — the same posterior as nats and
    // Hessians four times as large under the assumed noise; off (or without a measured noise), as recorded.
    use crate::pose::posterior::FrameNoise;
    let config = PosteriorConfig {
        frame_noise: true,
        noise_floor_m: 0.0,
        temperature: 3.0,
        covariance_temperature: 2.0,
        ..PosteriorConfig::default()
    };
    let evidence = |k: f64| {
        [
            ModeEvidence {
                pose: Se2::new(0.0, 0.0, 0.1),
                nats: 0.0,
                hessian: diag(4e8 * k, 2e8 * k, 3e4 * k),
            },
            ModeEvidence {
                pose: Se2::new(0.004, 0.0, 1.2),
                nats: 1.5 * k,
                hessian: diag(1e8 * k, 1e8 * k, 1e4 * k),
            },
        ]
    };
    let none = Symmetry::default();
    let noise = FrameNoise {
        assumed_m: 1.38e-3,
        measured_m: 0.69e-3,
        contact_rms_m: None,
    };
    let quieter =
        PosePosterior::from_evidence_with(&evidence(1.0), 200, None, Some(noise), &none, &config);
    let as_nats =
        PosePosterior::from_evidence_with(&evidence(4.0), 200, None, None, &none, &config);
    assert_eq!(quieter.modes.len(), 2);
    for (a, b) in quieter.modes.iter().zip(&as_nats.modes) {
        assert!(
            (a.weight - b.weight).abs() < 1e-12,
            "{} against {}",
            a.weight,
            b.weight
        );
        for i in 0..3 {
            for j in 0..3 {
                assert!((a.cov[i][j] - b.cov[i][j]).abs() <= 1e-9 * b.cov[i][i].abs().max(1e-30));
            }
        }
    }
    // The floor adds to the frame's noise in quadrature: σ_f = σ₀/2 with a floor of √3·σ₀/2 is σ₀ again.
    let floored = PosteriorConfig {
        noise_floor_m: 3f64.sqrt() * 0.69e-3,
        ..config.clone()
    };
    assert!((floored.evidence_scale(Some(&noise)) - 1.0).abs() < 1e-9);
    let off = PosteriorConfig {
        frame_noise: false,
        ..config.clone()
    };
    let recalibrated = quieter.recalibrated(&none, &off);
    let plain = PosePosterior::from_evidence_with(&evidence(1.0), 200, None, None, &none, &off);
    assert_eq!(recalibrated.modes, plain.modes);
    assert_eq!(recalibrated.noise, Some(noise));
}

#[test]
fn a_calibration_from_before_the_frames_noise_keeps_the_evidence_as_recorded() {
    // A file without `frame_noise` was fitted to the evidence as recorded: reading it must not rescale that evidence
    // with the bundled calibration's switch; the bundled one, written out, reads back as it is.
    let old: PosteriorConfig = serde_json::from_str(r#"{"temperature": 2.54}"#).unwrap();
    assert!(!old.frame_noise && old.temperature == 2.54);
    let asked: PosteriorConfig = serde_json::from_str(r#"{"frame_noise": true}"#).unwrap();
    assert!(asked.frame_noise);
    // Tracks were fused at full weight before `fusion_weight` existed; out of 0–1 it is refused.
    assert_eq!(old.fusion_weight, 1.0);
    let with = |kappa: f64| PosteriorConfig {
        fusion_weight: kappa,
        ..PosteriorConfig::default()
    };
    for bad in [-0.1, 1.5, f64::NAN] {
        assert!(with(bad)
            .validate()
            .unwrap_err()
            .to_string()
            .contains("fusion_weight"));
    }
    for good in [0.0, 1.0] {
        assert!(with(good).validate().is_ok());
    }
    let bundled = PosteriorConfig::default();
    let back: PosteriorConfig =
        serde_json::from_str(&serde_json::to_string(&bundled).unwrap()).unwrap();
    assert_eq!(back, bundled);
}

#[test]
fn region_mass_of_one_gaussian_follows_the_chi_square_law() {
    // Analytic truth: for one 3-D Gaussian the HPD region through a point at Mahalanobis distance d holds
    // P(χ²₃ ≤ d²) = erf(d/√2) − √(2/π) d e^{−d²/2}.
    let sd = [0.002, 0.001, 0.05];
    let mode = PosteriorMode {
        weight: 1.0,
        mean: [0.01, -0.02, 0.3],
        cov: diag(sd[0] * sd[0], sd[1] * sd[1], sd[2] * sd[2]),
        nats: 0.0,
        hessian: diag(1.0, 1.0, 1.0),
        tails: Default::default(),
    };
    let post = PosePosterior {
        modes: vec![mode],
        contact_px: 300,
        predicted_contact_px: None,
        noise: None,
        distinct_nats: Vec::new(),
    };
    let none = Symmetry::default();
    for d in [0.5f64, 1.5, 2.5] {
        // Along a diagonal direction, d in Mahalanobis units.
        let u = d / 3f64.sqrt();
        let pose = Se2::new(0.01 + u * sd[0], -0.02 - u * sd[1], 0.3 + u * sd[2]);
        let want =
            erf(d / 2f64.sqrt()) - (2.0 / std::f64::consts::PI).sqrt() * d * (-d * d / 2.0).exp();
        let got = post.region_mass(pose, &none, 20_000).unwrap();
        assert!((got - want).abs() < 0.015, "d {d}: {got} vs {want}");
    }
    // θ is circular: a turn by a full period is the same point.
    let at = Se2::new(0.01, -0.02, 0.3 + std::f64::consts::TAU);
    assert!(post.region_mass(at, &none, 2000).unwrap() < 0.01);
}

#[test]
fn weights_follow_the_tempered_likelihood_and_modes_merge() {
    // Δ = 0, 8 nats and a duplicate of the first at τ = 4: weights 1 : e^{-2}, the duplicate merged.
    let h = diag(1e7, 1e7, 1e3);
    let ev = |x: f64, nats: f64| ModeEvidence {
        pose: Se2::new(x, 0.0, 0.0),
        nats,
        hessian: h,
    };
    let config = PosteriorConfig {
        temperature: 4.0,
        ..PosteriorConfig::untempered()
    };
    let post = PosePosterior::from_evidence(
        &[ev(0.01, 8.0), ev(0.0, 0.0), ev(0.0005, 1.0)],
        300,
        &Symmetry::default(),
        &config,
    );
    assert_eq!(post.modes.len(), 2);
    let ratio = post.modes[1].weight / post.modes[0].weight;
    assert!((ratio - (-2.0f64).exp()).abs() < 1e-12);
    assert!((post.modes.iter().map(|m| m.weight).sum::<f64>() - 1.0).abs() < 1e-12);
    // Analytic: the region through the light mode's peak (density ratio e^{-2} to the heavy one's, same
    // covariance, far apart) holds the heavy mode out to d² = 4: w₁ · P(χ²₃ ≤ 4), with P = erf(√2) − √(2/π)·2e^{-2}.
    let m = post
        .region_mass(Se2::new(0.01, 0.0, 0.0), &Symmetry::default(), 20_000)
        .unwrap();
    let chi = erf(2f64.sqrt()) - (2.0 / std::f64::consts::PI).sqrt() * 2.0 * (-2.0f64).exp();
    let want = post.modes[0].weight * chi;
    assert!((m - want).abs() < 0.015, "{m} vs {want}");
    // Recalibrated with τ = 1 from the kept evidence: e^{-8} < min_weight, so the light mode goes.
    let sharp = post.recalibrated(
        &Symmetry::default(),
        &PosteriorConfig {
            temperature: 1.0,
            ..config
        },
    );
    assert_eq!(sharp.modes.len(), 1);
    assert_eq!(sharp.modes[0].weight, 1.0);
}

#[test]
fn tails_follow_the_contact_and_their_densities_are_exact() {
    // The shares are the logistic of logit + slope · ln(pixels / reference), the far one first.
    let config = PosteriorConfig {
        tail_logit: -1.0,
        tail_contact_slope: -0.5,
        far_logit: -3.0,
        far_contact_slope: -1.0,
        tail_exponent: 0.0,
        tail_core_scale: 2.0,
        tail_position_m: 0.001,
        tail_theta_rad: 0.1,
        far_position_m: 0.004,
        ..PosteriorConfig::untempered()
    };
    let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
    let evidence = [ModeEvidence {
        pose: Se2::new(0.001, 0.002, 0.5),
        nats: 0.0,
        hessian: diag(1e8, 1e8, 1e4),
    }];
    let none = Symmetry::default();
    for px in [75usize, 300, 1200] {
        let l = (px as f64 / 300.0).ln();
        let post = PosePosterior::from_evidence(&evidence, px, &none, &config);
        let t = post.modes[0].tails;
        let far = logistic(-3.0 - l);
        assert!((t.far - far).abs() < 1e-12);
        assert!((t.tail - (1.0 - far) * logistic(-1.0 - 0.5 * l)).abs() < 1e-12);
        // The tail: the core scaled by 2 and widened.
        let core = post.modes[0].cov;
        assert!((t.tail_cov[0][0] - (4.0 * core[0][0] + 1e-6)).abs() < 1e-15);
        assert!((t.tail_cov[2][2] - (4.0 * core[2][2] + 0.01)).abs() < 1e-12);
        // The spread is the moment of core and tail (the far share apart).
        let spread = post.modes[0].spread_cov();
        let near = 1.0 - t.far;
        for i in 0..3 {
            let want = ((near - t.tail) * core[i][i] + t.tail * t.tail_cov[i][i]) / near;
            assert!((spread[i][i] - want).abs() <= 1e-12 * want, "{px} {i}");
        }
    }
    // The far component alone: θ uniform (the density does not change with θ and is the position Gaussian's over
    // 2π) and the region through a point at Mahalanobis distance d in position holds P(χ²₂ ≤ d²) = 1 − e^{−d²/2}.
    let mut far_only = PosePosterior::from_evidence(&evidence, 300, &none, &config);
    far_only.modes[0].tails.far = 1.0;
    far_only.modes[0].tails.tail = 0.0;
    let s = 0.004;
    let at = |d: f64, theta: f64| Se2::new(0.001 + d * s, 0.002, theta);
    let want_log = -0.5 - (std::f64::consts::TAU * s * s).ln() - std::f64::consts::TAU.ln();
    for theta in [0.5, -2.0, 3.0] {
        let got = far_only.log_density(at(1.0, theta), &none);
        assert!((got - want_log).abs() < 1e-9, "{got} vs {want_log}");
    }
    for d in [0.5f64, 1.5, 2.5] {
        let got = far_only.region_mass(at(d, 1.0), &none, 20_000).unwrap();
        let want = 1.0 - (-d * d / 2.0).exp();
        assert!((got - want).abs() < 0.015, "d {d}: {got} vs {want}");
    }
}

#[test]
fn rival_explanations_within_the_window_move_the_tail_and_far_shares() {
    // Analytic: with the contact's slopes at 0, tail = logistic(tail_logit + tail_rivals · ln n) and
    // far = logistic(far_logit + far_rivals · ln n), n the distinct poses within the window of the best (itself
    // included); logistic(ln n) = n / (n + 1).
    let config = PosteriorConfig {
        temperature: 0.1,
        tail_logit: 0.0,
        tail_contact_slope: 0.0,
        tail_rivals: 1.0,
        far_logit: -4.0,
        far_contact_slope: 0.0,
        far_ambiguity: 0.0,
        far_rivals: 2.0,
        rival_window_nats: 12.0,
        ..PosteriorConfig::untempered()
    };
    let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
    let at = |x: f64, nats: f64| ModeEvidence {
        pose: Se2::new(x, 0.0, 0.0),
        nats,
        hessian: diag(1e8, 1e8, 1e4),
    };
    let none = Symmetry::default();
    // Rivals at 2 and 5 nats count, one at 20 does not; at τ = 0.1 both rivals weigh < e^-20, below min_weight, and
    // are no modes: counted all the same.
    let evidence = [at(0.0, 0.0), at(0.01, 2.0), at(-0.01, 5.0), at(0.02, 20.0)];
    let post = PosePosterior::from_evidence(&evidence, 300, &none, &config);
    assert_eq!(post.modes.len(), 1);
    assert_eq!(post.distinct_nats, vec![0.0, 2.0, 5.0, 20.0]);
    let far = logistic(-4.0 + 2.0 * 3f64.ln());
    let t = post.modes[0].tails;
    assert!((t.far - far).abs() < 1e-12, "{} against {far}", t.far);
    assert!((t.tail - (1.0 - far) * 0.75).abs() < 1e-12, "{}", t.tail);
    // Recalibrated from the record, the rivals that are no modes still count; a wider window takes the fourth.
    let again = post.recalibrated(&none, &config);
    assert!((again.modes[0].tails.tail - t.tail).abs() < 1e-12);
    let wide = post.recalibrated(
        &none,
        &PosteriorConfig {
            rival_window_nats: 25.0,
            ..config.clone()
        },
    );
    let far4 = logistic(-4.0 + 2.0 * 4f64.ln());
    assert!((wide.modes[0].tails.tail - (1.0 - far4) * 0.8).abs() < 1e-12);
    // One explanation alone: the shares at the logits themselves.
    let alone = PosePosterior::from_evidence(&evidence[..1], 300, &none, &config);
    let far1 = logistic(-4.0);
    assert!((alone.modes[0].tails.tail - (1.0 - far1) * 0.5).abs() < 1e-12);
    // A record from before the rivals were kept: its modes' nats stand in.
    let mut old = post.clone();
    old.distinct_nats.clear();
    let old = old.recalibrated(&none, &config);
    assert!((old.modes[0].tails.tail - (1.0 - far1) * 0.5).abs() < 1e-12);
}

#[test]
fn a_contact_the_pose_leaves_unexplained_moves_the_tail_and_far_shares() {
    // Analytic: ln(misfit / noise) = ln e = 1, so tail = logistic(tail_misfit) · (1 − far) and
    // far = logistic(far_logit + far_misfit); without the misfit (older records) both at their logits.
    let config = PosteriorConfig {
        tail_logit: 0.0,
        tail_contact_slope: 0.0,
        tail_misfit: 1.5,
        far_logit: -4.0,
        far_contact_slope: 0.0,
        far_ambiguity: 0.0,
        far_misfit: 2.0,
        ..PosteriorConfig::untempered()
    };
    let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
    let evidence = [ModeEvidence {
        pose: Se2::new(0.0, 0.0, 0.0),
        nats: 0.0,
        hessian: diag(1e8, 1e8, 1e4),
    }];
    let none = Symmetry::default();
    let noise = |contact_rms_m| FrameNoise {
        assumed_m: 1.38e-3,
        measured_m: 1e-3,
        contact_rms_m,
    };
    let shares = |n: FrameNoise| {
        let post = PosePosterior::from_evidence_with(&evidence, 300, None, Some(n), &none, &config);
        (post.modes[0].tails.tail, post.modes[0].tails.far)
    };
    let (tail, far) = shares(noise(Some(std::f64::consts::E * 1e-3)));
    let want_far = logistic(-2.0);
    assert!((far - want_far).abs() < 1e-12, "{far}");
    assert!(
        (tail - (1.0 - want_far) * logistic(1.5)).abs() < 1e-12,
        "{tail}"
    );
    let (tail, far) = shares(noise(None));
    assert!((far - logistic(-4.0)).abs() < 1e-12);
    assert!((tail - (1.0 - logistic(-4.0)) * 0.5).abs() < 1e-12);
}

#[test]
fn half_widths_hold_their_share_of_the_mode() {
    // Analytic: one Gaussian's ±σ holds erf(1/√2) and its 90 % central interval is ±1.6449 σ.
    let sd = [0.001, 0.002, 0.03];
    let mut mode = PosteriorMode {
        weight: 1.0,
        mean: [0.01, -0.02, 0.5],
        cov: diag(sd[0] * sd[0], sd[1] * sd[1], sd[2] * sd[2]),
        nats: 0.0,
        hessian: [[0.0; 3]; 3],
        tails: ModeTails::default(),
    };
    let none = Symmetry::default();
    let h = mode.half_widths(ONE_SIGMA, &none);
    for i in 0..3 {
        assert!(
            (h[i] / sd[i] - 1.0).abs() < 1e-9,
            "{i}: {} against {}",
            h[i],
            sd[i]
        );
    }
    assert!((mode.half_widths(0.9, &none)[2] / sd[2] - 1.644_853_6).abs() < 1e-6);
    // Core, tail and far component: the share of draws from the mixture within ±h (an independent Monte Carlo
    // integral) is the level asked for.
    mode.tails = ModeTails {
        tail: 0.3,
        tail_cov: diag(
            25.0 * sd[0] * sd[0],
            16.0 * sd[1] * sd[1],
            100.0 * sd[2] * sd[2],
        ),
        far: 0.1,
        far_position_m: 0.008,
    };
    // Two-fold symmetry: the far θ is uniform over half a turn.
    let two_fold = Symmetry {
        rotation: RotationSymmetry::NFold(2),
        translation_axis: None,
    };
    let period = std::f64::consts::PI;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let n = 200_000;
    let draws: Vec<[f64; 3]> = (0..n)
        .map(|_| {
            let u: f64 = rand::Rng::random(&mut rng);
            let z: [f64; 3] = [0; 3].map(|_| StandardNormal.sample(&mut rng));
            if u < 0.6 {
                [0, 1, 2].map(|i| z[i] * sd[i])
            } else if u < 0.9 {
                [0, 1, 2].map(|i| z[i] * mode.tails.tail_cov[i][i].sqrt())
            } else {
                let v: f64 = rand::Rng::random(&mut rng);
                [z[0] * 0.008, z[1] * 0.008, (v - 0.5) * period]
            }
        })
        .collect();
    for p in [0.5, ONE_SIGMA, 0.9] {
        let h = mode.half_widths(p, &two_fold);
        for i in 0..3 {
            let inside = draws.iter().filter(|d| d[i].abs() <= h[i]).count() as f64 / n as f64;
            assert!((inside - p).abs() < 0.005, "level {p}, axis {i}: {inside}");
        }
    }
    // A far component alone: θ uniform over the period, so the interval is that share of it.
    mode.tails = ModeTails {
        tail: 0.0,
        tail_cov: mode.cov,
        far: 1.0,
        far_position_m: 0.008,
    };
    assert!((mode.half_widths(0.5, &two_fold)[2] - period / 4.0).abs() < 1e-9);
}

#[test]
fn symmetry_reduces_the_difference() {
    // A 4-fold object turned by π/2 is the same pose; a translation axis along x (object frame), the object at
    // θ = π/2: its world axis is y, so a y offset does not count.
    let four = Symmetry {
        rotation: RotationSymmetry::NFold(4),
        translation_axis: None,
    };
    assert!(same_pose(
        Se2::new(0.0, 0.0, std::f64::consts::FRAC_PI_2),
        Se2::default(),
        &four
    ));
    let bar = Symmetry {
        rotation: RotationSymmetry::Continuous,
        translation_axis: Some([1.0, 0.0]),
    };
    let r = Se2::new(0.0, 0.0, std::f64::consts::FRAC_PI_2);
    let (e, rows) = reduced_difference(Se2::new(0.003, 0.05, 1.0), r, &bar);
    assert_eq!((e.len(), rows.len()), (1, 1));
    assert!((e[0].abs() - 0.003).abs() < 1e-12);
}

/// erf by Abramowitz–Stegun 7.1.26 (|error| < 1.5e-7), for the test's analytic truth.
fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let y = 1.0
        - (((((1.061_405_429 * t - 1.453_152_027) * t) + 1.421_413_741) * t - 0.284_496_736) * t
            + 0.254_829_592)
            * t
            * (-x * x).exp();
    y.copysign(x)
}
