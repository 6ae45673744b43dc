//! Heavy work off the UI thread. A persistent **simulation worker** runs the simulator (paper IV.A, V.A) for the
//! latest requested scene (older requests are dropped, so dragging a slider never queues work); one-off **jobs**
//! (the inflation sweep, file dialogs; later de-rendering runs) run on their own threads with a cancel flag. Every
//! thread reports through the one [`WorkerMsg`] enum, which the app drains at the start of each frame.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, Context, Result};
use tactile_derender::image::Image;
use tactile_derender::sensor::Scene;
use tactile_derender::sim::calibration::{self, MeasuredImprint, SweepPoint};
use tactile_derender::sim::{PreparedObject, SimConfig, SimOutput, Simulator};

use crate::state::{CalibrationSettings, ObjectSource, SceneState};
use crate::view3d::geometry::SceneGeometry;

/// Which background activity a message is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobKind {
    Simulation,
    Calibration,
    Dialog,
    Dataset,
    Derender,
    Pose,
    Recording,
    /// Tracking a recording's frames.
    Track,
    /// Fitting the sensor to a recording's no-contact frames.
    SensorCalibration,
}

/// What a file dialog was opened for; its answer comes back with it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DialogPurpose {
    OpenSession,
    SaveSessionAs,
    OpenObjectMesh,
    OpenElastomerMesh,
    OpenMeasured,
    ExportDir,
    OpenDataset,
    OpenCheckpoint,
    OpenDerenderImprint,
    /// An `.mcap` recording.
    OpenRecording,
    /// A folder of depth frames.
    OpenRecordingFolder,
}

/// Everything background threads report.
pub enum WorkerMsg {
    /// `done` of `total` steps of a job.
    Progress {
        job: JobKind,
        done: usize,
        total: usize,
    },
    /// A finished simulation.
    Simulated(Box<SimResult>),
    /// A finished inflation sweep.
    Calibrated {
        generation: u64,
        points: Vec<SweepPoint>,
    },
    /// The dataset inspector's loader (thumbnails, the selected pair, object index).
    Dataset(crate::dataset_view::DatasetMsg),
    /// A loaded recording.
    Recording(crate::recording_view::RecordingMsg),
    /// A finished sensor calibration.
    SensorCalibrated {
        generation: u64,
        result: Box<crate::sensor_calibration::CalibrationResult>,
    },
    /// A tracked frame of a recording, or the end of the track.
    Track(crate::track_view::TrackMsg),
    /// A finished de-rendering run.
    Derendered(Box<crate::derender::RunResult>),
    /// A finished pose analysis.
    Posed {
        generation: u64,
        analysis: Box<crate::pose_view::PoseAnalysis>,
    },
    /// A file dialog's answer (`None`: cancelled, or no dialog available on this system).
    Dialog {
        purpose: DialogPurpose,
        path: Option<PathBuf>,
    },
    /// A job failed; `message` is one line for the user.
    Error {
        job: JobKind,
        generation: u64,
        message: String,
    },
}

/// The inputs of one simulation.
#[derive(Clone, Debug, PartialEq)]
pub struct SimRequest {
    pub generation: u64,
    pub scene: SceneState,
    pub sim: SimConfig,
    pub seed: u64,
}

/// One simulated scene with what the views need.
pub struct SimResult {
    pub generation: u64,
    pub output: SimOutput,
    /// Wall time of the simulator run alone (render, contact, signature), milliseconds.
    pub simulate_ms: f64,
    /// Wall time including rebuilding cached membrane or object, milliseconds.
    pub total_ms: f64,
    /// Geometry for the 3D view (world frame).
    pub geometry: Arc<SceneGeometry>,
    /// Where the sensor was (world frame), and `t_world_camera` of its camera.
    pub sensor: tactile_derender::sensor::SensorPose,
    pub t_world_camera: glam::DAffine3,
    /// Where the object's highest point lies from the membrane's apex (why there may be no contact).
    pub contact_hint: tactile_derender::sim::ContactHint,
    /// What the user should know about the object's file (a size that says its units are wrong).
    pub object_warnings: Vec<String>,
}

/// Load the object mesh named by `source` in its resting pose (as `tnd` does: [`ObjectSource::spec`]).
pub fn load_object(source: &ObjectSource) -> Result<PreparedObject> {
    Ok(load_object_noting(source)?.0)
}

/// [`load_object`], and what the user should know about the file (e.g. a size that says its units are wrong).
pub fn load_object_noting(source: &ObjectSource) -> Result<(PreparedObject, Vec<String>)> {
    let loaded = source.spec().load()?;
    Ok((PreparedObject::new(loaded.mesh)?, loaded.warnings))
}

/// The scene (object pose, sensor pose pressing the object) of `state` for a prepared simulator and object.
pub fn scene_of(state: &SceneState, sim: &Simulator, object: &PreparedObject) -> Scene {
    Scene {
        object: state.object_pose,
        sensor: sim.pressing_pose(
            object,
            state.sensor_x,
            state.sensor_y,
            state.sensor_yaw,
            state.press,
        ),
    }
}

/// Caches of the simulation worker: the simulator (membrane, SDF, E) and the object (BVH) are rebuilt only when their
/// inputs change.
#[derive(Default)]
struct SimCache {
    sim: Option<(SimConfig, Simulator)>,
    object: Option<(ObjectSource, PreparedObject, Vec<String>)>,
}

impl SimCache {
    fn run(&mut self, req: &SimRequest) -> Result<SimResult> {
        let t0 = Instant::now();
        if self.sim.as_ref().map(|(c, _)| c) != Some(&req.sim) {
            self.sim = None;
            let sim = Simulator::new(req.sim.clone()).context("sensor")?;
            self.sim = Some((req.sim.clone(), sim));
        }
        if self.object.as_ref().map(|(s, _, _)| s) != Some(&req.scene.object) {
            self.object = None;
            let (object, warnings) = load_object_noting(&req.scene.object)
                .with_context(|| format!("object {}", req.scene.object.display_name()))?;
            self.object = Some((req.scene.object.clone(), object, warnings));
        }
        let (Some((_, sim)), Some((_, object, object_warnings))) = (&self.sim, &self.object) else {
            return Err(anyhow!("internal: simulator cache is empty"));
        };
        let scene = scene_of(&req.scene, sim, object);
        let (output, simulate_s) = sim.simulate_timed(object, &scene, req.seed);
        let geometry = Arc::new(SceneGeometry::build(
            req.generation,
            sim,
            object,
            &scene,
            &output,
        ));
        Ok(SimResult {
            generation: req.generation,
            output,
            simulate_ms: simulate_s * 1e3,
            total_ms: t0.elapsed().as_secs_f64() * 1e3,
            geometry,
            sensor: scene.sensor,
            t_world_camera: sim.t_world_camera(&scene.sensor),
            contact_hint: sim.contact_hint(object, &scene),
            object_warnings: object_warnings.clone(),
        })
    }
}

/// Handle to the background threads.
pub struct Worker {
    sim_tx: Sender<SimRequest>,
    msg_tx: Sender<WorkerMsg>,
    msg_rx: Receiver<WorkerMsg>,
    ctx: egui::Context,
    calibration_cancel: Option<Arc<AtomicBool>>,
}

impl Worker {
    /// Start the simulation thread; `ctx` is woken whenever a message is ready.
    pub fn start(ctx: egui::Context) -> Result<Self> {
        let (sim_tx, sim_rx) = mpsc::channel::<SimRequest>();
        let (msg_tx, msg_rx) = mpsc::channel();
        let tx = msg_tx.clone();
        let wake = ctx.clone();
        std::thread::Builder::new()
            .name("tnd-sim".into())
            .spawn(move || simulation_loop(&sim_rx, &tx, &wake))
            .context("cannot start the simulation thread")?;
        Ok(Self {
            sim_tx,
            msg_tx,
            msg_rx,
            ctx,
            calibration_cancel: None,
        })
    }

    /// Ask for a simulation (replacing any request not yet started).
    pub fn simulate(&self, req: SimRequest) -> Result<()> {
        self.sim_tx
            .send(req)
            .map_err(|_| anyhow!("the simulation thread has stopped"))
    }

    /// A sender for threads started elsewhere (dataset loader, de-rendering runs).
    pub fn sender(&self) -> Sender<WorkerMsg> {
        self.msg_tx.clone()
    }

    /// The context the threads wake.
    pub fn context(&self) -> egui::Context {
        self.ctx.clone()
    }

    /// Messages that arrived since the last call.
    pub fn drain(&self) -> Vec<WorkerMsg> {
        self.msg_rx.try_iter().collect()
    }

    /// Start an inflation sweep (cancelling a running one).
    pub fn calibrate(
        &mut self,
        generation: u64,
        req: SimRequest,
        settings: CalibrationSettings,
        measured: Option<Image>,
    ) {
        self.cancel_calibration();
        let cancel = Arc::new(AtomicBool::new(false));
        self.calibration_cancel = Some(cancel.clone());
        let tx = self.msg_tx.clone();
        let ctx = self.ctx.clone();
        let spawned = std::thread::Builder::new()
            .name("tnd-calibration".into())
            .spawn(move || {
                let msg = match sweep(&req, &settings, measured.as_ref(), &cancel, &tx, &ctx) {
                    Ok(points) => WorkerMsg::Calibrated { generation, points },
                    Err(e) => WorkerMsg::Error {
                        job: JobKind::Calibration,
                        generation,
                        message: format!(
                            "inflation sweep: {}",
                            tactile_derender::error::render_anyhow(&e)
                        ),
                    },
                };
                let _ = tx.send(msg);
                ctx.request_repaint();
            });
        if let Err(e) = spawned {
            let _ = self.msg_tx.send(WorkerMsg::Error {
                job: JobKind::Calibration,
                generation,
                message: format!("cannot start the sweep thread: {e}"),
            });
        }
    }

    /// Cancel the running sweep, if any.
    pub fn cancel_calibration(&mut self) {
        raise_cancel(&mut self.calibration_cancel);
    }

    /// Show a native file dialog on its own thread (rfd returns at once where no dialog is available; the typed path
    /// fields are the fallback).
    pub fn dialog(&self, purpose: DialogPurpose, start_dir: Option<PathBuf>) {
        let tx = self.msg_tx.clone();
        let ctx = self.ctx.clone();
        let _ = std::thread::Builder::new()
            .name("tnd-dialog".into())
            .spawn(move || {
                let path = crate::dialogs::run(purpose, start_dir);
                let _ = tx.send(WorkerMsg::Dialog { purpose, path });
                ctx.request_repaint();
            });
    }
}

fn simulation_loop(rx: &Receiver<SimRequest>, tx: &Sender<WorkerMsg>, ctx: &egui::Context) {
    let mut cache = SimCache::default();
    while let Ok(mut req) = rx.recv() {
        // Latest wins: skip requests superseded while the previous one ran.
        while let Ok(newer) = rx.try_recv() {
            req = newer;
        }
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| cache.run(&req)));
        let msg = match result {
            Ok(Ok(r)) => WorkerMsg::Simulated(Box::new(r)),
            Ok(Err(e)) => WorkerMsg::Error {
                job: JobKind::Simulation,
                generation: req.generation,
                message: format!("simulation: {}", tactile_derender::error::render_anyhow(&e)),
            },
            Err(_) => {
                cache = SimCache::default();
                WorkerMsg::Error {
                    job: JobKind::Simulation,
                    generation: req.generation,
                    message:
                        "simulation: internal error (the simulator panicked); please report it"
                            .into(),
                }
            }
        };
        if tx.send(msg).is_err() {
            return;
        }
        ctx.request_repaint();
    }
}

fn sweep(
    req: &SimRequest,
    settings: &CalibrationSettings,
    measured: Option<&Image>,
    cancel: &AtomicBool,
    tx: &Sender<WorkerMsg>,
    ctx: &egui::Context,
) -> Result<Vec<SweepPoint>> {
    let inflations = calibration::inflation_values(settings.lo, settings.hi, settings.steps)?;
    let object = load_object(&req.scene.object)?;
    let sim = Simulator::new(req.sim.clone())?;
    let scene = scene_of(&req.scene, &sim, &object);
    let measured = measured.map(|imprint| MeasuredImprint {
        imprint,
        threshold: settings.threshold,
    });
    let points = calibration::sweep_inflation(
        &req.sim,
        &object,
        &scene,
        &inflations,
        measured,
        &mut |done, total| {
            let _ = tx.send(WorkerMsg::Progress {
                job: JobKind::Calibration,
                done,
                total,
            });
            ctx.request_repaint();
            !cancel.load(Ordering::Relaxed)
        },
    )?;
    Ok(points)
}

/// A progress callback for a background job: sends `Progress { job, done, total }` through `tx` at most ~60 times a
/// second (always the last step) and wakes the UI.
pub fn throttled_progress(
    job: JobKind,
    tx: Sender<WorkerMsg>,
    ctx: egui::Context,
) -> impl FnMut(usize, usize) {
    let mut last = std::time::Instant::now();
    move |done, total| {
        if done == total || last.elapsed().as_millis() >= 16 {
            last = std::time::Instant::now();
            let _ = tx.send(WorkerMsg::Progress { job, done, total });
            ctx.request_repaint();
        }
    }
}

impl JobKind {
    /// How the job names itself in its error lines, its thread's name, and what panicking means for it.
    fn names(self) -> (&'static str, &'static str, &'static str) {
        match self {
            JobKind::Simulation => ("simulation", "tnd-simulation", "the simulator panicked"),
            JobKind::Calibration => ("calibration", "tnd-calibration", "the sweep panicked"),
            JobKind::Dialog => ("file dialog", "tnd-dialog", "the dialog panicked"),
            JobKind::Dataset => ("dataset", "tnd-dataset", "the loader panicked"),
            JobKind::Derender => ("de-render", "tnd-derender", "the sampler panicked"),
            JobKind::Pose => ("pose", "tnd-pose", "registration panicked"),
            JobKind::Recording => ("recording", "tnd-recording", "reading panicked"),
            JobKind::Track => ("track", "tnd-track", "tracking panicked"),
            JobKind::SensorCalibration => (
                "sensor calibration",
                "tnd-sensor-calibration",
                "the calibration panicked",
            ),
        }
    }
}

/// Run `work` on its own thread as one run (`generation`) of background job `job`: `work` gets a throttled
/// progress callback and returns the message to send; an error or a panic becomes one [`WorkerMsg::Error`] line.
pub fn spawn_job(
    job: JobKind,
    generation: u64,
    tx: Sender<WorkerMsg>,
    ctx: egui::Context,
    work: impl FnOnce(&mut dyn FnMut(usize, usize)) -> Result<WorkerMsg> + Send + 'static,
) -> Result<()> {
    let (label, thread, panicked) = job.names();
    std::thread::Builder::new()
        .name(thread.into())
        .spawn(move || {
            let mut progress = throttled_progress(job, tx.clone(), ctx.clone());
            let result =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(&mut progress)));
            let msg = match result {
                Ok(Ok(msg)) => msg,
                Ok(Err(e)) => WorkerMsg::Error {
                    job,
                    generation,
                    message: format!("{label}: {}", tactile_derender::error::render_anyhow(&e)),
                },
                Err(_) => WorkerMsg::Error {
                    job,
                    generation,
                    message: format!("{label}: internal error ({panicked}); please report it"),
                },
            };
            let _ = tx.send(msg);
            ctx.request_repaint();
        })
        .map(|_| ())
        .map_err(|e| anyhow!("cannot start the {label} thread: {e}"))
}

/// Stop the job behind `flag`, if any: set its cancel flag and forget it.
pub fn raise_cancel(flag: &mut Option<Arc<AtomicBool>>) {
    if let Some(f) = flag.take() {
        f.store(true, Ordering::Relaxed);
    }
}
