//! The workbench shell: the saved [`State`], everything derived from it (simulation result, textures, sweep, GPU
//! geometry), the frame loop (drain worker messages -> draw panels -> apply their commands), persistence and the
//! one-shot screenshot mode.

mod analysis;
mod dispatch;
mod recording;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use egui::Color32;
use tactile_derender::mesh::Units;
use tactile_derender::sim::calibration::SweepPoint;

use crate::command::Command;
use crate::images::ImageTextures;
use crate::measured::Measured;
use crate::panels;
use crate::state::State;
use crate::timings::Timings;
use crate::view3d::gpu;
use crate::worker::{JobKind, SimRequest, SimResult, Worker, WorkerMsg};

/// Key of the persisted state in eframe's storage.
const STORAGE_KEY: &str = "tnd-workbench";

/// What eframe persistence keeps between runs: the state and the session file it came from.
#[derive(Default, serde::Serialize, serde::Deserialize)]
#[serde(default)]
struct Persisted {
    state: State,
    session_path: Option<PathBuf>,
    /// Recently opened or saved session files, newest first.
    #[serde(default)]
    recent: Vec<PathBuf>,
}

/// Text typed into path fields (not saved: the state holds the paths actually in use).
#[derive(Clone, Debug)]
pub struct PathInputs {
    pub session_path: String,
    pub object_path: String,
    pub object_units: Units,
    pub elastomer_path: String,
    pub measured_path: String,
    pub dataset_path: String,
    pub model_path: String,
    pub imprint_path: String,
    pub recording_path: String,
}

impl Default for PathInputs {
    fn default() -> Self {
        Self {
            session_path: String::new(),
            object_path: String::new(),
            object_units: Units::Mm,
            elastomer_path: String::new(),
            measured_path: String::new(),
            dataset_path: String::new(),
            model_path: String::new(),
            imprint_path: String::new(),
            recording_path: String::new(),
        }
    }
}

/// The inflation sweep as the UI sees it.
#[derive(Default)]
pub struct CalibrationView {
    pub generation: u64,
    pub running: bool,
    pub progress: Option<(usize, usize)>,
    pub points: Vec<SweepPoint>,
}

/// Where `--screenshot` reports: `None` until the PNG was written (or failed).
pub type ScreenshotSlot = Arc<Mutex<Option<Result<(), String>>>>;

/// How the binary starts the app (command-line options).
#[derive(Default)]
pub struct Launch {
    /// Open this session instead of the last one.
    pub session: Option<PathBuf>,
    /// Render the window once into this PNG, report into the slot, and close.
    pub screenshot: Option<(PathBuf, ScreenshotSlot)>,
    /// Draw the 3D view with the CPU fallback even when wgpu is available.
    pub cpu_3d: bool,
    /// Print the timings as one JSON line when the window closes.
    pub print_timings: bool,
    /// Start a de-rendering run (the session's settings) once the scene is simulated (screenshots, timings).
    pub run_derender: bool,
    /// Then register its samples (Pose tab screenshots).
    pub run_pose: bool,
    /// Put this mesh file, in these units, in the scene (after the session).
    pub object: Option<(PathBuf, Units)>,
    /// Use this sensor (a sensor file, e.g. from `tnd calibrate --out`) instead of the session's.
    pub sensor: Option<tactile_derender::sim::SimConfig>,
}

/// A pending `--screenshot`.
struct ScreenshotJob {
    out: PathBuf,
    requested: bool,
    started: Instant,
    result: ScreenshotSlot,
}

/// The running workbench.
pub struct WorkbenchApp {
    /// The saved state (sessions, persistence).
    pub state: State,
    /// The session file the state was last opened from or saved to.
    pub session_path: Option<PathBuf>,
    pub inputs: PathInputs,
    pub(crate) worker: Option<Worker>,
    /// Generation of the newest simulation request.
    pub(crate) generation: u64,
    /// The newest simulation result.
    pub sim: Option<Box<SimResult>>,
    /// Generation of the last simulation that failed.
    failed_generation: Option<u64>,
    /// When each outstanding simulation generation was requested.
    requested_at: std::collections::BTreeMap<u64, Instant>,
    pub(crate) textures: ImageTextures,
    pub calibration: CalibrationView,
    pub(crate) measured: Option<Measured>,
    /// Dataset inspector and de-rendering runs (live side).
    pub analysis: crate::analysis_runs::AnalysisViews,
    /// The Recording tab's loaded recording and textures.
    pub recording: crate::recording_view::RecordingView,
    /// Errors shown in the window until dismissed.
    pub errors: Vec<String>,
    /// The last informational message.
    pub notice: Option<String>,
    pub timings: Timings,
    /// wgpu render state, when eframe runs on wgpu (None: CPU fallback for the 3D view).
    pub(crate) render_state: Option<eframe::egui_wgpu::RenderState>,
    pub(crate) adapter_name: Option<String>,
    screenshot: Option<ScreenshotJob>,
    persist: bool,
    print_timings: bool,
    /// When the timings were last printed, and the update-sample count then.
    printed: Option<(Instant, usize)>,
    last_frame: Option<Instant>,
    frames: u64,
    /// A de-rendering run to start once the scene is simulated (`--run-derender`).
    auto_run: bool,
    /// A pose analysis to start once the run's samples are there (`--run-pose`).
    pub(crate) auto_pose: bool,
    /// Undo and redo of scene, sensor and elastomer edits.
    pub history: crate::history::History,
    /// Recently opened or saved session files, newest first (at most [`RECENT_SESSIONS`]; kept across restarts).
    pub recent: Vec<PathBuf>,
}

/// How many recent sessions the Recent menu lists.
pub const RECENT_SESSIONS: usize = 8;

impl Default for WorkbenchApp {
    fn default() -> Self {
        Self::with_state(State::default())
    }
}

impl WorkbenchApp {
    /// An app on `state` without GPU, persistence or screenshot (tests use this).
    pub fn with_state(state: State) -> Self {
        let mut app = Self {
            state: State::default(),
            session_path: None,
            inputs: PathInputs::default(),
            worker: None,
            generation: 0,
            sim: None,
            failed_generation: None,
            requested_at: Default::default(),
            textures: ImageTextures::default(),
            calibration: CalibrationView::default(),
            measured: None,
            analysis: Default::default(),
            recording: Default::default(),
            errors: Vec::new(),
            notice: None,
            timings: Timings::default(),
            render_state: None,
            adapter_name: None,
            screenshot: None,
            persist: false,
            print_timings: false,
            printed: None,
            last_frame: None,
            frames: 0,
            auto_run: false,
            auto_pose: false,
            history: Default::default(),
            recent: Vec::new(),
        };
        app.replace_state(state);
        app
    }

    /// The app as eframe starts it: `launch.session` wins over the persisted last session; `launch.screenshot`
    /// renders the window once into that PNG, reports into the slot and closes the window.
    pub fn new(cc: &eframe::CreationContext<'_>, launch: Launch) -> Self {
        let persisted: Option<Persisted> =
            cc.storage.and_then(|s| eframe::get_value(s, STORAGE_KEY));
        let mut app = Self::default();
        if let Some(p) = &persisted {
            app.recent = p.recent.clone();
        }
        if let Some(p) = persisted.filter(|_| launch.session.is_none()) {
            match crate::session::validate(&p.state) {
                Ok(()) => {
                    app.replace_state(p.state);
                    app.inputs.session_path = p
                        .session_path
                        .as_ref()
                        .map(|s| s.display().to_string())
                        .unwrap_or_default();
                    app.session_path = p.session_path;
                }
                Err(e) => app.error(format!("last session not restored: {e}")),
            }
        }
        if let Some(path) = launch.session {
            app.apply(Command::OpenSession(path));
        }
        if let Some(sensor) = launch.sensor {
            app.apply(Command::SetSim(sensor));
        }
        if let Some((path, units)) = launch.object {
            app.inputs.object_units = units;
            app.dialog_answer(crate::worker::DialogPurpose::OpenObjectMesh, Some(path));
        }
        if let Some(rs) = cc.wgpu_render_state.as_ref().filter(|_| !launch.cpu_3d) {
            gpu::GpuResources::install(rs);
            app.adapter_name = Some(rs.adapter.get_info().name);
            app.render_state = Some(rs.clone());
        }
        app.persist = launch.screenshot.is_none();
        app.print_timings = launch.print_timings;
        app.auto_run = launch.run_derender || launch.run_pose;
        app.auto_pose = launch.run_pose;
        // The run's own tab, so that a screenshot shows what was run.
        if launch.run_pose {
            app.state.view.tab = crate::state::Tab::Pose;
        } else if launch.run_derender {
            app.state.view.tab = crate::state::Tab::Derender;
        }
        app.screenshot = launch.screenshot.map(|(out, result)| ScreenshotJob {
            out,
            requested: false,
            started: Instant::now(),
            result,
        });
        app
    }

    /// Number of contact pixels of the current simulation.
    pub fn contact_pixels(&self) -> Option<usize> {
        self.sim.as_ref().map(|s| s.output.contact_pixels)
    }

    /// True while a simulation or sweep has not reported back.
    pub fn busy(&self) -> bool {
        self.calibration.running
            || self.analysis.derender.running
            || self.analysis.pose.running
            || self.recording.loading
            || self.recording.track.running
            || self.worker.is_some()
                && self.sim.as_ref().map(|s| s.generation) != Some(self.generation)
                && !self.sim_failed_for_latest()
    }

    /// True when the simulation of the current scene failed (its error is in the status bar).
    pub fn sim_failed_for_latest(&self) -> bool {
        self.failed_generation == Some(self.generation)
    }

    pub(crate) fn error(&mut self, message: String) {
        if self.errors.last() != Some(&message) {
            self.errors.push(message);
        }
    }

    /// The simulation inputs of the current state.
    pub(crate) fn sim_request(&self) -> SimRequest {
        SimRequest {
            generation: self.generation,
            scene: self.state.scene.clone(),
            sim: self.state.sim.clone(),
            seed: self.state.seed,
        }
    }

    /// Ask the worker to simulate the current state.
    pub(crate) fn request_simulation(&mut self) {
        self.generation += 1;
        self.requested_at.insert(self.generation, Instant::now());
        let req = self.sim_request();
        if let Some(w) = &self.worker {
            if let Err(e) = w.simulate(req) {
                self.error(tactile_derender::error::render_anyhow(&e));
            }
        }
    }

    fn ensure_worker(&mut self, ctx: &egui::Context) {
        if self.worker.is_some() {
            return;
        }
        match Worker::start(ctx.clone()) {
            Ok(w) => {
                self.worker = Some(w);
                self.request_simulation();
                if let Some(p) = self.state.dataset.path.clone() {
                    self.open_dataset(p);
                }
                if self.state.recording.path.is_some() {
                    self.load_recording();
                }
            }
            Err(e) => self.error(tactile_derender::error::render_anyhow(&e)),
        }
    }

    fn handle_messages(&mut self, ctx: &egui::Context) {
        let Some(worker) = &self.worker else { return };
        for msg in worker.drain() {
            match msg {
                WorkerMsg::Simulated(result) => {
                    // The first result includes starting the worker and building every cache: not an update.
                    if let Some(t) = self
                        .requested_at
                        .get(&result.generation)
                        .filter(|_| self.sim.is_some())
                    {
                        self.timings.update.push(t.elapsed().as_secs_f64() * 1e3);
                    }
                    self.requested_at = self.requested_at.split_off(&(result.generation + 1));
                    self.timings.simulate.push(result.simulate_ms);
                    if self
                        .sim
                        .as_ref()
                        .is_none_or(|s| s.generation < result.generation)
                    {
                        self.errors.retain(|e| !e.starts_with("simulation:"));
                        self.sim = Some(result);
                    }
                }
                WorkerMsg::Progress { job, done, total } => match job {
                    JobKind::Calibration => self.calibration.progress = Some((done, total)),
                    JobKind::Derender => self.analysis.derender.progress = Some((done, total)),
                    JobKind::Recording if self.recording.loading => {
                        self.recording.progress = Some((done, total))
                    }
                    JobKind::Pose if self.analysis.pose.running => {
                        self.analysis.pose.progress = Some((done, total))
                    }
                    JobKind::Track if self.recording.track.running => {
                        self.recording.track.progress = Some((done, total))
                    }
                    JobKind::SensorCalibration if self.recording.sensor_calibration.running => {
                        self.recording.sensor_calibration.progress = Some((done, total))
                    }
                    _ => {}
                },
                WorkerMsg::Dataset(msg) => self.dataset_message(ctx, msg),
                WorkerMsg::Recording(msg) => self.recording_message(msg),
                WorkerMsg::SensorCalibrated { generation, result } => {
                    self.sensor_calibrated(generation, result)
                }
                WorkerMsg::Track(msg) => self.track_message(msg),
                WorkerMsg::Derendered(result) => self.derendered(ctx, result),
                WorkerMsg::Posed {
                    generation,
                    analysis,
                } => self.posed(generation, analysis),
                WorkerMsg::Calibrated { generation, points } => {
                    if generation == self.calibration.generation {
                        self.calibration.running = false;
                        self.calibration.points = points;
                    }
                }
                WorkerMsg::Dialog { purpose, path } => self.dialog_answer(purpose, path),
                WorkerMsg::Error {
                    job,
                    generation,
                    message,
                } => {
                    match job {
                        JobKind::Simulation => self.failed_generation = Some(generation),
                        JobKind::Calibration if generation == self.calibration.generation => {
                            self.calibration.running = false;
                        }
                        JobKind::Derender => {
                            self.derender_failed(generation, message);
                            continue;
                        }
                        JobKind::Recording if generation != self.recording.generation => continue,
                        JobKind::Recording => {
                            self.recording.loading = false;
                            self.recording.cancel = None;
                        }
                        JobKind::Track if generation != self.recording.track.generation => continue,
                        JobKind::Track => {
                            self.recording.track.running = false;
                            self.recording.track.cancel = None;
                        }
                        JobKind::SensorCalibration
                            if generation != self.recording.sensor_calibration.generation =>
                        {
                            continue
                        }
                        JobKind::SensorCalibration => {
                            self.recording.sensor_calibration.running = false;
                            self.recording.sensor_calibration.cancel = None;
                        }
                        JobKind::Pose if generation != self.analysis.pose.generation => continue,
                        JobKind::Pose => {
                            self.analysis.pose.running = false;
                            self.analysis.pose.cancel = None;
                        }
                        _ => {}
                    }
                    self.error(message);
                }
            }
        }
    }

    /// Draw the whole window once and apply what the user did. eframe calls this through [`eframe::App::ui`]; tests
    /// call it from egui_kittest.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        let t0 = Instant::now();
        let ctx = ui.ctx().clone();
        self.ensure_worker(&ctx);
        self.handle_messages(&ctx);
        if let Some(result) = &self.sim {
            self.textures
                .update(&ctx, result.generation, &result.output, &self.state.view);
            if let Some(rs) = &self.render_state {
                gpu::upload(rs, &result.geometry);
            }
        }
        let mut commands = Vec::new();
        if self.auto_run && self.sim.is_some() && !self.busy() {
            self.auto_run = false;
            commands.push(Command::RunDerender);
        } else if self.auto_pose && !self.auto_run && !self.busy() {
            self.auto_pose = false;
            if self.analysis.derender.result.is_some() {
                let tab = self.state.view.tab;
                commands.push(Command::RunPose);
                commands.push(Command::SetView(crate::state::ViewState {
                    tab,
                    ..self.state.view.clone()
                }));
            }
        }
        commands.extend(crate::shortcuts::pressed(
            &ctx,
            self.session_path.as_deref(),
        ));
        panels::show_all(self, ui, &mut commands);
        for cmd in commands {
            self.apply(cmd);
        }
        if self.busy() {
            ctx.request_repaint_after(std::time::Duration::from_millis(50));
        }
        self.update_timings(t0);
        self.drive_screenshot(&ctx);
    }

    fn update_timings(&mut self, t0: Instant) {
        self.timings.ui.push(t0.elapsed().as_secs_f64() * 1e3);
        if let Some(last) = self.last_frame {
            let dt = last.elapsed().as_secs_f64() * 1e3;
            // Idle gaps (no repaint requested) are not frame times.
            if dt < 250.0 {
                self.timings.frame.push(dt);
            }
        }
        self.last_frame = Some(Instant::now());
        self.frames += 1;
        if self.print_timings {
            let n = self.timings.update.len() + self.timings.frame.len();
            let due = self
                .printed
                .is_none_or(|(t, count)| t.elapsed().as_secs_f64() > 2.0 && count != n);
            if due {
                println!("{}", self.timings.summary_json());
                self.printed = Some((Instant::now(), n));
            }
        }
    }

    fn drive_screenshot(&mut self, ctx: &egui::Context) {
        let dataset_loading = self.analysis.dataset.as_ref().is_some_and(|b| {
            b.missing > 0 || (self.state.dataset.selected.is_some() && b.selected.is_none())
        }) || (self.state.dataset.path.is_some()
            && self.analysis.dataset.is_none());
        let auto_runs = self.auto_run
            || self.auto_pose
            || self.analysis.derender.running
            || self.analysis.pose.running;
        let ready = !self.busy()
            && !self.auto_run
            && !self.auto_pose
            && !dataset_loading
            && self.sim.is_some()
            && self.frames > 4;
        // A load or simulation that failed is as ready as the window gets: save at once, naming the error shown.
        let failed = (!self.busy()
            && !dataset_loading
            && (self.sim.is_none() || self.sim_failed_for_latest())
            && self.frames > 4)
            .then(|| self.errors.last().cloned())
            .flatten();
        let Some(job) = &mut self.screenshot else {
            return;
        };
        if let Ok(slot) = job.result.lock() {
            if slot.is_some() {
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                return;
            }
        }
        // A de-rendering or pose run on a slow machine takes minutes; a plain screenshot waits a minute at most.
        let limit_s = if auto_runs {
            SCREENSHOT_RUN_LIMIT_S
        } else {
            SCREENSHOT_LIMIT_S
        };
        let timed_out = !ready && failed.is_none() && job.started.elapsed().as_secs() > limit_s;
        if !job.requested && (ready || failed.is_some() || timed_out) {
            job.requested = true;
            let out = job.out.clone();
            let slot = job.result.clone();
            let wake = ctx.clone();
            ctx.request_screenshot(move |image| {
                // Saved either way; a window that never got ready is an error (exit status 1) naming the wait.
                let saved = save_color_image(&out, &image).and_then(|()| {
                    if let Some(error) = &failed {
                        Err(format!("saved; the workbench shows an error: {error}"))
                    } else if timed_out {
                        Err(format!(
                            "saved after waiting {limit_s} s, before the workbench was ready (a run or a load \
                             still going); the image shows it unfinished"
                        ))
                    } else {
                        Ok(())
                    }
                });
                if let Ok(mut s) = slot.lock() {
                    *s = Some(saved);
                }
                wake.request_repaint();
            });
        }
        ctx.request_repaint();
    }

    pub(crate) fn status_color(&self) -> Color32 {
        if self.errors.is_empty() {
            Color32::GRAY
        } else {
            Color32::from_rgb(220, 60, 60)
        }
    }
}

/// Longest wait of `--screenshot` for the window to be ready, seconds.
const SCREENSHOT_LIMIT_S: u64 = 60;
/// The same with `--run-derender` or `--run-pose` (16 samples and their registrations on 2 cores: about a minute).
const SCREENSHOT_RUN_LIMIT_S: u64 = 600;

/// Write an egui screenshot as PNG (atomically).
fn save_color_image(path: &std::path::Path, image: &egui::ColorImage) -> Result<(), String> {
    let [w, h] = image.size;
    let mut rgb = image::RgbImage::new(w as u32, h as u32);
    for (i, px) in image.pixels.iter().enumerate() {
        rgb.put_pixel(
            (i % w) as u32,
            (i / w) as u32,
            image::Rgb([px.r(), px.g(), px.b()]),
        );
    }
    tactile_derender::io::preview::save_png(path, &rgb).map_err(|e| e.to_string())
}

impl eframe::App for WorkbenchApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        if self.persist {
            let p = Persisted {
                state: self.state.clone(),
                session_path: self.session_path.clone(),
                recent: self.recent.clone(),
            };
            eframe::set_value(storage, STORAGE_KEY, &p);
        }
    }

    fn on_exit(&mut self) {
        if self.print_timings {
            println!("{}", self.timings.summary_json());
        }
    }
}
