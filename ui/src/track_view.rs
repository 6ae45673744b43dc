//! The Recording tab's **track**: the object's pose on every contact frame of the loaded recording
//! ([`tactile_derender::pipeline::track`], as `tnd recording track`), on a background thread, frame by frame with
//! progress and cancel; each frame's row arrives as it is done, so the pose-over-time plot fills while it runs.
//! The De-render tab's model and settings draw the samples, the Scene panel's object is registered, and the press
//! is found per frame.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{anyhow, Context, Result};
use tactile_derender::model::DiffusionModel;
use tactile_derender::pipeline::track::{
    FrameTrack, PressChoice, TrackContext, Tracker, TrackingConfig,
};
use tactile_derender::pipeline::{DerenderConfig, PipelineError};
use tactile_derender::pose::PoseConfig;
use tactile_derender::recording::ProcessedRecording;
use tactile_derender::sensor::Se2;
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};

use crate::state::ObjectSource;
use crate::worker::{JobKind, WorkerMsg};

/// Live state of the track.
#[derive(Default)]
pub struct TrackView {
    /// The rows so far, in frame order.
    pub rows: Vec<FrameTrack>,
    /// The recording the rows are of.
    pub recording: Option<PathBuf>,
    pub running: bool,
    pub progress: Option<(usize, usize)>,
    pub cancel: Option<Arc<AtomicBool>>,
    pub generation: u64,
}

/// The track thread's messages.
pub enum TrackMsg {
    /// One frame done.
    Row {
        generation: u64,
        row: Box<FrameTrack>,
    },
    /// Every frame done (or the run was cancelled).
    Done { generation: u64, cancelled: bool },
}

/// What one track run needs.
pub struct TrackRequest {
    pub generation: u64,
    pub recording: Arc<ProcessedRecording>,
    /// The recorded pose per frame (scoring only).
    pub poses: Vec<Option<Se2>>,
    pub object: ObjectSource,
    pub model: PathBuf,
    pub derender: DerenderConfig,
    pub sim: SimConfig,
    /// The pose engine's settings (the session's).
    pub pose: PoseConfig,
    /// Which frames, and what each hands to the next (the session's, `tnd recording track`'s options).
    pub tracking: TrackingConfig,
    /// Every n-th frame (`tnd recording track --every`).
    pub every: usize,
    /// The contact threshold the recording's contact pixels were counted at, metres (its read settings').
    pub contact_threshold_m: f64,
}

impl TrackRequest {
    /// The frames to track: every n-th of those with contact and enough pixels with a return
    /// ([`tactile_derender::recording::ProcessedRecording::unusable`], as `tnd recording track`; a light press's
    /// where no frame has contact over the threshold).
    pub fn frames(&self) -> Vec<usize> {
        self.tracking
            .frames(
                &self.recording,
                self.every,
                self.contact_threshold_m,
                &mut |_, _| {},
            )
            .0
    }
}

/// Run `req` on its own thread; rows and the end come back as [`WorkerMsg::Track`].
pub fn spawn(
    req: TrackRequest,
    cancel: Arc<AtomicBool>,
    tx: std::sync::mpsc::Sender<WorkerMsg>,
    ctx: egui::Context,
) -> Result<()> {
    let generation = req.generation;
    let rows_tx = tx.clone();
    crate::worker::spawn_job(JobKind::Track, generation, tx, ctx, move |progress| {
        let frames = req.frames();
        progress(0, frames.len());
        let sim = Simulator::new(req.sim.clone()).context("sensor configuration")?;
        let object = req.object.spec().load()?;
        let prepared = PreparedObject::new(object.mesh.clone())?;
        let device = tactile_derender::model::device::open_device(&req.derender.device)?;
        let model = DiffusionModel::load_on(&req.model, &device)?;
        let track = TrackContext {
            model: &model,
            object: &object,
            prepared: &prepared,
            sim: &sim,
            derender: &req.derender,
            pose: &req.pose,
            press: PressChoice::Auto,
            tracking: &req.tracking,
        };
        let mut tracker = Tracker::new(track)?;
        let mut cancelled = false;
        for (i, &k) in frames.iter().enumerate() {
            let mut row = match tracker.track(&req.recording, k, &mut |_, _| {
                !cancel.load(Ordering::Relaxed)
            }) {
                Ok(row) => row,
                Err(PipelineError::Cancelled) => {
                    cancelled = true;
                    break;
                }
                Err(e) => {
                    return Err(anyhow!(
                        "frame {k}: {}",
                        tactile_derender::error::render(&e)
                    ))
                }
            };
            let recorded = req.poses.get(k).copied().flatten();
            row.score(recorded.map(|p| (p, None)), &object.symmetry);
            let _ = rows_tx.send(WorkerMsg::Track(TrackMsg::Row {
                generation,
                row: Box::new(row),
            }));
            progress(i + 1, frames.len());
            if cancel.load(Ordering::Relaxed) {
                cancelled = true;
                break;
            }
        }
        Ok(WorkerMsg::Track(TrackMsg::Done {
            generation,
            cancelled,
        }))
    })
}
