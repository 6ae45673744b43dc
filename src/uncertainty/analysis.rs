//! The uncertainty analysis of one signature (paper V.D): register every generated sample from one fixed start and
//! collect the errors (see the module docs of [`super`]); with two or more samples, also the multi-sample estimate
//! (the samples' consensus contact, [`crate::pose::from_depth::consensus_depth`], registered from K random starts).

use glam::DAffine3;

use super::{FailedRegistration, SampleError, UncertaintyReport};
use crate::image::Image;
use crate::metrics::evaluate::EvalError;
use crate::pose::from_depth::consensus_depth;
use crate::pose::{Estimator, ObjectModel, SensorContext};
use crate::pose::{Hypothesis, InitStrategy, PoseError};
use crate::sensor::Se2;

/// The most samples whose own registrations propose poses to the multi-sample estimate's signature check (the
/// consensus of them all proposes too).
pub const MULTI_PROPOSALS: usize = 16;

/// Inputs of one analysis.
pub struct Signature<'a> {
    /// `t_world_camera` of the sensor camera.
    pub t_world_camera: DAffine3,
    /// The generated samples of X̂0 (metres).
    pub samples: &'a [Image],
    /// The baseline's in-contact depth, if a signature is available.
    pub baseline: Option<&'a Image>,
    /// The true pose, when known.
    pub truth: Option<Se2>,
    /// The fixed start; `None`: the best of a K-start registration of the first sample with contact.
    pub init: Option<Se2>,
    /// (S, Y), the measured signature and imprint: with them (and
    /// [`crate::pose::PoseConfig::check_signature`]) the multi-sample estimate is the signature check's
    /// pick among the consensus's and every sample's hypotheses.
    pub measured: Option<(&'a Image, &'a Image)>,
    /// What earlier frames of the same contact said ([`crate::pose::PosePrior`]): the K-start registrations start
    /// from its poses; `None`: [`crate::pose::PoseConfig::inits`] random starts.
    pub prior: Option<&'a crate::pose::PosePrior>,
}

/// The K-start registration (from `strategy`'s starts) that gives an analysis its fixed start: the first of
/// `samples` with contact that registers, as `(index, every hypothesis best first)`; `None` when no sample has
/// contact. A sample that fails is skipped here (the analysis records it with the others); the error of the last
/// one is returned when none registers.
pub fn first_registration(
    estimator: &Estimator,
    object: &ObjectModel,
    ctx: &SensorContext,
    t_world_camera: &DAffine3,
    samples: &[Image],
    strategy: &InitStrategy,
    seed: u64,
) -> Result<Option<(usize, Vec<Hypothesis>)>, PoseError> {
    let mut last_error = None;
    for (i, s) in samples.iter().enumerate() {
        match estimator.register_depth(object, s, ctx, t_world_camera, strategy, seed) {
            Ok(Some(h)) if !h.is_empty() => return Ok(Some((i, h))),
            Ok(_) => {}
            Err(e) => last_error = Some(e),
        }
    }
    last_error.map_or(Ok(None), Err)
}

/// Register each sample from the fixed start and measure the errors against the truth (or, without it, against the
/// fixed start's source estimate). Samples without contact are skipped.
pub fn analyse(
    estimator: &Estimator,
    object: &ObjectModel,
    ctx: &SensorContext,
    sig: &Signature<'_>,
    seed: u64,
) -> Result<UncertaintyReport, EvalError> {
    analyse_with_progress(estimator, object, ctx, sig, seed, &mut |_, _| true)
}

/// [`analyse`] reporting `progress(done, total)` after each registration (the K-start search when `sig.init` is
/// `None`, every sample, the baseline); returning `false` stops it with [`EvalError::Cancelled`].
pub fn analyse_with_progress(
    estimator: &Estimator,
    object: &ObjectModel,
    ctx: &SensorContext,
    sig: &Signature<'_>,
    seed: u64,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<UncertaintyReport, EvalError> {
    let multi = sig.samples.len() > 1;
    let total = usize::from(sig.init.is_none())
        + sig.samples.len()
        + usize::from(sig.baseline.is_some())
        + usize::from(multi);
    let mut done = 0;
    let mut step = |done: &mut usize| {
        *done += 1;
        if progress(*done, total) {
            Ok(())
        } else {
            Err(EvalError::Cancelled)
        }
    };
    let strategy = estimator.starts(seed, sig.prior);
    let init = match sig.init {
        Some(i) => i,
        None => {
            let found = first_registration(
                estimator,
                object,
                ctx,
                &sig.t_world_camera,
                sig.samples,
                &strategy,
                seed,
            )
            .map_err(|source| EvalError::Pose {
                object: "uncertainty".into(),
                source,
            })?
            .and_then(|(_, h)| h.first().map(|b| b.pose))
            .ok_or_else(|| {
                EvalError::Generator(
                    "no generated sample has any contact; nothing to register".into(),
                )
            })?;
            step(&mut done)?;
            found
        }
    };
    let reference = sig.truth.unwrap_or(init);
    let fixed = InitStrategy::Fixed(init);
    let mut samples = Vec::with_capacity(sig.samples.len());
    // One sample (or the baseline, or the consensus) that cannot be registered is recorded and the others go on.
    let mut failed = Vec::new();
    let mut record = |what: String, e: &dyn std::error::Error| {
        failed.push(FailedRegistration {
            what,
            reason: crate::error::render(e),
        })
    };
    for (i, s) in sig.samples.iter().enumerate() {
        let hyps = match estimator.register_depth(
            object,
            s,
            ctx,
            &sig.t_world_camera,
            &fixed,
            seed.wrapping_add(i as u64),
        ) {
            Ok(h) => h,
            Err(e) => {
                record(format!("sample {i}"), &e);
                None
            }
        };
        if let Some(best) = hyps.as_ref().and_then(|h| h.first()) {
            samples.push(SampleError::new(
                best.pose,
                best.cost,
                reference,
                &object.symmetry,
            ));
        }
        step(&mut done)?;
    }
    let baseline = match sig.baseline {
        Some(b) => {
            match estimator.register_depth(object, b, ctx, &sig.t_world_camera, &fixed, seed) {
                Ok(h) => h.and_then(|h| h.first().copied()).map(|best| {
                    SampleError::new(best.pose, best.cost, reference, &object.symmetry)
                }),
                Err(e) => {
                    record("baseline".into(), &e);
                    None
                }
            }
        }
        None => None,
    };
    if sig.baseline.is_some() {
        step(&mut done)?;
    }
    let multi_sample = if multi {
        // With a prior, from its poses alone (the first registration explored).
        let carried = sig.prior.map(crate::pose::PosePrior::carried_only);
        let strategy = match &carried {
            Some(_) => estimator.starts(seed, carried.as_ref()),
            None => strategy,
        };
        let estimate = multi_sample_estimate(estimator, object, ctx, sig, &strategy);
        step(&mut done)?;
        match estimate {
            Ok(m) => m,
            Err(e) => {
                record("multi-sample estimate".into(), &e);
                None
            }
        }
    } else {
        None
    };
    let mut report =
        UncertaintyReport::new(reference, sig.truth.is_some(), init, samples, baseline);
    report.multi_sample = multi_sample
        .as_ref()
        .map(|m| SampleError::new(m.pose, m.cost, reference, &object.symmetry));
    report.multi_sample_posterior = multi_sample.and_then(|m| m.posterior);
    report.failed = failed;
    report.modes = super::pose_modes(&report.samples, &object.symmetry);
    report.theta_period_deg = object.symmetry.rotation.period_rad().map(f64::to_degrees);
    Ok(report)
}

/// The multi-sample estimate of `sig`: the samples' consensus contact registered from `strategy`'s starts; with the
/// signature check ([`Estimator::choose`]) every sample (and, with
/// [`crate::pose::PoseConfig::imprint_proposals`], the threshold baseline's contact) is registered from
/// them too and the check picks among all those hypotheses, with its posterior.
pub fn multi_sample_estimate(
    estimator: &Estimator,
    object: &ObjectModel,
    ctx: &SensorContext,
    sig: &Signature<'_>,
    strategy: &InitStrategy,
) -> Result<Option<MultiSample>, PoseError> {
    let consensus = consensus_depth(sig.samples, estimator.config.consensus_probability)?;
    let checked = estimator.config.check_signature && sig.measured.is_some();
    let mut registered = vec![consensus];
    if checked {
        // Each proposing sample is registered from every start, the bulk of the estimate's time; samples beyond the
        // first MULTI_PROPOSALS add to the consensus only (their poses repeat the first ones': a 50-sample
        // posterior then costs what a 16-sample one does here).
        registered.extend(sig.samples.iter().take(MULTI_PROPOSALS).cloned());
        // The imprint's threshold contact proposes too (its depths are the signature's: nothing to anchor).
        if let (true, Some(b)) = (estimator.config.imprint_proposals, sig.baseline) {
            registered.push(b.clone());
        }
    }
    // The samples arrive anchored (or not) as the caller chose: no second anchoring here.
    let hypotheses = estimator.pooled_hypotheses(
        object,
        &registered,
        ctx,
        &sig.t_world_camera,
        None,
        strategy,
    )?;
    let chosen = estimator.choose_with_posterior(
        object,
        &hypotheses,
        ctx,
        &sig.t_world_camera,
        sig.measured,
    )?;
    Ok(chosen.map(|(p, posterior)| {
        let cost = hypotheses
            .iter()
            .find(|h| h.pose == p)
            .map_or(f64::NAN, |h| h.cost);
        MultiSample {
            pose: p,
            cost,
            posterior,
        }
    }))
}

/// The multi-sample estimate ([`multi_sample_estimate`]).
#[derive(Clone, Debug)]
pub struct MultiSample {
    pub pose: Se2,
    /// Its registration cost (NaN for a pose the signature check refined).
    pub cost: f64,
    /// The signature check's posterior over the pooled hypotheses (`None` without the check).
    pub posterior: Option<crate::pose::posterior::PosePosterior>,
}
