//! **Fusing a track's frames**: the object does not move while the sensor presses it, so the posterior of one frame
//! is evidence for the next. [`fuse`] weighs each mode of a frame's posterior by how well the previous frame's
//! posterior predicts it — for a static pose the predictive weight of mode i is ∫ N(x; mᵢ, Cᵢ) (Cᵢ each mode's spread, core and tail) p₋(x) dx =
//! Σⱼ πⱼ N(mᵢ; mⱼ, Cᵢ + Cⱼ) over the previous modes j — plus a small [`REINIT_SHARE`] for a pose the earlier frames
//! did not see (a wrong start is not locked in). Means and covariances stay the frame's own: neighbouring frames
//! share the model's errors, so multiplying their Gaussians would claim more certainty than the data holds.

use super::posterior::{
    gaussian_log_density, log_sum_exp, project, reduced_difference, PosePosterior,
};
use crate::objects::Symmetry;

/// Share of the fused prior that is flat (relative to the best-predicted mode): a mode the previous frame gave no
/// weight keeps this fraction of its own evidence.
pub const REINIT_SHARE: f64 = 0.05;

/// `current` reweighted by `previous` (module docs), heaviest first; `current` itself when either has no modes.
pub fn fuse(
    current: &PosePosterior,
    previous: &PosePosterior,
    symmetry: &Symmetry,
) -> PosePosterior {
    if current.modes.is_empty() || previous.modes.is_empty() {
        return current.clone();
    }
    // log Σⱼ πⱼ N(mᵢ; mⱼ, Cᵢ + Cⱼ) per current mode.
    let predicted: Vec<f64> = current
        .modes
        .iter()
        .map(|m| {
            let terms: Vec<f64> = previous
                .modes
                .iter()
                .map(|p| {
                    let (e, rows) = reduced_difference(m.pose(), p.pose(), symmetry);
                    let (mut cov, previous) = (m.spread_cov(), p.spread_cov());
                    for (r, row) in cov.iter_mut().enumerate() {
                        for (c, v) in row.iter_mut().enumerate() {
                            *v += previous[r][c];
                        }
                    }
                    p.weight.ln() + gaussian_log_density(&e, &project(&cov, &rows))
                })
                .collect();
            log_sum_exp(&terms)
        })
        .collect();
    let best = predicted.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut fused = current.clone();
    for (m, lp) in fused.modes.iter_mut().zip(&predicted) {
        let relative = if best.is_finite() {
            (lp - best).exp()
        } else {
            1.0
        };
        m.weight *= REINIT_SHARE + relative;
    }
    let total: f64 = fused.modes.iter().map(|m| m.weight).sum();
    if total > 0.0 && total.is_finite() {
        fused.modes.iter_mut().for_each(|m| m.weight /= total);
    }
    fused.modes.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    fused
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

    #[test]
    fn the_previous_frame_decides_between_modes_the_current_one_cannot_tell_apart() {
        let a = Se2::new(0.0, 0.0, 0.3);
        let flipped = Se2::new(0.0, 0.0, 0.3 + std::f64::consts::PI);
        let symmetry = Symmetry::default();
        // The current frame slightly prefers the flipped pose; the previous one was sure of `a`.
        let current = PosePosterior {
            modes: vec![mode(0.55, flipped, 0.001, 0.05), mode(0.45, a, 0.001, 0.05)],
            contact_px: 100,
            predicted_contact_px: None,
        };
        let previous = PosePosterior {
            modes: vec![mode(1.0, Se2::new(0.0005, 0.0, 0.32), 0.001, 0.05)],
            contact_px: 100,
            predicted_contact_px: None,
        };
        let fused = fuse(&current, &previous, &symmetry);
        assert_eq!(fused.modes[0].pose(), a);
        // Independent truth: the flipped mode keeps REINIT_SHARE of its weight (its prediction is ~e^-1800 of a's),
        // a keeps 1 + REINIT_SHARE of its own.
        let (wa, wf) = (0.45 * (1.0 + REINIT_SHARE), 0.55 * REINIT_SHARE);
        assert!((fused.modes[0].weight - wa / (wa + wf)).abs() < 1e-9);
        let total: f64 = fused.modes.iter().map(|m| m.weight).sum();
        assert!((total - 1.0).abs() < 1e-12);
        // Means and covariances are the frame's own.
        assert_eq!(fused.modes[0].cov, current.modes[1].cov);
        // Evidence strong enough still wins against the prior: 0.99 against 0.01 at a 20x prior ratio.
        let strong = PosePosterior {
            modes: vec![mode(0.99, flipped, 0.001, 0.05), mode(0.01, a, 0.001, 0.05)],
            contact_px: 100,
            predicted_contact_px: None,
        };
        assert_eq!(fuse(&strong, &previous, &symmetry).modes[0].pose(), flipped);
        // Nothing to fuse with: unchanged.
        assert_eq!(
            fuse(&current, &PosePosterior::default(), &symmetry),
            current
        );
    }
}
