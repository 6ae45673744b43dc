//! The app's side of the analysis tabs' jobs (dataset inspector, de-rendering, pose): starting, cancelling and
//! taking in each job's messages, and the exports of their results.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, Result};

use super::WorkbenchApp;
use crate::analysis_runs::{run_images, selected_pair};
use crate::dataset_view::{DatasetBrowser, DatasetMsg};
use crate::derender::{self, InputSource, PoseContext, RunInput, RunRequest, RunResult};
use crate::measured::PairScene;
use crate::pose_job::{self, PoseRequest};
use crate::pose_view::PoseAnalysis;
use crate::state::{DerenderInput, ObjectSource, Tab};
use crate::worker::raise_cancel;

impl WorkbenchApp {
    /// Take in a dataset loader message.
    pub(crate) fn dataset_message(&mut self, ctx: &egui::Context, msg: DatasetMsg) {
        let generation = match &msg {
            DatasetMsg::Thumbnail { generation, .. }
            | DatasetMsg::Pair { generation, .. }
            | DatasetMsg::Objects { generation, .. }
            | DatasetMsg::Error { generation, .. } => *generation,
        };
        let Some(b) = self
            .analysis
            .dataset
            .as_mut()
            .filter(|b| b.generation == generation)
        else {
            return;
        };
        if let Some(e) = b.handle(ctx, msg) {
            self.error(e);
        }
    }

    /// Take in a finished run.
    pub(crate) fn derendered(&mut self, ctx: &egui::Context, r: Box<RunResult>) {
        let view = &mut self.analysis.derender;
        if r.generation != view.generation {
            return;
        }
        view.running = false;
        view.cancel = None;
        view.model = Some((
            r.model.source().to_path_buf(),
            r.config.device.clone(),
            r.model.clone(),
        ));
        view.images = run_images(ctx, &r);
        view.pending_input = None;
        view.result = Some(r);
        self.errors.retain(|e| !e.starts_with("de-render:"));
    }

    /// A run failed or was cancelled.
    pub(crate) fn derender_failed(&mut self, generation: u64, message: String) {
        let view = &mut self.analysis.derender;
        if generation != view.generation {
            return;
        }
        view.running = false;
        view.cancel = None;
        if message.ends_with(": cancelled") {
            self.notice = Some("de-rendering cancelled".into());
        } else {
            self.error(message);
        }
    }

    /// Open the dataset at `path` in the inspector.
    /// Without the worker (before the first frame) only the path is kept; the first frame opens it.
    pub(crate) fn open_dataset(&mut self, path: PathBuf) {
        let Some(w) = &self.worker else {
            self.inputs.dataset_path = path.display().to_string();
            self.state.dataset.path = Some(path);
            self.analysis.dataset = None;
            return;
        };
        self.analysis.dataset_generation += 1;
        let generation = self.analysis.dataset_generation;
        match DatasetBrowser::open(&path, generation, w.sender(), w.context()) {
            Ok(b) => {
                self.inputs.dataset_path = path.display().to_string();
                let s = &mut self.state.dataset;
                if s.path.as_ref() != Some(&path) {
                    s.selected = None;
                    s.object = None;
                }
                if b.dataset.len(s.split) == 0 {
                    s.split = tactile_derender::dataset::SplitName::ALL
                        .into_iter()
                        .find(|&x| b.dataset.len(x) > 0)
                        .unwrap_or(s.split);
                }
                s.path = Some(path);
                self.analysis.dataset = Some(b);
                if let Some(i) = self.state.dataset.selected {
                    self.select_pair(i);
                }
            }
            Err(e) => self.error(format!(
                "dataset: {}",
                tactile_derender::error::render_anyhow(&e)
            )),
        }
    }

    /// Select pair `index` of the shown split and load it at full size.
    pub(crate) fn select_pair(&mut self, index: usize) {
        let split = self.state.dataset.split;
        self.state.dataset.selected = Some(index);
        if let Some(b) = &mut self.analysis.dataset {
            if index < b.dataset.len(split) {
                b.request_pair((split, index));
            } else {
                self.state.dataset.selected = None;
            }
        }
    }

    /// Make the selected dataset pair the de-rendering input and show the De-render tab.
    pub(crate) fn send_pair_to_derender(&mut self) -> Result<()> {
        let (b, sel) = selected_pair(&self.analysis)?;
        let m = &sel.pair.meta;
        self.state.derender.input = DerenderInput::DatasetPair {
            dir: b.dir.clone(),
            split: m.split,
            index: m.split_index,
        };
        let pose = PoseContext::of_pair(&b.dataset, &sel.pair)?;
        self.analysis.derender.pending_input = Some(RunInput {
            imprint: sel.pair.imprint.clone(),
            truth: Some(sel.pair.target.clone()),
            label: format!("{} pair {} ({})", m.split, m.split_index, m.object),
            pose: Some(pose),
            resampled: b.dataset.manifest().frames_resampled(),
        });
        self.state.view.tab = Tab::Derender;
        Ok(())
    }

    /// Place the simulated scene where the selected dataset pair was taken.
    pub(crate) fn place_pair_scene(&mut self) -> Result<()> {
        let (b, sel) = selected_pair(&self.analysis)?;
        let set = b.dataset.object_set()?;
        let m = &sel.pair.meta;
        let pair = PairScene {
            object: ObjectSource::Library {
                set: set.spec(),
                name: m.object.clone(),
            },
            object_pose: m.object_pose,
            sensor: m.sensor,
        };
        self.place_scene(&pair)?;
        self.state.derender.input = DerenderInput::Scene;
        self.state.view.tab = Tab::Scene;
        Ok(())
    }

    fn derender_input(&self) -> Result<InputSource> {
        Ok(match &self.state.derender.input {
            DerenderInput::Scene => {
                let sim = self
                    .sim
                    .as_ref()
                    .ok_or_else(|| anyhow!("the scene has not been simulated yet"))?;
                let out = &sim.output;
                InputSource::Images(Box::new(RunInput {
                    pose: Some(PoseContext {
                        object: self.state.scene.object.clone(),
                        truth: Some(self.state.scene.object_pose),
                        t_world_camera: sim.t_world_camera,
                        signature: out.signature.clone(),
                        sim: self.state.sim.clone(),
                        find_press: false,
                        resampled: false,
                    }),
                    imprint: out.imprint.clone(),
                    truth: Some(out.target.clone()),
                    label: format!(
                        "scene: {}, press {:.1} mm",
                        self.state.scene.object.display_name(),
                        self.state.scene.press * 1e3
                    ),
                    resampled: false,
                }))
            }
            DerenderInput::DatasetPair { dir, split, index } => {
                match &self.analysis.derender.pending_input {
                    Some(i) => InputSource::Images(Box::new(i.clone())),
                    None => InputSource::Pair {
                        dir: dir.clone(),
                        split: *split,
                        index: *index,
                    },
                }
            }
            DerenderInput::Measurement { path } => InputSource::Npy {
                path: path.clone(),
                sim: Box::new(self.state.sim.clone()),
            },
            DerenderInput::RecordingFrame { path, frame } => {
                let loaded = self
                    .recording
                    .loaded
                    .as_ref()
                    .filter(|l| &l.path == path)
                    .ok_or_else(|| {
                        anyhow!(
                            "open the recording {} in the Recording tab first",
                            path.display()
                        )
                    })?;
                InputSource::RecordingFrame(Box::new(crate::derender::RecordingFrameInput {
                    recording: loaded.processed.clone(),
                    frame: *frame,
                    name: path.file_name().map_or_else(
                        || path.display().to_string(),
                        |n| n.to_string_lossy().into(),
                    ),
                    pose: loaded.poses.get(*frame).copied().flatten(),
                    object: self.state.scene.object.clone(),
                    scene: self.state.scene.clone(),
                    sim: self.state.sim.clone(),
                }))
            }
        })
    }

    /// Start a run with the current settings (cancelling a running one).
    pub(crate) fn run_derender(&mut self) -> Result<()> {
        self.state.derender.config.validate(None)?;
        let model_path = self.state.model.path.clone();
        let input = self.derender_input()?;
        let w = self
            .worker
            .as_ref()
            .ok_or_else(|| anyhow!("de-rendering needs the worker thread"))?;
        let (tx, ctx) = (w.sender(), w.context());
        self.cancel_derender();
        let view = &mut self.analysis.derender;
        view.generation += 1;
        let cached = view
            .model
            .as_ref()
            .filter(|(_, device, _)| *device == self.state.derender.config.device)
            .map(|(p, _, m)| (p.clone(), m.clone()));
        let req = RunRequest {
            generation: view.generation,
            model_path,
            cached,
            input,
            config: self.state.derender.config.clone(),
        };
        let cancel = Arc::new(AtomicBool::new(false));
        view.cancel = Some(cancel.clone());
        view.running = true;
        view.progress = None;
        view.started = Some(Instant::now());
        derender::spawn(req, cancel, tx, ctx).inspect_err(|_| {
            self.analysis.derender.running = false;
        })
    }

    /// Take in a finished pose analysis.
    pub(crate) fn posed(&mut self, generation: u64, analysis: Box<PoseAnalysis>) {
        let view = &mut self.analysis.pose;
        if generation == view.generation {
            view.running = false;
            view.cancel = None;
            view.highlight = None;
            view.result = Some(analysis);
            self.errors.retain(|e| !e.starts_with("pose:"));
        }
    }

    /// Register the current run's samples and the baseline in the background.
    pub(crate) fn run_pose(&mut self) -> Result<()> {
        let r = self
            .analysis
            .derender
            .result
            .as_ref()
            .ok_or_else(|| anyhow!("run de-rendering first"))?;
        let context = r.input.pose.clone().ok_or_else(|| {
            anyhow!("this input has no object or sensor pose (an imported measurement); registration needs them")
        })?;
        let w = self
            .worker
            .as_ref()
            .ok_or_else(|| anyhow!("registration needs the worker thread"))?;
        let view = &mut self.analysis.pose;
        view.generation += 1;
        let req = PoseRequest {
            generation: view.generation,
            context,
            imprint: r.input.imprint.clone(),
            samples: r.samples.clone(),
            seed: r.config.seed,
            config: self.state.pose.clone(),
        };
        raise_cancel(&mut view.cancel);
        let cancel = Arc::new(AtomicBool::new(false));
        pose_job::spawn(req, cancel.clone(), w.sender(), w.context())?;
        view.cancel = Some(cancel);
        view.progress = None;
        view.running = true;
        view.result = None;
        self.state.view.tab = Tab::Pose;
        Ok(())
    }

    pub(crate) fn export_pose(&mut self) -> Result<()> {
        let r = self
            .analysis
            .pose
            .result
            .as_ref()
            .ok_or_else(|| anyhow!("register the samples first"))?;
        let claimed = tactile_derender::io::output::claim(
            tactile_derender::io::output::Claim::folder(
                "export folder",
                &self.state.view.export_dir.join("pose"),
            )
            .force(true),
        )?;
        let dir = claimed.path().to_path_buf();
        r.report.write(&dir)?;
        let req = r
            .inputs
            .as_ref()
            .ok_or_else(|| anyhow!("this analysis holds no inputs to export"))?;
        let c = &req.context;
        let sim = tactile_derender::sim::Simulator::new(c.sim.clone())?;
        let object = c.object.spec().load()?;
        let estimate = tactile_derender::pipeline::PoseEstimate {
            object: r.object.clone(),
            hypotheses: r.hypotheses.clone(),
            imprint_hypotheses: r.imprint_hypotheses.clone(),
            registered_sample: r.registered_sample,
            checked: r.checked,
            checked_from_imprint: r.checked_from_imprint,
            signature_rival: r.signature_rival,
            with_contact: r.sample_index.clone(),
            report: r.report.clone(),
            posterior: r.posterior.clone(),
            truth_region: r.truth_region,
            anchor_shift_m: r.anchor_shift_m.clone(),
        };
        let input = tactile_derender::pipeline::PoseInput {
            t_world_camera: c.t_world_camera,
            observation: tactile_derender::pipeline::Observation {
                samples: &req.samples,
                imprint: &req.imprint,
                signature: Some(&c.signature),
                truth: c.truth,
                prior: None,
                camera_path: None,
            },
        };
        let files = tactile_derender::pipeline::write_pose_geometry(
            &dir,
            &object,
            &sim,
            &input,
            &estimate,
            &req.config,
            req.seed,
            tactile_derender::io::ply::PlyEncoding::Binary,
        )?;
        tactile_derender::pipeline::write_fit_figure(
            &dir,
            &object,
            &sim,
            &input,
            &estimate,
            &Default::default(),
        )?;
        let count = files.len();
        // pose.json, the record `tnd pose` writes for the same estimate.
        let placed = tactile_derender::pipeline::PlacedEstimate {
            press_m: r.press_found_m,
            t_world_camera: c.t_world_camera,
            estimate,
        };
        let generator = match &self.state.model.path {
            Some(p) => format!("model {} (the workbench's De-render run)", p.display()),
            None => "the bundled model (the workbench's De-render run)".into(),
        };
        let record = tactile_derender::pipeline::pose_record::PoseRecord::new(
            &placed,
            c.truth,
            &r.symmetry,
            tactile_derender::pipeline::pose_record::RecordSource {
                generator,
                seed: req.seed,
                calibration: None,
                out: dir.clone(),
                rerun: None,
                geometry: files,
            },
        );
        record.write(&dir.join("pose.json"))?;
        self.notice = Some(format!(
            "wrote pose.json, samples.csv, kde.csv, the uncertainty and fit figures (SVG, PNG) and {count} PLY files \
             to {}",
            dir.display()
        ));
        Ok(())
    }

    /// Cancel the running run, if any.
    pub(crate) fn cancel_derender(&mut self) {
        raise_cancel(&mut self.analysis.derender.cancel);
    }

    /// Replace the dataset inspector's settings; a new selection (or split) loads its pair.
    pub(crate) fn set_dataset(&mut self, d: crate::state::DatasetSettings) {
        let split_changed = d.split != self.state.dataset.split;
        let selected = d.selected;
        self.state.dataset = d;
        match selected {
            Some(i) if split_changed || self.analysis.dataset.is_some() => self.select_pair(i),
            _ => {}
        }
    }

    /// Replace the de-rendering settings; a new input forgets the pending one.
    pub(crate) fn set_derender(&mut self, d: crate::state::DerenderSettings) {
        if d.input != self.state.derender.input {
            self.analysis.derender.pending_input = None;
        }
        self.state.derender = d;
    }

    /// Choose the model checkpoint.
    pub(crate) fn set_model(&mut self, m: crate::state::ModelSettings) {
        self.state.model = m;
        if let Some(p) = &self.state.model.path {
            self.inputs.model_path = p.display().to_string();
        }
    }

    /// Forget the running pose analysis: the thread stops at its next registration, and its answer (an error
    /// "cancelled") is then stale.
    pub(crate) fn cancel_pose(&mut self) {
        let view = &mut self.analysis.pose;
        raise_cancel(&mut view.cancel);
        view.generation += 1;
        view.running = false;
        view.progress = None;
    }
}
