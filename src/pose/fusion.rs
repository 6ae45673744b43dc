//! **Fusing a track's frames**: the object does not move while the sensor presses it, so the posterior of one frame
//! is the prior of the next. [`fuse`] weighs each mode i of a frame's posterior by how well the previous frame's
//! posterior p₋ predicts it: for a static pose that is ∫ N(x; mᵢ, Cᵢ) p₋(x) dx (Cᵢ the mode's spread, core and
//! tail), the whole mixture of p₋ with its tails and far components
//! ([`PosePosterior::predictive_log_density`]), mixed with a flat prior of share [`REINIT_SHARE`] over
//! [`REINIT_EXTENT_M`] and the symmetry's θ period, so that a pose the earlier frames did not see can still win
//! and a wrong start is not locked in. Means and covariances stay the frame's own: neighbouring frames share the
//! model's errors, so multiplying their Gaussians would claim more certainty than the data holds.
//!
//! Both densities are absolute, so the prior is as strong as the previous posterior is sharp: a calibrated,
//! sharp posterior (σθ of a few degrees) keeps a track on its pose through a frame whose small contact prefers
//! another by a few nats, and a broad one (a small first contact, a large far share) barely moves the next frame.
//!
//! Each mode's prediction (with the flat share) is raised to the power κ
//! ([`super::posterior::PosteriorConfig::fusion_weight`]) before it reweighs the mode: frames of one press share the
//! model's and the membrane's errors, so the evidence of the frames before is worth a fraction of as much independent
//! evidence (the frame before counts κ, the one before that κ², as the fusion passes on). Fitted to tracked presses of
//! real meshes, κ = 0.15: fused at full weight the tracks' 50 % regions held the truth in 40 % of frames held out, at
//! 0.15 in 43–44 % (docs/uncertainty.md).

use super::posterior::{log_sum_exp, reduced_difference, PosePosterior};
use crate::objects::Symmetry;
use crate::sensor::Se2;

/// Share of the fused prior that is flat over [`REINIT_EXTENT_M`] and the θ period: a pose the previous frames gave
/// no weight.
pub const REINIT_SHARE: f64 = 0.05;

/// Side of the square (metres) over which the flat share of the prior spreads: where an object's contact can be on a
/// Soft Bubble's membrane.
pub const REINIT_EXTENT_M: f64 = 0.05;

/// `current` reweighted by `previous`'s prediction raised to the power `kappa`
/// ([`super::posterior::PosteriorConfig::fusion_weight`]: 1 as the module docs say, 0 not at all), heaviest first;
/// `current` itself when either has no modes.
pub fn fuse(
    current: &PosePosterior,
    previous: &PosePosterior,
    symmetry: &Symmetry,
    kappa: f64,
) -> PosePosterior {
    if current.modes.is_empty() || previous.modes.is_empty() || kappa <= 0.0 {
        return current.clone();
    }
    let flat = REINIT_SHARE.ln() + flat_log_density(current.modes[0].pose(), symmetry);
    let kept = (1.0 - REINIT_SHARE).ln();
    // log [(1 − ε) ∫ N(x; mᵢ, Cᵢ) p₋(x) dx + ε u] per current mode.
    let predicted: Vec<f64> = current
        .modes
        .iter()
        .map(|m| {
            let p = previous.predictive_log_density(m.pose(), &m.spread_cov(), symmetry);
            kappa * log_sum_exp(&[kept + p, flat])
        })
        .collect();
    let best = predicted.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut fused = current.clone();
    for (m, lp) in fused.modes.iter_mut().zip(&predicted) {
        m.weight *= (lp - best).exp();
    }
    let total: f64 = fused.modes.iter().map(|m| m.weight).sum();
    if total > 0.0 && total.is_finite() {
        fused.modes.iter_mut().for_each(|m| m.weight /= total);
    } else {
        return current.clone();
    }
    fused.modes.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    fused
}

/// Log density of the flat prior over the coordinates `symmetry` leaves identifiable at `pose`: 1 / [`REINIT_EXTENT_M`]
/// per position coordinate, 1 / the θ period.
fn flat_log_density(pose: Se2, symmetry: &Symmetry) -> f64 {
    let (_, rows) = reduced_difference(pose, pose, symmetry);
    match symmetry.rotation.period_rad() {
        Some(period) => -((rows.len() - 1) as f64) * REINIT_EXTENT_M.ln() - period.ln(),
        None => -(rows.len() as f64) * REINIT_EXTENT_M.ln(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::posterior::PosteriorMode;
    use crate::sensor::Se2;

    fn mode(weight: f64, pose: Se2, sigma_m: f64, sigma_rad: f64) -> PosteriorMode {
        let mut cov = [[0.0; 3]; 3];
        cov[0][0] = sigma_m * sigma_m;
        cov[1][1] = sigma_m * sigma_m;
        cov[2][2] = sigma_rad * sigma_rad;
        PosteriorMode {
            weight,
            mean: [pose.x, pose.y, pose.theta],
            cov,
            nats: 0.0,
            hessian: [[0.0; 3]; 3],
            tails: Default::default(),
        }
    }

    /// A frame's posterior of `modes` at a contact of `contact_px` pixels (no prediction, noise or rivals kept).
    fn posterior(modes: Vec<PosteriorMode>, contact_px: usize) -> PosePosterior {
        PosePosterior {
            modes,
            contact_px,
            predicted_contact_px: None,
            noise: None,
            distinct_nats: Vec::new(),
        }
    }

    /// The density of N(0, var) at d: the independent truth of the tests below (the fusion's densities come from the
    /// mixture code).
    fn normal(d: f64, var: f64) -> f64 {
        (-0.5 * d * d / var).exp() / (std::f64::consts::TAU * var).sqrt()
    }

    #[test]
    fn the_previous_frame_decides_between_modes_the_current_one_cannot_tell_apart() {
        let a = Se2::new(0.0, 0.0, 0.3);
        let flipped = Se2::new(0.0, 0.0, 0.3 + std::f64::consts::PI);
        let symmetry = Symmetry::default();
        // The current frame slightly prefers the flipped pose; the previous one was sure of `a`.
        let current = posterior(
            vec![mode(0.55, flipped, 0.001, 0.05), mode(0.45, a, 0.001, 0.05)],
            100,
        );
        let before = Se2::new(0.0005, 0.0, 0.32);
        let previous = posterior(vec![mode(1.0, before, 0.001, 0.05)], 100);
        let fused = fuse(&current, &previous, &symmetry, 1.0);
        assert_eq!(fused.modes[0].pose(), a);
        // Independent truth: each mode's weight times (1 − ε) N(mᵢ; m₋, Cᵢ + C₋) + ε u, u flat over the 5 cm square
        // and 2π; the flipped mode's prediction is e^-970 of a's, so it keeps the flat share alone.
        let flat = REINIT_SHARE / (REINIT_EXTENT_M * REINIT_EXTENT_M * std::f64::consts::TAU);
        let predict = |m: Se2, s_m: f64, s_rad: f64| {
            let dt = (m.theta - before.theta + std::f64::consts::PI)
                .rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            (1.0 - REINIT_SHARE)
                * normal(m.x - before.x, 1e-6 + s_m * s_m)
                * normal(m.y - before.y, 1e-6 + s_m * s_m)
                * normal(dt, 0.0025 + s_rad * s_rad)
                + flat
        };
        let (wa, wf) = (
            0.45 * predict(a, 0.001, 0.05),
            0.55 * predict(flipped, 0.001, 0.05),
        );
        assert!((fused.modes[0].weight - wa / (wa + wf)).abs() < 1e-9);
        assert!(fused.modes[0].weight > 0.9999, "{fused:?}");
        let total: f64 = fused.modes.iter().map(|m| m.weight).sum();
        assert!((total - 1.0).abs() < 1e-12);
        // Means and covariances are the frame's own.
        assert_eq!(fused.modes[0].cov, current.modes[1].cov);
        // A broad previous posterior (a first frame of a small contact) is a weak prior: evidence of 10⁵ to 1 wins.
        let (s_m, s_rad) = (0.005, 0.5);
        let broad = posterior(vec![mode(1.0, before, s_m, s_rad)], 30);
        let strong = posterior(
            vec![
                mode(1.0 - 1e-5, flipped, 0.001, 0.05),
                mode(1e-5, a, 0.001, 0.05),
            ],
            100,
        );
        let fused = fuse(&strong, &broad, &symmetry, 1.0);
        assert_eq!(fused.modes[0].pose(), flipped);
        let predict_broad = |m: Se2| {
            let dt = (m.theta - before.theta + std::f64::consts::PI)
                .rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            let (vm, vr) = (s_m * s_m + 1e-6, s_rad * s_rad + 0.0025);
            (1.0 - REINIT_SHARE)
                * normal(m.x - before.x, vm)
                * normal(m.y - before.y, vm)
                * normal(dt, vr)
                + flat
        };
        let (wf, wa) = (
            (1.0 - 1e-5) * predict_broad(flipped),
            1e-5 * predict_broad(a),
        );
        assert!((fused.modes[0].weight - wf / (wf + wa)).abs() < 1e-9);
        // Nothing to fuse with: unchanged.
        assert_eq!(
            fuse(&current, &PosePosterior::default(), &symmetry, 1.0),
            current
        );
    }

    #[test]
    fn the_fusion_weight_raises_the_prior_to_its_power() {
        // Two modes 0.3 rad apart, equally weighted by the current frame; the previous frame sure of the first.
        let symmetry = Symmetry::default();
        let (a, b) = (Se2::new(0.0, 0.0, 0.0), Se2::new(0.0, 0.0, 0.3));
        let current = posterior(
            vec![mode(0.5, a, 0.001, 0.05), mode(0.5, b, 0.001, 0.05)],
            100,
        );
        let previous = posterior(vec![mode(1.0, a, 0.001, 0.05)], 100);
        // Independent truth: the prior of each mode is (1 − ε) N(Δθ; 0, 2 σθ²) N(0; 0, 2 σ²)² + ε u, raised to κ.
        let flat = REINIT_SHARE / (REINIT_EXTENT_M * REINIT_EXTENT_M * std::f64::consts::TAU);
        let prior = |dt: f64| {
            (1.0 - REINIT_SHARE) * normal(0.0, 2e-6) * normal(0.0, 2e-6) * normal(dt, 0.005) + flat
        };
        for kappa in [1.0, 0.5, 0.1] {
            let fused = fuse(&current, &previous, &symmetry, kappa);
            let (wa, wb) = (prior(0.0).powf(kappa), prior(0.3).powf(kappa));
            assert_eq!(fused.modes[0].pose(), a);
            assert!(
                (fused.modes[0].weight - wa / (wa + wb)).abs() < 1e-9,
                "κ = {kappa}: {fused:?}"
            );
        }
        // The weaker the prior's power, the less it moves the frame's own weights.
        let w = |kappa: f64| fuse(&current, &previous, &symmetry, kappa).modes[0].weight;
        assert!(w(1.0) > w(0.5) && w(0.5) > w(0.1) && w(0.1) > 0.5);
        // κ = 0: every frame its own.
        assert_eq!(fuse(&current, &previous, &symmetry, 0.0), current);
    }

    #[test]
    fn a_far_share_in_the_previous_posterior_keeps_other_angles_possible() {
        // The previous frame's far component (θ uniform, position within far_position_m) predicts a mode at the
        // same place but another angle, where its core alone would not: its share of the density, analytically.
        let symmetry = Symmetry::default();
        let before = Se2::new(0.0, 0.0, 0.0);
        let turned = Se2::new(0.0, 0.0, 2.0);
        let mut previous = mode(1.0, before, 0.001, 0.05);
        previous.tails.far = 0.2;
        previous.tails.far_position_m = 0.004;
        let previous = posterior(vec![previous], 100);
        let current = posterior(
            vec![
                mode(0.5, before, 0.001, 0.05),
                mode(0.5, turned, 0.001, 0.05),
            ],
            100,
        );
        let fused = fuse(&current, &previous, &symmetry, 1.0);
        let flat = REINIT_SHARE / (REINIT_EXTENT_M * REINIT_EXTENT_M * std::f64::consts::TAU);
        let far = |vm: f64| 0.2 * normal(0.0, vm) * normal(0.0, vm) / std::f64::consts::TAU;
        let core = |dt: f64| 0.8 * normal(0.0, 2e-6) * normal(0.0, 2e-6) * normal(dt, 0.005);
        let w_same = (1.0 - REINIT_SHARE) * (core(0.0) + far(1.6e-5 + 1e-6)) + flat;
        let w_turned = (1.0 - REINIT_SHARE) * (core(2.0) + far(1.6e-5 + 1e-6)) + flat;
        assert!((fused.modes[0].weight - w_same / (w_same + w_turned)).abs() < 1e-9);
        assert_eq!(fused.modes[1].pose(), turned);
        // Without the far share the turned mode would keep only the flat prior: the far component matters.
        let without = w_same / (w_same + (1.0 - REINIT_SHARE) * core(2.0) + flat);
        assert!(fused.modes[0].weight < without);
    }
}
