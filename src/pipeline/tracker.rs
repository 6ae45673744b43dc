//! # The tracker: one pose engine for a whole recording, each frame's estimate carried to the next
//!
//! [`Tracker`] runs [`super::track`]'s frames in order (module docs there): the De-render and Pose use cases on one
//! frame, with a [`PosePrior`] from the frame before while the contact stays the same ([`TrackingConfig`]).

use serde::{Deserialize, Serialize};

use super::track::{position_spread_mm, std_dev, FrameTrack, PressChoice};
use super::{LoadedObject, PipelineError, Progress};
use crate::model::DiffusionModel;
use crate::objects::Symmetry;
use crate::pose::camera_path::CameraPath;
use crate::pose::{Estimator, PoseConfig, PosePrior};
use crate::recording::process::LightPress;
use crate::recording::ProcessedRecording;
use crate::sensor::Se2;
use crate::sim::{PreparedObject, Simulator};

/// What one frame's estimate needs besides the frame.
pub struct TrackContext<'a> {
    pub model: &'a DiffusionModel,
    pub object: &'a LoadedObject,
    /// The same object, prepared for rendering (its top and ray caster).
    pub prepared: &'a PreparedObject,
    pub sim: &'a Simulator,
    pub derender: &'a super::DerenderConfig,
    pub pose: &'a PoseConfig,
    pub press: PressChoice,
    pub tracking: &'a TrackingConfig,
}

/// How a track uses the recording (module docs): which frames, and how much of a frame's work the frame before it
/// saves. On the command line `--per-frame`, `--carried-samples`, `--carried-steps`, `--refresh-every` and
/// `--min-contact-px`; all of them in sessions and track.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct TrackingConfig {
    /// Estimate every frame on its own, from scratch (as `tnd pose` does one frame), instead of carrying the
    /// previous frame's estimate forward.
    #[arg(long)]
    pub per_frame: bool,
    /// Samples drawn on a frame that carries the previous frame's estimate (a contact's first frame, and every
    /// frame with --per-frame, draws --samples).
    #[arg(long, default_value_t = DEFAULT_CARRIED_SAMPLES)]
    pub carried_samples: usize,
    /// Sampler steps on a carried frame (at most --steps).
    #[arg(long, default_value_t = DEFAULT_CARRIED_STEPS)]
    pub carried_steps: usize,
    /// Estimate a frame from scratch after this many carried frames in a row (0: only when the contact changes).
    #[arg(long, default_value_t = 0)]
    pub refresh_every: usize,
    /// Frames with fewer contact pixels (imprint over the contact threshold) are not tracked.
    #[arg(long, default_value_t = DEFAULT_MIN_CONTACT_PX)]
    pub min_contact_px: usize,
    /// Poses a frame hands to the next (its estimate first, then its posterior's other modes and its
    /// multi-sample estimate): the next frame's registrations start from them.
    #[arg(skip = DEFAULT_CARRIED_POSES)]
    pub carried_poses: usize,
    /// Random registration starts on a carried frame beside the carried poses (a pose the earlier frames missed can
    /// still be found).
    #[arg(skip = DEFAULT_CARRIED_RANDOM_STARTS)]
    pub carried_random_starts: usize,
    /// The contact has changed, and the frame is estimated from scratch, when less than this share of the smaller
    /// of its contact and the previous frame's lies in both (the object slid, or another part touches).
    #[arg(skip = DEFAULT_MIN_OVERLAP)]
    pub min_overlap: f64,
}

/// Default of [`TrackingConfig::carried_samples`].
pub const DEFAULT_CARRIED_SAMPLES: usize = 3;
/// Default of [`TrackingConfig::carried_steps`].
pub const DEFAULT_CARRIED_STEPS: usize = 6;
/// Default of [`TrackingConfig::min_contact_px`].
pub const DEFAULT_MIN_CONTACT_PX: usize = 10;
/// Default of [`TrackingConfig::carried_poses`].
pub const DEFAULT_CARRIED_POSES: usize = 3;
/// Default of [`TrackingConfig::carried_random_starts`].
pub const DEFAULT_CARRIED_RANDOM_STARTS: usize = 2;
/// Default of [`TrackingConfig::min_overlap`].
pub const DEFAULT_MIN_OVERLAP: f64 = 0.5;

impl Default for TrackingConfig {
    fn default() -> Self {
        Self {
            per_frame: false,
            carried_samples: DEFAULT_CARRIED_SAMPLES,
            carried_steps: DEFAULT_CARRIED_STEPS,
            refresh_every: 0,
            min_contact_px: DEFAULT_MIN_CONTACT_PX,
            carried_poses: DEFAULT_CARRIED_POSES,
            carried_random_starts: DEFAULT_CARRIED_RANDOM_STARTS,
            min_overlap: DEFAULT_MIN_OVERLAP,
        }
    }
}

impl TrackingConfig {
    /// The frames of `recording` to track, every `every`-th: those with enough pixels with a return
    /// ([`ProcessedRecording::unusable`]; `skipped` hears each other one with why) and
    /// [`TrackingConfig::min_contact_px`] contact pixels — over `contact_threshold_m` (the threshold
    /// [`ProcessedRecording::contact_px`] was counted at), or, where no frame has that much, over a light press's
    /// threshold ([`ProcessedRecording::light_press`], returned with the frames).
    pub fn frames(
        &self,
        recording: &ProcessedRecording,
        every: usize,
        contact_threshold_m: f64,
        skipped: &mut dyn FnMut(usize, String),
    ) -> (Vec<usize>, Option<LightPress>) {
        let usable: Vec<usize> = (0..recording.len())
            .step_by(every.max(1))
            .filter(|&k| match recording.unusable(k) {
                Some(why) => {
                    skipped(k, why);
                    false
                }
                None => true,
            })
            .collect();
        let with_contact = |counts: &[usize]| -> Vec<usize> {
            usable
                .iter()
                .copied()
                .filter(|&k| counts.get(k).is_some_and(|&px| px >= self.min_contact_px))
                .collect()
        };
        let todo = with_contact(&recording.contact_px);
        if !todo.is_empty() {
            return (todo, None);
        }
        match recording.light_press(contact_threshold_m) {
            Some((light, counts)) => {
                let todo = with_contact(&counts);
                let light = (!todo.is_empty()).then_some(light);
                (todo, light)
            }
            None => (todo, None),
        }
    }

    /// Every setting in range; the error names the first that is not.
    pub fn validate(&self) -> Result<(), PipelineError> {
        let bad = |name: &'static str, why: String| {
            Err(PipelineError::Settings(crate::error::InvalidSetting::new(
                name, why,
            )))
        };
        if !(1..=super::derender::MAX_SAMPLES).contains(&self.carried_samples) {
            return bad(
                "carried_samples",
                format!(
                    "tracking: carried_samples (samples on a carried frame) must be 1..={}, got {}",
                    super::derender::MAX_SAMPLES,
                    self.carried_samples
                ),
            );
        }
        if self.carried_steps == 0 {
            return bad(
                "carried_steps",
                "tracking: carried_steps must be at least 1".into(),
            );
        }
        if self.carried_poses == 0 {
            return bad(
                "carried_poses",
                "tracking: carried_poses must be at least 1".into(),
            );
        }
        if !(0.0..=1.0).contains(&self.min_overlap) {
            return bad(
                "min_overlap",
                format!(
                    "tracking: min_overlap is a share in [0, 1], got {}",
                    self.min_overlap
                ),
            );
        }
        Ok(())
    }
}

/// What a frame hands to the next; saved beside a track so that a resumed track goes on as if never stopped.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Carry {
    /// The frame that handed it on.
    pub frame: usize,
    pub prior: PosePrior,
    /// Carried frames up to and including `frame` since the last one estimated from scratch.
    pub carried_in_a_row: usize,
}

/// Tracks the frames of one recording in order (module docs): one pose engine for all of them (the object is
/// prepared once), and each frame's estimate carried to the next while the contact stays the same.
pub struct Tracker<'a> {
    ctx: TrackContext<'a>,
    engine: Estimator,
    carry: Option<Carry>,
    /// The sensor's camera at native pixels, built for the first recording whose frames were resampled.
    camera_path: Option<std::sync::Arc<CameraPath>>,
    /// θ of the last estimate reported, radians: each frame's poses are reported as the symmetric equivalents
    /// nearest it, so that a 4-fold object does not jump by 90° between frames that agree.
    reported_theta: Option<f64>,
}

impl<'a> Tracker<'a> {
    pub fn new(ctx: TrackContext<'a>) -> Result<Self, PipelineError> {
        ctx.tracking.validate()?;
        ctx.pose.validate()?;
        Ok(Self {
            engine: Estimator::new(ctx.pose.clone()),
            ctx,
            carry: None,
            camera_path: None,
            reported_theta: None,
        })
    }

    /// De-render frame `frame` of `recording` and estimate the object's pose (module docs); the row is not scored
    /// ([`FrameTrack::score`]). Frames are taken in increasing order; one out of order, or after a frame
    /// without contact, is estimated from scratch. `progress` counts sampling steps, then fits; returning `false`
    /// cancels.
    pub fn track(
        &mut self,
        recording: &ProcessedRecording,
        frame: usize,
        progress: Progress<'_>,
    ) -> Result<FrameTrack, PipelineError> {
        let resampled = recording.frames_resampled(&self.ctx.sim.config().camera);
        if resampled && self.camera_path.is_none() {
            self.camera_path = CameraPath::for_frames(self.ctx.sim.config(), true)?;
        }
        let camera_path = self.camera_path.as_ref().filter(|_| resampled);
        let ctx = &self.ctx;
        let (Some(imprint), Some(signature)) = (
            recording.imprints.get(frame),
            recording.signatures.get(frame),
        ) else {
            return Err(PipelineError::Settings(crate::error::InvalidSetting::new(
                "frame",
                format!(
                    "the recording has {} frames; there is no frame {frame}",
                    recording.len()
                ),
            )));
        };
        let carry = self
            .carry
            .take()
            .filter(|c| self.carries(c, recording, frame));
        let mut derender = ctx.derender.clone();
        derender.seed = ctx.derender.seed.wrapping_add(frame as u64);
        if carry.is_some() {
            derender.samples = derender.samples.min(ctx.tracking.carried_samples);
            derender.sampler.steps = derender.sampler.steps.min(ctx.tracking.carried_steps);
        }
        let guidance = super::imprint_guidance(&derender, ctx.sim, imprint, Some(signature))?;
        let out = super::derender(
            ctx.model,
            imprint,
            guidance.as_ref(),
            &derender,
            self.engine.config.consensus_probability,
            &mut *progress,
        )?;
        let mut row = FrameTrack::new(
            frame,
            recording.stamps_ns.get(frame).copied().unwrap_or(0),
            recording.contact_px.get(frame).copied().unwrap_or(0),
            out.samples.len(),
        );
        row.carried = carry.is_some();
        row.fused_with = carry
            .as_ref()
            .filter(|c| c.prior.posterior.is_some())
            .map(|c| c.frame);
        let observation = super::Observation {
            samples: &out.samples,
            imprint,
            signature: Some(signature),
            truth: None,
            prior: carry.as_ref().map(|c| &c.prior),
            camera_path,
        };
        let placed = match super::place_and_estimate(
            ctx.object,
            Some(ctx.prepared),
            ctx.sim,
            &observation,
            super::Placement::Press(ctx.press),
            &self.engine,
            derender.seed,
            &mut |done, total| progress(done, total),
        ) {
            Ok(p) => p,
            Err(PipelineError::NoContact) => return Ok(row),
            Err(e) => return Err(e),
        };
        fill_row(&mut row, &placed, &ctx.object.symmetry);
        align_theta(&mut row, self.reported_theta, &ctx.object.symmetry);
        self.reported_theta = row.estimate.map(|e| e.theta).or(self.reported_theta);
        self.carry = row.estimate.map(|estimate| Carry {
            frame,
            prior: PosePrior {
                poses: carried_poses(
                    estimate,
                    &placed.estimate,
                    &ctx.object.symmetry,
                    ctx.tracking.carried_poses,
                ),
                random_starts: ctx.tracking.carried_random_starts,
                press_m: placed.press_m,
                posterior: placed.estimate.posterior.clone(),
            },
            carried_in_a_row: carry.map_or(0, |c| c.carried_in_a_row + 1),
        });
        Ok(row)
    }

    /// What the last frame tracked hands to the next (`None`: it had no estimate).
    pub fn carry(&self) -> Option<&Carry> {
        self.carry.as_ref()
    }

    /// Go on from a saved [`Self::carry`] (a resumed track).
    pub fn resume(&mut self, carry: Carry) {
        self.reported_theta = carry.prior.poses.first().map(|p| p.theta);
        self.carry = Some(carry);
    }

    /// Whether frame `frame` carries `c` forward: tracking carries, the frames since `c`'s all had contact, the
    /// contact (imprint over the baseline's threshold) overlaps `c`'s frame's and no refresh is due.
    fn carries(&self, c: &Carry, recording: &ProcessedRecording, frame: usize) -> bool {
        let t = self.ctx.tracking;
        let threshold = self.engine.config.baseline.threshold_m as f32;
        let contact = |k: usize| -> Option<Vec<bool>> {
            recording
                .imprints
                .get(k)
                .map(|y| y.data.iter().map(|&v| v > threshold).collect())
        };
        let (Some(contact), Some(before)) = (contact(frame), contact(c.frame)) else {
            return false;
        };
        if t.per_frame || frame <= c.frame || contact.len() != before.len() {
            return false;
        }
        if t.refresh_every > 0 && c.carried_in_a_row + 1 >= t.refresh_every {
            return false;
        }
        let held =
            (c.frame + 1..frame).all(|k| recording.contact_px.get(k).is_some_and(|&n| n > 0));
        let count = |m: &[bool]| m.iter().filter(|&&b| b).count();
        let both = contact
            .iter()
            .zip(&before)
            .filter(|(a, b)| **a && **b)
            .count();
        let smaller = count(&contact).min(count(&before));
        held && smaller > 0 && both as f64 >= t.min_overlap * smaller as f64
    }
}

/// The poses a frame hands to the next: the estimate, the posterior's other modes (heaviest first) and the
/// multi-sample estimate, each pose once (by the object's symmetry), at most `n`.
fn carried_poses(
    estimate: Se2,
    found: &crate::pipeline::PoseEstimate,
    symmetry: &Symmetry,
    n: usize,
) -> Vec<Se2> {
    let mut poses = vec![estimate];
    let mut modes: Vec<_> = found
        .posterior
        .iter()
        .flat_map(|p| p.modes.iter())
        .collect();
    modes.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    let others = modes
        .into_iter()
        .map(|m| m.pose())
        .chain(found.report.multi_sample.as_ref().map(|m| m.pose));
    for p in others {
        if poses.len() >= n {
            break;
        }
        if !poses
            .iter()
            .any(|q| crate::uncertainty::same_pose(*q, p, symmetry))
        {
            poses.push(p);
        }
    }
    poses.truncate(n);
    poses
}

/// `row`'s poses as the equivalents nearest the last reported θ (the estimate; the others nearest the estimate):
/// the same poses, reported without jumps between a symmetric object's equivalent angles.
fn align_theta(row: &mut FrameTrack, reported_theta: Option<f64>, symmetry: &Symmetry) {
    if let (Some(e), Some(t)) = (row.estimate.as_mut(), reported_theta) {
        *e = symmetry.nearest_equivalent(*e, t);
    }
    let Some(theta) = row.estimate.map(|e| e.theta) else {
        return;
    };
    for pose in [row.multi_sample.as_mut(), row.baseline.as_mut()]
        .into_iter()
        .flatten()
    {
        *pose = symmetry.nearest_equivalent(*pose, theta);
    }
}

/// `row` with what `placed` estimated: press, poses, spreads and posterior.
fn fill_row(row: &mut FrameTrack, placed: &super::PlacedEstimate, symmetry: &Symmetry) {
    row.press_m = placed.press_m;
    let estimate = &placed.estimate;
    let report = &estimate.report;
    row.registered = report.samples.len();
    row.estimate = estimate.best();
    row.multi_sample = report.multi_sample.as_ref().map(|m| m.pose);
    row.baseline = report.baseline.as_ref().map(|b| b.pose);
    let poses: Vec<Se2> = report.samples.iter().map(|e| e.pose).collect();
    row.spread_mm = position_spread_mm(&poses);
    // θ of each sample against the reference (the estimate), reduced by the object's symmetry.
    let thetas: Option<Vec<f64>> = report.samples.iter().map(|e| e.theta_deg).collect();
    row.theta_spread_deg = thetas.as_deref().and_then(std_dev);
    if let Some(p) = &estimate.posterior {
        row.posterior_modes = p.modes.len();
        row.estimate_weight = row
            .estimate
            .and_then(|e| p.mode_of(e, symmetry))
            .map(|m| m.weight);
        row.covariance = row
            .estimate
            .and_then(|e| crate::pose::export::covariance_about(p, e, symmetry));
        row.half_width_68 = row
            .estimate
            .and_then(|e| p.estimate_half_widths(e, symmetry));
    }
    row.posterior = estimate.posterior.clone();
    row.pose_modes = if report.samples.len() >= 2 {
        report.major_modes().len()
    } else {
        0
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reported_poses_are_the_symmetric_equivalents_nearest_the_last() {
        use crate::objects::RotationSymmetry;
        use std::f64::consts::{FRAC_PI_2, PI, TAU};
        let four = Symmetry {
            rotation: RotationSymmetry::NFold(4),
            ..Symmetry::default()
        };
        // Invariants: the same pose (θ moved by whole periods, x and y kept) and within half a period of the
        // reference, for every reference and θ.
        for (period, symmetry) in [(FRAC_PI_2, four), (TAU, Symmetry::default())] {
            for i in 0..40 {
                let theta = -7.0 + 0.37 * f64::from(i);
                let reference = 3.0 - 0.21 * f64::from(i);
                let p = symmetry.nearest_equivalent(Se2::new(0.001, -0.002, theta), reference);
                let turns = (p.theta - theta) / period;
                assert!((turns - turns.round()).abs() < 1e-9, "{p:?}");
                assert!((p.theta - reference).abs() <= period / 2.0 + 1e-9, "{p:?}");
                assert_eq!((p.x, p.y), (0.001, -0.002));
            }
        }
        // A 4-fold cross tracked: -2.745, -1.178, 1.973, 1.968, 0.412 rad on consecutive frames are one angle (within
        // 0.02 rad), reported as such.
        let mut last = None;
        for theta in [-2.745, -1.178, 1.973, 1.968, 0.412] {
            let mut row = FrameTrack::new(0, 0, 100, 4);
            row.estimate = Some(Se2::new(0.0, 0.0, theta));
            row.multi_sample = Some(Se2::new(0.0, 0.0, theta + PI));
            align_theta(&mut row, last, &four);
            let (e, m) = (row.estimate.unwrap(), row.multi_sample.unwrap());
            assert!((e.theta - (-2.745)).abs() < 0.03, "{e:?}");
            assert!((m.theta - e.theta).abs() < 1e-9, "{m:?}");
            last = Some(e.theta);
        }
        // θ free (a cylinder): unchanged.
        let free = Symmetry {
            rotation: RotationSymmetry::Continuous,
            ..Symmetry::default()
        };
        assert_eq!(
            free.nearest_equivalent(Se2::new(0.0, 0.0, 2.0), -1.0).theta,
            2.0
        );
    }

    #[test]
    fn tracking_options_are_the_config_defaults_and_are_checked() {
        use clap::Parser;
        #[derive(Parser)]
        struct Cli {
            #[command(flatten)]
            tracking: TrackingConfig,
        }
        let parse = |args: &[&str]| {
            Cli::try_parse_from(std::iter::once("tnd").chain(args.iter().copied()))
                .map(|c| c.tracking)
        };
        assert_eq!(parse(&[]).unwrap(), TrackingConfig::default());
        let json: TrackingConfig = serde_json::from_str("{}").unwrap();
        assert_eq!(json, TrackingConfig::default());
        let c = parse(&[
            "--per-frame",
            "--carried-samples",
            "5",
            "--refresh-every",
            "4",
        ])
        .unwrap();
        assert!(c.per_frame && c.carried_samples == 5 && c.refresh_every == 4);
        assert_eq!(c.carried_steps, DEFAULT_CARRIED_STEPS);
        assert!(TrackingConfig::default().validate().is_ok());
        for (bad, name) in [
            (
                TrackingConfig {
                    carried_samples: 0,
                    ..Default::default()
                },
                "carried_samples",
            ),
            (
                TrackingConfig {
                    carried_steps: 0,
                    ..Default::default()
                },
                "carried_steps",
            ),
            (
                TrackingConfig {
                    min_overlap: 1.5,
                    ..Default::default()
                },
                "min_overlap",
            ),
            (
                TrackingConfig {
                    min_overlap: f64::NAN,
                    ..Default::default()
                },
                "min_overlap",
            ),
        ] {
            let e = bad.validate().unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
    }
}
