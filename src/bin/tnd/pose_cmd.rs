//! `tnd pose`: one tactile signature end to end — N samples of the in-contact depth from the generator, the pose
//! from a K-start registration of the first, every sample registered from that fixed start, the multi-sample
//! estimate (the samples' consensus contact), the threshold baseline, and the uncertainty outputs (samples.csv,
//! kde.csv, uncertainty.png, contact_probability.npy, pose.json).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use clap::Args;
use serde_json::json;
use tactile_derender::image::Image;
use tactile_derender::io::npy;
use tactile_derender::metrics::evaluate::{EvalConfig, EvalContext, EvalPair, Evaluator};
use tactile_derender::objects::ObjectSet;
use tactile_derender::pose::from_depth::contact_probability;
use tactile_derender::pose::threshold_contact;
use tactile_derender::sensor::Se2;
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};
use tactile_derender::uncertainty::analysis::{analyse, Signature};

use super::args::ObjectArgs;

#[derive(Args, Debug)]
pub struct PoseArgs {
    /// The generator: a model checkpoint, or `ground-truth` (then --target is the "generated" X0).
    #[arg(long)]
    pub model: String,
    /// The imprint Y = R − S (metres, .npy at the model resolution).
    #[arg(long)]
    pub imprint: PathBuf,
    #[command(flatten)]
    pub object: ObjectArgs,
    /// The true in-contact depth X0 (.npy), used by --model ground-truth.
    #[arg(long)]
    pub target: Option<PathBuf>,
    /// The signature S (.npy), for the threshold baseline.
    #[arg(long)]
    pub signature: Option<PathBuf>,
    /// The true pose X,Y,THETA (errors are measured against it; otherwise against the estimate).
    #[arg(long)]
    pub truth: Option<String>,
    /// Press depth of the sensor apex below the object's top, metres (places the sensor as `tnd sim` does).
    #[arg(long, default_value_t = 0.006)]
    pub press: f64,
    /// Model samples.
    #[arg(long, default_value_t = 50)]
    pub samples: usize,
    #[command(flatten)]
    pub sampler: tactile_derender::model::SamplerConfig,
    /// Seed of the sampler and the registration starts.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
}

fn read(path: &Path, want: (usize, usize)) -> Result<Image> {
    let img = npy::read_metres_image(path)?;
    if (img.width, img.height) != want {
        bail!(
            "{}: image is {}x{}, the sensor renders {}x{}",
            path.display(),
            img.width,
            img.height,
            want.0,
            want.1
        );
    }
    Ok(img)
}

pub fn run(a: PoseArgs) -> Result<()> {
    let sim = Simulator::new(SimConfig::default())?;
    let res = (sim.intrinsics().width, sim.intrinsics().height);
    let imprint = read(&a.imprint, res)?;
    let (name, mesh) = a.object.load()?;
    let symmetry = ObjectSet::open(&a.object.objects)
        .ok()
        .and_then(|s| s.find(&name).map(|e| e.symmetry))
        .unwrap_or_default();
    let prepared = PreparedObject::new(mesh.clone())?;
    let sensor = sim.pressing_pose(&prepared, 0.0, 0.0, 0.0, a.press);
    let truth = a
        .truth
        .as_deref()
        .map(Se2::parse)
        .transpose()
        .map_err(|e| anyhow!("--truth: {e}"))?;
    let target = match &a.target {
        Some(p) => read(p, res)?,
        None => Image::filled(res.0, res.1, 0.0),
    };
    if a.model == "ground-truth" && a.target.is_none() {
        bail!("--model ground-truth needs --target FILE.npy (the in-contact depth to use as every sample)");
    }
    let gen = super::eval_cmd::generator(&a.model, &a.sampler)?;
    let signature = a.signature.as_ref().map(|p| read(p, res)).transpose()?;
    let pair = EvalPair {
        name: a.imprint.display().to_string(),
        object: name.clone(),
        object_pose: truth.unwrap_or_default(),
        t_world_camera: sim.t_world_camera(&sensor),
        target,
        signature: signature
            .clone()
            .unwrap_or_else(|| Image::filled(res.0, res.1, 0.0)),
        imprint: imprint.clone(),
    };
    let evaluator = Evaluator::new(EvalConfig::default());
    let object = evaluator.object_from_mesh(&name, &mesh, symmetry)?;
    let ctx = EvalContext {
        intrinsics: *sim.intrinsics(),
        membrane: sim.nominal_depth().clone(),
        objects: ObjectSet::builtin(),
    };
    let samples = gen.generate(&pair, a.samples.max(1), a.seed)?;
    let baseline = signature.map(|s| threshold_contact(&s, &imprint, &evaluator.config.baseline));
    let sig = Signature {
        t_world_camera: pair.t_world_camera,
        samples: &samples,
        baseline: baseline.as_ref(),
        truth,
        init: None,
    };
    let report = analyse(&evaluator, &object, &ctx, &sig, a.seed)?;
    report.write(&a.out)?;
    if samples.len() > 1 {
        let p = contact_probability(&samples)?;
        let path = a.out.join("contact_probability.npy");
        npy::write_image(&path, &p)?;
    }
    let summary = json!({"object": name, "generator": gen.name(), "samples": report.samples.len(),
        "estimate": report.init, "estimate_multi_sample": report.multi_sample.map(|m| m.pose),
        "truth": truth, "baseline": report.baseline, "multi_sample": report.multi_sample,
        "failed": report.failed,
        "position_err_mm": report.samples.iter().map(|s| s.position_mm).collect::<Vec<_>>(),
        "out": a.out});
    let path = a.out.join("pose.json");
    tactile_derender::io::write_atomic(&path, serde_json::to_string_pretty(&summary)?.as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))?;
    println!("{summary}");
    Ok(())
}
