//! `tnd recording`: look into a real sensor recording (MCAP file or folder of depth frames) and write a simulated
//! one. Turning a recording into pairs is `tnd dataset import --from REC`.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::{Args, Subcommand};
use serde_json::json;
use tactile_derender::pipeline::ObjectSpec;
use tactile_derender::recording::synth::{self, DepthEncoding, PressSequence};
use tactile_derender::recording::{self, ReadConfig, Recording};
use tactile_derender::sensor::Scene;
use tactile_derender::sim::{PreparedObject, Simulator};

use crate::args::SensorArgs;
use crate::progress;

#[derive(Args, Debug)]
pub struct RecordingArgs {
    #[command(subcommand)]
    pub command: RecordingCommand,
}

#[derive(Subcommand, Debug)]
pub enum RecordingCommand {
    /// List a recording's topics, detect the no-contact reference and print the contact area of every frame (JSON).
    Info(Box<InfoArgs>),
    /// Estimate the object's pose on every contact frame (de-render, register; track.csv, scored against the
    /// recorded poses when there are any).
    Track(Box<crate::track_cmd::TrackArgs>),
    /// Write a simulated press sequence (sensor lowered onto an object and lifted) as an MCAP recording.
    Simulate(Box<SimulateArgs>),
    /// Write frames as native .npy files (metres, NaN where the camera had no return), the no-contact reference
    /// (reference.npy) and frames.csv: the single frames `tnd pose --signature F --reference R` takes.
    Frames(Box<FramesArgs>),
}

#[derive(Args, Debug)]
pub struct FramesArgs {
    /// The recording: an .mcap file or a folder of depth frames.
    pub recording: PathBuf,
    /// Output folder (created; its frame files, reference.npy / reference_NNNNNN.npy and frames.csv are replaced,
    /// nothing else — write a new folder for another export, or old frame files stay beside the new).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
    /// Frames to write: all (default), contact (those with contact), or a list such as 0,5,10-20 (0-based).
    #[arg(long, default_value = "all")]
    pub frames: String,
    #[command(flatten)]
    pub read: ReadConfig,
    #[command(flatten)]
    pub sensor: SensorArgs,
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// The recording: an .mcap file or a folder of depth frames (16-bit PNG in mm, .npy/.npz).
    pub recording: PathBuf,
    #[command(flatten)]
    pub read: ReadConfig,
    #[command(flatten)]
    pub sensor: SensorArgs,
}

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Output .mcap file (an existing file is replaced only if tnd wrote it, or with --force).
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
    #[command(flatten)]
    pub object: ObjectSpec,
    /// Object pose relative to the sensor axis: X,Y,THETA (metres, metres, radians).
    #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
    pub pose: String,
    /// Deepest press of the sequence, metres.
    #[arg(long, default_value_t = 0.008)]
    pub max_press: f64,
    /// Frames without contact before and after the press.
    #[arg(long, default_value_t = 5)]
    pub rest: usize,
    /// Frames from touching to the deepest press (and back).
    #[arg(long, default_value_t = 10)]
    pub ramp: usize,
    /// Depth message: mm16 (16UC1 millimetres), f32 (32FC1 metres) or cloud (PointCloud2).
    #[arg(long, value_enum, default_value_t = DepthEncoding::Mm16)]
    pub encoding: DepthEncoding,
    /// Leave out the object-pose topic.
    #[arg(long)]
    pub no_pose_topic: bool,
    /// Seed of the measurement noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Give the frames a time-of-flight camera's artefacts (missing returns, noise growing with depth, flying
    /// pixels, a fixed pattern: `DepthCameraConfig::time_of_flight`) unless the sensor file sets `depth_camera`.
    #[arg(long)]
    pub tof: bool,
    /// Change the membrane's inflation by this much from the first frame to the last, linearly, metres (a
    /// drifting membrane: air, temperature; negative: deflating).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub drift: f64,
    /// Mark pixels without a return as 0 in f32 frames (default NaN, as ROS drivers do; mm16 frames always use 0).
    #[arg(long)]
    pub missing_as_zero: bool,
    #[command(flatten)]
    pub sensor: SensorArgs,
}

pub fn run(a: RecordingArgs) -> Result<()> {
    match a.command {
        RecordingCommand::Info(i) => info(*i),
        RecordingCommand::Simulate(s) => simulate(*s),
        RecordingCommand::Track(t) => crate::track_cmd::run(*t),
        RecordingCommand::Frames(f) => frames(*f),
    }
}

/// Open `path` and process its depth stream with a progress bar, saying on stderr how far the membrane drifted.
fn open_processed(
    path: &std::path::Path,
    read: &ReadConfig,
    sim: &tactile_derender::sim::SimConfig,
) -> Result<(
    Recording,
    recording::StreamInfo,
    recording::ProcessedRecording,
)> {
    let rec = Recording::open(path, &read.folder())?;
    let stream = rec.depth_stream(read.topic.as_deref())?.clone();
    let mut bar = progress::bar("frames", "frame", stream.messages);
    let processed = recording::process(
        &rec,
        &stream,
        &sim.camera,
        &read.process(),
        &mut progress::callback(&mut bar),
    );
    progress::finish(&mut bar);
    let processed = processed?;
    crate::calibrate_cmd::tell_drift(path, processed.drift_m(), &processed.stretches);
    Ok((rec, stream, processed))
}

fn info(a: InfoArgs) -> Result<()> {
    let sim = a.sensor.sim_config()?;
    let (rec, stream, p) = open_processed(&a.recording, &a.read, &sim)?;
    // The frame of most contact; none when no frame has any.
    let peak = (0..p.len())
        .max_by_key(|&i| p.contact_px[i])
        .filter(|&i| p.contact_px[i] > 0);
    println!(
        "{}",
        json!({
            "recording": crate::path_json(rec.path()),
            "streams": rec.streams(),
            "depth_topic": stream.name,
            "frames": p.len(),
            "source_size": p.source_size,
            "reference_frames": p.reference_frames,
            "no_contact_stretches": p.stretches,
            "drift_m": p.drift_m(),
            "local_references": p.reference_of.is_some(),
            "measured_px": p.measured_px,
            "peak_contact_frame": peak,
            "times_s": p.times_s(),
            "contact_px": p.contact_px,
        })
    );
    Ok(())
}

fn simulate(a: SimulateArgs) -> Result<()> {
    let pose = crate::args::parse_pose("--pose", &a.pose)?;
    crate::args::check_press("--max-press", a.max_press, true)?;
    let mut config = a.sensor.sim_config()?;
    if a.tof && config.depth_camera.is_ideal() {
        config.depth_camera = tactile_derender::sim::DepthCameraConfig::time_of_flight();
    }
    let loaded = a.object.load()?;
    loaded.check_scale("a recording")?;
    let object = PreparedObject::new(loaded.mesh)?;
    // The recording is built in memory: a press sequence, not an hour of frames.
    const MAX_FRAMES: usize = 3000;
    if a.rest
        .saturating_mul(2)
        .saturating_add(a.ramp.saturating_mul(2))
        > MAX_FRAMES
    {
        anyhow::bail!(
            "--rest {} --ramp {}: a press sequence of at most {MAX_FRAMES} frames (100 s at 30 fps) is simulated",
            a.rest,
            a.ramp
        );
    }
    let mut seq = PressSequence::down_and_up(pose, a.max_press, a.rest, a.ramp);
    seq.encoding = a.encoding;
    seq.seed = a.seed;
    seq.missing_as_zero = a.missing_as_zero;
    if !(a.drift.is_finite() && a.drift.abs() <= 0.01) {
        anyhow::bail!(
            "--drift {} m: a membrane drifts by millimetres (at most 0.01 m here)",
            a.drift
        );
    }
    seq.drift_m = a.drift;
    if a.no_pose_topic {
        seq.pose_topic = None;
    }
    let mut inputs = a.sensor.inputs();
    inputs.push(Path::new(&a.object.object));
    let out = crate::outputs::file(
        "out",
        &a.out,
        a.force.force,
        &inputs,
        &synth::written_by_tnd,
    )?;
    // A sequence that never touches the object is a recording of the membrane alone: say so, as `tnd sim` does.
    let deepest = seq
        .presses
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let sim = Simulator::new(config.clone())?;
    let scene = Scene {
        object: pose,
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, deepest),
    };
    if sim.simulate(&object, &scene, seq.seed).contact_pixels == 0 {
        crate::sim_cmd::warn_no_contact(" in any frame", &sim, &object, &scene);
    }
    let frames = synth::write_press_recording(out.path(), &config, &object, &seq)?;
    println!(
        "{}",
        json!({
            "out": crate::path_json(&a.out),
            "object": loaded.name,
            "frames": frames,
            "depth_topic": seq.depth_topic,
            "pose_topic": seq.pose_topic,
            "encoding": seq.encoding,
            "pose": [pose.x, pose.y, pose.theta],
            // To the nanometre: 0.0021, not 0.0021000000000000003.
            "presses_m": seq.presses.iter().map(|p| (p * 1e9).round() / 1e9).collect::<Vec<_>>(),
        })
    );
    Ok(())
}

/// `--frames`: all, contact, or a list of frame numbers and ranges (`0,5,10-20`); `contact_px` per frame.
fn frame_list(text: &str, contact_px: &[usize]) -> Result<Vec<usize>> {
    match text.trim() {
        "all" => return Ok((0..contact_px.len()).collect()),
        "contact" => {
            return Ok((0..contact_px.len())
                .filter(|&k| contact_px[k] > 0)
                .collect())
        }
        _ => {}
    }
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let number = |s: &str| {
            s.trim().parse::<usize>().map_err(|_| {
                anyhow::anyhow!(
                    "--frames {text}: '{part}' is not a frame number or a range A-B (0-based)"
                )
            })
        };
        match part.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (number(a)?, number(b)?);
                if b < a {
                    anyhow::bail!("--frames {text}: the range {part} runs backwards");
                }
                if b >= contact_px.len() {
                    anyhow::bail!(
                        "--frames {text}: the recording has {} frames (0..{})",
                        contact_px.len(),
                        contact_px.len().saturating_sub(1)
                    );
                }
                out.extend(a..=b);
            }
            None => out.push(number(part)?),
        }
    }
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

fn frames(a: FramesArgs) -> Result<()> {
    let sim = a.sensor.sim_config()?;
    let (rec, stream, processed) = open_processed(&a.recording, &a.read, &sim)?;
    let list = frame_list(&a.frames, &processed.contact_px)?;
    let mut inputs = a.sensor.inputs();
    inputs.push(&a.recording);
    let _out = crate::outputs::folder("--out", &a.out, a.force.force, &inputs)?;
    let mut bar = progress::bar("writing", "frame", list.len());
    let rows = recording::frames_out::write_frames(
        &rec,
        &stream,
        &processed,
        &sim.camera.native,
        &list,
        &a.out,
        &mut progress::callback(&mut bar),
    );
    progress::finish(&mut bar);
    let rows = rows?;
    let contact = rows.iter().filter(|r| r.contact_px > 0).count();
    eprintln!(
        "{}: {} frames ({contact} with contact) and {} (median of the no-contact frames {:?})",
        a.out.display(),
        rows.len(),
        recording::frames_out::REFERENCE_NPY,
        processed.reference_frames
    );
    println!(
        "{}",
        json!({
            "recording": crate::path_json(rec.path()),
            "out": crate::path_json(&a.out),
            "frames": rows,
            "reference": crate::path_json(a.out.join(recording::frames_out::REFERENCE_NPY)),
            "reference_frames": processed.reference_frames,
        })
    );
    Ok(())
}
