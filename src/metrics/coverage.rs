//! **Coverage** of the pose posterior ([`crate::pose::posterior`]): how often the truth lies inside the reported
//! 50 / 90 / 95 % regions, and how many estimates are *confidently wrong* (more than [`WRONG_MM`] off with the truth
//! outside the 95 % region). A calibrated posterior covers the truth in about p of the pairs at level p.
//!
//! [`fit_posterior`] fits the posterior's calibration ([`PosteriorConfig`]: temperatures, floors and heavy tails) to a
//! set of evaluated pairs — the records of `tnd eval` on a user's own labelled recordings, or our validation set — by
//! the mean negative log density of the truth, a proper score: it rewards sharp posteriors and punishes confident
//! misses, so its optimum is calibrated at every level the family can express (Nelder–Mead from a few starts).
//! [`reliability`] measures the result the way forecasters do: coverage against level (the reliability diagram),
//! sharpness (median σ against median error) and the mean negative log density.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use super::nelder_mead::nelder_mead;
use crate::objects::Symmetry;
use crate::pose::posterior::{PosePosterior, PosteriorConfig, ONE_SIGMA};
use crate::sensor::Se2;

/// The region levels reported.
pub const LEVELS: [f64; 3] = [0.5, 0.9, 0.95];
/// An estimate this far off (position error, mm) with the truth outside its 95 % region is confidently wrong.
pub const WRONG_MM: f64 = 5.0;
/// Levels of the reliability diagram ([`reliability`]).
pub const RELIABILITY_LEVELS: [f64; 11] = [0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95];
/// Each pair's negative log density is capped at this in [`mean_nll`] and [`reliability`] (so that one pair far outside every mode does
/// not decide alone).
pub const NLL_CAP: f64 = 50.0;

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
    /// θ error of the estimate, radians (`None` where the symmetry leaves θ free).
    pub theta_rad: Option<f64>,
    /// Pixels in contact (for the contact-size bins).
    pub contact_pixels: usize,
    /// A track's carried frame: the index, in the same slice and before this one, of the frame whose posterior the
    /// tracker fused this one with ([`crate::pose::fusion::fuse`]). A recalibration replays the fusion in order
    /// ([`calibrated`]), so that a calibration fitted to tracks is fitted to what the track reports.
    pub prior: Option<usize>,
}

/// Each pair's posterior recalibrated by `config`, and each track frame's ([`Scored::prior`]) fused in order with
/// its earlier frame's as recalibrated and fused: what the tracker would have reported under `config`. (Records keep
/// a frame's fused posterior; its modes' evidence is the frame's own, so [`PosePosterior::recalibrated`] gives the
/// frame's own posterior back before the fusion.)
pub fn calibrated(scored: &[Scored<'_>], config: &PosteriorConfig) -> Vec<PosePosterior> {
    let mut out: Vec<PosePosterior> = scored
        .par_iter()
        .map(|s| s.posterior.recalibrated(&s.symmetry, config))
        .collect();
    for (i, s) in scored.iter().enumerate() {
        if let Some(j) = s.prior.filter(|&j| j < i) {
            out[i] = crate::pose::fusion::fuse(&out[i], &out[j], &s.symmetry, config.fusion_weight);
        }
    }
    out
}

/// The pairs of `scored` with `posteriors` (one each, in order) in place of theirs, as final: no fusion left to
/// replay.
pub fn with_posteriors<'a>(
    scored: &[Scored<'a>],
    posteriors: &'a [PosePosterior],
) -> Vec<Scored<'a>> {
    scored
        .iter()
        .zip(posteriors)
        .map(|(s, p)| Scored {
            posterior: p,
            prior: None,
            ..s.clone()
        })
        .collect()
}

/// Coverage of `scored` with each posterior recalibrated by `config` ([`calibrated`]; as recorded when `None`), `draws` Monte Carlo
/// draws per region.
pub fn coverage_with(
    scored: &[Scored<'_>],
    config: Option<&PosteriorConfig>,
    draws: usize,
) -> Option<Coverage> {
    let recalibrated = config.map(|c| calibrated(scored, c));
    let pairs: Vec<(f64, f64)> = scored
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let p = recalibrated.as_ref().map_or(s.posterior, |r| &r[i]);
            let mass = p.region_mass(s.truth, &s.symmetry, draws);
            (mass.unwrap_or(f64::NAN), s.position_mm)
        })
        .collect();
    Coverage::of(pairs.into_iter())
}

/// How a set of posteriors forecasts the truth ([`reliability`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reliability {
    pub pairs: usize,
    /// [`RELIABILITY_LEVELS`].
    pub levels: Vec<f64>,
    /// Fraction of the pairs whose truth lies inside the region of each level (calibrated: equal to the level).
    pub inside: Vec<f64>,
    /// Mean negative log density of the truth (each capped at [`NLL_CAP`]; over x, y in metres and θ in radians).
    pub mean_nll: f64,
    /// Sharpness: the median over pairs of the top mode's standard deviation (its core and tail together,
    /// [`crate::pose::posterior::PosteriorMode::sigmas`]) per position axis, mm …
    pub median_sigma_position_mm: f64,
    /// … and of θ, degrees (`None` where the symmetry leaves θ free in every pair) …
    pub median_sigma_theta_deg: Option<f64>,
    /// … and of θ of the top mode's core alone, degrees: the σ of the contacts the estimate got right (heavy-tailed
    /// errors put the rest in the tail) …
    #[serde(default)]
    pub median_core_sigma_theta_deg: Option<f64>,
    /// … and the median half-width of the top mode's central interval holding [`ONE_SIGMA`] of it
    /// ([`crate::pose::posterior::PosteriorMode::half_widths`]): the spread read as a Gaussian's ±σ, position (mm,
    /// the RMS over x and y) …
    #[serde(default)]
    pub median_half_width_position_mm: Option<f64>,
    /// … and θ, degrees …
    #[serde(default)]
    pub median_half_width_theta_deg: Option<f64>,
    /// … against the median error of the estimate: position (mm) …
    pub median_error_position_mm: f64,
    /// … and θ, degrees.
    pub median_error_theta_deg: Option<f64>,
}

/// The coverage, reliability diagram, sharpness and mean negative log density of `scored`'s posteriors,
/// recalibrated by `config` ([`calibrated`]; as recorded when `None`), from one Monte Carlo region mass per pair (`draws` draws);
/// pairs without modes are left out; `None` without pairs.
pub fn reliability(
    scored: &[Scored<'_>],
    config: Option<&PosteriorConfig>,
    draws: usize,
) -> Option<(Coverage, Reliability)> {
    // Each pair with its region mass, negative log density, top mode's σ, its core's σθ and its ±σ half-widths.
    type PairScore<'a, 'b> = (&'a Scored<'b>, f64, f64, [f64; 3], f64, [f64; 3]);
    let recalibrated = config.map(|c| calibrated(scored, c));
    let per_pair: Vec<PairScore<'_, '_>> = scored
        .par_iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let p = recalibrated.as_ref().map_or(s.posterior, |r| &r[i]);
            let mass = p.region_mass(s.truth, &s.symmetry, draws)?;
            let nll = (-p.log_density(s.truth, &s.symmetry)).min(NLL_CAP);
            let top = p.top()?;
            let core_theta = top.cov[2][2].max(0.0).sqrt();
            let half = top.half_widths(ONE_SIGMA, &s.symmetry);
            Some((s, mass, nll, top.sigmas(), core_theta, half))
        })
        .collect();
    let coverage = Coverage::of(per_pair.iter().map(|(s, m, ..)| (*m, s.position_mm)))?;
    let n = per_pair.len() as f64;
    let with_theta = || {
        per_pair
            .iter()
            .filter(|(s, ..)| s.symmetry.rotation.period_rad().is_some())
    };
    let sigma_theta: Vec<f64> = with_theta()
        .map(|(_, _, _, sig, ..)| sig[2].to_degrees())
        .collect();
    let core_theta: Vec<f64> = with_theta()
        .map(|(.., core, _)| core.to_degrees())
        .collect();
    let half_theta: Vec<f64> = with_theta()
        .map(|(.., half)| half[2].to_degrees())
        .collect();
    let error_theta: Vec<f64> = per_pair
        .iter()
        .filter_map(|(s, ..)| s.theta_rad.map(|t| t.abs().to_degrees()))
        .collect();
    let median_or_nan = |v: Vec<f64>| median(v).unwrap_or(f64::NAN);
    let reliability = Reliability {
        pairs: per_pair.len(),
        levels: RELIABILITY_LEVELS.to_vec(),
        inside: RELIABILITY_LEVELS
            .iter()
            .map(|&p| per_pair.iter().filter(|(_, m, ..)| *m <= p).count() as f64 / n)
            .collect(),
        mean_nll: per_pair.iter().map(|(_, _, v, ..)| v).sum::<f64>() / n,
        median_sigma_position_mm: median_or_nan(
            per_pair
                .iter()
                .map(|(_, _, _, s, ..)| ((s[0] * s[0] + s[1] * s[1]) / 2.0).sqrt() * 1e3)
                .collect(),
        ),
        median_sigma_theta_deg: median(sigma_theta),
        median_core_sigma_theta_deg: median(core_theta),
        median_half_width_position_mm: median(
            per_pair
                .iter()
                .map(|(.., h)| ((h[0] * h[0] + h[1] * h[1]) / 2.0).sqrt() * 1e3)
                .collect(),
        ),
        median_half_width_theta_deg: median(half_theta),
        median_error_position_mm: median_or_nan(
            per_pair.iter().map(|(s, ..)| s.position_mm).collect(),
        ),
        median_error_theta_deg: median(error_theta),
    };
    Some((coverage, reliability))
}

/// The median of the finite values ([`super::summary::MeanStd`]); `None` without any.
fn median(v: Vec<f64>) -> Option<f64> {
    let m = super::summary::MeanStd::of(v.into_iter().map(Some)).median;
    m.is_finite().then_some(m)
}

/// Per pair, 1 / the number of pairs in its contact-size bin ([`super::breakdown::CONTACT_BINS`]), scaled to a
/// mean of 1.
fn bin_weights(scored: &[Scored<'_>]) -> Vec<f64> {
    let bins = &super::breakdown::CONTACT_BINS;
    let bin = |s: &Scored<'_>| {
        bins.iter()
            .position(|&(lo, hi)| (lo..hi).contains(&s.contact_pixels))
    };
    let mut counts = vec![0usize; bins.len() + 1];
    for s in scored {
        counts[bin(s).unwrap_or(bins.len())] += 1;
    }
    let used = counts.iter().filter(|&&c| c > 0).count().max(1) as f64;
    scored
        .iter()
        .map(|s| scored.len() as f64 / (used * counts[bin(s).unwrap_or(bins.len())] as f64))
        .collect()
}

/// Mean negative log density of the truths under `scored`'s posteriors recalibrated by `config`, each pair weighted
/// by `weights` and capped at `cap` (so that one pair far outside every mode does not decide alone).
pub fn mean_nll(scored: &[Scored<'_>], weights: &[f64], config: &PosteriorConfig, cap: f64) -> f64 {
    let posteriors = calibrated(scored, config);
    let total: f64 = scored
        .par_iter()
        .zip(&posteriors)
        .zip(weights)
        .map(|((s, p), w)| w * (-p.log_density(s.truth, &s.symmetry)).min(cap))
        .sum();
    total / scored.len().max(1) as f64
}

/// A fitted calibration and how it scores on the pairs it was fitted to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    pub config: PosteriorConfig,
    /// The fit's objective: [`mean_nll`] with each contact-size bin weighted alike.
    pub mean_nll: f64,
    pub coverage: Option<Coverage>,
}

/// The calibration fitted to `scored` (module docs): `base`'s other settings kept, its fitted ones the first start;
/// where the records keep the contact the best mode predicts, fitted with each contact count, and where they keep
/// the frames' noise, with and without [`PosteriorConfig::frame_noise`]; the best fit kept. One calibration for
/// every frame: `base`'s [`PosteriorConfig::resampled_frames`] is dropped.
pub fn fit_posterior(scored: &[Scored<'_>], base: &PosteriorConfig) -> Fit {
    // One calibration for the frames fitted to, whatever kind they are.
    let base = &PosteriorConfig {
        resampled_frames: None,
        ..base.clone()
    };
    // What the records allow is tried both ways; the rest as `base` has it.
    let both_if = |kept: bool, given: bool| if kept { vec![false, true] } else { vec![given] };
    let counts = both_if(
        scored
            .iter()
            .any(|s| s.posterior.predicted_contact_px.is_some()),
        base.contact_from_prediction,
    );
    let noises = both_if(
        scored.iter().any(|s| s.posterior.noise.is_some()),
        base.frame_noise,
    );
    let variants: Vec<(bool, bool)> = counts
        .iter()
        .flat_map(|&c| noises.iter().map(move |&n| (c, n)))
        .collect();
    let fits: Vec<Fit> = variants
        .into_iter()
        .map(|(predicted, frame_noise)| {
            fit_one(
                scored,
                &PosteriorConfig {
                    contact_from_prediction: predicted,
                    frame_noise,
                    ..base.clone()
                },
            )
        })
        .collect();
    fits.into_iter()
        .min_by(|a, b| a.mean_nll.total_cmp(&b.mean_nll))
        .unwrap_or(Fit {
            config: base.clone(),
            mean_nll: f64::NAN,
            coverage: None,
        })
}

/// [`fit_posterior`] with `base`'s contact count.
fn fit_one(scored: &[Scored<'_>], base: &PosteriorConfig) -> Fit {
    let fusion = scored.iter().any(|s| s.prior.is_some());
    let x0 = encode(base, fusion);
    // Each contact-size bin counts alike (a pair weighs 1 / its bin's pairs): the posterior is to be calibrated in
    // every bin, and small contacts, the hardest, are the fewest.
    let weights = bin_weights(scored);
    let objective = |x: &[f64]| mean_nll(scored, &weights, &decode(x, base, fusion), NLL_CAP);
    // From the given calibration and from two others (sharp / broad), each refined from its optimum once more.
    let mut starts = vec![x0.clone()];
    for (ln_tau, ln_floor) in [(0.0, -9.0), (3.0, -7.0)] {
        let mut x = x0.clone();
        x[0] = ln_tau;
        x[1] = ln_tau;
        x[2] = ln_floor;
        starts.push(x);
    }
    let mut step = vec![
        1.0, 1.0, 1.0, 1.0, 0.3, 1.0, 0.5, 1.0, 1.0, 1.0, 0.5, 0.7, 0.3, 0.5, 0.3, 1.0, 0.5, 0.5,
        0.5, 0.5,
    ];
    // The noise floor only where the frames' noise weighs the evidence.
    if base.frame_noise {
        step.push(1.0);
    }
    // The fusion weight only where track frames are fused; its first step points into 0–1.
    if fusion {
        step.push(if base.fusion_weight > 0.7 { -0.3 } else { 0.3 });
    }
    let mut best: Option<(Vec<f64>, f64)> = None;
    for x in starts {
        let (x, _) = nelder_mead(&objective, &x, &step, 600);
        let half: Vec<f64> = step.iter().map(|s| s / 2.0).collect();
        let (x, v) = nelder_mead(&objective, &x, &half, 400);
        if best.as_ref().is_none_or(|(_, b)| v < *b) {
            best = Some((x, v));
        }
    }
    let Some((x, mean_nll)) = best else {
        return Fit {
            config: base.clone(),
            mean_nll: f64::NAN,
            coverage: None,
        };
    };
    let config = decode(&x, base, fusion);
    Fit {
        coverage: coverage_with(scored, Some(&config), 1000),
        config,
        mean_nll,
    }
}

/// The fitted settings as free coordinates (logs of scales, logits and slopes as they are); the noise floor where
/// the frames' noise weighs the evidence, and [`PosteriorConfig::fusion_weight`] where `fusion` (the pairs include
/// fused track frames).
fn encode(c: &PosteriorConfig, fusion: bool) -> Vec<f64> {
    let mut x = vec![
        c.temperature.ln(),
        c.covariance_temperature.ln(),
        c.floor_position_m.max(1e-6).ln(),
        c.floor_theta_rad.max(1e-5).ln(),
        c.floor_exponent,
        c.tail_logit,
        c.tail_contact_slope,
        c.tail_position_m.max(1e-6).ln(),
        c.tail_theta_rad.max(1e-5).ln(),
        c.far_logit,
        c.far_contact_slope,
        c.far_position_m.max(1e-6).ln(),
        c.tail_exponent,
        c.tail_core_scale.max(1e-3).ln(),
        c.far_exponent,
        c.far_ambiguity,
        c.tail_rivals,
        c.far_rivals,
        c.tail_misfit,
        c.far_misfit,
    ];
    if c.frame_noise {
        x.push(c.noise_floor_m.max(1e-5).ln());
    }
    if fusion {
        x.push(c.fusion_weight);
    }
    x
}

/// The inverse of [`encode`] (with the same `fusion`) onto `base`, each setting clamped to a plausible range (the fit
/// cannot wander off to a degenerate optimum: a zero-width core on a handful of exact pairs).
fn decode(x: &[f64], base: &PosteriorConfig, fusion: bool) -> PosteriorConfig {
    let exp = |v: f64, lo: f64, hi: f64| v.clamp(lo.ln(), hi.ln()).exp();
    // Past the 20 settings every fit has, as `encode` lays them out: the noise floor where the frames' noise is on,
    // then the fusion weight where `fusion`.
    let mut extra = x.get(20..).unwrap_or_default().iter();
    let noise_floor_m = if base.frame_noise {
        extra
            .next()
            .map_or(base.noise_floor_m, |&v| exp(v, 1e-5, 0.005))
    } else {
        base.noise_floor_m
    };
    let fusion_weight = if fusion {
        extra
            .next()
            .map_or(base.fusion_weight, |&v| v.clamp(0.0, 1.0))
    } else {
        base.fusion_weight
    };
    PosteriorConfig {
        temperature: exp(x[0], 0.05, 1e5),
        covariance_temperature: exp(x[1], 0.05, 1e5),
        floor_position_m: exp(x[2], 1e-5, 0.01),
        floor_theta_rad: exp(x[3], 1e-4, 0.5),
        floor_exponent: x[4].clamp(0.0, 2.0),
        tail_logit: x[5].clamp(-12.0, 6.0),
        tail_contact_slope: x[6].clamp(-4.0, 4.0),
        tail_position_m: exp(x[7], 1e-5, 0.03),
        tail_theta_rad: exp(x[8], 1e-4, 1.5),
        far_logit: x[9].clamp(-12.0, 6.0),
        far_contact_slope: x[10].clamp(-4.0, 4.0),
        far_position_m: exp(x[11], 1e-4, 0.05),
        tail_exponent: x[12].clamp(-1.0, 2.0),
        tail_core_scale: exp(x[13], 1.0, 30.0),
        far_exponent: x[14].clamp(-1.0, 2.0),
        far_ambiguity: x[15].clamp(-10.0, 10.0),
        tail_rivals: x[16].clamp(-10.0, 10.0),
        far_rivals: x[17].clamp(-10.0, 10.0),
        tail_misfit: x[18].clamp(-10.0, 10.0),
        far_misfit: x[19].clamp(-10.0, 10.0),
        noise_floor_m,
        fusion_weight,
        ..base.clone()
    }
}

#[cfg(test)]
#[path = "coverage_tests.rs"]
mod tests;
