//! `tnd calibrate`: fit the sensor (membrane inflation and footprint, camera position, depth noise) to a recording's
//! no-contact frames ([`tactile_derender::recording::calibrate`]), print what changed, and write a sensor file that
//! every command takes as `--sensor FILE`; optionally a figure of the fit (measured and fitted reference, residual).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Result};
use clap::Args;
use tactile_derender::io::preview::{render_panel, save_png, side_by_side, PanelStyle};
use tactile_derender::recording::calibrate::{
    calibrate, CalibrateConfig, CalibrationImages, SensorCalibration,
};
use tactile_derender::recording::Recording;
use tactile_derender::sensor::membrane_fit::MembraneFitConfig;

use crate::args::SensorArgs;
use crate::progress;
use crate::recording_cmd::RecordingReadArgs;

#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// The recording: an .mcap file or a folder of depth frames (16-bit PNG in mm, .npy/.npz). Its frames without
    /// contact are what is fitted; the pressed object need not be known.
    #[arg(long)]
    pub from: PathBuf,
    #[command(flatten)]
    pub read: RecordingReadArgs,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// Fit the footprint too (held by default: within the camera's view a wider footprint looks almost like a
    /// camera further back, so fitting both makes the inflation less certain; see the standard errors).
    #[arg(long)]
    pub fit_footprint: bool,
    /// Keep the given camera position (fit only inflation, footprint and noise).
    #[arg(long)]
    pub keep_camera: bool,
    /// Write the calibrated sensor here (JSON; pass it to any command as --sensor FILE).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write a figure of the fit here (PNG): measured reference, calibrated membrane, residual.
    #[arg(long)]
    pub figure: Option<PathBuf>,
    /// Print the calibration as one JSON object (metres) instead of lines for people.
    #[arg(long)]
    pub json: bool,
}

/// The figure: the measured reference, the calibrated membrane, and their difference.
fn write_figure(path: &Path, cal: &SensorCalibration, images: &CalibrationImages) -> Result<()> {
    let range = images
        .measured
        .range_where(|d| d > 0.0)
        .map(|(lo, hi)| (lo, hi.max(lo + 1e-4)));
    let depth_style = |title: &str| PanelStyle {
        title: title.into(),
        range_m: range,
        scale: 2,
        ..PanelStyle::default()
    };
    let span = (3.0 * cal.residual_rms_m.max(cal.noise_floor_rms_m)).max(2e-4) as f32;
    let panels = [
        render_panel(&images.measured, &depth_style("measured reference")),
        render_panel(&images.fitted, &depth_style("calibrated membrane")),
        render_panel(
            &images.residual,
            &PanelStyle {
                title: "measured - calibrated".into(),
                range_m: Some((-span, span)),
                zero_is_missing: false,
                scale: 2,
                ..PanelStyle::default()
            },
        ),
    ];
    let caption = cal.summary_lines();
    save_png(path, &side_by_side(&panels, &caption))
        .map_err(|e| anyhow!("--figure {}: {e}", path.display()))
}

/// Say on stderr what a command that calibrates by default found (or why it could not), and how to turn it off.
pub fn tell_calibration(from: &Path, cal: Option<&SensorCalibration>, failed: Option<&str>) {
    match (cal, failed) {
        (Some(c), _) => {
            eprintln!(
                "{}: sensor calibrated from {} no-contact frame(s) (--no-calibrate keeps the given sensor; the \
                 largest change is {:.2} mm):",
                from.display(),
                c.no_contact_frames.len(),
                c.largest_change_m() * 1e3
            );
            for line in c.summary_lines() {
                eprintln!("  {line}");
            }
        }
        (None, Some(why)) => eprintln!(
            "warning: {}: the sensor could not be calibrated from the recording, the given sensor is used: {why}",
            from.display()
        ),
        (None, None) => {}
    }
}

pub fn run(a: CalibrateArgs) -> Result<()> {
    let given = a.sensor.sim_config()?;
    let rec = Recording::open(&a.from, &a.read.folder())?;
    let stream = rec.depth_stream(a.read.topic.as_deref())?.clone();
    let config = CalibrateConfig {
        reference: a.read.reference,
        fit: MembraneFitConfig {
            footprint: a.fit_footprint,
            camera_position: !a.keep_camera,
            ..MembraneFitConfig::default()
        },
        ..CalibrateConfig::default()
    };
    let mut bar = progress::bar("frames", "frame", 0);
    let result = calibrate(
        &rec,
        &stream,
        &given,
        &config,
        &mut progress::callback(&mut bar),
    );
    progress::finish(&mut bar);
    let (cal, images) = result?;
    if let Some(out) = &a.out {
        tactile_derender::sim::sensor_file::save(out, &cal.sensor)?;
    }
    if let Some(fig) = &a.figure {
        write_figure(fig, &cal, &images)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&cal)?);
        return Ok(());
    }
    println!(
        "{}: {} no-contact frame(s) of {} ({}, {}x{})",
        a.from.display(),
        cal.no_contact_frames.len(),
        cal.frames,
        stream.name,
        cal.frame_size[0],
        cal.frame_size[1]
    );
    for line in cal.summary_lines() {
        println!("  {line}");
    }
    if let Some(s) = cal.noise_std_model_m {
        println!(
            "  noise at the model's {}x{}: {:.2} mm per pixel",
            cal.sensor.camera.resolution.0,
            cal.sensor.camera.resolution.1,
            s * 1e3
        );
    }
    match &a.out {
        Some(out) => println!(
            "wrote {}: pass --sensor {} to tnd sim, pose, sample, dataset gen/import and recording track",
            out.display(),
            out.display()
        ),
        None => println!("(nothing written: --out FILE writes the calibrated sensor)"),
    }
    Ok(())
}
