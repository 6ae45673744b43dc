//! **Coverage** of the pose posterior ([`crate::pose::posterior`]): how often the truth lies inside the reported
//! 50 / 90 / 95 % regions, and how many estimates are *confidently wrong* (more than [`WRONG_MM`] off with the truth
//! outside the 95 % region). A calibrated posterior covers the truth in about p of the pairs at level p.
//!
//! [`fit_posterior`] chooses the posterior's calibration ([`PosteriorConfig`]: temperature and floors) for a set of
//! evaluated pairs — the records of `tnd eval` on a user's own labelled recordings, or our validation set — by the
//! mean negative log density of the truth (a proper score: it rewards sharp posteriors and punishes confident
//! misses), among the settings whose 90 % coverage is within [`FIT_TOLERANCE`] of 0.9.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::objects::Symmetry;
use crate::pose::posterior::{PosePosterior, PosteriorConfig};
use crate::sensor::Se2;

/// The region levels reported.
pub const LEVELS: [f64; 3] = [0.5, 0.9, 0.95];
/// An estimate this far off (position error, mm) with the truth outside its 95 % region is confidently wrong.
pub const WRONG_MM: f64 = 5.0;
/// [`fit_posterior`] keeps settings whose 90 % coverage is within this of 0.9.
pub const FIT_TOLERANCE: f64 = 0.03;
/// [`fit_posterior`] measures the coverage of this many best-scoring settings.
const FIT_CANDIDATES: usize = 60;

/// Coverage of one method's posteriors over a set of pairs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Coverage {
    /// Pairs with a posterior and a truth.
    pub pairs: usize,
    /// Fraction of them whose truth lies inside the 50 %, 90 % and 95 % region.
    pub inside: [f64; 3],
    /// Pairs more than [`WRONG_MM`] off with the truth outside the 95 % region.
    pub confidently_wrong: usize,
}

impl Coverage {
    /// From `(region mass of the truth, position error mm)` per pair; `None` without pairs.
    pub fn of(pairs: impl Iterator<Item = (f64, f64)>) -> Option<Self> {
        let all: Vec<(f64, f64)> = pairs.filter(|(m, _)| m.is_finite()).collect();
        if all.is_empty() {
            return None;
        }
        let n = all.len() as f64;
        Some(Self {
            pairs: all.len(),
            inside: LEVELS.map(|p| all.iter().filter(|(m, _)| *m <= p).count() as f64 / n),
            confidently_wrong: all
                .iter()
                .filter(|(m, e)| *m > LEVELS[2] && *e > WRONG_MM)
                .count(),
        })
    }
}

/// One evaluated estimate with its posterior.
#[derive(Clone, Debug)]
pub struct Scored<'a> {
    pub posterior: &'a PosePosterior,
    pub truth: Se2,
    pub symmetry: Symmetry,
    /// Position error of the estimate, mm.
    pub position_mm: f64,
    /// Pixels in contact (for the contact-size bins).
    pub contact_pixels: usize,
}

/// Coverage of `scored` with each posterior recalibrated by `config` (as recorded when `None`), `draws` Monte Carlo
/// draws per region.
pub fn coverage_with(
    scored: &[Scored<'_>],
    config: Option<&PosteriorConfig>,
    draws: usize,
) -> Option<Coverage> {
    let pairs: Vec<(f64, f64)> = scored
        .par_iter()
        .map(|s| {
            let mass = match config {
                Some(c) => s.posterior.recalibrated(&s.symmetry, c).region_mass(
                    s.truth,
                    &s.symmetry,
                    draws,
                ),
                None => s.posterior.region_mass(s.truth, &s.symmetry, draws),
            };
            (mass.unwrap_or(f64::NAN), s.position_mm)
        })
        .collect();
    Coverage::of(pairs.into_iter())
}

/// Mean negative log density of the truths under `scored`'s posteriors recalibrated by `config`, each capped at
/// `cap` (so that one pair far outside every mode does not decide alone).
pub fn mean_nll(scored: &[Scored<'_>], config: &PosteriorConfig, cap: f64) -> f64 {
    let total: f64 = scored
        .par_iter()
        .map(|s| {
            let p = s.posterior.recalibrated(&s.symmetry, config);
            (-p.log_density(s.truth, &s.symmetry)).min(cap)
        })
        .sum();
    total / scored.len().max(1) as f64
}

/// A fitted calibration and how it scores on the pairs it was fitted to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    pub config: PosteriorConfig,
    pub mean_nll: f64,
    pub coverage: Option<Coverage>,
}

/// The calibration of `base` (its other settings kept) that fits `scored` best over a grid of temperatures and
/// floors (module docs).
pub fn fit_posterior(scored: &[Scored<'_>], base: &PosteriorConfig) -> Fit {
    let temperatures = [1.0, 4.0, 16.0, 64.0, 256.0, 1024.0, 4096.0, 16384.0];
    let floors_mm = [0.0, 0.5, 1.0, 2.0, 4.0];
    let floors_deg = [0.0, 2.0, 5.0, 10.0, 20.0];
    let exponents = [0.0, 0.5, 1.0];
    let mut grid = Vec::new();
    for &t in &temperatures {
        for &p in &floors_mm {
            for &d in &floors_deg {
                for &e in &exponents {
                    grid.push(PosteriorConfig {
                        temperature: t,
                        floor_position_m: p * 1e-3,
                        floor_theta_rad: f64::to_radians(d),
                        floor_exponent: e,
                        ..base.clone()
                    });
                }
            }
        }
    }
    const CAP: f64 = 50.0;
    let mut scored_grid: Vec<(f64, PosteriorConfig)> = grid
        .into_iter()
        .map(|c| (mean_nll(scored, &c, CAP), c))
        .collect();
    scored_grid.sort_by(|a, b| a.0.total_cmp(&b.0));
    // The best scores whose 90 % coverage is close to 0.9; the one closest to it when none is.
    let mut closest: Option<Fit> = None;
    for (nll, config) in scored_grid.into_iter().take(FIT_CANDIDATES) {
        let coverage = coverage_with(scored, Some(&config), 1000);
        let fit = Fit {
            config,
            mean_nll: nll,
            coverage,
        };
        let miss = |f: &Fit| {
            f.coverage
                .map_or(f64::INFINITY, |c| (c.inside[1] - 0.9).abs())
        };
        if miss(&fit) <= FIT_TOLERANCE {
            return fit;
        }
        if closest.as_ref().is_none_or(|c| miss(&fit) < miss(c)) {
            closest = Some(fit);
        }
    }
    closest.unwrap_or(Fit {
        config: base.clone(),
        mean_nll: f64::NAN,
        coverage: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::posterior::ModeEvidence;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

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
        let (sp, st) = (0.0002f64, 0.3f64.to_radians());
        let hessian = [
            [1.0 / (sp * sp), 0.0, 0.0],
            [0.0, 1.0 / (sp * sp), 0.0],
            [0.0, 0.0, 1.0 / (st * st)],
        ];
        let raw = PosteriorConfig {
            temperature: 1.0,
            floor_position_m: 0.0,
            floor_theta_rad: 0.0,
            ..PosteriorConfig::default()
        };
        let posteriors: Vec<(PosePosterior, Se2)> = (0..300)
            .map(|_| {
                let truth = Se2::new(
                    pos.sample(&mut rng),
                    pos.sample(&mut rng),
                    rot.sample(&mut rng),
                );
                let evidence = ModeEvidence {
                    pose: Se2::default(),
                    nats: 0.0,
                    hessian,
                };
                (
                    PosePosterior::from_evidence(&[evidence], 300, &Symmetry::default(), &raw),
                    truth,
                )
            })
            .collect();
        let scored: Vec<Scored<'_>> = posteriors
            .iter()
            .map(|(p, t)| Scored {
                posterior: p,
                truth: *t,
                symmetry: Symmetry::default(),
                position_mm: t.x.hypot(t.y) * 1e3,
                contact_pixels: 500,
            })
            .collect();
        let before = coverage_with(&scored, None, 1000).unwrap();
        assert!(before.inside[1] < 0.1, "{before:?}");
        let fit = fit_posterior(&scored, &raw);
        let after = fit.coverage.unwrap();
        assert!((after.inside[1] - 0.9).abs() <= 0.05, "{fit:?}");
        assert!(after.inside[0] > 0.35 && after.inside[0] < 0.65, "{fit:?}");
    }
}
