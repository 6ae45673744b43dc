//! `tnd bench posterior`: the wall time of `tnd pose`'s pipeline for N samples of one imprint — guided sampling (one
//! batch of N), the press search, the first registration with the signature check and the pose posterior, every
//! sample registered for the samples' KDE — on a simulated Soft Bubble contact, with the stages apart and the quality
//! each run keeps (the estimate's error, the samples' spread, the posterior's top weight and the truth's region).
//! Medians over `--runs`, one JSON line per sample count.
//!
//! The peer: diffusers samples the same DDIM loop as `steps` U-Net forwards at batch N plus its scheduler steps;
//! `../shared/peers/unet_torch.py --config <the model's config> --batches N --skip train,ddpm,ddim,ref` times that
//! forward (run it right before or after: these machines drift).

use std::path::Path;
use std::time::Instant;

use anyhow::{anyhow, Result};
use clap::Args;
use serde_json::json;
use tactile_derender::model::guidance::GuidanceConfig;
use tactile_derender::model::sampler::SamplerConfig;
use tactile_derender::model::DiffusionModel;
use tactile_derender::pipeline::press::PressChoice;
use tactile_derender::pipeline::{self, DerenderConfig, ObjectSpec, Observation, Placement};
use tactile_derender::pose::camera_path::CameraPath;
use tactile_derender::pose::PoseConfig;
use tactile_derender::sensor::resample::to_model;
use tactile_derender::sensor::{Scene, Se2};
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};
use tactile_derender::uncertainty::SampleError;

#[derive(Args, Debug)]
pub struct PosteriorBenchArgs {
    /// Print JSON lines (the only output format).
    #[arg(long)]
    pub json: bool,
    /// Model checkpoint (default: the bundled model; `small`: the bundled small one).
    #[arg(long, default_value = "default")]
    pub model: String,
    /// Built-in object of the simulated contact.
    #[arg(long, default_value = "cross_w12_s50")]
    pub object: String,
    /// True pose X,Y,THETA of the simulated contact (metres, radians).
    #[arg(long, default_value = "0.004,-0.003,0.5", allow_hyphen_values = true)]
    pub pose: String,
    /// Press depth of the simulated contact, metres.
    #[arg(long, default_value_t = 0.006)]
    pub press: f64,
    /// Sample counts to time, each as its own record (the default 16 of `tnd pose` beside the paper's 50).
    #[arg(long, value_delimiter = ',', default_value = "16,50")]
    pub samples: Vec<usize>,
    #[command(flatten)]
    pub sampler: SamplerConfig,
    #[command(flatten)]
    pub guidance: GuidanceConfig,
    // The pose engine's settings, as `tnd pose` takes them.
    #[command(flatten)]
    pub engine: PoseConfig,
    /// Timed runs per sample count (median reported); each draws its samples with seed `seed + run`.
    #[arg(long, default_value_t = 3)]
    pub runs: usize,
    /// Seed of the simulated noise and of the first run's samples.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Make the contact at the camera's native pixels and bring it down as `tnd dataset import` does (crop, area
    /// resampling), then time each sample count twice: the signature check predicting it at native pixels
    /// (`--check-native true`, what `tnd pose` does with such a frame) and with one ray per model pixel.
    #[arg(long)]
    pub native: bool,
}

/// One timed run's stages (seconds) and what it estimated.
struct RunRecord {
    sampling_s: f64,
    first_pose_s: f64,
    samples_s: f64,
    total_s: f64,
    position_mm: f64,
    /// `None` for an object with continuous symmetry.
    theta_deg: Option<f64>,
    samples_position_mm: f64,
    top_weight: Option<f64>,
    modes: usize,
    truth_region: Option<f64>,
}

pub fn run(a: &PosteriorBenchArgs) -> Result<()> {
    crate::args::check_press("--press", a.press, false)?;
    let sim = Simulator::new(SimConfig::default())?;
    let object = ObjectSpec::library("builtin", &a.object).load()?;
    let prepared = PreparedObject::new(object.mesh.clone())?;
    let truth = Se2::parse(&a.pose).map_err(|e| anyhow!("--pose: {e}"))?;
    let sensor = sim.pressing_pose(&prepared, 0.0, 0.0, 0.0, a.press);
    let scene = Scene {
        object: truth,
        sensor,
    };
    let contact = if a.native {
        let camera = &sim.config().camera;
        let mut out = Simulator::native(sim.config().clone())?.simulate(&prepared, &scene, a.seed);
        out.signature = to_model(camera, &out.signature)?;
        out.reference = to_model(camera, &out.reference)?;
        out.imprint = tactile_derender::sim::signature::imprint(&out.reference, &out.signature);
        // The contact at the model's resolution: the model pixels the import's crop and resampling give a value
        // from native contact (only the signature, reference and imprint go on to the pipeline).
        let mask = to_model(camera, &out.mask)?;
        out.contact_pixels = mask.data.iter().filter(|&&m| m > 0.5).count();
        out
    } else {
        sim.simulate(&prepared, &scene, a.seed)
    };
    let camera_path = CameraPath::for_frames(sim.config(), a.native)?;
    if contact.contact_pixels == 0 {
        return Err(anyhow!(
            "{} at {} pressed {} m leaves no contact; choose another --pose or --press",
            a.object,
            a.pose,
            a.press
        ));
    }
    let model = DiffusionModel::load(Path::new(&a.model))?;
    super::emit(
        json!({"bench": "posterior_info", "host": super::host(), "model": model.source(),
        "object": a.object, "truth": truth, "press_m": a.press, "contact_px": contact.contact_pixels,
        "native_frames": a.native,
        "sampler": a.sampler, "guidance": a.guidance}),
    );
    for &n in &a.samples {
        let config = DerenderConfig {
            samples: n,
            sampler: a.sampler,
            seed: a.seed,
            device: "cpu".into(),
            guidance: a.guidance,
        };
        // With --native: the camera path, then one ray per model pixel (the peer of the same run).
        let settings: &[bool] = if a.native { &[true, false] } else { &[false] };
        for &native in settings {
            let mut engine = a.engine.clone();
            engine.signature_check.native = native;
            let mut records: Vec<RunRecord> = Vec::new();
            for r in 0..a.runs.max(1) {
                let config = DerenderConfig {
                    seed: a.seed + r as u64,
                    ..config.clone()
                };
                records.push(time_run(
                    &model,
                    &sim,
                    &object,
                    &prepared,
                    &contact,
                    truth,
                    &config,
                    &engine,
                    camera_path.as_ref(),
                )?);
            }
            let median = |f: &dyn Fn(&RunRecord) -> f64| {
                let mut v: Vec<f64> = records.iter().map(f).collect();
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            let each = |f: &dyn Fn(&RunRecord) -> serde_json::Value| {
                records.iter().map(f).collect::<Vec<_>>()
            };
            super::emit(
                json!({"bench": "posterior", "samples": n, "runs": records.len(),
            "check_native": camera_path.is_some() && engine.signature_check.native,
            "sampler": config.sampler,
            "guided": config.guidance.enabled, "guidance_iterations": config.guidance.iterations,
            "guidance_from": config.guidance.from_fraction,
            "seconds_median": median(&|r| r.total_s), "sampling_s_median": median(&|r| r.sampling_s),
            "first_pose_s_median": median(&|r| r.first_pose_s),
            "samples_registration_s_median": median(&|r| r.samples_s),
            "position_mm": each(&|r| json!(r.position_mm)), "theta_deg": each(&|r| json!(r.theta_deg)),
            "samples_position_mm_median": each(&|r| json!(r.samples_position_mm)),
            "top_weight": each(&|r| json!(r.top_weight)), "modes": each(&|r| json!(r.modes)),
            "truth_region": each(&|r| json!(r.truth_region))}),
            );
        }
    }
    Ok(())
}

/// One run of the pose pipeline as `tnd pose` runs it (press found from the samples and the signature), timed.
#[allow(clippy::too_many_arguments)]
fn time_run(
    model: &DiffusionModel,
    sim: &Simulator,
    object: &pipeline::LoadedObject,
    prepared: &PreparedObject,
    contact: &tactile_derender::sim::SimOutput,
    truth: Se2,
    config: &DerenderConfig,
    eval: &PoseConfig,
    camera_path: Option<&std::sync::Arc<CameraPath>>,
) -> Result<RunRecord> {
    let t0 = Instant::now();
    let guidance =
        pipeline::imprint_guidance(config, sim, &contact.imprint, Some(&contact.signature))?;
    let out = pipeline::derender(
        model,
        &contact.imprint,
        guidance.as_ref(),
        config,
        eval.consensus_probability,
        &mut |_, _| true,
    )?;
    let sampling_s = t0.elapsed().as_secs_f64();
    let observation = Observation {
        samples: &out.samples,
        imprint: &contact.imprint,
        signature: Some(&contact.signature),
        truth: Some(truth),
        prior: None,
        camera_path,
    };
    // The first progress call comes once the press, the first registration, the check and the posterior are done;
    // the rest, one per registered sample.
    let t1 = Instant::now();
    let mut first_pose_s = None;
    let placed = pipeline::place_and_estimate(
        object,
        Some(prepared),
        sim,
        &observation,
        Placement::Press(PressChoice::Auto),
        // A new engine every run: `tnd pose` prepares the object once per call.
        &tactile_derender::pose::Estimator::new(eval.clone()),
        config.seed,
        &mut |done, _| {
            if done == 1 {
                first_pose_s = Some(t1.elapsed().as_secs_f64());
            }
            true
        },
    )?;
    let pose_s = t1.elapsed().as_secs_f64();
    let first_pose_s = first_pose_s.unwrap_or(pose_s);
    let estimate = placed.estimate;
    let best = estimate
        .best()
        .ok_or_else(|| anyhow!("the pipeline returned no pose"))?;
    let error = SampleError::new(best, 0.0, truth, &object.symmetry);
    let mut spread: Vec<f64> = estimate
        .report
        .samples
        .iter()
        .map(|s| s.position_mm)
        .collect();
    spread.sort_by(f64::total_cmp);
    Ok(RunRecord {
        sampling_s,
        first_pose_s,
        samples_s: pose_s - first_pose_s,
        total_s: sampling_s + pose_s,
        position_mm: error.position_mm,
        theta_deg: error.theta_deg,
        samples_position_mm: spread.get(spread.len() / 2).copied().unwrap_or(f64::NAN),
        top_weight: estimate
            .posterior
            .as_ref()
            .and_then(|p| p.top())
            .map(|m| m.weight),
        modes: estimate.posterior.as_ref().map_or(0, |p| p.modes.len()),
        truth_region: estimate.truth_region,
    })
}
