//! The app's side of the Recording tab's jobs: loading a recording, tracking its contact frames, calibrating the
//! sensor from it — starting, cancelling and taking in each job's messages, where they touch several views.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::{anyhow, Result};
use tactile_derender::recording::calibrate::CalibrateConfig;

use super::WorkbenchApp;
use crate::command::Command;
use crate::recording_view::{spawn_load, RecordingMsg, RecordingSettings};
use crate::sensor_calibration::{CalibrationRequest, CalibrationResult};
use crate::track_view::{TrackMsg, TrackRequest};

impl WorkbenchApp {
    /// (Re)load the recording of the saved settings on a background thread.
    pub(crate) fn load_recording(&mut self) {
        let Some(w) = self.worker.as_ref() else {
            return; // started with the worker (a session opened before the first frame)
        };
        let (tx, ctx) = (w.sender(), w.context());
        if let Some(p) = &self.state.recording.path {
            self.inputs.recording_path = p.display().to_string();
        }
        self.cancel_recording();
        // A track belongs to the frames it was made of; so does a calibration being made.
        self.cancel_track();
        self.cancel_sensor_calibration();
        let view = &mut self.recording;
        view.generation += 1;
        view.loading = true;
        view.progress = None;
        view.textures = None;
        let cancel = Arc::new(AtomicBool::new(false));
        view.cancel = Some(cancel.clone());
        let r = spawn_load(
            self.state.recording.clone(),
            self.state.sim.clone(),
            view.generation,
            cancel,
            tx,
            ctx,
        );
        if let Err(e) = r {
            self.recording.loading = false;
            self.error(format!("recording: {e}"));
        }
    }

    pub(crate) fn cancel_recording(&mut self) {
        crate::worker::raise_cancel(&mut self.recording.cancel);
        self.recording.loading = false;
    }

    /// Apply new settings: another topic or reference reloads, another frame only moves the cursor.
    pub(crate) fn set_recording(&mut self, settings: RecordingSettings) {
        let old = std::mem::replace(&mut self.state.recording, settings);
        let s = &self.state.recording;
        let reload = s.path != old.path || s.read != old.read;
        if reload && s.path.is_some() {
            self.load_recording();
        }
    }

    /// Take in a loaded recording.
    pub(crate) fn recording_message(&mut self, msg: RecordingMsg) {
        match msg {
            RecordingMsg::Loaded {
                generation,
                recording,
            } => {
                if generation != self.recording.generation {
                    return;
                }
                let n = recording.processed.len();
                self.recording.loading = false;
                self.recording.cancel = None;
                self.recording.textures = None;
                self.state.recording.frame = self.state.recording.frame.min(n.saturating_sub(1));
                self.notice = Some(format!(
                    "recording {}: {n} frames of {}",
                    recording.path.display(),
                    recording.processed.stream
                ));
                self.recording.loaded = Some(*recording);
            }
        }
    }

    /// De-render the frame under the cursor (then register it, with `pose`).
    pub(crate) fn derender_frame(&mut self, pose: bool) -> Result<()> {
        let loaded = self
            .recording
            .loaded
            .as_ref()
            .ok_or_else(|| anyhow!("open a recording first"))?;
        let mut d = self.state.derender.clone();
        d.input = crate::state::DerenderInput::RecordingFrame {
            path: loaded.path.clone(),
            frame: self.state.recording.frame,
        };
        self.state.derender = d;
        self.state.view.tab = if pose {
            crate::state::Tab::Pose
        } else {
            crate::state::Tab::Derender
        };
        self.run_derender()?;
        self.auto_pose = pose;
        Ok(())
    }
}

impl WorkbenchApp {
    /// Calibrate the sensor from the open recording's no-contact frames, on a background thread.
    pub(crate) fn calibrate_sensor(&mut self) -> Result<()> {
        let path = self
            .recording
            .loaded
            .as_ref()
            .map(|l| l.path.clone())
            .ok_or_else(|| anyhow!("open a recording first"))?;
        let w = self
            .worker
            .as_ref()
            .ok_or_else(|| anyhow!("the background worker is not running"))?;
        let (tx, ctx) = (w.sender(), w.context());
        self.cancel_sensor_calibration();
        let view = &mut self.recording.sensor_calibration;
        view.generation += 1;
        view.running = true;
        view.progress = None;
        let cancel = Arc::new(AtomicBool::new(false));
        view.cancel = Some(cancel.clone());
        let generation = view.generation;
        let given = self.state.sim.clone();
        let read = self.state.recording.read.clone();
        let config = CalibrateConfig::reading(&read.process());
        let req = CalibrationRequest {
            generation,
            recording: path,
            read,
            given,
            config,
        };
        let r = crate::sensor_calibration::spawn(req, cancel, tx, ctx);
        if r.is_err() {
            self.recording.sensor_calibration.running = false;
        }
        r
    }

    pub(crate) fn cancel_sensor_calibration(&mut self) {
        let view = &mut self.recording.sensor_calibration;
        crate::worker::raise_cancel(&mut view.cancel);
        view.running = false;
    }

    /// Write the calibrated sensor beside the recording as `<recording>_sensor.json` (a sensor file: `tnd ... --sensor`,
    /// `tnd-workbench --sensor`).
    pub(crate) fn save_sensor_file(&self) -> Result<PathBuf> {
        let r = self
            .recording
            .sensor_calibration
            .result
            .as_ref()
            .ok_or_else(|| anyhow!("calibrate the sensor first"))?;
        let stem = r
            .recording
            .file_stem()
            .map_or_else(|| "recording".into(), |s| s.to_string_lossy().into_owned());
        let dir = r.recording.parent().map(PathBuf::from).unwrap_or_default();
        let path = dir.join(format!("{stem}_sensor.json"));
        tactile_derender::sim::sensor_file::save(&path, &r.calibration.sensor)?;
        Ok(path)
    }

    /// Take in a finished calibration: the calibrated sensor becomes the session's (undoable).
    pub(crate) fn sensor_calibrated(&mut self, generation: u64, result: Box<CalibrationResult>) {
        let view = &mut self.recording.sensor_calibration;
        if generation != view.generation {
            return;
        }
        view.running = false;
        view.cancel = None;
        view.textures = None;
        let c = &result.calibration;
        self.notice = Some(format!(
            "sensor calibrated from {} no-contact frames of {}: inflation {:.2} mm, noise {} (Undo restores the \
             previous sensor)",
            c.no_contact_frames.len(),
            result.recording.display(),
            c.inflation_m * 1e3,
            c.noise_std_m
                .map_or("not measured".to_string(), |s| format!("{:.2} mm", s * 1e3))
        ));
        let sensor = c.sensor.clone();
        self.recording.sensor_calibration.result = Some(*result);
        self.apply(Command::SetSim(sensor));
    }
}

impl WorkbenchApp {
    /// Track every contact frame of the loaded recording (cancelling a running track).
    pub(crate) fn start_track(&mut self) -> Result<()> {
        let loaded = self
            .recording
            .loaded
            .as_ref()
            .ok_or_else(|| anyhow!("open a recording first"))?;
        self.state.derender.config.validate(None)?;
        let track = &self.state.recording.track;
        if track.every == 0 {
            return Err(anyhow!("track every n-th frame: n must be at least 1"));
        }
        track.tracking.validate()?;
        let w = self
            .worker
            .as_ref()
            .ok_or_else(|| anyhow!("the workbench is still starting"))?;
        let (tx, ctx) = (w.sender(), w.context());
        let model = self.state.model.path.clone().unwrap_or_else(|| {
            crate::derender::matched_model_path(
                loaded.processed.frames_resampled(&self.state.sim.camera),
            )
        });
        let view = &mut self.recording.track;
        crate::worker::raise_cancel(&mut view.cancel);
        view.generation += 1;
        let req = TrackRequest {
            generation: view.generation,
            recording: loaded.processed.clone(),
            poses: loaded.poses.clone(),
            object: self.state.scene.object.clone(),
            model,
            derender: self.state.derender.config.clone(),
            sim: self.state.sim.clone(),
            pose: self.state.pose.clone(),
            tracking: self.state.recording.track.tracking.clone(),
            every: self.state.recording.track.every,
            contact_threshold_m: self.state.recording.read.contact_threshold_m,
        };
        let frames = req.frames().len();
        if frames == 0 {
            return Err(anyhow!(
                "no frame has {} contact pixels (imprint over {:.1} mm, or a light press's threshold) to track",
                req.tracking.min_contact_px,
                req.contact_threshold_m * 1e3
            ));
        }
        view.rows.clear();
        view.recording = Some(loaded.path.clone());
        view.running = true;
        view.progress = Some((0, frames));
        let cancel = Arc::new(AtomicBool::new(false));
        view.cancel = Some(cancel.clone());
        if let Err(e) = crate::track_view::spawn(req, cancel, tx, ctx) {
            self.recording.track.running = false;
            return Err(e);
        }
        Ok(())
    }

    pub(crate) fn cancel_track(&mut self) {
        crate::worker::raise_cancel(&mut self.recording.track.cancel);
        self.recording.track.running = false;
    }

    /// Take in a row or the end of a track.
    pub(crate) fn track_message(&mut self, msg: TrackMsg) {
        let view = &mut self.recording.track;
        match msg {
            TrackMsg::Row { generation, row } if generation == view.generation => {
                view.rows.push(*row);
                view.rows.sort_by_key(|r| r.frame);
            }
            TrackMsg::Done {
                generation,
                cancelled,
            } if generation == view.generation => {
                view.running = false;
                view.cancel = None;
                let with = view.rows.iter().filter(|r| r.estimate.is_some()).count();
                self.notice = Some(format!(
                    "track {}: {} frames, {with} with a pose",
                    if cancelled { "cancelled" } else { "done" },
                    view.rows.len()
                ));
            }
            _ => {}
        }
    }

    /// Write the track as `<recording>_track.csv` beside the recording (atomically); its path.
    pub(crate) fn save_track(&mut self) -> Result<PathBuf> {
        let view = &self.recording.track;
        let rec = view
            .recording
            .as_ref()
            .ok_or_else(|| anyhow!("track a recording first"))?;
        let stem = rec
            .file_stem()
            .map_or_else(|| "recording".into(), |s| s.to_string_lossy().into_owned());
        // Beside the recording: a frame folder's track goes next to the folder, not into it.
        let dir = rec.parent().map(PathBuf::from).unwrap_or_default();
        let path = dir.join(format!("{stem}_track.csv"));
        // Replace only a track saved before (its header), never a file of the user's of that name.
        let header = tactile_derender::pipeline::track::FrameTrack::csv_header();
        let ours = |p: &Path| {
            std::fs::read_to_string(p).is_ok_and(|t| t.lines().next() == Some(header.as_str()))
        };
        let _claimed = tactile_derender::io::output::claim(
            tactile_derender::io::output::Claim::file("track", &path).ours(&ours),
        )
        .map_err(|e| match e {
            tactile_derender::io::output::OutputError::ForeignFile { .. } => anyhow!(
                "{} exists and is not a track tnd saved: move it away to save the track there",
                path.display()
            ),
            e => e.into(),
        })?;
        tactile_derender::io::write_atomic(
            &path,
            tactile_derender::pipeline::track::FrameTrack::csv(&view.rows).as_bytes(),
        )
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))?;
        Ok(path)
    }
}
