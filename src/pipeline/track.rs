//! # Tracking: the object's pose on every contact frame of a recording
//!
//! [`track_frame`] is the De-render and Pose use cases ([`super::derender()`], [`super::estimate_pose`]) on one frame
//! of a processed recording ([`crate::recording::ProcessedRecording`]): N samples of the in-contact depth, the
//! single-sample estimate, the multi-sample estimate and the threshold baseline, scored against the recorded pose
//! when the recording has one (the estimate never sees it). Frames are estimated independently, each with its own
//! seed (`seed + frame`), so a track can stop and resume anywhere and give the same rows.
//!
//! A Soft Bubble does not measure how far it is pressed into the object, and the registration works in the world
//! frame, so the sensor has to be placed over the object: [`PressChoice::Auto`] (the default) takes, for each frame,
//! the press that puts the samples' highest contact point on the object's top (the object lies on the table and the
//! sensor comes down on it, so the part pressed first is its top); [`PressChoice::Fixed`] uses one press for every
//! frame, as `tnd pose --press` does.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{LoadedObject, PipelineError, PoseInput, Progress};
use crate::dataset::import_recording::DEFAULT_MAX_PRESS_M;
use crate::image::Image;
use crate::metrics::evaluate::{EvalConfig, EvalContext, Evaluator};
use crate::model::DiffusionModel;
use crate::objects::ObjectSet;
use crate::recording::ProcessedRecording;
use crate::sensor::Se2;
use crate::sim::{PreparedObject, Simulator};
use crate::uncertainty::SampleError;

/// How far the sensor is pressed into the object, for placing it over the object.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PressChoice {
    /// Per frame, from the samples: their highest contact point on the object's top.
    #[default]
    Auto,
    /// The same press for every frame, metres.
    Fixed(f64),
}

impl FromStr for PressChoice {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(PressChoice::Auto);
        }
        match s.parse::<f64>() {
            Ok(p) if p.is_finite() && (0.0..=DEFAULT_MAX_PRESS_M).contains(&p) => {
                Ok(PressChoice::Fixed(p))
            }
            Ok(p) => Err(format!(
                "press {p} m is outside 0..{DEFAULT_MAX_PRESS_M} m (metres: 6 mm is 0.006)"
            )),
            Err(_) => Err(format!("'{s}' is neither \"auto\" nor a press in metres")),
        }
    }
}

impl fmt::Display for PressChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PressChoice::Auto => write!(f, "auto"),
            PressChoice::Fixed(p) => write!(f, "{p}"),
        }
    }
}

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
    /// The recorded pose, when the recording has one for this frame.
    pub recorded: Option<Se2>,
    /// Errors against the recorded pose: position mm, θ degrees (`None` θ: continuous symmetry).
    pub estimate_error: Option<(f64, Option<f64>)>,
    pub multi_sample_error: Option<(f64, Option<f64>)>,
    pub baseline_error: Option<(f64, Option<f64>)>,
}

impl FrameTrack {
    /// The header of [`Self::csv_row`].
    pub const CSV_HEADER: &'static str = "frame,stamp_ns,contact_px,press_m,samples,registered,\
x,y,theta,multi_x,multi_y,multi_theta,baseline_x,baseline_y,baseline_theta,\
recorded_x,recorded_y,recorded_theta,position_err_mm,theta_err_deg,\
multi_position_err_mm,multi_theta_err_deg,baseline_position_err_mm,baseline_theta_err_deg";

    /// The frame as one CSV row (metres, radians; errors in mm and degrees; empty where unknown).
    pub fn csv_row(&self) -> String {
        let pose = |p: Option<Se2>| match p {
            Some(p) => format!("{},{},{}", p.x, p.y, p.theta),
            None => ",,".into(),
        };
        let err = |e: Option<(f64, Option<f64>)>| match e {
            Some((mm, deg)) => format!("{mm},{}", deg.map_or(String::new(), |d| d.to_string())),
            None => ",".into(),
        };
        format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            self.frame,
            self.stamp_ns,
            self.contact_px,
            self.press_m.map_or(String::new(), |p| p.to_string()),
            self.samples,
            self.registered,
            pose(self.estimate),
            pose(self.multi_sample),
            pose(self.baseline),
            pose(self.recorded),
            err(self.estimate_error),
            err(self.multi_sample_error),
            err(self.baseline_error),
        )
    }
}

/// The press that puts the highest contact point of `samples` (as the registration sees them: anchored onto the
/// signature) on `object`'s top, clamped to `0..=max_press` metres; `None` when no sample has contact.
pub fn press_from_samples(
    sim: &Simulator,
    object: &PreparedObject,
    samples: &[Image],
    signature: &Image,
    imprint: &Image,
    eval: &EvalConfig,
    max_press: f64,
) -> Result<Option<f64>, PipelineError> {
    // At press 0 the sensor's apex is on the object's top; pressing p deeper moves every back-projected point p down.
    let t_world_camera = sim.t_world_camera(&sim.pressing_pose(object, 0.0, 0.0, 0.0, 0.0));
    let (anchored, _) = Evaluator::new(eval.clone()).anchor(samples, Some(signature), imprint)?;
    let mut presses: Vec<f64> = anchored
        .iter()
        .filter_map(|s| {
            crate::recon::back_project(&interior(s), sim.intrinsics(), &t_world_camera)
                .p_world
                .iter()
                .map(|p| p.z)
                .fold(None, |m: Option<f64>, z| Some(m.map_or(z, |m| m.max(z))))
        })
        .map(|z_top| z_top - object.top_z)
        .collect();
    if presses.is_empty() {
        return Ok(None);
    }
    // The lower median: with two samples, the one that says less.
    presses.sort_by(f64::total_cmp);
    Ok(Some(presses[(presses.len() - 1) / 2].clamp(0.0, max_press)))
}

/// Presses tried around the least one [`press_from_samples`] gives, metres: mostly deeper (the contact may be on a
/// lower part than the object's top), a little shallower (the samples' own error).
pub const PRESS_SEARCH_M: [f64; 11] = [
    -0.001, -0.0005, 0.0, 0.0005, 0.001, 0.0015, 0.002, 0.003, 0.004, 0.005, 0.006,
];

/// The press of [`PRESS_SEARCH_M`] around `least` whose pose (the first sample with contact registered from
/// the evaluation's random starts, then the signature check) best explains the signature.
fn search_press(
    ctx: &TrackContext<'_>,
    samples: &[Image],
    signature: &Image,
    imprint: &Image,
    least: f64,
    seed: u64,
) -> Result<f64, PipelineError> {
    let evaluator = Evaluator::new(ctx.eval.clone());
    let Some(first) = samples
        .iter()
        .find(|s| s.data.iter().any(|&d| crate::recon::is_valid_depth(d)))
    else {
        return Ok(least);
    };
    let ectx = EvalContext::of_simulator(ctx.sim, ObjectSet::builtin());
    let model =
        evaluator.object_from_mesh(&ctx.object.name, &ctx.object.mesh, ctx.object.symmetry)?;
    let strategy = evaluator.random_starts(seed);
    let measured = Some((signature, imprint));
    let mut scores: Vec<(f64, f64)> = Vec::new();
    for dp in PRESS_SEARCH_M {
        let press = least + dp;
        if press < 0.0 {
            continue;
        }
        if press > DEFAULT_MAX_PRESS_M {
            break;
        }
        let t = ctx
            .sim
            .t_world_camera(&ctx.sim.pressing_pose(ctx.prepared, 0.0, 0.0, 0.0, press));
        let hypotheses = evaluator.pooled_hypotheses(
            &model,
            std::slice::from_ref(first),
            &ectx,
            &t,
            measured,
            &strategy,
        )?;
        let scored = evaluator.choose_scored(&model, &hypotheses, &ectx, &t, measured)?;
        if let Some((_, _, Some(cost))) = scored {
            scores.push((press, cost));
        }
    }
    Ok(parabola_minimum(&scores).unwrap_or(least))
}

/// The lowest of the `(x, cost)` points (in increasing x), moved to the minimum of the parabola through it and
/// its two neighbours when it has both and they rise on either side; `None` when empty.
pub fn parabola_minimum(points: &[(f64, f64)]) -> Option<f64> {
    let k = (0..points.len()).min_by(|&a, &b| points[a].1.total_cmp(&points[b].1))?;
    if k == 0 || k + 1 == points.len() {
        return Some(points[k].0);
    }
    let ((x0, y0), (x1, y1), (x2, y2)) = (points[k - 1], points[k], points[k + 1]);
    // Vertex of the parabola through three points (any spacing).
    let num = (x1 - x0).powi(2) * (y1 - y2) - (x1 - x2).powi(2) * (y1 - y0);
    let den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0);
    if den.abs() < f64::EPSILON * y1.abs().max(1e-300) || !den.is_finite() {
        return Some(x1);
    }
    Some((x1 - 0.5 * num / den).clamp(x0, x2))
}

/// The contact pixels of `x` whose four neighbours are in contact too (a stray pixel of a sample cannot set the
/// press); all of them when none is.
fn interior(x: &Image) -> Image {
    let (w, h) = (x.width, x.height);
    let contact = |i: usize, j: usize| crate::recon::is_valid_depth(x.data[j * w + i]);
    let mut out = x.clone();
    let mut any = false;
    for j in 0..h {
        for i in 0..w {
            let inside = contact(i, j)
                && i > 0
                && j > 0
                && i + 1 < w
                && j + 1 < h
                && contact(i - 1, j)
                && contact(i + 1, j)
                && contact(i, j - 1)
                && contact(i, j + 1);
            if inside {
                any = true;
            } else {
                out.data[j * w + i] = 0.0;
            }
        }
    }
    if any {
        out
    } else {
        x.clone()
    }
}

/// What one frame's estimate needs besides the frame.
pub struct TrackContext<'a> {
    pub model: &'a DiffusionModel,
    pub object: &'a LoadedObject,
    /// The same object, prepared for rendering (its top and ray caster).
    pub prepared: &'a PreparedObject,
    pub sim: &'a Simulator,
    pub derender: &'a super::DerenderConfig,
    pub eval: &'a EvalConfig,
    pub press: PressChoice,
}

/// De-render frame `frame` of `recording` and estimate the object's pose (module docs); `recorded` is the pose the
/// recording gives for the frame, used only to score the estimates. `progress` counts sampling steps, then fits.
pub fn track_frame(
    ctx: &TrackContext<'_>,
    recording: &ProcessedRecording,
    frame: usize,
    recorded: Option<Se2>,
    progress: Progress<'_>,
) -> Result<FrameTrack, PipelineError> {
    let (Some(imprint), Some(signature)) = (
        recording.imprints.get(frame),
        recording.signatures.get(frame),
    ) else {
        return Err(PipelineError::Settings(format!(
            "the recording has {} frames; there is no frame {frame}",
            recording.len()
        )));
    };
    let mut derender = ctx.derender.clone();
    derender.seed = ctx.derender.seed.wrapping_add(frame as u64);
    let guidance = super::imprint_guidance(&derender, ctx.sim, imprint, Some(signature))?;
    let out = super::derender(
        ctx.model,
        imprint,
        guidance.as_ref(),
        &derender,
        ctx.eval.consensus_probability,
        progress,
    )?;
    let mut row = FrameTrack {
        frame,
        stamp_ns: recording.stamps_ns.get(frame).copied().unwrap_or(0),
        contact_px: recording.contact_px.get(frame).copied().unwrap_or(0),
        press_m: None,
        samples: out.samples.len(),
        registered: 0,
        estimate: None,
        multi_sample: None,
        baseline: None,
        recorded,
        estimate_error: None,
        multi_sample_error: None,
        baseline_error: None,
    };
    let press = match ctx.press {
        PressChoice::Fixed(p) => Some(p),
        PressChoice::Auto => press_from_samples(
            ctx.sim,
            ctx.prepared,
            &out.samples,
            signature,
            imprint,
            ctx.eval,
            DEFAULT_MAX_PRESS_M,
        )?,
    };
    let Some(mut press) = press else {
        return Ok(row);
    };
    if ctx.press == PressChoice::Auto {
        press = search_press(ctx, &out.samples, signature, imprint, press, derender.seed)?;
    }
    row.press_m = Some(press);
    let sensor = ctx.sim.pressing_pose(ctx.prepared, 0.0, 0.0, 0.0, press);
    let input = PoseInput {
        t_world_camera: ctx.sim.t_world_camera(&sensor),
        samples: &out.samples,
        imprint,
        signature: Some(signature),
        truth: recorded,
    };
    let estimate = match super::estimate_pose(
        ctx.object,
        ctx.sim,
        &input,
        ctx.eval,
        derender.seed,
        &mut |_, _| true,
    ) {
        Ok(e) => e,
        Err(PipelineError::NoContact) => return Ok(row),
        Err(e) => return Err(e),
    };
    let report = &estimate.report;
    let error = |pose: Se2| {
        recorded.map(|r| {
            let e = SampleError::new(pose, 0.0, r, &ctx.object.symmetry);
            (e.position_mm, e.theta_deg)
        })
    };
    row.registered = report.samples.len();
    row.estimate = estimate.best();
    row.multi_sample = report.multi_sample.as_ref().map(|m| m.pose);
    row.baseline = report.baseline.as_ref().map(|b| b.pose);
    row.estimate_error = row.estimate.and_then(error);
    row.multi_sample_error = row.multi_sample.and_then(error);
    row.baseline_error = row.baseline.and_then(error);
    Ok(row)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn press_choice_parses_auto_and_metres_and_refuses_millimetres() {
        assert_eq!("auto".parse::<PressChoice>(), Ok(PressChoice::Auto));
        assert_eq!(
            "0.006".parse::<PressChoice>(),
            Ok(PressChoice::Fixed(0.006))
        );
        assert!("6"
            .parse::<PressChoice>()
            .unwrap_err()
            .contains("6 mm is 0.006"));
        assert!("deep".parse::<PressChoice>().is_err());
        assert_eq!(
            PressChoice::Fixed(0.006).to_string().parse(),
            Ok(PressChoice::Fixed(0.006))
        );
    }

    #[test]
    fn parabola_minimum_finds_the_vertex_of_a_sampled_parabola() {
        // Independent truth: the vertex of (x − 0.0042)² + 1, sampled on an uneven grid.
        let f = |x: f64| (x - 0.0042_f64).powi(2) + 1.0;
        let xs = [0.002, 0.0025, 0.003, 0.004, 0.005, 0.0065];
        let points: Vec<(f64, f64)> = xs.iter().map(|&x| (x, f(x))).collect();
        let v = parabola_minimum(&points).unwrap();
        assert!((v - 0.0042).abs() < 1e-12, "{v}");
        // At the ends there is no bracket: the lowest point itself.
        assert_eq!(parabola_minimum(&points[..3]), Some(0.003));
        assert_eq!(parabola_minimum(&[]), None);
    }

    #[test]
    fn csv_rows_have_the_header_s_columns() {
        let columns = FrameTrack::CSV_HEADER.split(',').count();
        let mut row = FrameTrack {
            frame: 3,
            stamp_ns: 100,
            contact_px: 40,
            press_m: Some(0.004),
            samples: 2,
            registered: 0,
            estimate: None,
            multi_sample: None,
            baseline: None,
            recorded: None,
            estimate_error: None,
            multi_sample_error: None,
            baseline_error: None,
        };
        assert_eq!(row.csv_row().split(',').count(), columns);
        row.estimate = Some(Se2::new(0.001, 0.002, 0.3));
        row.recorded = Some(Se2::new(0.0, 0.0, 0.0));
        row.estimate_error = Some((2.2, None));
        row.baseline_error = Some((1.0, Some(-3.0)));
        let cells: Vec<String> = row.csv_row().split(',').map(String::from).collect();
        assert_eq!(cells.len(), columns);
        assert_eq!(cells[6..9], ["0.001", "0.002", "0.3"]);
        assert_eq!(cells[18..20], ["2.2", ""]);
        assert_eq!(cells[22..24], ["1", "-3"]);
    }
}
