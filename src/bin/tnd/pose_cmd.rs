//! `tnd pose`: one tactile signature end to end, through the same use cases as the workbench's De-render and Pose
//! tabs ([`tactile_derender::pipeline`]) — N samples of the in-contact depth, the pose from a K-start registration
//! of the first, every sample registered from that fixed start, the multi-sample estimate (the samples' consensus
//! contact), the threshold baseline, the uncertainty outputs (samples.csv, kde.csv, contact_probability.npy,
//! pose.json), the figures (uncertainty and fit, SVG + PNG) and the geometry as PLY (contact, free-space and consensus points, the object
//! at each estimate; world frame, metres).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use clap::Args;
use tactile_derender::io::figure::FigureConfig;
use tactile_derender::io::npy;
use tactile_derender::io::ply::PlyEncoding;
use tactile_derender::model::DiffusionModel;
use tactile_derender::pipeline::pose_record::{PoseRecord, RecordSource};
use tactile_derender::pipeline::press::PressChoice;
use tactile_derender::pipeline::{self, DerenderConfig, ObjectSpec};
use tactile_derender::pose::from_depth::contact_probability;
use tactile_derender::pose::PoseConfig;
use tactile_derender::sim::{PreparedObject, Simulator};

use super::args::SensorArgs;
use super::progress;

#[derive(Args, Debug)]
pub struct PoseArgs {
    /// The generator: a model checkpoint, a bundled model (`auto`: `recording` for frames resampled from a
    /// camera's native or cropped size, `default` for frames at the model resolution; `small`: twice as fast), or
    /// `ground-truth` (then --target is the "generated" X0).
    #[arg(long, default_value = "auto")]
    pub model: String,
    #[command(flatten)]
    pub measured: crate::measured::MeasuredArgs,
    #[command(flatten)]
    pub object: ObjectSpec,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// The true in-contact depth X0 (.npy), used by --model ground-truth.
    #[arg(long)]
    pub target: Option<PathBuf>,
    #[command(flatten)]
    pub pose: PoseConfig,
    /// The true pose X,Y,THETA (metres, metres, radians; errors are measured against it, otherwise against the
    /// first registration's best hypothesis, `best_hypothesis` in pose.json, where every sample's registration
    /// starts: the signature check's estimate may differ from it).
    #[arg(long, allow_hyphen_values = true)]
    pub truth: Option<String>,
    /// Press depth of the sensor apex below the object's top, to place the sensor over the object: "auto" (found
    /// from the samples and, with --signature, the press whose registered pose best explains the signature, as
    /// `tnd recording track` does; a sensor does not measure it) or metres (a simulation's --press).
    #[arg(long, default_value = "auto", allow_hyphen_values = true)]
    pub press: PressChoice,
    #[command(flatten)]
    pub derender: DerenderConfig,
    /// Encoding of the PLY files (contact, free-space and consensus points, the object at each estimate).
    #[arg(long, value_enum, default_value_t = PlyEncoding::Binary)]
    pub ply: PlyEncoding,
    /// Size of the figures (uncertainty and fit, SVG + PNG), pixels WxH.
    #[arg(long, default_value = "2400x1000", value_parser = super::args::parse_figure_size)]
    pub figure_size: FigureConfig,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
    #[command(flatten)]
    pub rerun: crate::rerun_out::RerunArgs,
}

pub fn run(a: PoseArgs) -> Result<()> {
    let mut inputs = a.measured.inputs();
    inputs.extend(a.sensor.inputs());
    inputs.extend([Path::new(&a.model), Path::new(&a.object.object)]);
    inputs.extend(a.target.as_deref());
    let _out = crate::outputs::folder("--out", &a.out, a.force.force, &inputs)?;
    let measured = a
        .measured
        .read(a.sensor.sim_config()?, a.sensor.sensor.is_some(), false)?;
    let sim = Simulator::new(measured.sim.clone())?;
    let rrd = a.rerun.open("tnd pose", a.force.force, &inputs)?;
    let (imprint, signature, resampled) =
        (measured.imprint, measured.signature, measured.resampled);
    let input_name = a
        .measured
        .imprint
        .as_ref()
        .or(a.measured.signature.as_ref())
        .map_or_else(String::new, |p| p.display().to_string());
    let object = a.object.load()?;
    object.check_scale("a pose")?;
    let prepared = PreparedObject::new(object.mesh.clone())?;
    let truth = a
        .truth
        .as_deref()
        .map(|t| crate::args::parse_pose("--truth", t))
        .transpose()?;
    let (generator, samples, probability) = if a.model == "ground-truth" {
        let target = a.target.as_ref().ok_or_else(|| {
            anyhow!("--model ground-truth needs --target FILE.npy (the in-contact depth to use as every sample)")
        })?;
        let target = crate::measured::read_model(target, sim.config())?;
        (
            "ground-truth".to_string(),
            vec![target; a.derender.samples.max(1)],
            None,
        )
    } else {
        let device = tactile_derender::model::device::open_device(&a.derender.device)?;
        let model_path = crate::args::resolve_model(&a.model, resampled, &input_name);
        let model = DiffusionModel::load_on(Path::new(&model_path), &device)?;
        let guidance = pipeline::imprint_guidance(&a.derender, &sim, &imprint, signature.as_ref())?;
        let mut bar = progress::bar("sampling", " steps", 0);
        let out = pipeline::derender(
            &model,
            &imprint,
            guidance.as_ref(),
            &a.derender,
            a.pose.consensus_probability,
            &mut progress::callback(&mut bar),
        )?;
        progress::finish(&mut bar);
        let guided = if guidance.is_some() {
            ", imprint-guided"
        } else {
            ""
        };
        (
            format!("model {}{guided}", model.source().display()),
            out.samples,
            Some(out.contact_probability),
        )
    };
    // A frame brought down from the camera's native pixels is predicted the same way by the signature check.
    let camera_path =
        tactile_derender::pose::camera_path::CameraPath::for_frames(sim.config(), resampled)?;
    let observation = pipeline::Observation {
        samples: &samples,
        imprint: &imprint,
        signature: signature.as_ref(),
        truth,
        prior: None,
        camera_path: camera_path.as_ref(),
    };
    let mut bar = progress::bar("registering", " fits", 0);
    let placed = match pipeline::place_and_estimate(
        &object,
        Some(&prepared),
        &sim,
        &observation,
        pipeline::Placement::Press(a.press),
        &tactile_derender::pose::Estimator::new(a.pose.clone()),
        a.derender.seed,
        &mut progress::callback(&mut bar),
    ) {
        Err(tactile_derender::pipeline::PipelineError::NoContact) => {
            bail!("{input_name}: no sample has any contact; nothing to register")
        }
        other => other?,
    };
    progress::finish(&mut bar);
    let input = placed.input(&observation);
    let estimate = &placed.estimate;
    let report = &estimate.report;
    warn_ambiguous(estimate, &object.symmetry);
    report.write_with(&a.out, &a.figure_size)?;
    pipeline::write_fit_figure(&a.out, &object, &sim, &input, estimate, &a.figure_size)?;
    if samples.len() > 1 {
        let p = match probability {
            Some(p) => p,
            None => contact_probability(&samples)?,
        };
        npy::write_image(&a.out.join("contact_probability.npy"), &p)?;
    }
    let geometry = pipeline::write_pose_geometry(
        &a.out,
        &object,
        &sim,
        &input,
        estimate,
        &a.pose,
        a.derender.seed,
        a.ply,
    )?;
    if let Some(log) = &rrd {
        log_to_rerun(log, &object, &sim, &input, estimate, &imprint, truth)?;
    }
    let rerun = crate::rerun_out::finish(rrd)?;
    let record = PoseRecord::new(
        &placed,
        truth,
        &object.symmetry,
        RecordSource {
            generator,
            seed: a.derender.seed,
            calibration: measured.calibration,
            out: a.out.clone(),
            rerun,
            geometry,
        },
    );
    if let Some(ros) = record.located() {
        let path = a.out.join("pose_with_covariance.json");
        tactile_derender::io::write_atomic(&path, serde_json::to_string_pretty(ros)?.as_bytes())
            .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))?;
    }
    record.write(&a.out.join("pose.json"))?;
    let summary = serde_json::to_string(&record)?;
    println!("{summary}");
    Ok(())
}

/// Say on stderr when the samples split between poses, or the signature explains a rival about as well.
fn warn_ambiguous(
    estimate: &pipeline::PoseEstimate,
    symmetry: &tactile_derender::objects::Symmetry,
) {
    let report = &estimate.report;
    if report.ambiguous() {
        let modes = report.major_modes();
        let among = estimate.best().is_some_and(|p| {
            modes
                .iter()
                .any(|m| tactile_derender::uncertainty::same_pose(m.pose, p, symmetry))
        });
        let described: Vec<String> = modes.iter().map(|m| m.describe()).collect();
        eprintln!(
            "warning: the samples split between poses the contact cannot tell apart ({}); {}",
            described.join("; "),
            if among {
                "the estimate is one of them"
            } else {
                "the estimate, the signature check's pick, is none of them"
            }
        );
    }
    if let Some(r) = estimate.signature_rival.filter(|r| r.ambiguous()) {
        eprintln!(
            "warning: the signature explains another pose about as well as the estimate ({}); which of the two it \
             is, the sensor's noise decides",
            r.describe()
        );
    }
}

/// The estimate in the rerun recording: the object at the truth, the estimate and the multi-sample estimate, the
/// posterior's regions, the imprint, and one step per sample (its depth) and per registered sample (its pose).
fn log_to_rerun(
    log: &tactile_derender::rrd::RrdLog,
    object: &pipeline::LoadedObject,
    sim: &Simulator,
    input: &pipeline::PoseInput<'_>,
    estimate: &pipeline::PoseEstimate,
    imprint: &tactile_derender::image::Image,
    truth: Option<tactile_derender::sensor::Se2>,
) -> Result<()> {
    let report = &estimate.report;
    let samples = input.samples;
    use crate::rerun_out::{camera_views, object_at, ESTIMATE_RGB, TRUTH_RGB};
    let t_world_camera = input.t_world_camera;
    log.set_step("sample", 0);
    if let Some(t) = truth {
        object_at(log, "world/object", &object.mesh, t, TRUTH_RGB)?;
    }
    if let Some(best) = estimate.best() {
        object_at(log, "world/estimate/best", &object.mesh, best, ESTIMATE_RGB)?;
    }
    if let Some(p) = &estimate.posterior {
        // Each mode's 90 % position region, on the table.
        let strips: Vec<Vec<glam::DVec3>> = p
            .modes
            .iter()
            .map(|m| {
                let mut ring: Vec<glam::DVec3> = m
                    .ellipse_xy(0.9, 64)
                    .iter()
                    .map(|[x, y]| glam::DVec3::new(*x, *y, 0.0))
                    .collect();
                ring.extend(ring.first().copied());
                ring
            })
            .collect();
        log.line_strips("world/posterior", &strips, [0, 170, 190])?;
    }
    if let Some(m) = &report.multi_sample {
        object_at(
            log,
            "world/estimate/multi_sample",
            &object.mesh,
            m.pose,
            ESTIMATE_RGB,
        )?;
    }
    camera_views(
        log,
        sim.intrinsics(),
        &t_world_camera,
        &[("imprint", imprint)],
        None,
    )?;
    // One step per sample: its depth and its registered pose.
    for (k, s) in samples.iter().enumerate() {
        log.set_step("sample", k);
        camera_views(
            log,
            sim.intrinsics(),
            &t_world_camera,
            &[("sample", s)],
            Some(("sample", s)),
        )?;
    }
    // The registered samples' poses, one step each (samples that failed to register have none).
    for (j, fit) in report.samples.iter().enumerate() {
        log.set_step("fit", j);
        object_at(
            log,
            "world/estimate/fit",
            &object.mesh,
            fit.pose,
            ESTIMATE_RGB,
        )?;
    }
    Ok(())
}
