//! Command-line options shared by several commands, mapped onto the library's config structs.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Result};
use clap::Args;
use tactile_derender::mesh::Units;
use tactile_derender::sensor::camera::parse_resolution;
use tactile_derender::sim::SimConfig;

/// Deepest press any command takes, metres: the whole sensor is about 90 mm deep, so anything deeper is a depth given
/// in millimetres.
const MAX_PRESS_M: f64 = 0.1;

/// Check a press depth given as `flag` (metres): finite, not negative (positive when `positive`), and not deeper
/// than the sensor (then it was given in millimetres: say what it means in metres).
pub fn check_press(flag: &str, press_m: f64, positive: bool) -> Result<()> {
    let sign_ok = if positive {
        press_m > 0.0
    } else {
        press_m >= 0.0
    };
    if !(press_m.is_finite() && sign_ok) {
        return Err(anyhow!(
            "{flag} must be a {} depth in metres, got {press_m}",
            if positive { "positive" } else { "non-negative" }
        ));
    }
    // Not millimetres either (a metre of press): no "did you mean", and no 309 digits for 1e308.
    if press_m > 1000.0 {
        return Err(anyhow!(
            "{flag} {press_m:e} m is deeper than the whole sensor (at most {MAX_PRESS_M} m); depths are in metres"
        ));
    }
    if press_m > MAX_PRESS_M {
        return Err(anyhow!(
            "{flag} {press_m} m is deeper than the whole sensor; depths are in metres (did you mean {}?)",
            press_m / 1000.0
        ));
    }
    Ok(())
}

/// Parse an object pose `X,Y,THETA` given as `flag` (metres, metres, radians), refusing positions no sensor could
/// reach (then they were given in millimetres) and angles beyond a full turn (then they were given in degrees).
pub fn parse_pose(flag: &str, text: &str) -> Result<tactile_derender::sensor::Se2> {
    let pose = tactile_derender::sensor::Se2::parse(text).map_err(|e| anyhow!("{flag}: {e}"))?;
    let slips = pose.unit_slips();
    if slips.is_empty() {
        return Ok(pose);
    }
    // The values meant: millimetres and degrees made metres and radians.
    let far = pose.x.abs().max(pose.y.abs()) > tactile_derender::sensor::MAX_REACH_M;
    let mm = if far { 1e-3 } else { 1.0 };
    let theta = if pose.theta.abs() > std::f64::consts::TAU {
        pose.theta.to_radians()
    } else {
        pose.theta
    };
    Err(anyhow!(
        "{flag} {text}: {} (did you mean {},{},{theta:.4}?)",
        slips.join("; "),
        pose.x * mm,
        pose.y * mm
    ))
}

/// A count given on the command line, at most `MAX` (`value_parser = at_most::<MAX>`): past it a run would only
/// exhaust memory or time (10^12 pairs allocated terabytes up front).
pub fn at_most<const MAX: usize>(s: &str) -> Result<usize, String> {
    let v: usize = s
        .trim()
        .parse()
        .map_err(|e| format!("'{s}' is not a count: {e}"))?;
    if v > MAX {
        return Err(format!("{v} is more than the {MAX} this takes"));
    }
    Ok(v)
}

/// `--force` of a command that writes an output ([`tactile_derender::io::output`]).
#[derive(Args, Clone, Copy, Debug, Default)]
pub struct ForceArg {
    /// Write into a folder that holds files tnd did not write (they are kept, never replaced), or replace an output
    /// file tnd did not write.
    #[arg(long)]
    pub force: bool,
}

/// Sensor, elastomer and signature options: overrides of a sensor file (`--sensor`) or of the library's
/// [`SimConfig`], whose defaults (the Soft Bubble of the paper) apply to every option left out.
#[derive(Args, Clone, Debug)]
pub struct SensorArgs {
    /// A sensor file (JSON, e.g. written by `tnd calibrate --out`): the sensor the options below start from, instead
    /// of the nominal Soft Bubble.
    #[arg(long, value_name = "FILE")]
    pub sensor: Option<PathBuf>,
    /// Rendered (model) resolution WxH, multiples of 8 (default 64x64).
    #[arg(long)]
    pub resolution: Option<String>,
    /// Elastomer inflation height, metres.
    #[arg(long)]
    pub inflation: Option<f64>,
    /// Elastomer footprint LENGTHxWIDTH in metres (e.g. 0.12x0.08).
    #[arg(long)]
    pub footprint: Option<String>,
    /// Elastomer mesh file (OBJ, STL, PLY, glTF/GLB; sensor frame) instead of the parametric membrane.
    #[arg(long)]
    pub elastomer_mesh: Option<PathBuf>,
    /// Units of --elastomer-mesh (m, cm, mm or metres per unit).
    #[arg(long, default_value = "m")]
    pub elastomer_units: String,
    /// Camera distance behind the membrane base, metres.
    #[arg(long)]
    pub camera_offset: Option<f64>,
    /// Tactile-shadow width in native sensor pixels.
    #[arg(long)]
    pub shadow_px: Option<f64>,
    /// Standard deviation of the depth noise, metres (0 disables).
    #[arg(long)]
    pub noise_std: Option<f64>,
}

impl SensorArgs {
    /// The files these options read (an output may not be one of them).
    pub fn inputs(&self) -> Vec<&Path> {
        [self.sensor.as_deref(), self.elastomer_mesh.as_deref()]
            .into_iter()
            .flatten()
            .collect()
    }

    /// The simulator configuration these options describe.
    pub fn sim_config(&self) -> Result<SimConfig> {
        let mut cfg = match &self.sensor {
            Some(path) => tactile_derender::sim::sensor_file::load(path)?,
            None => SimConfig::default(),
        };
        if let Some(r) = &self.resolution {
            cfg.camera.resolution = parse_resolution(r).map_err(|e| anyhow!(e))?;
        }
        if let Some(h) = self.inflation {
            cfg.elastomer.inflation = h;
        }
        if let Some(fp) = &self.footprint {
            let (a, b) = fp
                .split_once(['x', 'X'])
                .and_then(|(a, b)| Some((a.trim().parse().ok()?, b.trim().parse().ok()?)))
                .ok_or_else(|| anyhow!("--footprint '{fp}' must look like 0.12x0.08 (metres)"))?;
            cfg.elastomer.footprint_x = a;
            cfg.elastomer.footprint_y = b;
        }
        if let Some(p) = &self.elastomer_mesh {
            cfg.elastomer.mesh_file = Some(p.clone());
            cfg.elastomer.mesh_units = self.elastomer_units.parse::<Units>()?;
        }
        if let Some(c) = self.camera_offset {
            cfg.mount.position = [0.0, 0.0, -c];
        }
        if let Some(s) = self.shadow_px {
            cfg.signature.shadow_px = s;
        }
        if let Some(n) = self.noise_std {
            cfg.signature.noise_std = n;
        }
        cfg.camera
            .validate()
            .and_then(|()| tactile_derender::sim::bounds::check_settings(&cfg))
            .map_err(|e| anyhow!("sensor setting {}: {}", e.setting, e.message))?;
        Ok(cfg)
    }
}

/// `--figure-size WxH` (pixels).
pub fn parse_figure_size(s: &str) -> Result<tactile_derender::io::figure::FigureConfig, String> {
    let bad = || format!("'{s}' must look like 2400x1000 (pixels)");
    let (w, h) = parse_resolution(s).map_err(|_| bad())?;
    Ok(tactile_derender::io::figure::FigureConfig {
        width_px: u32::try_from(w).map_err(|_| bad())?,
        height_px: u32::try_from(h).map_err(|_| bad())?,
    })
}

/// `--model` with `auto` resolved for an input whose frames were (`resampled`) or were not area-resampled from a
/// camera's larger frame ([`tactile_derender::model::checkpoint::matched_model`]), saying on stderr when that picks
/// the recording model (`what` names the input).
pub fn resolve_model(model: &str, resampled: bool, what: &str) -> String {
    use tactile_derender::model::checkpoint::{matched_model, BUNDLED_RECORDING_MODEL_NAME};
    let picked = matched_model(std::path::Path::new(model), resampled);
    if picked.as_os_str() != model && picked.to_str() == Some(BUNDLED_RECORDING_MODEL_NAME) {
        eprintln!(
            "{what}: frames resampled from the camera's own size, so the bundled recording model (--model auto; \
             --model default for the other)"
        );
    }
    picked.display().to_string()
}

#[cfg(test)]
mod tests {
    use super::{check_press, parse_pose};

    #[test]
    fn depths_and_positions_in_millimetres_are_caught_with_their_metres() {
        assert!(check_press("--press", 0.006, false).is_ok());
        assert!(check_press("--press", 0.0, false).is_ok());
        assert!(check_press("--max-press", 0.0, true).is_err());
        let e = check_press("--press", 6.0, false).unwrap_err().to_string();
        assert!(
            e.starts_with("--press 6 m is deeper") && e.contains("did you mean 0.006?"),
            "{e}"
        );
        assert!(check_press("--press", f64::NAN, false).is_err());
        let p = parse_pose("--pose", "0.002,-0.001,0.35").unwrap();
        assert_eq!((p.x, p.y, p.theta), (0.002, -0.001, 0.35));
        let e = parse_pose("--pose", "2,-1,20").unwrap_err().to_string();
        assert!(
            e.contains("reach")
                && e.contains("full turn")
                && e.contains("did you mean 0.002,-0.001,0.3491?"),
            "{e}"
        );
        let e = parse_pose("--pose", "2,-1,0.5").unwrap_err().to_string();
        assert!(e.contains("did you mean 0.002,-0.001,0.5000?"), "{e}");
        // θ in degrees: 90 is a quarter turn, π/2 rad.
        let e = parse_pose("--pose", "0.003,0,90").unwrap_err().to_string();
        assert!(
            e.contains(
                "θ 90 is more than a full turn; θ is in radians (did you mean 0.003,0,1.5708?)"
            ),
            "{e}"
        );
        let e = parse_pose("--pose", "3,0,-45").unwrap_err().to_string();
        assert!(
            e.contains("reach") && e.contains("did you mean 0.003,0,-0.7854?"),
            "{e}"
        );
        assert_eq!(parse_pose("--pose", "0,0,-6.2").unwrap().theta, -6.2);
        assert!(parse_pose("--truth", "nope")
            .unwrap_err()
            .to_string()
            .starts_with("--truth: "));
    }
}
