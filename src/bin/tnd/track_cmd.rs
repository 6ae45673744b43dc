//! `tnd recording track`: the object's pose on every contact frame of a recording
//! ([`tactile_derender::pipeline::track`]), one row per frame in `track.csv`, written as each frame is done so that
//! a killed run resumes where it stopped; `track.json` keeps the settings (a resumed run must match them) and, at the
//! end, the summary.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use serde_json::{json, Value};
use tactile_derender::dataset::import_recording::{calibrate_or_explain, frame_poses, PoseSource};
use tactile_derender::io::write_atomic;
use tactile_derender::model::DiffusionModel;
use tactile_derender::pipeline::track::{
    Carry, FrameTrack, PressChoice, TrackContext, Tracker, TrackingConfig,
};
use tactile_derender::pipeline::track_posteriors::TrackPosteriors;
use tactile_derender::pipeline::{DerenderConfig, ObjectSpec};
use tactile_derender::pose::PoseConfig;
use tactile_derender::recording::source::DEFAULT_MAX_POSE_GAP_S;
use tactile_derender::recording::{self, ProcessedRecording, Recording, StreamKind};
use tactile_derender::sim::{PreparedObject, Simulator};

use crate::args::SensorArgs;
use crate::progress;
use tactile_derender::recording::ReadConfig;

/// What a track reads and how it estimates: `tnd recording track` and `tnd bench track` take the same.
#[derive(Args, Debug)]
pub struct TrackInputArgs {
    /// The recording: an .mcap file or a folder of depth frames (16-bit PNG in mm, .npy/.npz).
    pub recording: PathBuf,
    #[command(flatten)]
    pub object: ObjectSpec,
    #[command(flatten)]
    pub read: ReadConfig,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// The generator: a model checkpoint or a bundled model (`auto`: `recording` for frames resampled from the
    /// camera's native or cropped size, `default` for frames at the model resolution; `small`: twice as fast).
    #[arg(long, default_value = "auto")]
    pub model: String,
    #[command(flatten)]
    pub derender: DerenderConfig,
    /// How far the sensor is pressed into the object, to place it over the object: "auto" (per frame: from the
    /// samples' highest contact point on the object's top, 1 mm shallower to 6 mm deeper, the press whose registered
    /// pose best explains the signature) or metres for every frame (faster).
    #[arg(long, default_value = "auto", allow_hyphen_values = true)]
    pub press: PressChoice,
    /// Recorded poses to score the estimates against: a CSV (columns frame or stamp_ns, x, y, theta, optional
    /// press); default: the recording's pose topic when it has exactly one. Adding them to a finished track rescores
    /// it without tracking again.
    #[arg(long, conflicts_with = "pose_topic")]
    pub poses: Option<PathBuf>,
    /// The recording's object-pose topic to score against.
    #[arg(long)]
    pub pose_topic: Option<String>,
    #[command(flatten)]
    pub tracking: TrackingConfig,
    /// Use the given sensor as it is, instead of calibrating it from the recording's no-contact frames (membrane
    /// inflation and footprint, camera position, noise; see tnd calibrate).
    #[arg(long)]
    pub no_calibrate: bool,
    #[command(flatten)]
    pub pose: PoseConfig,
}

#[derive(Args, Debug)]
pub struct TrackArgs {
    #[command(flatten)]
    pub input: TrackInputArgs,
    /// Track every n-th frame.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// Output directory: track.csv (one row per frame) and track.json; a run killed part-way resumes into it.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
}

/// `path` made absolute (the same file however it is named); as given when it does not exist.
fn canonical(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

/// The settings a track's rows depend on; a resumed run must have the same. (The recorded poses are not among
/// them: every run scores all rows against the poses it is given.)
fn settings(a: &TrackArgs, sim: &tactile_derender::sim::SimConfig) -> Value {
    let mut object = a.input.object.clone();
    if Path::new(&object.object).exists() {
        object.object = canonical(Path::new(&object.object)).display().to_string();
    }
    let model = if Path::new(&a.input.model).exists() {
        canonical(Path::new(&a.input.model)).display().to_string()
    } else {
        a.input.model.clone()
    };
    let mut settings = json!({
        "recording": canonical(&a.input.recording), "topic": a.input.read.topic, "reference": a.input.read.reference,
        "contact_threshold_m": a.input.read.contact_threshold_m, "npy_scale": a.input.read.npy_scale,
        "png_scale": a.input.read.png_scale, "fps": a.input.read.fps,
        "object": object, "model": model, "derender": a.input.derender, "press": a.input.press.to_string(),
        "every": a.every, "min_contact_px": a.input.tracking.min_contact_px, "tracking": a.input.tracking, "sim": sim, "calibrate": !a.input.no_calibrate,
    });
    // Only when not the defaults: a track made before the pose options resumes under the same settings.
    if a.input.pose != PoseConfig::default() {
        settings["pose"] = json!(a.input.pose);
    }
    settings
}

/// What the recording's frames were when the track began: frame count, time stamps and contact areas (a recording
/// replaced under the same name is not resumed into).
fn fingerprint(p: &ProcessedRecording) -> Value {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    std::hash::Hash::hash(&p.stamps_ns, &mut h);
    std::hash::Hash::hash(&p.contact_px, &mut h);
    std::hash::Hash::hash(&p.reference_frames, &mut h);
    json!({"frames": p.len(), "hash": format!("{:016x}", std::hash::Hasher::finish(&h))})
}

/// The MCAP file of the tracked poses in the output folder, and its topic.
const POSE_TRACK: &str = "track.mcap";
const POSE_TOPIC: &str = "/tnd/object_pose";

/// Write every row with an estimate and a posterior as a `geometry_msgs/PoseWithCovarianceStamped` (frame
/// [`POSE_FRAME_ID`], the sensor's, as the recording's own pose topic and pose.json) into `out/track.mcap`; returns how
/// many.
fn write_pose_track(out: &Path, rows: &[FrameTrack]) -> Result<usize> {
    use tactile_derender::pose::export::{PoseWithCovarianceStamped, POSE_FRAME_ID};
    let poses: Vec<(u64, [f64; 3], [f64; 36])> = rows
        .iter()
        .filter_map(|r| {
            let (e, cov) = (r.estimate?, r.covariance?);
            let msg = PoseWithCovarianceStamped::new(e, &cov, POSE_FRAME_ID, r.stamp_ns);
            let covariance: [f64; 36] = msg.pose.covariance.try_into().ok()?;
            Some((r.stamp_ns, [e.x, e.y, e.theta], covariance))
        })
        .collect();
    tactile_derender::recording::synth::write_pose_track(
        &out.join(POSE_TRACK),
        POSE_TOPIC,
        POSE_FRAME_ID,
        &poses,
    )?;
    Ok(poses.len())
}

/// An earlier run into `out`: its settings file (`None`: none yet). A folder holding anything else is refused.
fn earlier_run(out: &Path) -> Result<Option<Value>> {
    let json_path = out.join("track.json");
    // Whose the folder's other files are was settled when it was claimed (crate::outputs).
    if !json_path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&json_path)
        .with_context(|| format!("{}: cannot read", json_path.display()))?;
    let earlier: Value = serde_json::from_str(&text)
        .map_err(|e| anyhow!("{}: not a track's settings: {e}", json_path.display()))?;
    Ok(Some(earlier))
}

/// Refuse `earlier` unless it was made with `settings`, naming the settings that differ and their values.
fn check_same(out: &Path, earlier: &Value, key: &str, now: &Value, what: &str) -> Result<()> {
    let then = earlier.get(key).unwrap_or(&Value::Null);
    if then == now {
        return Ok(());
    }
    let mut differing = tactile_derender::io::settings::setting_differences(now, then);
    // What the earlier run set and this one does not (a build that wrote other settings).
    if let (Some(t), Some(n)) = (then.as_object(), now.as_object()) {
        differing.extend(
            t.iter()
                .filter(|(k, _)| !n.contains_key(*k))
                .map(|(k, v)| format!("{k}: {v} -> not set")),
        );
    }
    bail!(
        "{}: holds a track of {what} ({}); choose a new --out, or the same settings to resume",
        out.display(),
        differing.join("; ")
    );
}

/// The rows of an earlier run's track.csv (none when there is none).
pub(crate) fn earlier_rows(out: &Path) -> Result<Vec<FrameTrack>> {
    let path = out.join("track.csv");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(Vec::new());
    };
    text.lines()
        .enumerate()
        .skip(1)
        .filter(|(_, l)| !l.is_empty())
        .map(|(i, l)| {
            FrameTrack::from_csv_row(l)
                .map_err(|e| anyhow!("{}: line {}: {e}", path.display(), i + 1))
        })
        .collect()
}

/// The file of what each tracked frame handed to the next ([`Carry`], by frame), so that a resumed run goes on as
/// an unbroken one would.
const CARRY_FILE: &str = "carry.json";

type Carries = std::collections::BTreeMap<usize, Option<Carry>>;

fn read_carries(out: &Path) -> Result<Carries> {
    let path = out.join(CARRY_FILE);
    match std::fs::read_to_string(&path) {
        Ok(text) => serde_json::from_str::<Carries>(&text)
            .map_err(|e| anyhow!("{}: not a track's carry file: {e}", path.display())),
        Err(_) => Ok(Carries::new()),
    }
}

fn write_carries(out: &Path, carries: &Carries) -> Result<()> {
    let path = out.join(CARRY_FILE);
    write_atomic(&path, serde_json::to_string(carries)?.as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))
}

fn write_rows(out: &Path, rows: &[FrameTrack]) -> Result<()> {
    let path = out.join("track.csv");
    write_atomic(&path, FrameTrack::csv(rows).as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))
}

fn write_json(out: &Path, value: &Value) -> Result<()> {
    let path = out.join("track.json");
    write_atomic(&path, serde_json::to_string_pretty(value)?.as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))
}

/// Mean and median of `v` (null when empty).
fn mean_median(mut v: Vec<f64>) -> Value {
    if v.is_empty() {
        return Value::Null;
    }
    v.sort_by(f64::total_cmp);
    json!({"mean": v.iter().sum::<f64>() / v.len() as f64, "median": v[v.len() / 2], "frames": v.len()})
}

/// A recording opened for tracking: the sensor calibrated from it (unless told not to), the frames processed, the
/// recorded poses found, the object and the model loaded.
pub(crate) struct Opened {
    pub stream: String,
    pub calibration: Option<tactile_derender::recording::calibrate::SensorCalibration>,
    pub sim: Simulator,
    pub poses: Option<PoseSource>,
    pub recorded: Vec<Option<tactile_derender::dataset::import_recording::FramePose>>,
    pub object: tactile_derender::pipeline::LoadedObject,
    pub prepared: PreparedObject,
    pub model: DiffusionModel,
    /// `--model` as resolved for the recording's frames (`auto` is a bundled model's name).
    pub model_name: String,
    pub processed: ProcessedRecording,
}

impl Opened {
    /// The context the tracker runs in.
    pub fn context<'a>(&'a self, a: &'a TrackInputArgs) -> TrackContext<'a> {
        TrackContext {
            model: &self.model,
            object: &self.object,
            prepared: &self.prepared,
            sim: &self.sim,
            derender: &a.derender,
            pose: &a.pose,
            press: a.press,
            tracking: &a.tracking,
        }
    }
}

/// Open `a`'s recording for tracking with the sensor `sim_config` (module docs of [`Opened`]).
pub(crate) fn open(
    a: &TrackInputArgs,
    sim_config: tactile_derender::sim::SimConfig,
) -> Result<Opened> {
    let rec = Recording::open(&a.recording, &a.read.folder())?;
    let stream = rec.depth_stream(a.read.topic.as_deref())?.clone();
    // The sensor that made the recording, from its no-contact frames, unless told to keep the given one.
    let calibration = if a.no_calibrate {
        None
    } else {
        let mut bar = progress::bar("calibrating", " frames", 0);
        let c = calibrate_or_explain(
            &rec,
            &stream,
            &sim_config,
            &a.read.process(),
            &mut progress::callback(&mut bar),
        );
        progress::finish(&mut bar);
        let (cal, failed) = c?;
        crate::calibrate_cmd::tell_calibration(&a.recording, cal.as_ref(), failed.as_deref());
        cal
    };
    let sim_config = calibration
        .as_ref()
        .map_or(sim_config, |c| c.sensor.clone());
    let sim = Simulator::new(sim_config.clone())?;
    let poses = match (&a.poses, &a.pose_topic) {
        (Some(csv), _) => Some(PoseSource::Csv(csv.clone())),
        (None, Some(t)) => Some(PoseSource::Topic(Some(t.clone()))),
        (None, None) => {
            let topics: Vec<_> = rec
                .streams()
                .iter()
                .filter(|s| s.kind == StreamKind::Pose)
                .collect();
            (topics.len() == 1).then(|| PoseSource::Topic(Some(topics[0].name.clone())))
        }
    };
    let object = a.object.load()?;
    // A mis-scaled object registers to nothing sensible; say so before hours of tracking.
    object.check_scale("a track")?;
    let prepared = PreparedObject::new(object.mesh.clone())?;
    let mut bar = progress::bar("reading", " frames", stream.messages);
    let processed = recording::process(
        &rec,
        &stream,
        &sim_config.camera,
        &a.read.process(),
        &mut progress::callback(&mut bar),
    );
    progress::finish(&mut bar);
    let processed = processed?;
    crate::calibrate_cmd::tell_drift(&a.recording, processed.drift_m(), &processed.stretches);
    let model_name = crate::args::resolve_model(
        &a.model,
        processed.frames_resampled(&sim_config.camera),
        &a.recording.display().to_string(),
    );
    let device = tactile_derender::model::device::open_device(&a.derender.device)?;
    let model = DiffusionModel::load_on(Path::new(&model_name), &device)?;
    a.derender
        .validate(Some(model.config().tactile_derender.num_train_timesteps))?;
    let recorded = match &poses {
        Some(p) => frame_poses(&rec, &processed.stamps_ns, p, DEFAULT_MAX_POSE_GAP_S)?,
        None => vec![None; processed.len()],
    };
    Ok(Opened {
        stream: stream.name.clone(),
        calibration,
        sim,
        poses,
        recorded,
        object,
        prepared,
        model,
        model_name,
        processed,
    })
}

pub fn run(a: TrackArgs) -> Result<()> {
    if a.every == 0 {
        bail!("--every must be at least 1");
    }
    let mut inputs = a.input.sensor.inputs();
    inputs.extend([
        a.input.recording.as_path(),
        Path::new(&a.input.object.object),
    ]);
    let _out = crate::outputs::folder("--out", &a.out, a.force.force, &inputs)?;
    let sim_config = a.input.sensor.sim_config()?;
    let mut settings = settings(&a, &sim_config);
    // Refuse another run's folder before any long work; nothing is written until the track can start. `--model
    // auto` is resolved by the recording's frames, so it is compared once they are read.
    let earlier = earlier_run(&a.out)?;
    let same_settings = |settings: &Value| -> Result<()> {
        let Some(e) = &earlier else {
            return Ok(());
        };
        // Pose settings are stored only when not the defaults; compared as the defaults where absent, so that a
        // difference is named setting by setting (`pose.posterior.fusion_weight: 1.0 -> 0.15`).
        let with_pose = |v: &Value| {
            let mut v = v.clone();
            if let Some(map) = v.as_object_mut() {
                map.entry("pose")
                    .or_insert_with(|| json!(PoseConfig::default()));
            }
            v
        };
        let mut e = e.clone();
        if let Some(then) = e.get_mut("settings") {
            *then = with_pose(then);
        }
        check_same(
            &a.out,
            &e,
            "settings",
            &with_pose(settings),
            "other settings",
        )
    };
    let mut early = settings.clone();
    if let Some(then) = earlier.as_ref().and_then(|e| e["settings"].get("model")) {
        if a.input.model == tactile_derender::model::checkpoint::AUTO_MODEL_NAME {
            early["model"] = then.clone();
        }
    }
    same_settings(&early)?;
    let opened = open(&a.input, sim_config)?;
    if a.input.model == tactile_derender::model::checkpoint::AUTO_MODEL_NAME {
        settings["model"] = json!(opened.model_name);
    }
    same_settings(&settings)?;
    let (processed, recorded, object) = (&opened.processed, &opened.recorded, &opened.object);
    let frames = fingerprint(processed);
    if let Some(e) = &earlier {
        check_same(&a.out, e, "recording", &frames, "another recording")?;
    }
    let mut tracker = Tracker::new(opened.context(&a.input))?;
    let (todo, light) = a.input.tracking.frames(
        processed,
        a.every,
        a.input.read.contact_threshold_m,
        &mut |_, why| eprintln!("{}: {why}", a.input.recording.display()),
    );
    if let Some(light) = light {
        eprintln!(
            "{}: warning: {}; {} frame(s)",
            a.input.recording.display(),
            light.describe(a.input.tracking.min_contact_px),
            todo.len()
        );
    }
    if todo.is_empty() {
        let (peak, px) = (0..processed.len())
            .map(|k| (k, processed.contact_px[k]))
            .max_by_key(|p| p.1)
            .unwrap_or((0, 0));
        if px == 0 {
            bail!(
                "{}: no frame shows contact (imprint over {} mm) to track: the object may never touch the membrane \
                 (or check --reference and the sensor options)",
                a.input.recording.display(),
                a.input.read.contact_threshold_m * 1e3
            );
        }
        bail!(
            "{}: no frame has {} contact pixels (imprint over {} mm) to track; the most is {px} at frame {peak} \
             (lower --min-contact-px or --contact-threshold, or check --reference and the sensor options)",
            a.input.recording.display(),
            a.input.tracking.min_contact_px,
            a.input.read.contact_threshold_m * 1e3
        );
    }
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create", a.out.display()))?;
    let mut rows = earlier_rows(&a.out)?;
    let mut posteriors =
        TrackPosteriors::read(&a.out)?.unwrap_or_else(|| TrackPosteriors::new(object.symmetry));
    posteriors.restore(&mut rows);
    write_json(&a.out, &json!({"settings": settings, "recording": frames}))?;
    let done: BTreeSet<usize> = rows.iter().map(|r| r.frame).collect();
    if !done.is_empty() {
        eprintln!(
            "resuming the track in {}: {} of {} frames done",
            a.out.display(),
            done.len(),
            todo.len()
        );
    }
    let mut carries = read_carries(&a.out)?;
    let score = |row: &mut FrameTrack| {
        let r = recorded.get(row.frame).copied().flatten();
        row.score(r.map(|p| (p.pose, p.press)), &object.symmetry);
    };
    let mut bar = progress::bar("tracking", " frames", todo.len());
    let mut this_run = 0;
    for (i, &k) in todo.iter().enumerate() {
        if !done.contains(&k) {
            // Resumed after the frame before: go on with what it handed on, as an unbroken run would.
            let before = i.checked_sub(1).map(|j| todo[j]);
            if let Some(Some(c)) = before
                .filter(|b| done.contains(b))
                .and_then(|b| carries.get(&b))
            {
                tracker.resume(c.clone());
            }
            let mut row = tracker.track(processed, k, &mut |_, _| true)?;
            score(&mut row);
            posteriors.keep(&row);
            posteriors.write(&a.out)?;
            rows.push(row);
            rows.sort_by_key(|r| r.frame);
            carries.insert(k, tracker.carry().cloned());
            write_carries(&a.out, &carries)?;
            write_rows(&a.out, &rows)?;
            this_run += 1;
        }
        let _ = kdam::BarExt::update_to(&mut bar, i + 1);
    }
    progress::finish(&mut bar);
    // Every row scored against the poses given now (an earlier run may have had none).
    rows.iter_mut().for_each(score);
    write_rows(&a.out, &rows)?;
    let pose_messages = write_pose_track(&a.out, &rows)?;

    let column = |get: fn(&FrameTrack) -> Option<f64>| -> Value {
        mean_median(rows.iter().filter_map(get).collect())
    };
    let summary = json!({
        "recording": crate::path_json(&a.input.recording), "depth_topic": opened.stream, "object": object.name,
        "frames": processed.len(), "reference_frames": processed.reference_frames,
        "tracked": rows.len(), "this_run": this_run,
        "pose_track": {"file": crate::path_json(a.out.join(POSE_TRACK)), "topic": POSE_TOPIC, "messages": pose_messages},
        "no_estimate": rows.iter().filter(|r| r.estimate.is_none()).count(),
        "scored_against": opened.poses.as_ref().map(|p| match p {
            PoseSource::Csv(c) => c.display().to_string(),
            PoseSource::Topic(t) => t.clone().unwrap_or_default(),
        }),
        "position_err_mm": column(|r| r.estimate_error.map(|e| e.0)),
        "theta_err_deg": column(|r| r.estimate_error.and_then(|e| e.1).map(f64::abs)),
        "multi_position_err_mm": column(|r| r.multi_sample_error.map(|e| e.0)),
        "multi_theta_err_deg": column(|r| r.multi_sample_error.and_then(|e| e.1).map(f64::abs)),
        "baseline_position_err_mm": column(|r| r.baseline_error.map(|e| e.0)),
        "baseline_theta_err_deg": column(|r| r.baseline_error.and_then(|e| e.1).map(f64::abs)),
        "spread_mm": column(|r| r.spread_mm),
        "ambiguous_frames": rows.iter().filter(|r| r.pose_modes > 1).count(),
        "press_m": column(|r| r.press_m),
        "press_err_mm": column(|r| r.press_m.zip(r.recorded_press_m).map(|(p, q)| (p - q).abs() * 1e3)),
        "truth_inside": truth_inside(&rows),
        "out": a.out.join("track.csv"),
        "calibration": opened.calibration,
    });
    write_json(
        &a.out,
        &json!({"settings": settings, "recording": frames, "summary": summary}),
    )?;
    println!("{summary}");
    Ok(())
}

/// How often the recorded pose lies inside the track's posterior regions: the share of rows with a
/// `truth_region` at most 0.5, 0.9 and 0.95 (`null` without such rows). A calibrated posterior holds it in about
/// that share of frames.
fn truth_inside(rows: &[FrameTrack]) -> Value {
    let regions: Vec<f64> = rows.iter().filter_map(|r| r.truth_region).collect();
    if regions.is_empty() {
        return Value::Null;
    }
    let share = |p: f64| regions.iter().filter(|&&m| m <= p).count() as f64 / regions.len() as f64;
    json!({"frames": regions.len(), "0.5": share(0.5), "0.9": share(0.9), "0.95": share(0.95)})
}
