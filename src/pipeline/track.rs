//! # Tracking: the object's pose on every contact frame of a recording
//!
//! [`track_frame`] is the De-render and Pose use cases ([`super::derender()`], [`super::estimate_pose`]) on one frame
//! of a processed recording ([`crate::recording::ProcessedRecording`]): N samples of the in-contact depth, the
//! single-sample estimate, the multi-sample estimate and the threshold baseline, scored against the recorded pose
//! when the recording has one (the estimate never sees it). Frames are estimated independently, each with its own
//! seed (`seed + frame`), so a track can stop and resume anywhere and give the same rows.
//!
//! The sensor is placed over the object as [`super::press`] says ([`PressChoice::Auto`] by default: per frame, from the
//! samples and the signature).

use serde::{Deserialize, Serialize};

pub use super::press::PressChoice;
use super::press::SensorPlacement;
use super::{LoadedObject, PipelineError, PoseInput, Progress};
use crate::metrics::evaluate::EvalConfig;
use crate::model::DiffusionModel;
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

    /// `rows` as a CSV table with [`Self::CSV_HEADER`] (what `tnd recording track` writes as track.csv).
    pub fn csv(rows: &[FrameTrack]) -> String {
        let mut text = format!("{}\n", Self::CSV_HEADER);
        for r in rows {
            text.push_str(&r.csv_row());
            text.push('\n');
        }
        text
    }

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
    let placement = SensorPlacement {
        sim: ctx.sim,
        object: ctx.object,
        prepared: ctx.prepared,
        eval: ctx.eval,
    };
    let press = placement.press(
        ctx.press,
        &out.samples,
        Some(signature),
        imprint,
        derender.seed,
    )?;
    let Some(press) = press else {
        return Ok(row);
    };
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
