//! `tnd calibrate`: fit the sensor (membrane inflation and footprint, camera position, depth noise) to a recording's
//! no-contact frames ([`tactile_derender::recording::calibrate`]), print what changed, and write a sensor file that
//! every command takes as `--sensor FILE`; optionally a figure of the fit (measured and fitted reference, residual).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use clap::Args;
use tactile_derender::io::preview::{render_panel, save_png, side_by_side, PanelStyle};
use tactile_derender::recording::calibrate::{
    calibrate, CalibrateConfig, CalibrationImages, SensorCalibration,
};
use tactile_derender::recording::Recording;
use tactile_derender::sensor::membrane_fit::MembraneFitConfig;

use crate::args::SensorArgs;
use crate::progress;
use tactile_derender::recording::ReadConfig;

#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// The recording: an .mcap file or a folder of depth frames (16-bit PNG in mm, .npy/.npz). Its frames without
    /// contact are what is fitted; the pressed object need not be known.
    #[arg(long)]
    pub from: PathBuf,
    #[command(flatten)]
    pub read: ReadConfig,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// Fit the footprint too (held by default: within the camera's view a wider footprint looks almost like a
    /// camera further back, so fitting both makes the inflation less certain; see the standard errors).
    #[arg(long)]
    pub fit_footprint: bool,
    /// Keep the given camera position (fit only inflation, footprint and noise).
    #[arg(long)]
    pub keep_camera: bool,
    /// The pressed object (an entry of --objects): with the recording's object poses (its pose topic, or --poses)
    /// the contact frames calibrate the tactile-shadow width too.
    #[arg(long)]
    pub object: Option<String>,
    /// Object set of --object: "builtin" or a directory with objects.json.
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    /// CSV of the object's pose per frame (columns frame or stamp_ns, x, y, theta, optional press) for --object;
    /// default: the recording's pose topic.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Also write the measured membrane here (OBJ, sensor frame, metres): the calibrated dome plus the measured
    /// residual, smoothed, closed into a solid; the sensor file then uses it as its membrane. For a membrane the
    /// dome cannot explain (the calibration warns of its model error).
    #[arg(long, value_name = "OBJ")]
    pub measured_membrane: Option<PathBuf>,
    /// Write the calibrated sensor here (JSON; pass it to any command as --sensor FILE).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write a figure of the fit here (PNG): measured reference, calibrated membrane, residual.
    #[arg(long)]
    pub figure: Option<PathBuf>,
    /// Print the calibration as one JSON object (metres) instead of lines for people.
    #[arg(long)]
    pub json: bool,
    /// Replace --out, --figure or --measured-membrane files that tnd did not write (otherwise refused; tnd's own
    /// are replaced).
    #[arg(long)]
    pub force: bool,
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

/// Say on stderr how far the membrane drifted between the recording's no-contact stretches, when it did, and what
/// was done about it ([`tactile_derender::recording::drift`]).
pub fn tell_drift(
    from: &Path,
    drift: f64,
    stretches: &[tactile_derender::recording::drift::QuietStretch],
) {
    use tactile_derender::recording::drift::{DRIFT_TOLERANCE_M, DRIFT_WARNING_M};
    if drift <= DRIFT_TOLERANCE_M {
        return;
    }
    let per_stretch: Vec<String> = stretches
        .iter()
        .map(|s| format!("frames {}-{}: {:+.2} mm", s.first, s.last, s.drift_m * 1e3))
        .collect();
    let listed = if per_stretch.is_empty() {
        String::new()
    } else {
        format!(" ({})", per_stretch.join(", "))
    };
    eprintln!(
        "{}{}: the membrane drifted up to {:.2} mm between no-contact stretches{listed}; each frame's imprint is \
         taken against the references before and after it, blended by its time",
        if drift > DRIFT_WARNING_M { "warning: " } else { "" },
        from.display(),
        drift * 1e3,
    );
    if drift > DRIFT_WARNING_M {
        eprintln!(
            "  past {:.1} mm a contact long after its no-contact frames may carry the drift in its imprint; record \
             an undeformed frame before every press",
            DRIFT_WARNING_M * 1e3
        );
    }
}

/// The tactile-shadow width from the recording's contact frames with a known pose of `name` (set in `cal`).
fn fit_shadow_width(
    a: &CalibrateArgs,
    rec: &Recording,
    stream: &tactile_derender::recording::StreamInfo,
    name: &str,
    cal: &mut SensorCalibration,
) -> Result<()> {
    use tactile_derender::dataset::import_recording::{
        frame_poses, noise_free_simulator, PoseSource,
    };
    use tactile_derender::dataset::shadow_fit::{fit_shadow, ContactFrame};
    let set = tactile_derender::objects::ObjectSet::open(&a.objects)?;
    let object = tactile_derender::sim::PreparedObject::new(set.mesh(name)?)?;
    let processed = tactile_derender::recording::process(
        rec,
        stream,
        &cal.sensor.camera,
        &a.read.process(),
        &mut |_, _| true,
    )?;
    let source = match &a.poses {
        Some(csv) => PoseSource::Csv(csv.clone()),
        None => PoseSource::Topic(None),
    };
    let poses = frame_poses(
        rec,
        &processed.stamps_ns,
        &source,
        tactile_derender::recording::source::DEFAULT_MAX_POSE_GAP_S,
    )?;
    let frames: Vec<ContactFrame> = (0..processed.len())
        .filter(|&i| processed.contact_px[i] >= 10)
        .filter_map(|i| {
            poses[i].map(|p| ContactFrame {
                imprint: &processed.imprints[i],
                pose: p.pose,
                press: p.press,
            })
        })
        .collect();
    let sim = noise_free_simulator(&cal.sensor)?;
    match fit_shadow(
        &sim,
        &object,
        &frames,
        tactile_derender::dataset::import_recording::DEFAULT_MAX_PRESS_M,
    ) {
        Some(fit) => cal.set_shadow(fit.shadow_px),
        None => cal.warnings.push(format!(
            "no contact frame with a pose of {name}: the shadow width is the given one"
        )),
    }
    Ok(())
}

pub fn run(a: CalibrateArgs) -> Result<()> {
    let mut inputs = a.sensor.inputs();
    inputs.push(&a.from);
    inputs.extend(a.poses.as_deref());
    // Each output file, and how to know one tnd wrote.
    type Output<'a> = (&'a str, Option<&'a Path>, &'a dyn Fn(&Path) -> bool);
    let outputs: [Output; 3] = [
        (
            "--out",
            a.out.as_deref(),
            &tactile_derender::sim::sensor_file::written_by_tnd,
        ),
        (
            "--figure",
            a.figure.as_deref(),
            &tactile_derender::io::preview::written_by_tnd,
        ),
        (
            "--measured-membrane",
            a.measured_membrane.as_deref(),
            &tactile_derender::mesh::obj::written_by_tnd,
        ),
    ];
    let given: Vec<&Path> = outputs.iter().filter_map(|o| o.1).collect();
    if let Some(twice) = given
        .iter()
        .enumerate()
        .find_map(|(i, p)| given[..i].contains(p).then_some(p))
    {
        bail!(
            "{} is given as two outputs: each needs a file of its own",
            twice.display()
        );
    }
    let _claims = outputs
        .into_iter()
        .filter_map(|(flag, path, ours)| Some((flag, path?, ours)))
        .map(|(flag, path, ours)| crate::outputs::file(flag, path, a.force, &inputs, ours))
        .collect::<Result<Vec<_>>>()?;
    let given = a.sensor.sim_config()?;
    let rec = Recording::open(&a.from, &a.read.folder())?;
    let stream = rec.depth_stream(a.read.topic.as_deref())?.clone();
    let config = CalibrateConfig {
        fit: MembraneFitConfig {
            footprint: a.fit_footprint,
            camera_position: !a.keep_camera,
            ..MembraneFitConfig::default()
        },
        ..CalibrateConfig::reading(&a.read.process())
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
    let (mut cal, images) = result?;
    if let Some(name) = &a.object {
        fit_shadow_width(&a, &rec, &stream, name, &mut cal)?;
    }
    if let Some(obj) = &a.measured_membrane {
        let mesh = tactile_derender::recording::measured_membrane::measured_membrane(&cal, &images)
            .map_err(|e| anyhow!("--measured-membrane {}: {e}", obj.display()))?;
        tactile_derender::mesh::obj::write(obj, &mesh)?;
        let path = std::fs::canonicalize(obj).unwrap_or_else(|_| obj.clone());
        cal.sensor.elastomer.mesh_file = Some(path);
        cal.sensor.elastomer.mesh_units = tactile_derender::mesh::Units::M;
    }
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
