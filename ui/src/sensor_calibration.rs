//! The Recording tab's **sensor calibration**: one button fits the sensor to the open recording's no-contact
//! frames on a background thread ([`tactile_derender::recording::calibrate`], the same function as `tnd calibrate`
//! and the recording import), applies the calibrated sensor to the session — an undoable sensor edit, so the
//! simulation, de-rendering, the pose job and the track all use it — and shows the fit: what changed, the residual,
//! and the measured reference, the calibrated membrane and their difference.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::Result;
use egui::{TextureHandle, TextureOptions};
use tactile_derender::recording::calibrate::{
    calibrate, CalibrateConfig, CalibrationImages, SensorCalibration,
};
use tactile_derender::recording::Recording;

use crate::colormap::to_color_image;
use crate::worker::{JobKind, WorkerMsg};

/// A finished calibration and the recording it came from.
pub struct CalibrationResult {
    pub recording: PathBuf,
    pub calibration: SensorCalibration,
    pub images: CalibrationImages,
}

/// What a calibration job needs.
pub struct CalibrationRequest {
    pub generation: u64,
    /// The recording (an .mcap file or a frame folder).
    pub recording: PathBuf,
    /// How it is read (the Recording tab's settings).
    pub read: tactile_derender::recording::ReadConfig,
    /// The sensor the calibration starts from.
    pub given: tactile_derender::sim::SimConfig,
    pub config: CalibrateConfig,
}

/// Run `req` on its own thread ([`calibrate`], as `tnd calibrate`), reporting progress and the result through
/// `tx`; setting `cancel` stops it.
pub fn spawn(
    req: CalibrationRequest,
    cancel: Arc<AtomicBool>,
    tx: std::sync::mpsc::Sender<WorkerMsg>,
    ctx: egui::Context,
) -> Result<()> {
    let generation = req.generation;
    crate::worker::spawn_job(
        JobKind::SensorCalibration,
        generation,
        tx,
        ctx,
        move |progress| {
            let rec = Recording::open(&req.recording, &req.read.folder())?;
            let stream = rec.depth_stream(req.read.topic.as_deref())?.clone();
            let (calibration, images) = calibrate(
                &rec,
                &stream,
                &req.given,
                &req.config,
                &mut |done, total| {
                    progress(done, total);
                    !cancel.load(Ordering::Relaxed)
                },
            )?;
            Ok(WorkerMsg::SensorCalibrated {
                generation,
                result: Box::new(CalibrationResult {
                    recording: req.recording,
                    calibration,
                    images,
                }),
            })
        },
    )
}

/// Textures of a calibration's three images, and their colour ranges (metres).
pub struct CalibrationTextures {
    pub depth_range: (f32, f32),
    pub residual_range: (f32, f32),
    pub measured: TextureHandle,
    pub fitted: TextureHandle,
    pub residual: TextureHandle,
}

/// Live state of the calibration.
#[derive(Default)]
pub struct SensorCalibrationView {
    pub running: bool,
    pub generation: u64,
    pub progress: Option<(usize, usize)>,
    pub cancel: Option<Arc<AtomicBool>>,
    pub result: Option<CalibrationResult>,
    pub textures: Option<CalibrationTextures>,
}

impl SensorCalibrationView {
    /// The result's textures (made once per result).
    pub fn textures(&mut self, ctx: &egui::Context) -> Option<&CalibrationTextures> {
        let r = self.result.as_ref()?;
        if self.textures.is_none() {
            let im = &r.images;
            let depth_range = im
                .measured
                .range_where(|d| d > 0.0)
                .map_or((0.06, 0.1), |(lo, hi)| (lo, hi.max(lo + 1e-3)));
            let c = &r.calibration;
            let span = (3.0 * c.residual_rms_m.max(c.noise_floor_rms_m)).max(2e-4) as f32;
            let tex = |name: &str, img, range, zim| {
                ctx.load_texture(
                    name,
                    to_color_image(img, range, zim),
                    TextureOptions::NEAREST,
                )
            };
            self.textures = Some(CalibrationTextures {
                depth_range,
                residual_range: (-span, span),
                measured: tex("cal_measured", &im.measured, depth_range, true),
                fitted: tex("cal_fitted", &im.fitted, depth_range, true),
                residual: tex("cal_residual", &im.residual, (-span, span), false),
            });
        }
        self.textures.as_ref()
    }
}
