//! `tnd recording track`: the object's pose on every contact frame of a recording
//! ([`tactile_derender::pipeline::track`]), one row per frame in `track.csv`, written as each frame is done so that
//! a killed run resumes where it stopped; `track.json` keeps the settings (a resumed run must match them) and, at the
//! end, the summary.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use serde_json::{json, Value};
use tactile_derender::dataset::import_recording::{frame_poses, PoseSource};
use tactile_derender::io::write_atomic;
use tactile_derender::metrics::evaluate::EvalConfig;
use tactile_derender::model::DiffusionModel;
use tactile_derender::pipeline::track::{track_frame, FrameTrack, PressChoice, TrackContext};
use tactile_derender::pipeline::{DerenderConfig, ObjectSpec};
use tactile_derender::recording::source::DEFAULT_MAX_POSE_GAP_S;
use tactile_derender::recording::{self, Recording, StreamKind};
use tactile_derender::sim::{PreparedObject, Simulator};

use crate::args::SensorArgs;
use crate::progress;
use crate::recording_cmd::RecordingReadArgs;

#[derive(Args, Debug)]
pub struct TrackArgs {
    /// The recording: an .mcap file or a folder of depth frames (16-bit PNG in mm, .npy/.npz).
    pub recording: PathBuf,
    #[command(flatten)]
    pub object: ObjectSpec,
    #[command(flatten)]
    pub read: RecordingReadArgs,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// The generator: a model checkpoint (default: the bundled model; `small`: the bundled small one).
    #[arg(long, default_value = "default")]
    pub model: String,
    #[command(flatten)]
    pub derender: DerenderConfig,
    /// How far the sensor is pressed into the object, to place it over the object: "auto" (per frame, the samples'
    /// highest contact point on the object's top) or metres for every frame.
    #[arg(long, default_value = "auto")]
    pub press: PressChoice,
    /// Recorded poses to score the estimates against: a CSV (columns frame or stamp_ns, x, y, theta); default: the
    /// recording's pose topic when it has exactly one.
    #[arg(long, conflicts_with = "pose_topic")]
    pub poses: Option<PathBuf>,
    /// The recording's object-pose topic to score against.
    #[arg(long)]
    pub pose_topic: Option<String>,
    /// Track every n-th frame.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// Frames with fewer contact pixels (imprint over --contact-threshold) are not tracked.
    #[arg(long, default_value_t = 10)]
    pub min_contact_px: usize,
    /// Output directory: track.csv (one row per frame) and track.json; a run killed part-way resumes into it.
    #[arg(long)]
    pub out: PathBuf,
}

/// The settings a track's rows depend on; a resumed run must have the same.
fn settings(
    a: &TrackArgs,
    sim: &tactile_derender::sim::SimConfig,
    poses: &Option<PoseSource>,
) -> Value {
    json!({
        "recording": a.recording, "topic": a.read.topic, "reference": a.read.reference,
        "contact_threshold_m": a.read.contact_threshold, "npy_scale": a.read.npy_scale,
        "png_scale": a.read.png_scale, "fps": a.read.fps,
        "object": a.object, "model": a.model, "derender": a.derender, "press": a.press.to_string(),
        "poses": poses, "every": a.every, "min_contact_px": a.min_contact_px, "sim": sim,
    })
}

/// The rows of an earlier run into `out` with the same settings (frame, CSV line); none when there is no earlier
/// run. Another run's directory is refused.
fn earlier_rows(out: &Path, settings: &Value) -> Result<Vec<(usize, String)>> {
    let json_path = out.join("track.json");
    let csv_path = out.join("track.csv");
    if !json_path.exists() {
        if out
            .read_dir()
            .map(|mut d| d.next().is_some())
            .unwrap_or(false)
        {
            bail!(
                "{}: not empty and holds no track; choose a new --out",
                out.display()
            );
        }
        return Ok(Vec::new());
    }
    let text = std::fs::read_to_string(&json_path)
        .with_context(|| format!("{}: cannot read", json_path.display()))?;
    let earlier: Value = serde_json::from_str(&text)
        .map_err(|e| anyhow!("{}: not a track's settings: {e}", json_path.display()))?;
    if earlier.get("settings") != Some(settings) {
        let mut differing = Vec::new();
        differences("", settings, &earlier["settings"], &mut differing);
        bail!(
            "{}: holds a track made with other settings ({}); choose a new --out or the same settings",
            out.display(),
            differing.join(", ")
        );
    }
    let Ok(text) = std::fs::read_to_string(&csv_path) else {
        return Ok(Vec::new());
    };
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let frame = line
            .split(',')
            .next()
            .and_then(|f| f.parse::<usize>().ok())
            .ok_or_else(|| anyhow!("{}: line {}: no frame number", csv_path.display(), i + 1))?;
        rows.push((frame, line.to_string()));
    }
    Ok(rows)
}

/// The dotted names of the settings where `now` and `then` differ (`derender.samples`).
fn differences(prefix: &str, now: &Value, then: &Value, out: &mut Vec<String>) {
    match (now, then) {
        (Value::Object(a), Value::Object(b)) => {
            for (k, v) in a {
                let name = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                differences(&name, v, b.get(k).unwrap_or(&Value::Null), out);
            }
        }
        (a, b) if a != b => out.push(prefix.to_string()),
        _ => {}
    }
}

fn write_rows(out: &Path, rows: &[(usize, String)]) -> Result<()> {
    let mut text = format!("{}\n", FrameTrack::CSV_HEADER);
    for (_, line) in rows {
        text.push_str(line);
        text.push('\n');
    }
    let path = out.join("track.csv");
    write_atomic(&path, text.as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))
}

fn write_json(out: &Path, value: &Value) -> Result<()> {
    let path = out.join("track.json");
    write_atomic(&path, serde_json::to_string_pretty(value)?.as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))
}

/// Mean and median of `v` (None when empty).
fn mean_median(mut v: Vec<f64>) -> Value {
    if v.is_empty() {
        return Value::Null;
    }
    v.sort_by(f64::total_cmp);
    json!({"mean": v.iter().sum::<f64>() / v.len() as f64, "median": v[v.len() / 2], "frames": v.len()})
}

pub fn run(a: TrackArgs) -> Result<()> {
    if a.every == 0 {
        bail!("--every must be at least 1");
    }
    let sim_config = a.sensor.sim_config()?;
    let sim = Simulator::new(sim_config.clone())?;
    let rec = Recording::open(&a.recording, &a.read.folder())?;
    let stream = rec.depth_stream(a.read.topic.as_deref())?.clone();
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
    let settings = settings(&a, &sim_config, &poses);
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create", a.out.display()))?;
    let mut rows = earlier_rows(&a.out, &settings)?;
    write_json(&a.out, &json!({"settings": settings}))?;

    let object = a.object.load()?;
    for w in &object.warnings {
        eprintln!("warning: {w}");
    }
    let prepared = PreparedObject::new(object.mesh.clone())?;
    let device = tactile_derender::model::device::open_device(&a.derender.device)?;
    let model = DiffusionModel::load_on(Path::new(&a.model), &device)?;

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
    let recorded = match &poses {
        Some(p) => frame_poses(&rec, &processed.stamps_ns, p, DEFAULT_MAX_POSE_GAP_S)?,
        None => vec![None; processed.len()],
    };
    let todo: Vec<usize> = (0..processed.len())
        .step_by(a.every)
        .filter(|&k| processed.contact_px[k] >= a.min_contact_px)
        .collect();
    if todo.is_empty() {
        let (peak, px) = (0..processed.len())
            .map(|k| (k, processed.contact_px[k]))
            .max_by_key(|p| p.1)
            .unwrap_or((0, 0));
        bail!(
            "{}: no frame has {} contact pixels (imprint over {} mm) to track; the most is {px} at frame {peak} \
             (lower --min-contact-px or --contact-threshold, or check --reference and the sensor options)",
            a.recording.display(),
            a.min_contact_px,
            a.read.contact_threshold * 1e3
        );
    }
    let done: BTreeSet<usize> = rows.iter().map(|r| r.0).collect();
    if !done.is_empty() {
        eprintln!(
            "resuming the track in {}: {} of {} frames done",
            a.out.display(),
            done.len(),
            todo.len()
        );
    }
    let eval = EvalConfig::default();
    let ctx = TrackContext {
        model: &model,
        object: &object,
        prepared: &prepared,
        sim: &sim,
        derender: &a.derender,
        eval: &eval,
        press: a.press,
    };
    let mut bar = progress::bar("tracking", " frames", todo.len());
    let mut tracked = Vec::new();
    for (i, &k) in todo.iter().enumerate() {
        if !done.contains(&k) {
            let row = track_frame(
                &ctx,
                &processed,
                k,
                recorded[k].map(|p| p.pose),
                &mut |_, _| true,
            )?;
            rows.push((k, row.csv_row()));
            rows.sort_by_key(|r| r.0);
            write_rows(&a.out, &rows)?;
            tracked.push(row);
        }
        let _ = kdam::BarExt::update_to(&mut bar, i + 1);
    }
    progress::finish(&mut bar);

    // The summary over every row of the track (those of an earlier, interrupted run too).
    let text = std::fs::read_to_string(a.out.join("track.csv"))?;
    let column = |name: &str| -> Vec<f64> {
        let Some(c) = FrameTrack::CSV_HEADER.split(',').position(|h| h == name) else {
            return Vec::new();
        };
        text.lines()
            .skip(1)
            .filter_map(|l| l.split(',').nth(c).and_then(|v| v.parse::<f64>().ok()))
            .collect()
    };
    let summary = json!({
        "recording": a.recording, "depth_topic": stream.name, "object": object.name,
        "frames": processed.len(), "reference_frames": processed.reference_frames,
        "tracked": rows.len(), "this_run": tracked.len(),
        "no_estimate": rows.len() - column("x").len(),
        "scored_against": poses.as_ref().map(|p| match p {
            PoseSource::Csv(c) => c.display().to_string(),
            PoseSource::Topic(t) => t.clone().unwrap_or_default(),
        }),
        "position_err_mm": mean_median(column("position_err_mm")),
        "multi_position_err_mm": mean_median(column("multi_position_err_mm")),
        "baseline_position_err_mm": mean_median(column("baseline_position_err_mm")),
        "press_m": mean_median(column("press_m")),
        "out": a.out.join("track.csv"),
    });
    write_json(&a.out, &json!({"settings": settings, "summary": summary}))?;
    println!("{summary}");
    Ok(())
}
