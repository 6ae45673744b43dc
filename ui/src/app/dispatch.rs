//! The **dispatcher**: every [`Command`] a panel, a shortcut or a dialog pushes is applied here, in one place, with
//! scene, sensor and elastomer edits recorded for undo.

use std::path::PathBuf;

use anyhow::{anyhow, Result};
use tactile_derender::io::{npy, preview};
use tactile_derender::sim::SimConfig;

use super::WorkbenchApp;
use crate::command::Command;
use crate::images::ImageKind;
use crate::measured;
use crate::session;
use crate::state::{
    CalibrationSettings, DerenderInput, ModelSettings, ObjectSource, SceneState, State, Tab,
};
use crate::worker::DialogPurpose;

impl WorkbenchApp {
    /// Apply one command. Errors are shown in the window; nothing here panics. Scene, sensor and elastomer edits
    /// are recorded for undo.
    pub fn apply(&mut self, cmd: Command) {
        match crate::history::edit_kind(&cmd) {
            Some(kind) => {
                let before = crate::history::Snapshot::of(&self.state);
                self.apply_now(cmd);
                if crate::history::Snapshot::of(&self.state) != before {
                    self.history.record(kind, before);
                }
            }
            None => self.apply_now(cmd),
        }
    }

    fn apply_now(&mut self, cmd: Command) {
        match cmd {
            // Scene, sensor and calibration settings.
            Command::SetScene(scene) => self.set_scene(scene),
            Command::SetSim(sim) => self.set_sim(sim),
            Command::SetSeed(seed) => self.set_seed(seed),
            Command::SetCalibration(c) => self.set_calibration(c),
            Command::SetView(v) => self.state.view = v,
            // Sessions, dialogs and dropped files.
            Command::NewSession => self.new_session(),
            Command::OpenSession(path) => self.open_session(path),
            Command::SaveSession(path) => self.save_session(path),
            Command::Browse(purpose) => self.browse(purpose),
            Command::OpenDropped(path) => self.open_dropped(path),
            // The measured imprint and the inflation calibration.
            Command::LoadMeasured(path) => self.load_measured(path),
            Command::UseMeasuredScene => {
                if let Err(e) = self.use_measured_scene() {
                    self.error(format!(
                        "measured scene: {}",
                        tactile_derender::error::render_anyhow(&e)
                    ));
                }
            }
            Command::ClearMeasured => self.clear_measured(),
            Command::RunCalibration => self.run_calibration(),
            Command::CancelCalibration => self.cancel_calibration(),
            Command::PickInflation(h) => self.pick_inflation(h),
            Command::Export { image, png } => {
                if let Err(e) = self.export(image, png) {
                    self.error(format!(
                        "export: {}",
                        tactile_derender::error::render_anyhow(&e)
                    ));
                }
            }
            Command::DismissErrors => self.errors.clear(),
            // Dataset, De-render and Pose tabs.
            Command::OpenDataset(path) => self.open_dataset(path),
            Command::SetDataset(d) => self.set_dataset(d),
            Command::SendPairToDerender => {
                let r = self.send_pair_to_derender();
                self.report("send to de-render", r);
            }
            Command::PlacePairScene => {
                let r = self.place_pair_scene();
                self.report("place the scene", r);
            }
            Command::SetDerender(d) => self.set_derender(d),
            Command::SetModel(m) => self.set_model(m),
            Command::RunDerender => {
                let r = self.run_derender();
                self.report("de-render", r);
            }
            Command::CancelDerender => self.cancel_derender(),
            Command::RunPose => {
                let r = self.run_pose();
                self.report("pose", r);
            }
            Command::CancelPose => self.cancel_pose(),
            Command::ExportPose => {
                let r = self.export_pose();
                self.report("export", r);
            }
            Command::HighlightSample(k) => self.analysis.pose.highlight = k,
            Command::SetPose(pose) => self.state.pose = *pose,
            Command::ZoomImage(target) => self.analysis.zoom = target,
            // Recording tab.
            Command::OpenRecording(path) => self.open_recording(path),
            Command::SetRecording(settings) => self.set_recording(settings),
            Command::CancelRecording => self.cancel_recording(),
            Command::DerenderFrame { pose } => {
                let r = self.derender_frame(pose);
                self.report("de-render", r);
            }
            Command::TrackRecording => {
                let r = self.start_track();
                self.report("track", r);
            }
            Command::CancelTrack => self.cancel_track(),
            Command::CalibrateSensor => {
                let r = self.calibrate_sensor();
                self.report("sensor calibration", r);
            }
            Command::CancelSensorCalibration => self.cancel_sensor_calibration(),
            Command::SaveSensorFile => match self.save_sensor_file() {
                Ok(path) => self.notice = Some(format!("sensor saved as {}", path.display())),
                Err(e) => self.error(format!("sensor file: {e}")),
            },
            Command::SaveTrack => match self.save_track() {
                Ok(path) => self.notice = Some(format!("track saved as {}", path.display())),
                Err(e) => self.error(format!("track: {e}")),
            },
            // History.
            Command::Undo => self.undo(),
            Command::Redo => self.redo(),
        }
    }

    // Scene, sensor and calibration settings.

    /// Take a new scene and re-simulate (nothing when it is the same).
    fn set_scene(&mut self, scene: SceneState) {
        if scene != self.state.scene {
            self.state.scene = scene;
            self.request_simulation();
        }
    }

    /// Take new sensor settings and re-simulate; a new camera re-reads the open recording.
    fn set_sim(&mut self, sim: SimConfig) {
        if sim != self.state.sim {
            // A recording's imprints are cropped and resampled with the camera: a new camera re-reads it.
            let camera_changed = sim.camera != self.state.sim.camera;
            self.state.sim = sim;
            self.request_simulation();
            if camera_changed && self.state.recording.path.is_some() {
                self.load_recording();
            }
        }
    }

    /// Take a new seed and re-simulate (nothing when it is the same).
    fn set_seed(&mut self, seed: u64) {
        if seed != self.state.seed {
            self.state.seed = seed;
            self.request_simulation();
        }
    }

    /// Take new calibration settings; another dataset pair reloads the measured imprint.
    fn set_calibration(&mut self, c: CalibrationSettings) {
        let pair_changed = (c.measured_split, c.measured_index)
            != (
                self.state.calibration.measured_split,
                self.state.calibration.measured_index,
            );
        self.state.calibration = c;
        let dataset = self.measured.as_ref().filter(|m| m.scene.is_some());
        if let (true, Some(m)) = (pair_changed, dataset) {
            let path = m.path.clone();
            self.apply(Command::LoadMeasured(path));
        }
    }

    // Sessions and dropped files.

    /// Start over with the default session.
    fn new_session(&mut self) {
        self.replace_state(State::default());
        self.session_path = None;
        self.inputs.session_path.clear();
        self.notice = Some("new session: the default scene".into());
    }

    /// Read a session file and make it the state.
    fn open_session(&mut self, path: PathBuf) {
        match session::read(&path) {
            Ok(state) => {
                self.replace_state(state);
                self.session_is(path, "opened");
            }
            Err(e) => self.error(tactile_derender::error::render_anyhow(&e)),
        }
    }

    /// Write the state to a session file.
    fn save_session(&mut self, path: PathBuf) {
        match session::write(&path, &self.state) {
            Ok(()) => self.session_is(path, "saved"),
            Err(e) => self.error(tactile_derender::error::render_anyhow(&e)),
        }
    }

    /// `path` is now the session's file, just `done` ("opened", "saved"): in the path field, the notice, the recent
    /// sessions.
    fn session_is(&mut self, path: PathBuf, done: &str) {
        self.inputs.session_path = path.display().to_string();
        self.notice = Some(format!("{done} {}", path.display()));
        self.remember_session(&path);
        self.session_path = Some(path);
    }

    /// Open a file dropped on the window as what its kind says (a session, mesh, recording, ...).
    fn open_dropped(&mut self, path: PathBuf) {
        let de_render = self.state.view.tab == crate::state::Tab::Derender;
        match crate::shortcuts::purpose_of(&path, de_render) {
            Some(purpose) => self.dialog_answer(purpose, Some(path)),
            None => self.error(crate::shortcuts::unknown(&path)),
        }
    }

    // The measured imprint and the inflation calibration.

    /// Load the measured imprint (a `.npy` file or a dataset pair) the calibration compares with.
    fn load_measured(&mut self, path: PathBuf) {
        let c = &self.state.calibration;
        match measured::load(&path, c.measured_split, c.measured_index) {
            Ok(m) => {
                self.inputs.measured_path = path.display().to_string();
                self.state.calibration.measured = Some(path);
                self.measured = Some(m);
            }
            Err(e) => self.error(format!(
                "measured imprint: {}",
                tactile_derender::error::render_anyhow(&e)
            )),
        }
    }

    /// Forget the measured imprint.
    fn clear_measured(&mut self) {
        self.state.calibration.measured = None;
        self.measured = None;
        self.inputs.measured_path.clear();
    }

    /// Stop the inflation sweep.
    fn cancel_calibration(&mut self) {
        if let Some(w) = &mut self.worker {
            w.cancel_calibration();
        }
    }

    /// Set the membrane's inflation to `h` (metres), as a sensor edit.
    fn pick_inflation(&mut self, h: f64) {
        let mut sim = self.state.sim.clone();
        sim.elastomer.inflation = h;
        self.apply(Command::SetSim(sim));
    }

    // Recording tab and history.

    /// Open a recording with default settings on the Recording tab.
    fn open_recording(&mut self, path: PathBuf) {
        self.state.recording = crate::recording_view::RecordingSettings {
            path: Some(path),
            ..Default::default()
        };
        self.state.view.tab = Tab::Recording;
        self.load_recording();
    }

    /// Step back one scene, sensor or elastomer edit.
    fn undo(&mut self) {
        let now = crate::history::Snapshot::of(&self.state);
        match self.history.undo(now) {
            Some(s) => self.restore(s, "undone"),
            None => self.notice = Some("nothing to undo".into()),
        }
    }

    /// Step forward one undone edit.
    fn redo(&mut self) {
        let now = crate::history::Snapshot::of(&self.state);
        match self.history.redo(now) {
            Some(s) => self.restore(s, "redone"),
            None => self.notice = Some("nothing to redo".into()),
        }
    }

    /// Show `result`'s error, if any, as one line prefixed with `what`.
    fn report(&mut self, what: &str, result: Result<()>) {
        if let Err(e) = result {
            self.error(format!(
                "{what}: {}",
                tactile_derender::error::render_anyhow(&e)
            ));
        }
    }

    /// Put `path` first in the recent sessions.
    fn remember_session(&mut self, path: &std::path::Path) {
        self.recent.retain(|p| p != path);
        self.recent.insert(0, path.to_path_buf());
        self.recent.truncate(crate::app::RECENT_SESSIONS);
    }

    /// Put an undo/redo snapshot back and re-simulate.
    fn restore(&mut self, s: crate::history::Snapshot, what: &str) {
        s.restore(&mut self.state);
        if let ObjectSource::File { path, units } = &self.state.scene.object {
            self.inputs.object_path = path.display().to_string();
            self.inputs.object_units = *units;
        }
        self.inputs.elastomer_path = self
            .state
            .sim
            .elastomer
            .mesh_file
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_default();
        self.notice = Some(format!("{what}: scene, sensor and elastomer"));
        self.request_simulation();
    }

    /// Replace the whole state (new or opened session) and recompute what depends on it.
    pub(crate) fn replace_state(&mut self, state: State) {
        self.history.clear();
        self.state = state;
        self.calibration = Default::default();
        self.measured = None;
        self.inputs.measured_path.clear();
        if let ObjectSource::File { path, units } = &self.state.scene.object {
            self.inputs.object_path = path.display().to_string();
            self.inputs.object_units = *units;
        }
        if let Some(p) = &self.state.sim.elastomer.mesh_file {
            self.inputs.elastomer_path = p.display().to_string();
        }
        if let Some(p) = self.state.calibration.measured.clone() {
            self.inputs.measured_path = p.display().to_string();
            let c = &self.state.calibration;
            match measured::load(&p, c.measured_split, c.measured_index) {
                Ok(m) => self.measured = Some(m),
                Err(e) => self.error(format!(
                    "measured imprint: {}",
                    tactile_derender::error::render_anyhow(&e)
                )),
            }
        }
        self.analysis = Default::default();
        self.inputs.model_path = self
            .state
            .model
            .path
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_default();
        if let Some(p) = self.state.dataset.path.clone() {
            self.open_dataset(p);
        }
        self.request_simulation();
    }

    /// Turn a file dialog's answer into the command it was opened for.
    pub(crate) fn dialog_answer(&mut self, purpose: DialogPurpose, path: Option<PathBuf>) {
        let Some(path) = path else {
            self.notice = Some("no file chosen (type the path into the field instead)".into());
            return;
        };
        match purpose {
            DialogPurpose::OpenSession => self.apply(Command::OpenSession(path)),
            DialogPurpose::SaveSessionAs => self.apply(Command::SaveSession(path)),
            DialogPurpose::OpenObjectMesh => {
                self.inputs.object_path = path.display().to_string();
                let units = self.inputs.object_units;
                let mut scene = self.state.scene.clone();
                scene.object = ObjectSource::File { path, units };
                self.apply(Command::SetScene(scene));
            }
            DialogPurpose::OpenElastomerMesh => {
                self.inputs.elastomer_path = path.display().to_string();
                let mut sim = self.state.sim.clone();
                sim.elastomer.mesh_file = Some(path);
                self.apply(Command::SetSim(sim));
            }
            DialogPurpose::OpenMeasured => self.apply(Command::LoadMeasured(path)),
            DialogPurpose::ExportDir => {
                let mut view = self.state.view.clone();
                view.export_dir = path;
                self.apply(Command::SetView(view));
            }
            DialogPurpose::OpenDataset => self.apply(Command::OpenDataset(path)),
            DialogPurpose::OpenCheckpoint => {
                self.apply(Command::SetModel(ModelSettings { path: Some(path) }))
            }
            DialogPurpose::OpenRecording | DialogPurpose::OpenRecordingFolder => {
                self.apply(Command::OpenRecording(path))
            }
            DialogPurpose::OpenDerenderImprint => {
                self.inputs.imprint_path = path.display().to_string();
                let mut d = self.state.derender.clone();
                d.input = DerenderInput::Measurement { path };
                self.apply(Command::SetDerender(d));
            }
        }
    }

    fn browse(&mut self, purpose: DialogPurpose) {
        let start = match purpose {
            DialogPurpose::OpenSession | DialogPurpose::SaveSessionAs => {
                Some(PathBuf::from("sessions"))
            }
            _ => std::env::current_dir().ok(),
        };
        match &self.worker {
            Some(w) => w.dialog(purpose, start),
            None => self.error("file dialogs are not available (no worker thread)".into()),
        }
    }

    fn use_measured_scene(&mut self) -> Result<()> {
        let pair = self
            .measured
            .as_ref()
            .and_then(|m| m.scene.clone())
            .ok_or_else(|| anyhow!("load a dataset pair as the measured imprint first"))?;
        self.place_scene(&pair)
    }

    /// Put the sensor and object where a dataset pair was taken (the sensor base at its height).
    pub(crate) fn place_scene(&mut self, pair: &measured::PairScene) -> Result<()> {
        let elastomer = &self.state.sim.elastomer;
        let apex = if elastomer.mesh_file.is_none() {
            elastomer.inflation
        } else {
            return Err(anyhow!(
                "placing the sensor needs the parametric membrane's inflation; switch to the parametric dome"
            ));
        };
        let object = crate::worker::load_object(&pair.object)?;
        let scene = measured::scene_for(pair, &self.state.scene, apex, object.top_z)?;
        self.apply(Command::SetScene(scene));
        Ok(())
    }

    fn run_calibration(&mut self) {
        let req = self.sim_request();
        let settings = self.state.calibration.clone();
        let measured = self.measured.as_ref().map(|m| m.imprint.clone());
        self.calibration.generation += 1;
        self.calibration.running = true;
        self.calibration.progress = None;
        self.calibration.points.clear();
        let generation = self.calibration.generation;
        self.state.view.tab = Tab::Calibration;
        match &mut self.worker {
            Some(w) => w.calibrate(generation, req, settings, measured),
            None => {
                self.calibration.running = false;
                self.error(
                    "the inflation sweep needs the worker thread, which is not running".into(),
                );
            }
        }
    }

    fn export(&mut self, kind: ImageKind, png: bool) -> Result<()> {
        let result = self
            .sim
            .as_ref()
            .ok_or_else(|| anyhow!("nothing simulated yet"))?;
        let img = kind.image(&result.output);
        // Files of the user's in the export folder are kept, never replaced: an export of the same name stops.
        let claimed = tactile_derender::io::output::claim(
            tactile_derender::io::output::Claim::folder(
                "export folder",
                &self.state.view.export_dir,
            )
            .force(true),
        )?;
        let path = claimed.path().join(format!(
            "{}.{}",
            kind.file_stem(),
            if png { "png" } else { "npy" }
        ));
        if png {
            let range = crate::images::range_for(kind, img, &self.state.view);
            let style = preview::PanelStyle {
                title: kind.title().replace('·', "*"),
                range_m: Some(range),
                zero_is_missing: kind.zero_is_missing(),
                scale: 4,
                millimetres: kind.millimetres(),
            };
            preview::save_png(&path, &preview::render_panel(img, &style))?;
        } else {
            npy::write_image(&path, img)?;
        }
        self.notice = Some(format!("wrote {}", path.display()));
        Ok(())
    }
}
