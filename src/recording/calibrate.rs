//! **Sensor calibration from a recording**: a Soft Bubble is never exactly its nominal model (inflation drifts with
//! pressure and temperature, the camera sits a little off), and a recording already measures it. Its no-contact
//! frames (found as [`super::process`] finds them, with the noise-aware threshold) are measurements of the membrane:
//! their per-pixel mean is the reference R the membrane and camera position are fitted to
//! ([`crate::sensor::membrane_fit`]), and their spread about that mean is the depth noise σ. Nothing about the
//! pressed object is needed.
//!
//! The result is the given sensor with the fitted inflation, footprint, camera position and noise: a
//! [`SimConfig`] that every command takes as `--sensor FILE`, plus what changed, the residual of the fit and
//! warnings where the parametric membrane does not explain the frames.

use serde::{Deserialize, Serialize};

use super::process::{quiet_frames, ProcessConfig, ReferenceChoice};
use super::source::{Recording, StreamInfo};
use super::RecordingError;
use crate::image::Image;
use crate::sensor::membrane_fit::MembraneFitConfig;
use crate::sensor::resample::{self, InputSize};
use crate::sensor::Intrinsics;
use crate::sim::SimConfig;

#[path = "calibrate_fit.rs"]
mod fit;
use fit::calibrate_frames;

/// Model error (RMS of the residual beyond the noise) above which the calibration warns that the membrane model
/// does not explain the no-contact frames, metres.
pub const MODEL_ERROR_WARNING_M: f64 = 3e-4;

/// Settings of a calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CalibrateConfig {
    /// The no-contact frames: detected (`auto`), or one given frame (then the noise cannot be measured).
    pub reference: ReferenceChoice,
    /// Frames read at most, evenly spread over the recording (default 400).
    pub max_frames: usize,
    /// 5 x 5-window imprint under which a frame is surely without contact, metres (default 1 mm; frames of a
    /// noisy sensor are judged against their own noise as well, [`super::process`]).
    pub quiet_threshold_m: f64,
    /// What the membrane fit may change.
    pub fit: MembraneFitConfig,
}

impl Default for CalibrateConfig {
    fn default() -> Self {
        Self {
            reference: ReferenceChoice::Auto,
            max_frames: 400,
            quiet_threshold_m: ProcessConfig::default().quiet_threshold_m,
            fit: MembraneFitConfig::default(),
        }
    }
}

impl CalibrateConfig {
    /// The calibration of a recording whose frames become imprints as `process` says (its reference choice and
    /// quiet threshold), the fit at its defaults: what `tnd calibrate`, `tnd recording track`, `tnd dataset import`
    /// and the workbench's Recording tab run.
    pub fn reading(process: &ProcessConfig) -> Self {
        Self {
            reference: process.reference,
            quiet_threshold_m: process.quiet_threshold_m,
            ..Self::default()
        }
    }
}

/// One calibrated setting beside the value it replaced.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Change {
    /// The setting, as `--sensor` files and the CLI name it (e.g. `elastomer.inflation`).
    pub setting: String,
    pub given: f64,
    pub calibrated: f64,
    /// One standard error of the calibrated value (0 where not known).
    pub std_error: f64,
}

/// What a calibration found. Lengths in metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorCalibration {
    /// Inflation height of the membrane's apex above its base.
    pub inflation_m: f64,
    /// Footprint length (x) and width (y).
    pub footprint_m: [f64; 2],
    /// The camera's optical centre in the sensor frame (z negative: behind the membrane base).
    pub camera_position_m: [f64; 3],
    /// Depth noise per pixel of the recorded frames (the sensor's own resolution), with the depth encoding's
    /// rounding taken out; `None` when fewer than two no-contact frames were found.
    pub noise_std_m: Option<f64>,
    /// The same noise at the model's resolution (after the crop and area resampling every imprint goes through).
    pub noise_std_model_m: Option<f64>,
    /// Step of the recorded depths when they are rounded (16-bit millimetres: 0.001), else `None`.
    pub depth_step_m: Option<f64>,
    /// RMS of the measured reference minus the calibrated membrane's depth, over the pixels the camera measured.
    pub residual_rms_m: f64,
    /// Largest absolute residual.
    pub residual_max_m: f64,
    /// The RMS residual the noise alone would leave (noise / sqrt(no-contact frames)).
    pub noise_floor_rms_m: f64,
    /// The residual's RMS beyond the noise floor (in quadrature): how far the membrane model is from the frames.
    /// Over [`MODEL_ERROR_WARNING_M`] a warning says so.
    pub model_error_rms_m: f64,
    /// Whether the parametric membrane was fitted (false: the sensor's membrane is a mesh file, only checked).
    pub membrane_fitted: bool,
    /// Frames in the recording, and how many were read.
    pub frames: usize,
    pub frames_read: usize,
    /// The no-contact frames the calibration used (0-based).
    pub no_contact_frames: Vec<usize>,
    /// Size of the recorded frames `[width, height]`.
    pub frame_size: [usize; 2],
    /// Every setting the calibration set, beside the given value.
    pub changes: Vec<Change>,
    /// What the no-contact frames show of the depth camera (missing returns, noise growing with depth, a fixed
    /// pattern; [`super::camera_fit`]); `None` with fewer than three frames. Set in [`Self::sensor`] when it
    /// shows anything.
    #[serde(default)]
    pub camera: Option<super::camera_fit::CameraFit>,
    /// The membrane's largest drift between runs of no-contact frames, metres ([`super::drift`]).
    #[serde(default)]
    pub drift_m: f64,
    /// Things the user should know (the fit does not explain the frames, too few no-contact frames, ...).
    pub warnings: Vec<String>,
    /// The calibrated sensor: the given one with the settings above.
    pub sensor: SimConfig,
}

/// The images behind a calibration (for its figure), at the recorded frames' resolution, metres.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationImages {
    /// The measured reference: mean of the no-contact frames.
    pub measured: Image,
    /// The calibrated membrane's depth.
    pub fitted: Image,
    /// Measured minus fitted (0 where either is missing).
    pub residual: Image,
}

impl SensorCalibration {
    /// One line per change and warning, for people: millimetres.
    pub fn summary_lines(&self) -> Vec<String> {
        let mut lines: Vec<String> = self
            .changes
            .iter()
            .map(|c| {
                if c.setting.ends_with("_px") {
                    return format!(
                        "{}: {:.1} px (given {:.1} px, from the contact frames with a pose)",
                        c.setting, c.calibrated, c.given
                    );
                }
                let sd = if c.std_error > 0.0 {
                    format!(" +/- {:.2}", c.std_error * 1e3)
                } else {
                    String::new()
                };
                format!(
                    "{}: {:.2} mm{sd} (given {:.2} mm, {:+.2} mm)",
                    c.setting,
                    c.calibrated * 1e3,
                    c.given * 1e3,
                    (c.calibrated - c.given) * 1e3
                )
            })
            .collect();
        lines.push(format!(
            "membrane residual: RMS {:.2} mm (noise alone {:.2} mm, model error {:.2} mm), largest {:.2} mm, over {} \
             no-contact frames",
            self.residual_rms_m * 1e3,
            self.noise_floor_rms_m * 1e3,
            self.model_error_rms_m * 1e3,
            self.residual_max_m * 1e3,
            self.no_contact_frames.len()
        ));
        if let Some(c) = self.camera.as_ref().filter(|c| !c.camera.is_ideal()) {
            let d = &c.camera;
            lines.push(format!(
                "depth camera: noise ∝ depth^{:.1} ({:.2} mm at {:.0} mm), {:.1} % random dropouts, {:.0}-px edge band \
                 without returns, fixed pattern {:.2} mm ({} of {} pixels never returned)",
                d.noise_exponent,
                self.sensor.signature.noise_std * 1e3,
                d.noise_reference_m * 1e3,
                d.dropout * 100.0,
                d.edge_missing_px,
                d.fixed_pattern_m * 1e3,
                c.never_returned_px,
                c.pixels
            ));
        }
        if self.drift_m > super::drift::DRIFT_TOLERANCE_M {
            lines.push(format!(
                "membrane drift: up to {:.2} mm between runs of no-contact frames (calibrated from the {} that agree \
                 with the fitted membrane)",
                self.drift_m * 1e3,
                self.no_contact_frames.len()
            ));
        }
        lines.extend(self.warnings.iter().map(|w| format!("warning: {w}")));
        lines
    }

    /// Set the tactile-shadow width (native pixels) found from contact frames ([`crate::dataset::shadow_fit`]),
    /// listed among the changes.
    pub fn set_shadow(&mut self, shadow_px: f64) {
        self.changes.push(Change {
            setting: "signature.shadow_px".into(),
            given: self.sensor.signature.shadow_px,
            calibrated: shadow_px,
            std_error: 0.0,
        });
        self.sensor.signature.shadow_px = shadow_px;
    }

    /// The largest change of a length setting, metres (how far the given sensor was from the recorded one).
    pub fn largest_change_m(&self) -> f64 {
        self.changes
            .iter()
            .filter(|c| c.setting != "signature.noise_std" && !c.setting.ends_with("_px"))
            .map(|c| (c.calibrated - c.given).abs())
            .fold(0.0, f64::max)
    }
}

/// The intrinsics of frames of `width x height` under `camera` (native, cropped or model-sized).
pub(crate) fn frame_intrinsics(
    sim: &SimConfig,
    width: usize,
    height: usize,
) -> Result<(Intrinsics, InputSize), String> {
    let size = resample::classify(&sim.camera, width, height)?;
    let k = match size {
        InputSize::Native => sim.camera.native,
        InputSize::Cropped => sim.camera.crop(),
        InputSize::Model => sim.camera.intrinsics(),
    };
    Ok((k, size))
}

/// Per-pixel mean over `frames` of the frames that measured the pixel, where at least half of them did (0
/// elsewhere: a pixel that rarely returns is missing; one that drops out now and then is still measured).
pub fn mean_image(frames: &[&Image]) -> Image {
    let first = frames[0];
    let mut out = Image::filled(first.width, first.height, 0.0);
    for (i, o) in out.data.iter_mut().enumerate() {
        let (sum, n) = frames
            .iter()
            .map(|f| f.data[i])
            .filter(|&d| d > 0.0 && d.is_finite())
            .fold((0.0f64, 0usize), |(s, n), d| (s + f64::from(d), n + 1));
        if n > 0 && 2 * n >= frames.len() {
            *o = (sum / n as f64) as f32;
        }
    }
    out
}

/// Standard deviation of the frames about their per-pixel mean `mean` (unbiased: n − 1 degrees of freedom per
/// pixel), over the pixels each frame measured, ignoring deviations over five standard deviations (a contact that slipped into a no-contact frame);
/// `None` with fewer than two frames.
fn spread_about(frames: &[&Image], mean: &Image) -> Option<f64> {
    let n = frames.len();
    if n < 2 {
        return None;
    }
    let pass = |limit: f64| {
        let (mut s, mut count) = (0.0f64, 0usize);
        for f in frames {
            for (&d, &m) in f.data.iter().zip(&mean.data) {
                if m > 0.0 && d > 0.0 {
                    let r = f64::from(d) - f64::from(m);
                    if r.abs() <= limit {
                        s += r * r;
                        count += 1;
                    }
                }
            }
        }
        (count > 0).then(|| (s / count as f64 * n as f64 / (n - 1) as f64).sqrt())
    };
    let all = pass(f64::INFINITY)?;
    let clipped = pass(5.0 * all)?;
    pass(5.0 * clipped)
}

/// The step of the frames' depths when every measured value is a whole number of millimetres (16UC1 recordings).
fn depth_step(frame: &Image) -> Option<f64> {
    let mut any = false;
    for &d in frame.data.iter().filter(|&&d| d > 0.0) {
        let mm = f64::from(d) * 1e3;
        if (mm - mm.round()).abs() > 1e-3 {
            return None;
        }
        any = true;
    }
    any.then_some(1e-3)
}

/// Calibrate the sensor `given` from the no-contact frames of `stream` in `rec` (module docs).
/// `progress(done, total)` is called per frame read; returning false cancels.
pub fn calibrate(
    rec: &Recording,
    stream: &StreamInfo,
    given: &SimConfig,
    config: &CalibrateConfig,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<(SensorCalibration, CalibrationImages), RecordingError> {
    let frames_err = |message: String| RecordingError::Frames {
        path: rec.path().to_path_buf(),
        message,
    };
    let n = stream.messages;
    if n == 0 {
        return Err(frames_err(format!("{} has no frames", stream.name)));
    }
    let picks: Vec<usize> = match config.reference {
        ReferenceChoice::Frame(k) if k < n => vec![k],
        ReferenceChoice::Frame(k) => {
            return Err(frames_err(format!(
                "reference frame {k} is beyond the last frame {}",
                n - 1
            )))
        }
        ReferenceChoice::Auto => {
            let m = config.max_frames.max(2).min(n);
            (0..m)
                .map(|j| j * (n - 1) / (m - 1).max(1))
                .collect::<std::collections::BTreeSet<_>>()
                .into_iter()
                .collect()
        }
    };
    let mut native = Vec::with_capacity(picks.len());
    let mut model = Vec::with_capacity(picks.len());
    for (j, &i) in picks.iter().enumerate() {
        let f = rec.depth_frame(stream, i, &given.camera.native)?;
        if let Some(first) = native.first() {
            let first: &Image = first;
            if (first.width, first.height) != (f.depth.width, f.depth.height) {
                return Err(frames_err(format!(
                    "frame {i} is {}x{} but frame {} is {}x{}",
                    f.depth.width, f.depth.height, picks[0], first.width, first.height
                )));
            }
        }
        model.push(
            resample::to_model(&given.camera, &f.depth)
                .map_err(|m| frames_err(format!("frame {i}: {m}")))?,
        );
        native.push(f.depth);
        if !progress(j + 1, picks.len()) {
            return Err(RecordingError::Cancelled);
        }
    }
    let quiet: Vec<usize> = match config.reference {
        ReferenceChoice::Frame(_) => vec![0],
        ReferenceChoice::Auto => {
            let process = ProcessConfig {
                quiet_threshold_m: config.quiet_threshold_m,
                quiet_frames: usize::MAX,
                ..ProcessConfig::default()
            };
            quiet_frames(&model, &process)
        }
    };
    calibrate_frames(&native, &model, quiet, &picks, n, given, config).map_err(frames_err)
}

/// Calibrate the sensor `given` from frames of the membrane without contact (e.g. `tnd pose --reference`), all of
/// them used: native (or cropped, or model-sized) depth images, metres.
pub fn calibrate_references(
    frames: Vec<Image>,
    given: &SimConfig,
    config: &CalibrateConfig,
) -> Result<(SensorCalibration, CalibrationImages), crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("reference frames", || {
        if frames.is_empty() {
            return Err("no reference frames".into());
        }
        let mut model = Vec::with_capacity(frames.len());
        for (i, f) in frames.iter().enumerate() {
            if (f.width, f.height) != (frames[0].width, frames[0].height) {
                return Err(format!(
                    "reference {i} is {}x{} but reference 0 is {}x{}",
                    f.width, f.height, frames[0].width, frames[0].height
                ));
            }
            model.push(resample::to_model(&given.camera, f)?);
        }
        let all: Vec<usize> = (0..frames.len()).collect();
        calibrate_frames(
            &frames,
            &model,
            all.clone(),
            &all,
            frames.len(),
            given,
            config,
        )
    })
}

#[cfg(test)]
#[path = "calibrate_tests.rs"]
mod tests;
