//! The Recording tab's **sensor calibration**: one button fits the sensor to the open recording's no-contact
//! frames on a background thread ([`tactile_derender::recording::calibrate`], the same function as `tnd calibrate`
//! and the recording import), applies the calibrated sensor to the session — an undoable sensor edit, so the
//! simulation, de-rendering, the pose job and the track all use it — and shows the fit: what changed, the residual,
//! and the measured reference, the calibrated membrane and their difference.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{anyhow, Result};
use egui::{TextureHandle, TextureOptions};
use tactile_derender::recording::calibrate::{
    calibrate, CalibrateConfig, CalibrationImages, SensorCalibration,
};
use tactile_derender::recording::{FolderOptions, Recording};

use crate::colormap::to_color_image;
use crate::command::Command;
use crate::worker::{JobKind, WorkerMsg};

/// A finished calibration and the recording it came from.
pub struct CalibrationResult {
    pub recording: PathBuf,
    pub calibration: SensorCalibration,
    pub images: CalibrationImages,
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

impl crate::app::WorkbenchApp {
    /// Calibrate the sensor from the open recording's no-contact frames, on a background thread.
    pub(crate) fn calibrate_sensor(&mut self) -> Result<()> {
        let path = self
            .recording
            .loaded
            .as_ref()
            .map(|l| l.path.clone())
            .ok_or_else(|| anyhow!("open a recording first"))?;
        let w = self
            .worker
            .as_ref()
            .ok_or_else(|| anyhow!("the background worker is not running"))?;
        let (tx, ctx) = (w.sender(), w.context());
        self.cancel_sensor_calibration();
        let view = &mut self.recording.sensor_calibration;
        view.generation += 1;
        view.running = true;
        view.progress = None;
        let cancel = Arc::new(AtomicBool::new(false));
        view.cancel = Some(cancel.clone());
        let generation = view.generation;
        let given = self.state.sim.clone();
        let topic = self.state.recording.topic.clone();
        let config = CalibrateConfig {
            reference: self.state.recording.reference,
            ..CalibrateConfig::default()
        };
        let r = crate::worker::spawn_job(
            JobKind::SensorCalibration,
            generation,
            tx,
            ctx,
            move |progress| {
                let rec = Recording::open(&path, &FolderOptions::default())?;
                let stream = rec.depth_stream(topic.as_deref())?.clone();
                let (calibration, images) =
                    calibrate(&rec, &stream, &given, &config, &mut |done, total| {
                        progress(done, total);
                        !cancel.load(Ordering::Relaxed)
                    })?;
                Ok(WorkerMsg::SensorCalibrated {
                    generation,
                    result: Box::new(CalibrationResult {
                        recording: path,
                        calibration,
                        images,
                    }),
                })
            },
        );
        if r.is_err() {
            self.recording.sensor_calibration.running = false;
        }
        r
    }

    pub(crate) fn cancel_sensor_calibration(&mut self) {
        let view = &mut self.recording.sensor_calibration;
        crate::worker::raise_cancel(&mut view.cancel);
        view.running = false;
    }

    /// Write the calibrated sensor beside the recording as `<recording>_sensor.json` (a sensor file: `tnd ... --sensor`,
    /// `tnd-workbench --sensor`).
    pub(crate) fn save_sensor_file(&self) -> Result<PathBuf> {
        let r = self
            .recording
            .sensor_calibration
            .result
            .as_ref()
            .ok_or_else(|| anyhow!("calibrate the sensor first"))?;
        let stem = r
            .recording
            .file_stem()
            .map_or_else(|| "recording".into(), |s| s.to_string_lossy().into_owned());
        let dir = r.recording.parent().map(PathBuf::from).unwrap_or_default();
        let path = dir.join(format!("{stem}_sensor.json"));
        tactile_derender::sim::sensor_file::save(&path, &r.calibration.sensor)?;
        Ok(path)
    }

    /// Take in a finished calibration: the calibrated sensor becomes the session's (undoable).
    pub(crate) fn sensor_calibrated(&mut self, generation: u64, result: Box<CalibrationResult>) {
        let view = &mut self.recording.sensor_calibration;
        if generation != view.generation {
            return;
        }
        view.running = false;
        view.cancel = None;
        view.textures = None;
        let c = &result.calibration;
        self.notice = Some(format!(
            "sensor calibrated from {} no-contact frames of {}: inflation {:.2} mm, noise {} (Undo restores the \
             previous sensor)",
            c.no_contact_frames.len(),
            result.recording.display(),
            c.inflation_m * 1e3,
            c.noise_std_m
                .map_or("not measured".to_string(), |s| format!("{:.2} mm", s * 1e3))
        ));
        let sensor = c.sensor.clone();
        self.recording.sensor_calibration.result = Some(*result);
        self.apply(Command::SetSim(sensor));
    }
}
