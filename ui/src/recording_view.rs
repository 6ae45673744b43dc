//! The **Recording** tab's live side: a real sensor recording (MCAP file or depth-frame folder) read and turned into
//! one imprint per frame on a background thread ([`tactile_derender::recording::process`], with progress and
//! cancel), the object poses of its pose topic per frame, and the textures of the frame under the timeline cursor.
//! The saved side is [`RecordingSettings`] in the session.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;

use anyhow::{anyhow, Result};
use egui::{TextureHandle, TextureOptions};
use serde::{Deserialize, Serialize};
use tactile_derender::pipeline::track::TrackingConfig;
use tactile_derender::recording::source::DEFAULT_MAX_POSE_GAP_S;
use tactile_derender::recording::{
    self, ProcessedRecording, ReadConfig, Recording, StreamInfo, StreamKind,
};
use tactile_derender::sensor::Se2;
use tactile_derender::sim::SimConfig;

use crate::colormap::to_color_image;
use crate::worker::{JobKind, WorkerMsg};

/// Saved settings of the Recording tab.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RecordingSettings {
    /// The recording (`.mcap` file or frame folder); `None`: nothing open.
    pub path: Option<PathBuf>,
    /// How it is read (depth topic, no-contact reference, contact threshold, a folder's units): the settings `tnd
    /// recording track` takes as options.
    #[serde(flatten)]
    pub read: ReadConfig,
    /// The frame under the timeline cursor.
    pub frame: usize,
    /// How the track goes through the recording: the same settings as `tnd recording track` (`--every`, and
    /// `--per-frame`, `--carried-samples`, ... of [`TrackSettings::tracking`]).
    pub track: TrackSettings,
}

/// The Recording tab's track settings (in the session).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrackSettings {
    /// Track every n-th frame (1: every frame), as `tnd recording track --every`.
    pub every: usize,
    /// Which frames are tracked and what each hands to the next.
    pub tracking: TrackingConfig,
}

impl Default for TrackSettings {
    fn default() -> Self {
        Self {
            every: 1,
            tracking: TrackingConfig::default(),
        }
    }
}

/// A loaded recording.
pub struct LoadedRecording {
    pub path: PathBuf,
    /// Every stream of the file.
    pub streams: Vec<StreamInfo>,
    pub processed: Arc<ProcessedRecording>,
    /// The object's pose per frame from the pose topic (nearest message within 50 ms), if there is one.
    pub poses: Vec<Option<Se2>>,
    /// The settings it was loaded with (a change of topic or reference reloads).
    pub loaded_with: RecordingSettings,
}

/// The background thread's answer.
pub enum RecordingMsg {
    Loaded {
        generation: u64,
        recording: Box<LoadedRecording>,
    },
}

/// Textures of one frame: imprint, signature, reference.
pub struct FrameTextures {
    pub frame: usize,
    /// Colour range of the signature and reference, metres (the frame's measured depths).
    pub depth_range: (f32, f32),
    pub imprint: TextureHandle,
    pub signature: TextureHandle,
    pub reference: TextureHandle,
}

/// Live state of the tab.
#[derive(Default)]
pub struct RecordingView {
    pub loaded: Option<LoadedRecording>,
    pub generation: u64,
    pub loading: bool,
    pub progress: Option<(usize, usize)>,
    pub cancel: Option<Arc<AtomicBool>>,
    pub textures: Option<FrameTextures>,
    /// The pose on every contact frame.
    pub track: crate::track_view::TrackView,
    /// The sensor fitted to the recording's no-contact frames.
    pub sensor_calibration: crate::sensor_calibration::SensorCalibrationView,
}

/// Colour range of imprints, metres.
pub const IMPRINT_RANGE: (f32, f32) = (-0.002, 0.012);

impl RecordingView {
    /// The textures of `frame` (made when the cursor moved).
    pub fn textures_for(&mut self, ctx: &egui::Context, frame: usize) -> Option<&FrameTextures> {
        let p = &self.loaded.as_ref()?.processed;
        let frame = frame.min(p.len().checked_sub(1)?);
        if self.textures.as_ref().is_none_or(|t| t.frame != frame) {
            let s = &p.signatures[frame];
            let depth = s
                .range_where(|d| d > 0.0)
                .map_or((0.07, 0.1), |(lo, hi)| (lo, hi.max(lo + 0.004)));
            let tex = |name: &str, img, range, zim| {
                ctx.load_texture(
                    name,
                    to_color_image(img, range, zim),
                    TextureOptions::NEAREST,
                )
            };
            self.textures = Some(FrameTextures {
                frame,
                depth_range: depth,
                imprint: tex("rec_imprint", &p.imprints[frame], IMPRINT_RANGE, false),
                signature: tex("rec_signature", s, depth, true),
                reference: tex("rec_reference", &p.reference, depth, true),
            });
        }
        self.textures.as_ref()
    }
}

/// Read and process the recording of `settings` on its own thread.
pub fn spawn_load(
    settings: RecordingSettings,
    sim: SimConfig,
    generation: u64,
    cancel: Arc<AtomicBool>,
    tx: Sender<WorkerMsg>,
    ctx: egui::Context,
) -> Result<()> {
    crate::worker::spawn_job(JobKind::Recording, generation, tx, ctx, move |progress| {
        let recording = load(&settings, &sim, &mut |done, total| {
            progress(done, total);
            !cancel.load(Ordering::Relaxed)
        })?;
        Ok(WorkerMsg::Recording(RecordingMsg::Loaded {
            generation,
            recording: Box::new(recording),
        }))
    })
}

fn load(
    settings: &RecordingSettings,
    sim: &SimConfig,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<LoadedRecording> {
    let path = settings
        .path
        .clone()
        .ok_or_else(|| anyhow!("no recording chosen"))?;
    let rec = Recording::open(&path, &settings.read.folder())?;
    let stream = rec.depth_stream(settings.read.topic.as_deref())?.clone();
    let processed = recording::process(
        &rec,
        &stream,
        &sim.camera,
        &settings.read.process(),
        progress,
    )?;
    let poses = match rec.streams().iter().find(|s| s.kind == StreamKind::Pose) {
        Some(ps) => rec.poses_at(ps, &processed.stamps_ns, DEFAULT_MAX_POSE_GAP_S)?,
        None => vec![None; processed.len()],
    };
    Ok(LoadedRecording {
        path,
        streams: rec.streams().to_vec(),
        processed: Arc::new(processed),
        poses,
        loaded_with: RecordingSettings {
            frame: 0,
            ..settings.clone()
        },
    })
}
