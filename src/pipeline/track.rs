//! # Tracking: the object's pose on every contact frame of a recording
//!
//! [`Tracker::track`] is the De-render and Pose use cases ([`super::derender()`], [`super::place_and_estimate`]) on one
//! frame of a processed recording ([`crate::recording::ProcessedRecording`]): N samples of the in-contact depth, the
//! single-sample estimate, the multi-sample estimate and the threshold baseline, scored against the recorded pose
//! when the recording has one (the estimate never sees it). Each frame has its own seed (`seed + frame`).
//!
//! One tracker keeps one pose engine for all frames (the object is prepared once) and **carries each frame's
//! estimate to the next** ([`TrackingConfig`]): the object does not move while the sensor presses it, so a frame
//! whose contact overlaps the previous one's draws fewer samples with fewer steps, registers from the previous
//! frame's poses (a [`PosePrior`]) plus a few random starts, searches the press near the previous press, and has its
//! posterior reweighed by the previous one ([`crate::pose::fusion`]). A contact's first frame, and every frame with
//! [`TrackingConfig::per_frame`], is estimated from scratch. What a frame hands on ([`Carry`]) is saved beside the
//! track, so a track can stop and resume anywhere and give the same rows.
//!
//! The sensor is placed over the object as [`super::press`] says ([`PressChoice::Auto`] by default: per frame, from the
//! samples and the signature).

use serde::{Deserialize, Serialize};

pub use super::press::PressChoice;
use super::{LoadedObject, PipelineError, Progress};
use crate::model::DiffusionModel;
use crate::objects::Symmetry;
use crate::pose::{Estimator, PoseConfig, PosePrior};
use crate::recording::ProcessedRecording;
use crate::sensor::Se2;
use crate::sim::{PreparedObject, Simulator};
use crate::uncertainty::SampleError;

/// One frame of a track.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameTrack {
    /// Frame number in the recording (0-based).
    pub frame: usize,
    /// Time stamp, nanoseconds.
    pub stamp_ns: u64,
    /// Imprint pixels over the contact threshold.
    pub contact_px: usize,
    /// The press the sensor was placed at, metres (`None`: no sample had contact).
    pub press_m: Option<f64>,
    /// Samples drawn, and how many of them registered.
    pub samples: usize,
    pub registered: usize,
    /// The single-sample estimate `t_world_object` (`None`: no sample had contact).
    pub estimate: Option<Se2>,
    /// The multi-sample estimate (from two samples).
    pub multi_sample: Option<Se2>,
    /// The threshold baseline's pose.
    pub baseline: Option<Se2>,
    /// How far the registered samples' poses spread (from two): RMS distance of their positions from their mean,
    /// mm, and the standard deviation of their θ against the estimate's, degrees (`None`: continuous symmetry).
    /// The paper's uncertainty, one number each: a large spread says the frame's pose is not to be trusted.
    pub spread_mm: Option<f64>,
    pub theta_spread_deg: Option<f64>,
    /// How many distinct poses hold a fair share of the registered samples
    /// ([`crate::uncertainty::UncertaintyReport::major_modes`]): 1 is one pose, 2 or more an ambiguous contact, 0
    /// too few samples to say.
    pub pose_modes: usize,
    /// The recorded pose and press, when the recording (or the pose table) has them for this frame.
    pub recorded: Option<Se2>,
    pub recorded_press_m: Option<f64>,
    /// Errors against the recorded pose ([`Self::score`]): position mm, θ degrees (`None` θ: continuous
    /// symmetry), both reduced by the object's symmetry as `tnd eval` does.
    pub estimate_error: Option<(f64, Option<f64>)>,
    pub multi_sample_error: Option<(f64, Option<f64>)>,
    pub baseline_error: Option<(f64, Option<f64>)>,
    /// Modes of the pose posterior ([`crate::pose::posterior`]; 0: none), the weight of the one holding the
    /// estimate, and the posterior's covariance about the estimate over (x m, y m, θ rad)
    /// ([`crate::pose::export::covariance_about`]), as a `PoseWithCovariance` takes it.
    pub posterior_modes: usize,
    pub estimate_weight: Option<f64>,
    pub covariance: Option<crate::pose::posterior::Mat3>,
    /// The frame carried the previous frame's estimate forward ([`Tracker`]: fewer samples, registrations from
    /// its poses, the press searched near its press); `false`: estimated from scratch.
    pub carried: bool,
}

/// Columns of [`FrameTrack::csv_row`].
const CSV_COLUMNS: [&str; 37] = [
    "frame",
    "stamp_ns",
    "contact_px",
    "press_m",
    "samples",
    "registered",
    "x",
    "y",
    "theta",
    "multi_x",
    "multi_y",
    "multi_theta",
    "baseline_x",
    "baseline_y",
    "baseline_theta",
    "spread_mm",
    "theta_spread_deg",
    "pose_modes",
    "recorded_x",
    "recorded_y",
    "recorded_theta",
    "recorded_press_m",
    "position_err_mm",
    "theta_err_deg",
    "multi_position_err_mm",
    "multi_theta_err_deg",
    "baseline_position_err_mm",
    "baseline_theta_err_deg",
    "posterior_modes",
    "estimate_weight",
    "cov_xx",
    "cov_xy",
    "cov_xtheta",
    "cov_yy",
    "cov_ytheta",
    "cov_thetatheta",
    "carried",
];

/// Columns of a track written before the posterior's (read back with none).
const CSV_COLUMNS_V1: usize = 28;
/// Columns of a track written before tracks carried estimates (every row from scratch).
const CSV_COLUMNS_V2: usize = 36;

impl FrameTrack {
    /// A frame with nothing estimated yet.
    pub fn new(frame: usize, stamp_ns: u64, contact_px: usize, samples: usize) -> Self {
        Self {
            frame,
            stamp_ns,
            contact_px,
            press_m: None,
            samples,
            registered: 0,
            estimate: None,
            multi_sample: None,
            baseline: None,
            spread_mm: None,
            theta_spread_deg: None,
            pose_modes: 0,
            recorded: None,
            recorded_press_m: None,
            estimate_error: None,
            multi_sample_error: None,
            baseline_error: None,
            posterior_modes: 0,
            estimate_weight: None,
            covariance: None,
            carried: false,
        }
    }

    /// The CSV header of [`Self::csv_row`].
    pub fn csv_header() -> String {
        CSV_COLUMNS.join(",")
    }

    /// `rows` as a CSV table (what `tnd recording track` writes as track.csv).
    pub fn csv(rows: &[FrameTrack]) -> String {
        let mut text = format!("{}\n", Self::csv_header());
        for r in rows {
            text.push_str(&r.csv_row());
            text.push('\n');
        }
        text
    }

    /// The frame as one CSV row (metres, radians; spreads and errors in mm and degrees; empty where unknown). Numbers
    /// are written so that [`Self::from_csv_row`] reads them back exactly.
    pub fn csv_row(&self) -> String {
        let num = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
        let pose = |p: Option<Se2>| match p {
            Some(p) => format!("{},{},{}", p.x, p.y, p.theta),
            None => ",,".into(),
        };
        let err = |e: Option<(f64, Option<f64>)>| match e {
            Some((mm, deg)) => format!("{mm},{}", num(deg)),
            None => ",".into(),
        };
        [
            self.frame.to_string(),
            self.stamp_ns.to_string(),
            self.contact_px.to_string(),
            num(self.press_m),
            self.samples.to_string(),
            self.registered.to_string(),
            pose(self.estimate),
            pose(self.multi_sample),
            pose(self.baseline),
            num(self.spread_mm),
            num(self.theta_spread_deg),
            self.pose_modes.to_string(),
            pose(self.recorded),
            num(self.recorded_press_m),
            err(self.estimate_error),
            err(self.multi_sample_error),
            err(self.baseline_error),
            self.posterior_modes.to_string(),
            num(self.estimate_weight),
            match self.covariance {
                Some(c) => [c[0][0], c[0][1], c[0][2], c[1][1], c[1][2], c[2][2]]
                    .map(|v| v.to_string())
                    .join(","),
                None => ",,,,,".into(),
            },
            u8::from(self.carried).to_string(),
        ]
        .join(",")
    }

    /// Read a row written by [`Self::csv_row`].
    pub fn from_csv_row(line: &str) -> Result<Self, crate::error::InvalidInput> {
        crate::error::InvalidInput::wrap("track.csv row", || {
            let cells: Vec<&str> = line.split(',').collect();
            let mut cells = cells;
            if cells.len() == CSV_COLUMNS_V1 {
                // A track of an earlier version: no posterior.
                cells.extend(["0", "", "", "", "", "", "", ""]);
            }
            if cells.len() == CSV_COLUMNS_V2 {
                cells.push("0");
            }
            if cells.len() != CSV_COLUMNS.len() {
                return Err(format!(
                    "{} columns, a track row has {}",
                    cells.len(),
                    CSV_COLUMNS.len()
                ));
            }
            let num = |k: usize| -> Result<Option<f64>, String> {
                match cells[k] {
                    "" => Ok(None),
                    c => c
                        .parse::<f64>()
                        .map(Some)
                        .map_err(|_| format!("{} '{c}' is not a number", CSV_COLUMNS[k])),
                }
            };
            let int = |k: usize| -> Result<u64, String> {
                cells[k]
                    .parse::<u64>()
                    .map_err(|_| format!("{} '{}' is not a whole number", CSV_COLUMNS[k], cells[k]))
            };
            let pose = |k: usize| -> Result<Option<Se2>, String> {
                Ok(match (num(k)?, num(k + 1)?, num(k + 2)?) {
                    (Some(x), Some(y), Some(t)) => Some(Se2::new(x, y, t)),
                    _ => None,
                })
            };
            let err = |k: usize| -> Result<Option<(f64, Option<f64>)>, String> {
                Ok(num(k)?.map(|mm| (mm, num(k + 1).ok().flatten())))
            };
            Ok(Self {
                frame: int(0)? as usize,
                stamp_ns: int(1)?,
                contact_px: int(2)? as usize,
                press_m: num(3)?,
                samples: int(4)? as usize,
                registered: int(5)? as usize,
                estimate: pose(6)?,
                multi_sample: pose(9)?,
                baseline: pose(12)?,
                spread_mm: num(15)?,
                theta_spread_deg: num(16)?,
                pose_modes: int(17)? as usize,
                recorded: pose(18)?,
                recorded_press_m: num(21)?,
                estimate_error: err(22)?,
                multi_sample_error: err(24)?,
                baseline_error: err(26)?,
                posterior_modes: int(28)? as usize,
                estimate_weight: num(29)?,
                covariance: match [30, 31, 32, 33, 34, 35].map(num) {
                    [Ok(Some(xx)), Ok(Some(xy)), Ok(Some(xt)), Ok(Some(yy)), Ok(Some(yt)), Ok(Some(tt))] => {
                        Some([[xx, xy, xt], [xy, yy, yt], [xt, yt, tt]])
                    }
                    _ => None,
                },
                carried: match cells[36] {
                    "0" => false,
                    "1" => true,
                    c => return Err(format!("carried '{c}' is neither 0 nor 1")),
                },
            })
        })
    }

    /// Score the estimates against the recorded pose and press of the frame (none: no errors), for an object with
    /// `symmetry`.
    pub fn score(&mut self, recorded: Option<(Se2, Option<f64>)>, symmetry: &Symmetry) {
        self.recorded = recorded.map(|r| r.0);
        self.recorded_press_m = recorded.and_then(|r| r.1);
        let error = |pose: Option<Se2>| {
            pose.zip(self.recorded).map(|(p, r)| {
                let e = SampleError::new(p, 0.0, r, symmetry);
                (e.position_mm, e.theta_deg)
            })
        };
        self.estimate_error = error(self.estimate);
        self.multi_sample_error = error(self.multi_sample);
        self.baseline_error = error(self.baseline);
    }
}

/// RMS distance of `poses` from their mean position, mm (from two poses).
fn position_spread_mm(poses: &[Se2]) -> Option<f64> {
    if poses.len() < 2 {
        return None;
    }
    let n = poses.len() as f64;
    let (mx, my) = (
        poses.iter().map(|p| p.x).sum::<f64>() / n,
        poses.iter().map(|p| p.y).sum::<f64>() / n,
    );
    let ms = poses
        .iter()
        .map(|p| (p.x - mx).powi(2) + (p.y - my).powi(2))
        .sum::<f64>()
        / n;
    Some(ms.sqrt() * 1e3)
}

/// Standard deviation of `values` (from two).
fn std_dev(values: &[f64]) -> Option<f64> {
    if values.len() < 2 {
        return None;
    }
    let n = values.len() as f64;
    let m = values.iter().sum::<f64>() / n;
    Some((values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n).sqrt())
}

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
    /// [`TrackingConfig::min_contact_px`] contact pixels.
    pub fn frames(
        &self,
        recording: &ProcessedRecording,
        every: usize,
        skipped: &mut dyn FnMut(usize, String),
    ) -> Vec<usize> {
        (0..recording.len())
            .step_by(every.max(1))
            .filter(|&k| match recording.unusable(k) {
                Some(why) => {
                    skipped(k, why);
                    false
                }
                None => true,
            })
            .filter(|&k| recording.contact_px[k] >= self.min_contact_px)
            .collect()
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
}

impl<'a> Tracker<'a> {
    pub fn new(ctx: TrackContext<'a>) -> Result<Self, PipelineError> {
        ctx.tracking.validate()?;
        ctx.pose.validate()?;
        Ok(Self {
            engine: Estimator::new(ctx.pose.clone()),
            ctx,
            carry: None,
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
        let observation = super::Observation {
            samples: &out.samples,
            imprint,
            signature: Some(signature),
            truth: None,
            prior: carry.as_ref().map(|c| &c.prior),
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
    }
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
    fn csv_rows_have_the_header_s_columns_and_read_back_exactly() {
        let columns = FrameTrack::csv_header().split(',').count();
        let mut row = FrameTrack::new(3, 100, 40, 2);
        assert_eq!(row.csv_row().split(',').count(), columns);
        assert_eq!(FrameTrack::from_csv_row(&row.csv_row()), Ok(row.clone()));
        row.press_m = Some(0.004);
        row.estimate = Some(Se2::new(0.001, 0.002, 0.3));
        row.baseline = Some(Se2::new(1.0 / 3.0, -0.002, -2.9));
        row.spread_mm = Some(0.25);
        row.score(
            Some((Se2::new(0.0, 0.0, 0.0), Some(0.005))),
            &Symmetry::default(),
        );
        let cells: Vec<String> = row.csv_row().split(',').map(String::from).collect();
        assert_eq!(cells.len(), columns);
        assert_eq!(cells[6..9], ["0.001", "0.002", "0.3"]);
        // Independent truth: |(1, 2)| mm and 0.3 rad in degrees.
        let (mm, deg) = row.estimate_error.unwrap();
        assert!(
            (mm - 5f64.sqrt()).abs() < 1e-9 && (deg.unwrap() - 0.3f64.to_degrees()).abs() < 1e-9
        );
        assert_eq!(row.multi_sample_error, None);
        row.posterior_modes = 2;
        row.estimate_weight = Some(0.75);
        row.covariance = Some([[1e-6, 2e-7, 3e-5], [2e-7, 4e-6, -1e-5], [3e-5, -1e-5, 0.01]]);
        assert_eq!(FrameTrack::from_csv_row(&row.csv_row()), Ok(row.clone()));
        row.carried = true;
        assert_eq!(FrameTrack::from_csv_row(&row.csv_row()), Ok(row.clone()));
        // A row of a track written before carried frames reads back as estimated from scratch.
        let v2 = row
            .csv_row()
            .split(',')
            .take(36)
            .collect::<Vec<_>>()
            .join(",");
        let read = FrameTrack::from_csv_row(&v2).unwrap();
        assert!(!read.carried);
        assert_eq!(read.covariance, row.covariance);
        // A row of a track written before the posterior's columns reads back without one.
        let full = row.csv_row();
        let old = full.split(',').take(28).collect::<Vec<_>>().join(",");
        let read = FrameTrack::from_csv_row(&old).unwrap();
        assert_eq!((read.posterior_modes, read.covariance), (0, None));
        assert_eq!(read.estimate, row.estimate);
        assert!(FrameTrack::from_csv_row("1,2,3")
            .unwrap_err()
            .message
            .contains("3 columns"));
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

    #[test]
    fn spreads_are_rms_distances_and_standard_deviations() {
        let poses = [Se2::new(0.001, 0.0, 0.0), Se2::new(-0.001, 0.0, 0.0)];
        assert!((position_spread_mm(&poses).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(position_spread_mm(&poses[..1]), None);
        assert!((std_dev(&[1.0, 3.0]).unwrap() - 1.0).abs() < 1e-12);
    }
}
