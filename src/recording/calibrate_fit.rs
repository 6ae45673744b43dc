//! **Sensor calibration from a recording, the fit** ([`super`]): from frames already read, the membrane fitted to the
//! frames without contact in two passes (frames the first fit finds pushed in are left out of the second), the
//! residual and how much of it the noise does not explain, the depth camera's artefacts and the membrane's drift,
//! and the calibrated sensor with every change and warning.

use super::{
    depth_step, frame_intrinsics, mean_image, spread_about, CalibrateConfig, CalibrationImages,
    Change, SensorCalibration, MODEL_ERROR_WARNING_M,
};
use crate::image::Image;
use crate::recording::camera_fit::{self, CameraFit};
use crate::recording::{drift, process};
use crate::sensor::membrane_fit::{self, MembraneParams};
use crate::sensor::resample::InputSize;
use crate::sensor::Intrinsics;
use crate::sim::{SimConfig, Simulator};

/// The calibration from frames already read (`native` at their own resolution, `model` resampled), `quiet` the
/// indices of those without contact, `picks` the recording's frame number of each, `frames` the recording's length.
pub(super) fn calibrate_frames(
    native: &[Image],
    model: &[Image],
    quiet: Vec<usize>,
    picks: &[usize],
    frames: usize,
    given: &SimConfig,
    config: &CalibrateConfig,
) -> Result<(SensorCalibration, CalibrationImages), String> {
    let (width, height) = (native[0].width, native[0].height);
    let (intrinsics, _) = frame_intrinsics(given, width, height)?;
    let mut warnings = Vec::new();
    let step = depth_step(&native[quiet[0]]);
    let start = given_params(given);
    let membrane_fitted = given.elastomer.mesh_file.is_none();
    if !membrane_fitted {
        warnings.push(format!(
            "the membrane is the mesh file {}: checked against the frames, not fitted",
            given
                .elastomer
                .mesh_file
                .as_deref()
                .map_or_else(String::new, |p| p.display().to_string())
        ));
    }
    let (used, fit) = fit_unpressed(native, quiet, step, &intrinsics, given, config)?;
    // What was said and measured of the frames without contact is of those the fit used, after the pushed-in ones
    // were dropped (the first pass's set may hold a pressed frame).
    warnings.extend(few_frames_warning(used.len()));
    let used_model: Vec<&Image> = used.iter().map(|&q| &model[q]).collect();
    let noise_std_model_m = spread_about(&used_model, &mean_image(&used_model));
    let residual = Residual::of(&fit.measured, &fit.fitted);
    let noise_floor_rms_m =
        fit.noise_std_m.unwrap_or(given.signature.noise_std) / (used.len() as f64).sqrt();
    // The camera, from the frames the fit used (the noise: theirs, or the given); its fixed pattern is part of
    // the residual that is no error of the membrane.
    let used_frames: Vec<&Image> = used.iter().map(|&q| &native[q]).collect();
    let camera = camera_fit::fit_camera(
        &used_frames,
        &fit.measured,
        &fit.fitted,
        fit.noise_std_m.unwrap_or(given.signature.noise_std),
    );
    let pattern = camera.as_ref().map_or(0.0, |c| c.camera.fixed_pattern_m);
    let model_error_rms_m = model_error_rms(&fit, &residual, noise_floor_rms_m, pattern);
    if model_error_rms_m.is_nan() || model_error_rms_m > MODEL_ERROR_WARNING_M {
        warnings.push(model_error_warning(
            membrane_fitted,
            &residual,
            noise_floor_rms_m,
            model_error_rms_m,
        ));
    }

    let drift_m = frames_drift(model, &used);
    if drift_m > drift::DRIFT_WARNING_M {
        warnings.push(format!(
            "the membrane drifted up to {:.2} mm between runs of no-contact frames: the calibration is of their mean, \
             and its noise includes the drift; calibrate from a recording without a press in the middle",
            drift_m * 1e3
        ));
    }
    let sensor = calibrated_sensor(given, camera.as_ref(), &fit.params, fit.noise_std_m);
    let changes = calibration_changes(given, &start, &fit, config);
    let params = fit.params;
    if (params.inflation_m - start.inflation_m).abs() > 0.008 {
        warnings.push(format!(
            "the inflation is {:.1} mm from the given {:.1} mm: is the recording of this sensor, and is its depth in \
             the units the reader assumed?",
            (params.inflation_m - start.inflation_m).abs() * 1e3,
            start.inflation_m * 1e3
        ));
    }
    crate::sim::bounds::check_settings(&sensor).map_err(|e| {
        format!(
            "the calibrated sensor cannot exist ({}: {}): do the frames show this sensor's inflated membrane, with \
             depths in the units the reader assumed?",
            e.setting, e.message
        )
    })?;
    let calibration = SensorCalibration {
        inflation_m: params.inflation_m,
        footprint_m: params.footprint_m,
        camera_position_m: params.camera_position_m,
        noise_std_m: fit.noise_std_m,
        noise_std_model_m,
        depth_step_m: step,
        residual_rms_m: residual.rms_m,
        residual_max_m: residual.max_m,
        noise_floor_rms_m,
        model_error_rms_m,
        membrane_fitted,
        frames,
        frames_read: picks.len(),
        no_contact_frames: used.iter().map(|&q| picks[q]).collect(),
        frame_size: [width, height],
        changes,
        camera,
        drift_m,
        warnings,
        sensor,
    };
    Ok((
        calibration,
        CalibrationImages {
            measured: fit.measured,
            fitted: fit.fitted,
            residual: residual.image,
        },
    ))
}

/// Whether `frame` is pushed in somewhere against the membrane's depth `fitted`: an 11 x 11-window mean of
/// frame minus membrane more than 0.5 mm, and six times what the noise `sigma` leaves such a mean, towards the camera.
fn pushed_in(frame: &Image, fitted: &Image, sigma: f64) -> bool {
    let diff = fitted.zip_map(frame, |f, d| if f > 0.0 && d > 0.0 { f - d } else { 0.0 });
    let limit = 5e-4f64.max(6.0 * sigma / 11.0);
    process::box_means(&diff, 5).into_iter().any(|m| m > limit)
}

/// The given sensor's membrane as fit parameters.
fn given_params(sim: &SimConfig) -> MembraneParams {
    MembraneParams {
        footprint_m: [sim.elastomer.footprint_x, sim.elastomer.footprint_y],
        inflation_m: sim.elastomer.inflation,
        camera_position_m: sim.mount.position,
    }
}

/// The largest drift between runs of consecutive frames among `used` (indices into `model`, model resolution):
/// [`drift`]'s measure of each run's mean from the first's, their spread; 0 with one run.
fn frames_drift(model: &[Image], used: &[usize]) -> f64 {
    let means: Vec<Image> = drift::runs(used)
        .into_iter()
        .map(|(a, b)| mean_image(&(a..=b).map(|k| &model[k]).collect::<Vec<_>>()))
        .collect();
    means.first().map_or(0.0, |first| {
        drift::spread(means.iter().map(|m| drift::drift_between(first, m)))
    })
}

/// The membrane of one pass over frames without contact, and what the frames measured.
struct FittedMembrane {
    /// The frames' per-pixel mean: the measured reference.
    measured: Image,
    /// The frames' depth noise with the depth encoding's rounding taken out; `None` with fewer than two frames.
    noise_std_m: Option<f64>,
    /// The fitted membrane (a mesh membrane: the given one).
    params: MembraneParams,
    /// Standard errors of `params`; `None` where the membrane is a mesh, checked and not fitted.
    std_error: Option<MembraneParams>,
    /// The membrane's depth at the frames' resolution.
    fitted: Image,
}

/// The membrane fitted to the frames `quiet` of `native` (without contact, at intrinsics `intrinsics`) in two
/// passes: a light touch can hide among the frames without contact (it stands out of the noise only once the
/// membrane is known), so frames the first fit finds pushed in are left out of the second. Returns the frames the
/// final fit used, and the fit.
fn fit_unpressed(
    native: &[Image],
    quiet: Vec<usize>,
    step: Option<f64>,
    intrinsics: &Intrinsics,
    given: &SimConfig,
    config: &CalibrateConfig,
) -> Result<(Vec<usize>, FittedMembrane), String> {
    let start = given_params(given);
    let mut used = quiet;
    let mut pass = 0;
    loop {
        pass += 1;
        let frames: Vec<&Image> = used.iter().map(|&q| &native[q]).collect();
        let fit = fit_pass(&frames, step, intrinsics, &start, given, config)?;
        let sigma = fit.noise_std_m.unwrap_or(given.signature.noise_std);
        let keep: Vec<usize> = used
            .iter()
            .copied()
            .filter(|&q| !pushed_in(&native[q], &fit.fitted, sigma))
            .collect();
        if pass == 2 || keep.len() == used.len() || keep.is_empty() {
            return Ok((used, fit));
        }
        used = keep;
    }
}

/// One pass of the membrane fit: the mean and noise of `frames` (the depth encoding's rounding `step` taken out of
/// the noise), and the parametric membrane fitted to the mean from `start` (as `config.fit` allows), or, where the
/// sensor's membrane is a mesh, the mesh's depth to check against.
fn fit_pass(
    frames: &[&Image],
    step: Option<f64>,
    intrinsics: &Intrinsics,
    start: &MembraneParams,
    given: &SimConfig,
    config: &CalibrateConfig,
) -> Result<FittedMembrane, String> {
    let measured = mean_image(frames);
    let noise_std_m = spread_about(frames, &measured).map(|s| {
        let rounding = step.map_or(0.0, |q| q * q / 12.0);
        (s * s - rounding).max(0.25 * s * s).sqrt()
    });
    let (params, std_error, fitted) = if given.elastomer.mesh_file.is_none() {
        let t_sensor_camera = given.mount.t_sensor_camera();
        let fit = membrane_fit::fit(&measured, intrinsics, &t_sensor_camera, start, &config.fit)
            .map_err(|e| format!("membrane fit: {e}"))?;
        let fitted = membrane_fit::render(&fit.params, intrinsics, &t_sensor_camera);
        (fit.params, Some(fit.std_error), fitted)
    } else {
        (
            *start,
            None,
            mesh_depth(given, measured.width, measured.height)?,
        )
    };
    Ok(FittedMembrane {
        measured,
        noise_std_m,
        params,
        std_error,
        fitted,
    })
}

/// A mesh membrane is checked, not fitted: its rendering at the frames' resolution (`width x height`: native or
/// model-sized; all 0 at any other size).
fn mesh_depth(given: &SimConfig, width: usize, height: usize) -> Result<Image, String> {
    let sim = match frame_intrinsics(given, width, height).map(|(_, s)| s) {
        Ok(InputSize::Native) => Some(Simulator::native(given.clone())),
        Ok(InputSize::Model) => Some(Simulator::new(given.clone())),
        _ => None,
    }
    .transpose()
    .map_err(|e| e.to_string())?;
    Ok(sim.map_or_else(
        || Image::filled(width, height, 0.0),
        |s| s.nominal_depth().clone(),
    ))
}

/// The warning when fewer than three frames without contact were used (`n` of them), else `None`.
fn few_frames_warning(n: usize) -> Option<String> {
    (n < 3).then(|| {
        format!(
            "only {} frame(s) without contact: the membrane fit is less certain{}; record a second of the sensor \
             touching nothing",
            n,
            if n < 2 {
                " and the noise cannot be measured"
            } else {
                ""
            }
        )
    })
}

/// The measured reference minus the membrane's depth, metres.
struct Residual {
    /// Per pixel, 0 where either is missing.
    image: Image,
    /// RMS over the pixels where both are measured (NaN where none is).
    rms_m: f64,
    /// Largest absolute value there.
    max_m: f64,
}

impl Residual {
    /// `measured` minus `fitted`, and its RMS and largest value over the pixels both measured.
    fn of(measured: &Image, fitted: &Image) -> Self {
        let image = measured.zip_map(fitted, |m, f| if m > 0.0 && f > 0.0 { m - f } else { 0.0 });
        let residuals: Vec<f64> = image
            .data
            .iter()
            .zip(&measured.data)
            .zip(&fitted.data)
            .filter(|((_, &m), &f)| m > 0.0 && f > 0.0)
            .map(|((&r, _), _)| f64::from(r))
            .collect();
        let rms_m = if residuals.is_empty() {
            f64::NAN
        } else {
            (residuals.iter().map(|r| r * r).sum::<f64>() / residuals.len() as f64).sqrt()
        };
        let max_m = residuals.iter().map(|r| r.abs()).fold(0.0, f64::max);
        Self {
            image,
            rms_m,
            max_m,
        }
    }
}

/// What the noise does not explain: the residual's RMS beyond the noise floor `noise_floor_rms_m` and the depth
/// camera's fixed `pattern`, in quadrature. Without a measured noise (one frame) the given noise may be off, and so
/// would this be: there the residual's 5 x 5-window mean is judged instead (a membrane's error is smooth; noise
/// averages down five times).
fn model_error_rms(
    fit: &FittedMembrane,
    residual: &Residual,
    noise_floor_rms_m: f64,
    pattern: f64,
) -> f64 {
    if fit.noise_std_m.is_some() {
        (residual.rms_m.powi(2) - noise_floor_rms_m.powi(2) - pattern.powi(2))
            .max(0.0)
            .sqrt()
    } else {
        let smooth = process::box_means(&residual.image, 2);
        let seen: Vec<f64> = (0..smooth.len())
            .filter(|&i| fit.measured.data[i] > 0.0 && fit.fitted.data[i] > 0.0)
            .map(|i| smooth[i])
            .collect();
        let rms = (seen.iter().map(|r| r * r).sum::<f64>() / seen.len().max(1) as f64).sqrt();
        (rms.powi(2) - (noise_floor_rms_m / 5.0).powi(2))
            .max(0.0)
            .sqrt()
    }
}

/// The warning that the membrane (fitted, or the given mesh) does not explain the no-contact frames, with the
/// residual's numbers and what to do.
fn model_error_warning(
    membrane_fitted: bool,
    residual: &Residual,
    noise_floor_rms_m: f64,
    model_error_rms_m: f64,
) -> String {
    format!(
        "the {} membrane does not explain the no-contact frames: residual RMS {:.2} mm where the noise alone \
         leaves {:.2} mm ({:.2} mm of model error; largest residual {:.2} mm); the membrane may sag or be dented, \
         the camera tilted, or the frames not of this sensor: look at the residual map (tnd calibrate --figure) \
         and use the measured membrane (tnd calibrate --measured-membrane membrane.obj --out sensor.json)",
        if membrane_fitted { "calibrated" } else { "given" },
        residual.rms_m * 1e3,
        noise_floor_rms_m * 1e3,
        model_error_rms_m * 1e3,
        residual.max_m * 1e3
    )
}

/// The given sensor with the calibrated membrane `params`, the measured noise (where measured) and the depth
/// camera's artefacts (where `camera` shows any).
fn calibrated_sensor(
    given: &SimConfig,
    camera: Option<&CameraFit>,
    params: &MembraneParams,
    noise_std_m: Option<f64>,
) -> SimConfig {
    let mut sensor = given.clone();
    if let Some(c) = camera.filter(|c| !c.camera.is_ideal()) {
        sensor.depth_camera = c.camera.clone();
    }
    sensor.elastomer.footprint_x = params.footprint_m[0];
    sensor.elastomer.footprint_y = params.footprint_m[1];
    sensor.elastomer.inflation = params.inflation_m;
    sensor.mount.position = params.camera_position_m;
    if let Some(s) = noise_std_m {
        sensor.signature.noise_std = s;
    }
    sensor
}

/// Every setting the calibration set, beside the given value (`start` for the membrane): the fitted membrane's
/// parameters `config.fit` frees (only where the membrane was fitted), then the measured noise.
fn calibration_changes(
    given: &SimConfig,
    start: &MembraneParams,
    fit: &FittedMembrane,
    config: &CalibrateConfig,
) -> Vec<Change> {
    let params = &fit.params;
    let mut changes = Vec::new();
    if let Some(sd) = fit.std_error {
        let mut push = |setting: &str, given: f64, calibrated: f64, std_error: f64| {
            changes.push(Change {
                setting: setting.into(),
                given,
                calibrated,
                std_error,
            })
        };
        push(
            "elastomer.inflation",
            start.inflation_m,
            params.inflation_m,
            sd.inflation_m,
        );
        if config.fit.footprint {
            for (i, axis) in ["footprint_x", "footprint_y"].iter().enumerate() {
                push(
                    &format!("elastomer.{axis}"),
                    start.footprint_m[i],
                    params.footprint_m[i],
                    sd.footprint_m[i],
                );
            }
        }
        if config.fit.camera_position {
            for (i, axis) in ["x", "y", "z"].iter().enumerate() {
                push(
                    &format!("mount.position.{axis}"),
                    start.camera_position_m[i],
                    params.camera_position_m[i],
                    sd.camera_position_m[i],
                );
            }
        }
    }
    if let Some(s) = fit.noise_std_m {
        changes.push(Change {
            setting: "signature.noise_std".into(),
            given: given.signature.noise_std,
            calibrated: s,
            std_error: 0.0,
        });
    }
    changes
}
