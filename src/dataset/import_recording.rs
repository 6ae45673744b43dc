//! **Recordings as scored pairs**: as in the paper's real dataset, where the object's pose relative to the sensor is
//! known for a frame (a pose topic in the recording, or a CSV table), the frame's true in-contact depth X0 is
//! simulated with the calibrated sensor model, so a real press sequence becomes pairs for fine-tuning and
//! evaluation (`tnd dataset import --from REC.mcap`).
//!
//! First, unless told not to, the sensor is calibrated from the recording's no-contact frames
//! ([`crate::recording::calibrate`]: membrane inflation and footprint, camera position, noise), and the calibrated
//! sensor makes X0 and the press estimate and is stored with the dataset, so that evaluation (guidance, anchoring,
//! the signature check, free space) uses the sensor that made the recording, not its nominal model. The contact
//! frames with a pose then calibrate the tactile-shadow width ([`super::shadow_fit`]).
//!
//! Per frame: the imprint Y = R − S from [`crate::recording::process`]; frames with less contact than
//! `min_contact_px` (the no-contact part of a press) are skipped — unless no frame has that much, when a **light press**
//! is taken in at a threshold set by the no-contact frames' own noise ([`ProcessedRecording::light_press`]) and the
//! report says so; the pose is the pose message nearest in time (within
//! `max_pose_gap_s`) or the CSV row of the frame. The press depth comes from the CSV's `press` column, or, when no
//! source gives it, is **estimated** by matching the simulated noise-free imprint to the measured one (a grid over
//! `[-1 mm, max_press]` in 0.5 mm steps, then golden-section refinement; mean absolute imprint difference).
//!
//! Pose CSV columns: `frame` (0-based index in the depth stream) or `stamp_ns`, then `x`, `y` (metres), `theta`
//! (radians) and optionally `press` (metres).

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::import::{
    parse_csv, refuse_unless_interrupted_import, write_real_dataset, ImportReport, RealSource,
};
use super::shadow_fit::{fit_shadow, ContactFrame};
use super::shard::Record;
use super::{DatasetError, SplitName};
use crate::image::Image;
use crate::objects::ObjectSet;
use crate::recording::calibrate::{calibrate, CalibrateConfig, SensorCalibration};
use crate::recording::process::LightPress;
use crate::recording::source::{nearest_stamp, DEFAULT_MAX_POSE_GAP_S};
use crate::recording::{self, FolderOptions, ProcessConfig, ProcessedRecording, Recording};
use crate::sensor::{Scene, Se2};
use crate::sim::{PreparedObject, SimConfig, SimError, Simulator};

/// The file beside an imported recording's dataset that gives each pair's frame of the recording and its time
/// stamp: `index,frame,stamp_ns` (the pair's global index, the 0-based frame of the depth stream, nanoseconds).
pub const FRAMES_CSV: &str = "frames.csv";

/// Default deepest press the press estimate considers, metres.
pub const DEFAULT_MAX_PRESS_M: f64 = 0.03;

/// Where the object's pose per frame comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseSource {
    /// A `PoseStamped`/`Pose2D` topic of the recording (`None`: its only pose topic).
    Topic(Option<String>),
    /// A CSV table (module docs).
    Csv(PathBuf),
}

/// Settings of a recording import.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordingImportConfig {
    /// Depth topic (`None`: the only one).
    pub topic: Option<String>,
    pub process: ProcessConfig,
    pub folder: FolderOptions,
    /// The pressed object: an entry of the object set.
    pub object: String,
    pub poses: PoseSource,
    /// Keep every n-th frame (default 1).
    pub every: usize,
    /// Frames with fewer contact pixels (imprint over the threshold) are skipped (default 10).
    pub min_contact_px: usize,
    /// Largest time between a frame and its pose message, seconds (default 0.05).
    pub max_pose_gap_s: f64,
    /// Deepest press the estimate considers, metres (default 0.03).
    pub max_press_m: f64,
    /// Split of every pair (`None`: the automatic rule, by the object's split).
    pub split: Option<SplitName>,
    /// Seed of the automatic 9:1 split.
    pub seed: u64,
    /// Calibrate the sensor from the recording's no-contact frames first ([`crate::recording::calibrate`]) and use
    /// the calibrated sensor for X0, the press estimate and the dataset (default true); when the frames do not allow
    /// it (no frame without contact), the given sensor is used and the report says why.
    #[serde(default = "yes")]
    pub calibrate: bool,
    /// Where no frame has `min_contact_px` over the contact threshold, take the frames that have it over a
    /// threshold set by the recording's no-contact noise instead (default true; [`ProcessedRecording::light_press`]).
    #[serde(default = "yes")]
    pub light_press: bool,
}

fn yes() -> bool {
    true
}

impl RecordingImportConfig {
    /// Defaults for pressing `object` with poses from `poses`.
    pub fn new(object: &str, poses: PoseSource) -> Self {
        Self {
            topic: None,
            process: ProcessConfig::default(),
            folder: FolderOptions::default(),
            object: object.to_string(),
            poses,
            every: 1,
            min_contact_px: 10,
            max_pose_gap_s: DEFAULT_MAX_POSE_GAP_S,
            max_press_m: DEFAULT_MAX_PRESS_M,
            split: None,
            seed: 0,
            calibrate: true,
            light_press: true,
        }
    }
}

/// What a recording import did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RecordingImportReport {
    pub frames: usize,
    #[serde(flatten)]
    pub written: ImportReport,
    pub reference_frames: Vec<usize>,
    /// The membrane's largest drift between no-contact stretches, metres ([`crate::recording::drift`]).
    pub drift_m: f64,
    /// Whether each pair's imprint is against its own reference from the no-contact stretches around it (the drift
    /// exceeded the tolerance).
    pub local_references: bool,
    pub skipped_no_contact: usize,
    pub skipped_no_pose: usize,
    /// Frames left out because too few of their pixels have a return, one line each naming the frame
    /// ([`crate::recording::ProcessedRecording::unusable`]).
    pub skipped_missing: Vec<String>,
    /// Pairs whose press depth was estimated from the imprint.
    pub press_estimated: usize,
    /// Mean absolute imprint difference at the estimated presses, metres.
    pub press_fit_residual_m: f64,
    /// The sensor calibration the pairs were made with (`None`: not asked for, or not possible).
    pub calibration: Option<SensorCalibration>,
    /// Why a calibration that was asked for could not be made (the given sensor was used).
    pub calibration_failed: Option<String>,
    /// Set where the frames were chosen as a light press's ([`RecordingImportConfig::light_press`]).
    pub light_press: Option<LightPress>,
}

/// One frame's known pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FramePose {
    /// The object's pose `t_world_object`.
    pub pose: Se2,
    /// The press depth, metres, where the pose table gives one.
    pub press: Option<f64>,
}

/// Import a recording (MCAP file or frame folder) at `from` into a new real dataset at `out`.
pub fn import_recording(
    from: &Path,
    out: &Path,
    sim_config: &SimConfig,
    set: &ObjectSet,
    config: &RecordingImportConfig,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<RecordingImportReport, DatasetError> {
    let object_index = object_index(set, &config.object)?;
    if config.every == 0 {
        return Err(DatasetError::Config("--every must be at least 1".into()));
    }
    refuse_unless_interrupted_import(out)?;
    let rec = Recording::open(from, &config.folder)?;
    let stream = rec.depth_stream(config.topic.as_deref())?.clone();
    let (mut calibration, calibration_failed) = if config.calibrate {
        calibrate_or_explain(&rec, &stream, sim_config, &config.process, progress)?
    } else {
        (None, None)
    };
    let given = sim_config;
    let processed = recording::process(&rec, &stream, &given.camera, &config.process, progress)?;
    let poses = frame_poses(
        &rec,
        &processed.stamps_ns,
        &config.poses,
        config.max_pose_gap_s,
    )?;

    let object = PreparedObject::new(set.mesh(&config.object)?)?;

    let mut chosen = ChosenFrames::of(&processed, &processed.contact_px, &poses, config);
    let mut light_press = None;
    if chosen.todo.is_empty() && config.light_press {
        if let Some((light, retry)) = light_press_frames(&processed, &poses, config) {
            light_press = Some(light);
            chosen = retry;
        }
    }
    // The tactile shadow, which frames without contact cannot show, from the contact frames with a pose.
    if let Some(cal) = &mut calibration {
        calibrate_shadow(cal, &processed, &object, &chosen.todo, config.max_press_m)?;
    }
    let sim_config = calibration.as_ref().map_or(given, |c| &c.sensor);
    let sim = noise_free_simulator(sim_config)?;
    let made = frame_records(
        &sim,
        &object,
        &processed,
        &chosen.todo,
        object_index,
        config.max_press_m,
    );
    let residuals: Vec<f64> = made.iter().filter_map(|(_, r)| *r).collect();
    let mut records: Vec<Record> = made.into_iter().map(|(r, _)| r).collect();
    if records.is_empty() {
        return Err(DatasetError::Import {
            path: from.to_path_buf(),
            message: format!(
                "no frame became a pair: {} frames without contact (< {} px over {} mm), \
                 {} without a pose, {} with too few pixels that have a return{}",
                chosen.skipped_no_contact,
                config.min_contact_px,
                config.process.contact_threshold_m * 1e3,
                chosen.skipped_no_pose,
                chosen.skipped_missing.len(),
                largest_contact_hint(&processed, config)
            ),
        });
    }
    let frames_csv = frames_table(&mut records, &processed.stamps_ns);
    let n = records.len();
    let written = write_real_dataset(
        out,
        RealSource {
            from: &from.display().to_string(),
            table: &stream.name,
            sizes: vec![processed.source_size],
        },
        sim_config,
        set,
        config.seed,
        records,
        vec![config.split; n],
    )?;
    let csv_path = out.join(FRAMES_CSV);
    crate::io::write_atomic(&csv_path, frames_csv.as_bytes()).map_err(|e| {
        DatasetError::Import {
            path: csv_path.clone(),
            message: format!("cannot write the frame table: {}", e.kind()),
        }
    })?;
    Ok(RecordingImportReport {
        frames: processed.len(),
        written,
        reference_frames: processed.reference_frames.clone(),
        drift_m: processed.drift_m(),
        local_references: processed.reference_of.is_some(),
        skipped_no_contact: chosen.skipped_no_contact,
        skipped_no_pose: chosen.skipped_no_pose,
        skipped_missing: chosen.skipped_missing,
        press_estimated: residuals.len(),
        press_fit_residual_m: if residuals.is_empty() {
            0.0
        } else {
            residuals.iter().sum::<f64>() / residuals.len() as f64
        },
        calibration,
        calibration_failed,
        light_press,
    })
}

/// The frames of a light press ([`ProcessedRecording::light_press`]) where some frame has `config.min_contact_px`
/// over its threshold; `None` otherwise.
fn light_press_frames(
    processed: &ProcessedRecording,
    poses: &[Option<FramePose>],
    config: &RecordingImportConfig,
) -> Option<(LightPress, ChosenFrames)> {
    let (light, counts) = processed.light_press(config.process.contact_threshold_m)?;
    let chosen = ChosenFrames::of(processed, &counts, poses, config);
    (!chosen.todo.is_empty()).then_some((light, chosen))
}

/// The index of `object` in `set`; an error naming the set otherwise (and, where `object` looks like a mesh file,
/// how to make it an object of a set: a pair names its object in the dataset's set).
fn object_index(set: &ObjectSet, object: &str) -> Result<usize, DatasetError> {
    set.entries()
        .iter()
        .position(|e| e.name == object)
        .ok_or_else(|| {
            // A pair names its object in the dataset's set, so a mesh file has to join a set first.
            let path = Path::new(object);
            let hint = if path.extension().is_some() || path.exists() {
                let dir = path
                    .parent()
                    .filter(|d| !d.as_os_str().is_empty())
                    .unwrap_or(Path::new("."));
                let name = path
                    .file_stem()
                    .map_or_else(|| object.to_string(), |s| s.to_string_lossy().into_owned());
                format!(
                    "; a mesh file becomes an object of a set with `tnd objects import {}` (its folder), then \
                     --objects {} --object {name}",
                    dir.display(),
                    dir.display()
                )
            } else {
                String::new()
            };
            DatasetError::Config(format!(
                "object '{}' is not in the object set {}{hint}",
                object,
                set.spec()
            ))
        })
}

/// The frames of a recording that become pairs, and how many of the others were left out, and why.
struct ChosenFrames {
    /// Each chosen frame's index and its known pose.
    todo: Vec<(usize, FramePose)>,
    /// Frames with less contact than `min_contact_px`.
    skipped_no_contact: usize,
    /// Contact frames without a known pose.
    skipped_no_pose: usize,
    /// Frames with too few pixels that have a return, one line each naming the frame.
    skipped_missing: Vec<String>,
}

impl ChosenFrames {
    /// Every `config.every`-th frame of `processed` with enough pixels that have a return, at least
    /// `config.min_contact_px` of contact (`contact_px`, per frame) and a pose in `poses`.
    fn of(
        processed: &ProcessedRecording,
        contact_px: &[usize],
        poses: &[Option<FramePose>],
        config: &RecordingImportConfig,
    ) -> Self {
        let mut chosen = Self {
            todo: Vec::new(),
            skipped_no_contact: 0,
            skipped_no_pose: 0,
            skipped_missing: Vec::new(),
        };
        for i in (0..processed.len()).step_by(config.every) {
            if let Some(why) = processed.unusable(i) {
                chosen.skipped_missing.push(why);
            } else if contact_px
                .get(i)
                .is_none_or(|&px| px < config.min_contact_px)
            {
                chosen.skipped_no_contact += 1;
            } else if let Some(p) = poses[i] {
                chosen.todo.push((i, p));
            } else {
                chosen.skipped_no_pose += 1;
            }
        }
        chosen
    }
}

/// Where frames were skipped for too small a contact: the recording's largest contact (frame and pixels over the
/// threshold) and the options that would take it in, so that a light press is not a dead end.
fn largest_contact_hint(processed: &ProcessedRecording, config: &RecordingImportConfig) -> String {
    let largest = processed
        .contact_px
        .iter()
        .enumerate()
        .max_by_key(|&(_, &px)| px);
    let Some((k, &px)) = largest.filter(|&(_, &px)| px > 0) else {
        return String::new();
    };
    let why = if px < config.min_contact_px {
        "a light press: lower --contact-threshold or --min-contact-px to take it in".to_string()
    } else if k % config.every != 0 {
        format!("left out by --every {}", config.every)
    } else if let Some(why) = processed.unusable(k) {
        why
    } else {
        "no pose recorded near its time (--poses, --pose-topic)".to_string()
    };
    format!("; the largest contact is frame {k}'s {px} px ({why})")
}

/// Set the tactile-shadow width of the calibration `cal` from the contact frames `todo` of `processed` with their
/// poses ([`fit_shadow`]; left as it is where the fit finds none).
fn calibrate_shadow(
    cal: &mut SensorCalibration,
    processed: &ProcessedRecording,
    object: &PreparedObject,
    todo: &[(usize, FramePose)],
    max_press_m: f64,
) -> Result<(), SimError> {
    let sim = noise_free_simulator(&cal.sensor)?;
    let frames: Vec<ContactFrame> = todo
        .iter()
        .map(|&(i, fp)| ContactFrame {
            imprint: &processed.imprints[i],
            pose: fp.pose,
            press: fp.press,
        })
        .collect();
    if let Some(fit) = fit_shadow(&sim, object, &frames, max_press_m) {
        cal.set_shadow(fit.shadow_px);
    }
    Ok(())
}

/// One pair per frame of `todo` (in parallel): the frame's imprint, signature and reference from `processed`, its
/// pose, and the true contact the noise-free `sim` gives there ([`frame_truth`]), with the press fit's residual where
/// the press was estimated. Each record keeps its frame's index.
fn frame_records(
    sim: &Simulator,
    object: &PreparedObject,
    processed: &ProcessedRecording,
    todo: &[(usize, FramePose)],
    object_index: usize,
    max_press_m: f64,
) -> Vec<(Record, Option<f64>)> {
    todo.par_iter()
        .map(|&(i, fp)| {
            let y = &processed.imprints[i];
            let t = frame_truth(sim, object, fp.pose, y, fp.press, max_press_m);
            let record = Record {
                index: i,
                seed: 0,
                object: object_index,
                split: SplitName::Train,
                pose: fp.pose,
                sensor: t.scene.sensor,
                press: t.press,
                contact_pixels: t.mask.count_nonzero(),
                imprint: y.clone(),
                target: t.target,
                signature: processed.signatures[i].clone(),
                reference: processed.reference_for(i).into_owned(),
                mask: t.mask,
            };
            (record, t.press_fit_residual_m)
        })
        .collect()
}

/// [`FRAMES_CSV`]: each pair's frame and time stamp (`stamps_ns` of the recording's frames); the records are
/// renumbered from 0 as they go.
fn frames_table(records: &mut [Record], stamps_ns: &[u64]) -> String {
    let mut frames_csv = String::from("index,frame,stamp_ns\n");
    for (k, r) in records.iter_mut().enumerate() {
        frames_csv += &format!("{k},{},{}\n", r.index, stamps_ns[r.index]);
        r.index = k;
    }
    frames_csv
}

/// The sensor calibrated from the recording's no-contact frames, or why it could not be (then the given sensor is
/// used); a cancel is passed on.
#[allow(clippy::type_complexity)]
pub fn calibrate_or_explain(
    rec: &Recording,
    stream: &recording::StreamInfo,
    given: &SimConfig,
    process: &ProcessConfig,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<(Option<SensorCalibration>, Option<String>), recording::RecordingError> {
    let config = CalibrateConfig::reading(process);
    match calibrate(rec, stream, given, &config, progress) {
        Ok((cal, _)) => Ok((Some(cal), None)),
        Err(recording::RecordingError::Cancelled) => Err(recording::RecordingError::Cancelled),
        Err(e) => Ok((None, Some(e.to_string()))),
    }
}

/// The known pose of every frame of `rec` stamped `stamps_ns` (`None` where none is known): the pose message or
/// CSV row nearest in time within `max_gap_s`, or the CSV row naming the frame.
pub fn frame_poses(
    rec: &Recording,
    stamps_ns: &[u64],
    poses: &PoseSource,
    max_gap_s: f64,
) -> Result<Vec<Option<FramePose>>, DatasetError> {
    match poses {
        PoseSource::Topic(name) => {
            let stream = rec.pose_stream(name.as_deref())?.clone();
            Ok(rec
                .poses_at(&stream, stamps_ns, max_gap_s)?
                .into_iter()
                .map(|p| p.map(|pose| FramePose { pose, press: None }))
                .collect())
        }
        PoseSource::Csv(path) => csv_poses(path, stamps_ns, max_gap_s),
    }
}

/// Deepest press a pose table's `press` column may give, metres (10 cm: deeper is millimetres).
const MAX_PRESS_COLUMN_M: f64 = 0.1;

fn csv_poses(
    path: &Path,
    stamps_ns: &[u64],
    max_gap_s: f64,
) -> Result<Vec<Option<FramePose>>, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
    let bad = |message: String| DatasetError::Import {
        path: path.to_path_buf(),
        message,
    };
    let rows = parse_csv(&text).map_err(|e| bad(e.into()))?;
    let mut out = vec![None; stamps_ns.len()];
    // Frames by time, for rows that name a stamp.
    let mut order: Vec<usize> = (0..stamps_ns.len()).collect();
    order.sort_by_key(|&k| stamps_ns[k]);
    let sorted: Vec<u64> = order.iter().map(|&k| stamps_ns[k]).collect();
    for (i, row) in rows.iter().enumerate() {
        let at = |m: String| bad(format!("row {}: {m}", i + 1));
        let num = |key: &str| -> Result<Option<f64>, DatasetError> {
            match row.get(key).filter(|s| !s.is_empty()) {
                None => Ok(None),
                Some(s) => s
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .map(Some)
                    .ok_or_else(|| at(format!("{key} '{s}' is not a finite number"))),
            }
        };
        let need = |key: &str| num(key)?.ok_or_else(|| at(format!("missing '{key}'")));
        let frame = match (row.get("frame"), row.get("stamp_ns")) {
            (Some(f), _) => f
                .parse::<usize>()
                .map_err(|_| at(format!("frame '{f}' is not a frame number")))?,
            (None, Some(s)) => {
                let t: u64 = s
                    .parse()
                    .map_err(|_| at(format!("stamp_ns '{s}' is not an integer")))?;
                match nearest_stamp(&sorted, t, (max_gap_s * 1e9) as u64) {
                    Some(k) => order[k],
                    None => continue,
                }
            }
            (None, None) => return Err(at("give a 'frame' or a 'stamp_ns' column".into())),
        };
        if frame >= out.len() {
            return Err(at(format!(
                "frame {frame} is beyond the recording's {} frames",
                out.len()
            )));
        }
        let pose = Se2::new(need("x")?, need("y")?, need("theta")?);
        let press = num("press")?;
        // Millimetres and degrees (the usual slips) give values no sensor could see.
        let mut slips = pose.unit_slips();
        if let Some(p) = press.filter(|&p| p > MAX_PRESS_COLUMN_M) {
            slips.push(format!("press {p} is deeper than any sensor"));
        }
        if !slips.is_empty() {
            return Err(at(format!(
                "{}: the columns are metres and radians (millimetres or degrees?)",
                slips.join("; ")
            )));
        }
        out[frame] = Some(FramePose { pose, press });
    }
    Ok(out)
}

/// The sensor of `sim_config` without measurement noise: X0 and the press estimate do not depend on it.
pub fn noise_free_simulator(sim_config: &SimConfig) -> Result<Simulator, SimError> {
    let mut quiet = sim_config.clone();
    quiet.signature.noise_std = 0.0;
    Simulator::new(quiet)
}

/// What the simulator says about a real frame whose object pose is known.
#[derive(Clone, Debug)]
pub struct FrameTruth {
    /// Press depth, metres: the given one, or estimated from the imprint.
    pub press: f64,
    /// Mean absolute imprint difference at an estimated press, metres (`None` when the press was given).
    pub press_fit_residual_m: Option<f64>,
    /// Object and sensor poses.
    pub scene: Scene,
    /// Contact mask M and in-contact depth X0.
    pub mask: Image,
    pub target: Image,
}

/// The true contact of a frame with the object at `pose` (relative to the sensor axis): at `press`, or at the press
/// [`estimate_press`] finds for the measured `imprint`. `sim` should be noise-free ([`noise_free_simulator`]).
pub fn frame_truth(
    sim: &Simulator,
    object: &PreparedObject,
    pose: Se2,
    imprint: &Image,
    press: Option<f64>,
    max_press: f64,
) -> FrameTruth {
    let (press, press_fit_residual_m) = match press {
        Some(p) => (p, None),
        None => {
            let (p, r) = estimate_press(sim, object, pose, imprint, max_press);
            (p, Some(r))
        }
    };
    let scene = Scene {
        object: pose,
        sensor: sim.pressing_pose(object, 0.0, 0.0, 0.0, press),
    };
    let (mask, target) = sim.contact(&sim.render_depth(object, &scene));
    FrameTruth {
        press,
        press_fit_residual_m,
        scene,
        mask,
        target,
    }
}

/// The press depth whose simulated noise-free imprint best matches `measured` (mean absolute difference over the
/// pixels where both are defined), and that difference, metres.
pub fn estimate_press(
    sim: &Simulator,
    object: &PreparedObject,
    pose: Se2,
    measured: &Image,
    max_press: f64,
) -> (f64, f64) {
    let cost = |press: f64| -> f64 {
        let scene = Scene {
            object: pose,
            sensor: sim.pressing_pose(object, 0.0, 0.0, 0.0, press),
        };
        let y = sim.simulate(object, &scene, 0).imprint;
        let (mut s, mut n) = (0.0f64, 0usize);
        for (&a, &b) in y.data.iter().zip(&measured.data) {
            if a.is_finite() && b.is_finite() {
                s += f64::from((a - b).abs());
                n += 1;
            }
        }
        if n == 0 {
            f64::INFINITY
        } else {
            s / n as f64
        }
    };
    let step = 0.0005;
    let steps = ((max_press + 0.001) / step).ceil().max(1.0) as usize;
    let (mut best, mut best_cost) = (0.0, f64::INFINITY);
    for k in 0..=steps {
        let p = -0.001 + k as f64 * step;
        let c = cost(p);
        if c < best_cost {
            (best, best_cost) = (p, c);
        }
    }
    // Golden-section search in the bracket around the best grid point.
    let (mut a, mut b) = (best - step, best + step);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (cost(c), cost(d));
    for _ in 0..16 {
        if fc < fd {
            (b, d, fd) = (d, c, fc);
            c = b - g * (b - a);
            fc = cost(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + g * (b - a);
            fd = cost(d);
        }
    }
    let (p, f) = if fc < fd { (c, fc) } else { (d, fd) };
    if f < best_cost {
        (p, f)
    } else {
        (best, best_cost)
    }
}
