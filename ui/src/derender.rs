//! De-rendering runs (paper IV.B sampling, V.C Table I metrics) for the workbench: the model is loaded once and
//! cached, every run samples N in-contact depths X̂0 for one imprint Y on its own thread (progress and cancel through
//! the sampler's callback), then the per-pixel mean and standard deviation and — when the input's X0 is known — the
//! per-sample depth metrics (L1, PSNR, SSIM of the evaluation stage). Nothing here touches egui textures; [`crate::panels::derender_panel`] shows the result.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;

use anyhow::{anyhow, Result};
use tactile_derender::image::Image;
use tactile_derender::metrics::{depth_metrics, DepthMetrics, DepthMetricsConfig};
use tactile_derender::model::DiffusionModel;
use tactile_derender::pipeline::{self, DerenderConfig};
use tactile_derender::pose::estimator::DEFAULT_CONSENSUS_PROBABILITY;

use crate::worker::{JobKind, WorkerMsg};

/// The bundled model `name` (`default`, `recording`): `assets/models/<name>.safetensors` where it exists (working
/// directory first, then the source checkout, so a freshly trained file is picked up without a rebuild), otherwise
/// the copy compiled into the binary (the name itself), so the workbench works from any directory.
pub fn bundled_model_path(name: &str) -> PathBuf {
    let file = format!("assets/models/{name}.safetensors");
    let here = PathBuf::from(&file);
    if here.is_file() {
        return here;
    }
    // The workspace root without a `..` in the path the workbench shows.
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let built = manifest.parent().unwrap_or(manifest).join(&file);
    if built.is_file() {
        return built;
    }
    PathBuf::from(name)
}

/// The model a run uses when none is chosen, as `--model auto` picks it: the bundled recording model for frames
/// area-resampled from a camera's larger frame (recordings, their frames, imported datasets), the default otherwise.
pub fn matched_model_path(resampled: bool) -> PathBuf {
    bundled_model_path(tactile_derender::model::checkpoint::matched_bundled_name(
        resampled,
    ))
}

/// What pose estimation needs to know about an input (simulated scenes and dataset pairs).
#[derive(Clone, Debug, PartialEq)]
pub struct PoseContext {
    /// The pressed object.
    pub object: crate::state::ObjectSource,
    /// Its true pose `t_world_object`, when known (not for a recording without a pose topic).
    pub truth: Option<tactile_derender::sensor::Se2>,
    /// The sensor camera's pose.
    pub t_world_camera: glam::DAffine3,
    /// S, for the threshold baseline, metres.
    pub signature: Image,
    /// The sensor configuration the input was made with (intrinsics, membrane).
    pub sim: tactile_derender::sim::SimConfig,
    /// The sensor's press is not known (a recording frame without a recorded pose): the pose job finds it from the
    /// samples and the signature (`pipeline::press`, as `tnd recording track`) and places the sensor there, over
    /// the object at the origin, instead of `t_world_camera`.
    pub find_press: bool,
    /// The signature was brought to the model's resolution from the camera's native pixels (a recording's frame,
    /// an imported pair): the signature check predicts it the same way (`pose::camera_path`).
    pub resampled: bool,
}

impl PoseContext {
    /// The context of dataset pair `pair` of `ds`.
    pub fn of_pair(
        ds: &tactile_derender::dataset::Dataset,
        pair: &tactile_derender::dataset::Pair,
    ) -> Result<Self> {
        let set = ds.object_set()?;
        let sim = ds.sim_config().clone();
        Ok(Self {
            object: crate::state::ObjectSource::Library {
                set: set.spec(),
                name: pair.meta.object.clone(),
            },
            truth: Some(pair.meta.object_pose),
            t_world_camera: pair.meta.sensor.t_world_sensor() * sim.mount.t_sensor_camera(),
            signature: pair.signature.clone(),
            sim,
            find_press: false,
            resampled: ds.manifest().frames_resampled(),
        })
    }
}

/// The imprint a run de-renders, with its ground truth when known.
#[derive(Clone, Debug)]
pub struct RunInput {
    /// Y, metres.
    pub imprint: Image,
    /// X0, metres (simulated scenes and dataset pairs).
    pub truth: Option<Image>,
    /// One line for the UI ("scene: cross, press 6 mm", "train pair 3").
    pub label: String,
    /// Object, true pose and camera, when known.
    pub pose: Option<PoseContext>,
    /// Whether the frames were area-resampled from a camera's larger frame (which model a run without a chosen one
    /// uses: [`matched_model_path`]).
    pub resampled: bool,
}

/// Where a run's input comes from; files are read on the run's thread.
#[derive(Clone, Debug)]
pub enum InputSource {
    /// Images already in memory (the simulated scene, the selected dataset pair).
    Images(Box<RunInput>),
    /// Pair `index` of `split` of the dataset at `dir`.
    Pair {
        dir: PathBuf,
        split: tactile_derender::dataset::SplitName,
        index: usize,
    },
    /// An `.npy` imprint in metres (no ground truth).
    Npy {
        path: PathBuf,
        /// The sensor it was measured with: a native or cropped frame is brought to the model resolution as `tnd
        /// pose` brings it.
        sim: Box<tactile_derender::sim::SimConfig>,
    },
    /// A frame of a loaded recording.
    RecordingFrame(Box<RecordingFrameInput>),
}

/// A recording frame to de-render, and what is known about its scene.
#[derive(Clone, Debug)]
pub struct RecordingFrameInput {
    pub recording: Arc<tactile_derender::recording::ProcessedRecording>,
    pub frame: usize,
    /// A label for the recording (its file name).
    pub name: String,
    /// The object's pose from the recording's pose topic, if any.
    pub pose: Option<tactile_derender::sensor::Se2>,
    /// The object the user loaded (Scene panel).
    pub object: crate::state::ObjectSource,
    /// The scene (its sensor placement is used when the recording has no pose).
    pub scene: crate::state::SceneState,
    pub sim: tactile_derender::sim::SimConfig,
}

impl RecordingFrameInput {
    /// The run input: with a recorded pose, the press is estimated from the imprint (as `tnd dataset import`) and X0
    /// simulated there; without one, the sensor stands where the Scene panel places it and nothing is known.
    fn resolve(self) -> Result<RunInput> {
        use tactile_derender::dataset::import_recording::{
            frame_truth, noise_free_simulator, DEFAULT_MAX_PRESS_M,
        };
        use tactile_derender::sim::PreparedObject;
        let p = &self.recording;
        let k = self.frame;
        let imprint = p
            .imprints
            .get(k)
            .ok_or_else(|| anyhow!("the recording has no frame {k}"))?
            .clone();
        let signature = p.signatures[k].clone();
        let sim = noise_free_simulator(&self.sim)?;
        let object = PreparedObject::new(self.object.spec().load()?.mesh)?;
        let t = p.times_s().get(k).copied().unwrap_or(0.0);
        let (scene, truth, label) = match self.pose {
            Some(pose) => {
                let ft = frame_truth(&sim, &object, pose, &imprint, None, DEFAULT_MAX_PRESS_M);
                let label = format!(
                    "{} frame {k} (t = {t:.2} s); X0 simulated at the recorded pose, press {:.1} mm (estimated)",
                    self.name,
                    ft.press * 1e3
                );
                (ft.scene, Some(ft.target), label)
            }
            None => {
                let scene = crate::worker::scene_of(&self.scene, &sim, &object);
                let label = format!(
                    "{} frame {k} (t = {t:.2} s); no recorded pose: the press found from the samples",
                    self.name
                );
                (scene, None, label)
            }
        };
        let resampled = p.frames_resampled(&self.sim.camera);
        Ok(RunInput {
            pose: Some(PoseContext {
                object: self.object,
                truth: self.pose,
                t_world_camera: sim.t_world_camera(&scene.sensor),
                signature,
                sim: self.sim,
                find_press: truth.is_none(),
                resampled,
            }),
            imprint,
            truth,
            label,
            resampled,
        })
    }
}

impl InputSource {
    /// Read the input.
    pub fn resolve(self) -> Result<RunInput> {
        match self {
            InputSource::Images(i) => Ok(*i),
            InputSource::Pair { dir, split, index } => {
                let ds = tactile_derender::dataset::Dataset::open(&dir)?;
                let pair = ds
                    .pair(split, index)
                    .map_err(|e| anyhow!("{}: pair {index} of {split}: {e}", dir.display()))?;
                Ok(RunInput {
                    label: format!("{split} pair {index} ({})", pair.meta.object),
                    pose: Some(PoseContext::of_pair(&ds, &pair)?),
                    imprint: pair.imprint,
                    truth: Some(pair.target),
                    resampled: ds.manifest().frames_resampled(),
                })
            }
            InputSource::Npy { path, sim } => {
                // As `tnd pose --imprint`: a native (e.g. 224x171) or cropped frame is cropped and resampled to the
                // model resolution, a model-size one taken as it is (pixels without a value: 0); another size is
                // left for the model to refuse by name.
                let read = tactile_derender::io::npy::read_metres_image(&path)?;
                let resampled = tactile_derender::sensor::resample::is_resampled(
                    &sim.camera,
                    read.width,
                    read.height,
                );
                let imprint = tactile_derender::sensor::resample::to_model(&sim.camera, &read)
                    .unwrap_or(read);
                Ok(RunInput {
                    label: format!("measurement {}", path.display()),
                    imprint,
                    truth: None,
                    pose: None,
                    resampled,
                })
            }
            InputSource::RecordingFrame(f) => f.resolve(),
        }
    }
}

/// One requested run.
pub struct RunRequest {
    pub generation: u64,
    /// Checkpoint to use (`None`: the bundled one matched to the input, [`matched_model_path`]).
    pub model_path: Option<PathBuf>,
    /// The model loaded last, and from where: used when it is the one the run needs.
    pub cached: Option<(PathBuf, Arc<DiffusionModel>)>,
    pub input: InputSource,
    /// Samples, sampler and seed.
    pub config: DerenderConfig,
}

/// A finished run.
pub struct RunResult {
    pub generation: u64,
    pub model: Arc<DiffusionModel>,
    pub input: RunInput,
    /// X̂0 samples, metres.
    pub samples: Vec<Image>,
    /// Per-pixel mean of the samples, metres.
    pub mean: Image,
    /// Per-pixel (population) standard deviation of the samples, metres.
    pub std: Image,
    /// Per-pixel fraction of the samples in contact, 0..1.
    pub contact_probability: Image,
    /// The samples' consensus X̂0 (pixels at least half of them mark as contact, at their median depth), metres: what
    /// the multi-sample pose registers.
    pub consensus: Image,
    /// Scores of each sample against the ground truth (empty without one).
    pub scores: Vec<DepthMetrics>,
    /// Sampler wall time, seconds.
    pub seconds: f64,
    /// Whether the samples were guided towards the imprint (asked for, and the input's sensor known).
    pub guided: bool,
    /// The settings it ran with.
    pub config: DerenderConfig,
}

/// Load (unless cached), sample, and summarise one run ([`tactile_derender::pipeline::derender`], as `tnd sample`
/// and `tnd pose` do); `cancel` stops it between steps.
pub fn run(
    req: RunRequest,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<RunResult> {
    let input = req.input.resolve()?;
    let path = req
        .model_path
        .unwrap_or_else(|| matched_model_path(input.resampled));
    let model = match req.cached {
        Some((p, m)) if p == path => m,
        _ => Arc::new(DiffusionModel::load_on(
            &path,
            &tactile_derender::model::device::open_device(&req.config.device)?,
        )?),
    };
    // Guided towards the imprint where the sensor is known (scenes, dataset pairs, recordings).
    let guidance = match &input.pose {
        Some(pose) if req.config.guidance.active() => {
            let sim = tactile_derender::sim::Simulator::new(pose.sim.clone())?;
            pipeline::imprint_guidance(&req.config, &sim, &input.imprint, Some(&pose.signature))?
        }
        _ => None,
    };
    let guided = guidance.is_some();
    let out = pipeline::derender(
        &model,
        &input.imprint,
        guidance.as_ref(),
        &req.config,
        DEFAULT_CONSENSUS_PROBABILITY,
        &mut |done, total| {
            progress(done, total);
            !cancel.load(Ordering::Relaxed)
        },
    )?;
    let scores = match &input.truth {
        Some(truth) => out
            .samples
            .iter()
            .map(|s| depth_metrics(s, truth, &DepthMetricsConfig::default()))
            .collect::<Result<Vec<_>, _>>()?,
        None => Vec::new(),
    };
    Ok(RunResult {
        generation: req.generation,
        model,
        input,
        samples: out.samples,
        mean: out.mean,
        std: out.std,
        contact_probability: out.contact_probability,
        consensus: out.consensus,
        scores,
        seconds: out.seconds,
        guided,
        config: req.config,
    })
}

/// Start `req` on its own thread; it reports progress, the result or the error through `tx`.
pub fn spawn(
    req: RunRequest,
    cancel: Arc<AtomicBool>,
    tx: Sender<WorkerMsg>,
    ctx: egui::Context,
) -> Result<()> {
    let generation = req.generation;
    crate::worker::spawn_job(JobKind::Derender, generation, tx, ctx, move |progress| {
        Ok(WorkerMsg::Derendered(Box::new(run(
            req, &cancel, progress,
        )?)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_native_frame_is_brought_to_the_model_resolution_as_the_cli_does() {
        let dir = tempfile::tempdir().unwrap();
        let sim = tactile_derender::sim::SimConfig::default();
        let native = &sim.camera.native;
        let (w, h) = (native.width, native.height);
        // A flat imprint of 4 mm at the sensor's native size (224 x 171): the model sees 64 x 64 of 4 mm.
        let path = dir.path().join("native.npy");
        let frame = tactile_derender::image::Image::filled(w, h, 0.004);
        tactile_derender::io::npy::write_image(&path, &frame).unwrap();
        let input = InputSource::Npy {
            path: path.clone(),
            sim: Box::new(sim.clone()),
        }
        .resolve()
        .unwrap();
        let (mw, mh) = sim.camera.resolution;
        assert_eq!((input.imprint.width, input.imprint.height), (mw, mh));
        assert!(input.imprint.data.iter().all(|&v| (v - 0.004).abs() < 1e-7));
        // A model-size one is taken as it is.
        let model = tactile_derender::image::Image::filled(mw, mh, 0.002);
        tactile_derender::io::npy::write_image(&path, &model).unwrap();
        let input = InputSource::Npy {
            path,
            sim: Box::new(sim),
        }
        .resolve()
        .unwrap();
        assert_eq!(input.imprint, model);
    }
}
