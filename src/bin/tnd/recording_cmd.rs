//! `tnd recording`: look into a real sensor recording (MCAP file or folder of depth frames) and write a simulated
//! one. Turning a recording into pairs is `tnd dataset import --from REC`.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, Subcommand};
use serde_json::json;
use tactile_derender::pipeline::ObjectSpec;
use tactile_derender::recording::synth::{self, DepthEncoding, PressSequence};
use tactile_derender::recording::{self, FolderOptions, ProcessConfig, Recording, ReferenceChoice};
use tactile_derender::sim::PreparedObject;

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
}

/// How a recording is read (shared with `tnd dataset import`).
#[derive(Args, Debug, Clone)]
pub struct RecordingReadArgs {
    /// Depth topic of an MCAP file (sensor_msgs/Image or PointCloud2); default: its only depth topic.
    #[arg(long)]
    pub topic: Option<String>,
    /// No-contact reference frame: "auto" (median of the frames without contact) or a frame number (0-based).
    #[arg(long, default_value = "auto")]
    pub reference: ReferenceChoice,
    /// Imprint above which a pixel counts as contact, metres (the threshold baseline's 3 mm).
    #[arg(long, default_value_t = ProcessConfig::default().contact_threshold_m)]
    pub contact_threshold: f64,
    /// Metres per unit of .npy/.npz depth arrays (1 = metres, 0.001 = millimetres).
    #[arg(long, default_value_t = FolderOptions::default().npy_scale)]
    pub npy_scale: f64,
    /// Metres per unit of 16-bit PNG depth images (default: millimetres).
    #[arg(long, default_value_t = FolderOptions::default().png_scale)]
    pub png_scale: f64,
    /// Folder recordings: frames per second (for the time stamps).
    #[arg(long, default_value_t = FolderOptions::default().fps)]
    pub fps: f64,
}

impl RecordingReadArgs {
    pub fn folder(&self) -> FolderOptions {
        FolderOptions {
            npy_scale: self.npy_scale,
            png_scale: self.png_scale,
            fps: self.fps,
        }
    }

    pub fn process(&self) -> ProcessConfig {
        ProcessConfig {
            reference: self.reference,
            contact_threshold_m: self.contact_threshold,
            ..ProcessConfig::default()
        }
    }
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// The recording: an .mcap file or a folder of depth frames (16-bit PNG in mm, .npy/.npz).
    pub recording: PathBuf,
    #[command(flatten)]
    pub read: RecordingReadArgs,
    #[command(flatten)]
    pub sensor: SensorArgs,
}

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Output .mcap file.
    pub out: PathBuf,
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
    #[command(flatten)]
    pub sensor: SensorArgs,
}

pub fn run(a: RecordingArgs) -> Result<()> {
    match a.command {
        RecordingCommand::Info(i) => info(*i),
        RecordingCommand::Simulate(s) => simulate(*s),
        RecordingCommand::Track(t) => crate::track_cmd::run(*t),
    }
}

fn info(a: InfoArgs) -> Result<()> {
    let sim = a.sensor.sim_config()?;
    let rec = Recording::open(&a.recording, &a.read.folder())?;
    let stream = rec.depth_stream(a.read.topic.as_deref())?.clone();
    let mut bar = progress::bar("frames", "frame", stream.messages);
    let processed = recording::process(
        &rec,
        &stream,
        &sim.camera,
        &a.read.process(),
        &mut progress::callback(&mut bar),
    );
    progress::finish(&mut bar);
    let p = processed?;
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
    let config = a.sensor.sim_config()?;
    let loaded = a.object.load()?;
    loaded.check_scale("a recording")?;
    let object = PreparedObject::new(loaded.mesh)?;
    let mut seq = PressSequence::down_and_up(pose, a.max_press, a.rest, a.ramp);
    seq.encoding = a.encoding;
    seq.seed = a.seed;
    if a.no_pose_topic {
        seq.pose_topic = None;
    }
    let _lock = tactile_derender::io::lock::OutputLock::acquire(&a.out)?;
    let frames = synth::write_press_recording(&a.out, &config, &object, &seq)?;
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
