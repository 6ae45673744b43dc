//! `tnd eval`: the paper's Table I (depth: L1, PSNR, SSIM) and Table II (pose: position, θ, Chamfer) for a generator
//! and the threshold baseline over dataset splits; `--report DIR` adds a markdown file and KDE plots for a few pairs.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{anyhow, bail, Result};
use clap::Args;
use kdam::BarExt;
use serde_json::{json, Value};
use tactile_derender::dataset::{Dataset, SplitName};
use tactile_derender::image::Image;
use tactile_derender::io::output::Claimed;
use tactile_derender::metrics::eval_log::EvalLog;
use tactile_derender::metrics::evaluate::{
    EvalConfig, EvalPair, EvalReport, Generator, GroundTruthGenerator, MethodSummary, PairSource,
};
use tactile_derender::metrics::model_generator::ModelGenerator;
use tactile_derender::metrics::paper_table::{paper_tables, PaperEntry};
use tactile_derender::metrics::saved_samples::save_samples;
use tactile_derender::metrics::sources::DatasetSource;
use tactile_derender::pipeline::evaluate::Evaluator;

use crate::eval_tables::{breakdown_tables, markdown_table};
use tactile_derender::model::{DiffusionModel, GuidanceConfig, SamplerConfig, TactileConfig};
use tactile_derender::pose::{threshold_contact, PoseConfig};
use tactile_derender::uncertainty::analysis::{analyse, Signature};

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// The generator: a model checkpoint, a bundled model (`auto`: `recording` for pairs whose frames were
    /// resampled from a camera's larger frame — imported recordings, pairs generated through a depth camera —,
    /// `default` for pairs at the model resolution; `small`: twice as fast), or `ground-truth` (the true X0: tests
    /// everything but the model).
    #[arg(long, default_value = "auto")]
    pub model: String,
    /// Dataset directory (`tnd dataset gen`).
    #[arg(long, required_unless_present = "tables_from")]
    pub data: Option<PathBuf>,
    /// unseen_poses, unseen_objects, train or all (= unseen_poses and unseen_objects).
    #[arg(long, default_value = "all")]
    pub split: String,
    /// At most this many pairs per split.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Skip the first N pairs of each split (e.g. the pairs looked at while tuning), then take --limit.
    #[arg(long, default_value_t = 0)]
    pub skip: usize,
    /// Model samples per pair: above 1 the model is also scored on the multi-sample estimate (registration of the
    /// samples' consensus contact), shown as an extra row.
    #[arg(long, value_parser = crate::args::at_most::<256>, default_value_t = 1)]
    pub pose_samples: usize,
    /// Also print the rows per contact-size bin and per object (always in --json and --report).
    #[arg(long)]
    pub breakdown: bool,
    #[command(flatten)]
    pub sampler: SamplerConfig,
    #[command(flatten)]
    pub guidance: GuidanceConfig,
    /// Seed of the sampler and the registration starts.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Device that runs the model: cpu, cuda, cuda:N or metal (GPU builds: `--features cuda` or `metal`).
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// JSON only: leave out the markdown tables (on stderr) beside the JSON objects (one per split, on stdout).
    #[arg(long)]
    pub json: bool,
    /// Also write report.md and uncertainty plots (KDE over --report-samples samples) for --report-pairs pairs per
    /// split.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Pairs per split with an uncertainty analysis in the report.
    #[arg(long, value_parser = crate::args::at_most::<10_000>, default_value_t = 3)]
    pub report_pairs: usize,
    /// Samples per uncertainty analysis in the report (`--pose-samples` are the samples every pair is scored on).
    #[arg(long, value_parser = crate::args::at_most::<256>, default_value_t = 50)]
    pub report_samples: usize,
    #[command(flatten)]
    pub pose: PoseConfig,
    /// Also print this run in the paper's table layout and units (θ in rad, Chamfer in m², splits side by side).
    #[arg(long)]
    pub paper: bool,
    /// Evaluate nothing: print the paper's tables from earlier `tnd eval --json` outputs, one row per file
    /// (training configuration) plus the first file's threshold baseline. `LABEL=FILE` names a row (default: the
    /// generator in the file). Repeat the option or separate files with commas.
    #[arg(long, value_name = "[LABEL=]FILE", value_delimiter = ',')]
    pub tables_from: Vec<String>,
    /// Also write every pair's scores (both methods, estimated and true pose) as JSON lines to this file, each pair
    /// as it is scored. Run again with the same settings, the evaluation resumes: pairs the file holds are not
    /// scored again (a larger --limit extends it); a file of other settings is refused, naming them.
    #[arg(long)]
    pub records: Option<PathBuf>,
    /// Also save every scored pair's imprint, signature, true X0 and model samples (all --pose-samples of them) as
    /// DIR/<split>/<index>.npz, metres, for analysis in numpy (docs/evaluation.md).
    #[arg(long, value_name = "DIR")]
    pub save_samples: Option<PathBuf>,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
    /// The rerun recording has one step per pair on the "pair" timeline: the imprint, the true and generated X0 under
    /// the camera, the generated contact points, and the object at its true and estimated poses.
    #[command(flatten)]
    pub rerun: crate::rerun_out::RerunArgs,
}

/// The generator named by `--model` on `device`, with the model's own depth mapping (none for the ground truth).
pub fn generator(
    model: &str,
    sampler: &SamplerConfig,
    guidance: &GuidanceConfig,
    device: &str,
) -> Result<(Box<dyn Generator>, Option<TactileConfig>)> {
    if model == "ground-truth" {
        return Ok((Box::new(GroundTruthGenerator), None));
    }
    sampler.validate(None).map_err(anyhow::Error::msg)?;
    guidance.validate().map_err(anyhow::Error::msg)?;
    let device = tactile_derender::model::device::open_device(device)?;
    let model = DiffusionModel::load_on(Path::new(model), &device)?;
    let mapping = model.config().tactile_derender.clone();
    let gen = ModelGenerator {
        model,
        sampler: sampler.sampler_kind(),
        guidance: *guidance,
    };
    Ok((Box::new(gen), Some(mapping)))
}

/// A warning when the dataset's in-contact depths (sampled from the first evaluated split with pairs) lie outside
/// what the model represents, e.g. a model trained for another sensor: its samples would decode wrongly.
fn warn_if_the_model_does_not_fit(
    model: &str,
    mapping: Option<&TactileConfig>,
    data: &Path,
    dataset: &Dataset,
    splits: &[SplitName],
) -> Result<()> {
    let Some(mapping) = mapping else {
        return Ok(());
    };
    let Some(&split) = splits.iter().find(|&&s| dataset.len(s) > 0) else {
        return Ok(());
    };
    let range = tactile_derender::dataset::stats::target_range_sample(dataset, split, 64)?;
    if let Some(problem) = range.and_then(|[lo, hi]| mapping.contact_range_problem(lo, hi)) {
        eprintln!(
            "warning: {}: the model {model} does not fit this dataset's sensor: {problem}; its depths and poses will \
             be wrong (a model trained on this sensor's data, `tnd train --data {}`, fits it)",
            data.display(),
            data.display()
        );
    }
    Ok(())
}

/// The settings every pair's scores depend on: `--records` resumes only under the same. The model and the dataset
/// are named by path and by content (a retrained checkpoint or a regenerated dataset under the same name is not
/// resumed into); `--limit` is not among them (a larger limit extends a run), `--skip` is (the pairs' seeds count
/// from it).
fn records_settings(a: &EvalArgs, dataset: &Dataset) -> Result<Value> {
    use tactile_derender::dataset::shard::{file_digest, sha256_hex};
    use tactile_derender::model::checkpoint::{bundled_name, weights_file};
    let canonical = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let model = Path::new(&a.model);
    let model = if a.model == "ground-truth" {
        json!("ground-truth")
    } else if let Some((name, bytes)) = bundled_name(model) {
        json!({"bundled": name, "sha256": sha256_hex(bytes)})
    } else {
        let (_, sha256) = file_digest(&weights_file(model))?;
        json!({"path": canonical(model), "sha256": sha256})
    };
    let manifest = serde_json::to_vec(dataset.manifest())?;
    Ok(json!({
        "model": model, "data": canonical(dataset.dir()), "manifest_sha256": sha256_hex(&manifest),
        "seed": a.seed, "skip": a.skip, "pose_samples": a.pose_samples.max(1), "sampler": a.sampler,
        "guidance": a.guidance, "anchor": a.pose.anchor_to_signature,
        "signature_check": a.pose.check_signature, "imprint_proposals": a.pose.imprint_proposals,
        "check_refine": a.pose.signature_check.refine, "inits": a.pose.inits, "posterior": a.pose.posterior,
    }))
}

fn splits(s: &str) -> Result<Vec<SplitName>> {
    if s == "all" {
        return Ok(vec![SplitName::UnseenPoses, SplitName::UnseenObjects]);
    }
    Ok(vec![s.parse::<SplitName>().map_err(|e| {
        anyhow!("--split: {e}, or all (unseen_poses and unseen_objects)")
    })?])
}

/// `dir` exists (created if needed) and takes a file: a report folder that cannot is refused before the evaluation.
fn check_writable_folder(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| anyhow!("{}: cannot create: {e}", dir.display()))?;
    let probe = dir.join(format!(".tnd-write-check.{}", std::process::id()));
    std::fs::write(&probe, b"")
        .map_err(|e| anyhow!("{}: cannot write the report there: {e}", dir.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

pub fn run(mut a: EvalArgs) -> Result<()> {
    if !a.tables_from.is_empty() {
        print!("{}", paper_tables(&tables_from(&a.tables_from)?));
        return Ok(());
    }
    let data = a
        .data
        .as_deref()
        .ok_or_else(|| anyhow!("--data DIR is needed (or --tables-from FILE)"))?;
    tactile_derender::io::lock::check_not_written(data)?;
    let model_given = PathBuf::from(&a.model);
    let inputs = [data, model_given.as_path()];
    let force = a.force.force;
    let (records, _folders) = claim_outputs(&a, &inputs)?;
    // Records go to the real file: a symbolic link stays a link.
    if let Some(r) = &records {
        a.records = Some(r.path().to_path_buf());
    }
    let dataset = Dataset::open(data)?;
    a.model = crate::args::resolve_model(
        &a.model,
        dataset.manifest().frames_resampled(),
        &data.display().to_string(),
    );
    let (gen, mapping) = generator(&a.model, &a.sampler, &a.guidance, &a.device)?;
    warn_if_the_model_does_not_fit(
        &a.model,
        mapping.as_ref(),
        data,
        &dataset,
        &splits(&a.split)?,
    )?;
    let mut paper = Vec::new();
    a.pose.validate()?;
    let evaluator = Evaluator::new(EvalConfig {
        pose: a.pose.clone(),
        pose_samples: a.pose_samples.max(1),
        ..EvalConfig::default()
    });
    let rrd = a.rerun.open("tnd eval", force, &inputs)?;
    let mut pair_log = rrd.as_ref().map(PairLog::new);
    let mut markdown = String::new();
    let mut log = match &a.records {
        Some(path) => Some(EvalLog::open(path, records_settings(&a, &dataset)?)?),
        None => None,
    };
    let mut failed = 0;
    for split in splits(&a.split)? {
        let source = DatasetSource::new(&dataset, split, None)?.skip(a.skip, a.limit);
        if source.is_empty() {
            eprintln!("{}: split {split} has no pairs; skipped", data.display());
            continue;
        }
        let report = score_split(
            &a,
            split,
            &source,
            &evaluator,
            gen.as_ref(),
            log.as_mut(),
            pair_log.as_mut(),
        )?;
        failed += show_split(&a, split, &report, &mut markdown, &mut paper);
        if let Some(dir) = &a.report {
            uncertainty_plots(
                dir,
                split,
                &source,
                &evaluator,
                gen.as_ref(),
                &a,
                &mut markdown,
            )?;
        }
    }
    if a.paper {
        let tables = paper_tables(&paper);
        if !a.json {
            eprintln!("{tables}");
        }
        markdown.push_str("## In the paper's layout\n\n");
        markdown.push_str(&tables);
    }
    if let Some(log) = &log {
        eprintln!("records: {}", log.path().display());
    }
    if let Some(dir) = &a.report {
        write_report(dir, &gen.name(), data, a.seed, &markdown)?;
    }
    if let Some(path) = crate::rerun_out::finish(rrd)? {
        eprintln!("rerun: {}", path.display());
    }
    if failed > 0 {
        bail!("{failed} pair(s) could not be scored (listed above and in --records); the tables cover the others");
    }
    Ok(())
}

/// One writer per output, refused before any work (`inputs` are the command's inputs, never written): the
/// `--records` file, then the `--report` and `--save-samples` folders; the report folder must take files before the
/// evaluation runs, not after it. The claims hold while they live.
fn claim_outputs(a: &EvalArgs, inputs: &[&Path]) -> Result<(Option<Claimed>, Vec<Claimed>)> {
    let force = a.force.force;
    let records = a
        .records
        .as_deref()
        .map(|p| crate::outputs::file("--records", p, force, inputs, &EvalLog::written_by_tnd))
        .transpose()?;
    let folders = [("--report", &a.report), ("--save-samples", &a.save_samples)]
        .into_iter()
        .filter_map(|(flag, p)| Some((flag, p.as_deref()?)))
        .map(|(flag, p)| crate::outputs::folder(flag, p, force, inputs))
        .collect::<Result<Vec<_>>>()?;
    if let Some(dir) = &a.report {
        check_writable_folder(dir)?;
    }
    Ok((records, folders))
}

/// Score the pairs of `source` (split `split`) with a progress bar: into `log` where records are kept (resuming the
/// pairs it already holds), each pair's samples saved (`--save-samples`) and logged to `pair_log` (`--rerun`) as it
/// is scored. A recording or saving error stops the run at once (rather than after every pair is scored).
fn score_split(
    a: &EvalArgs,
    split: SplitName,
    source: &DatasetSource<'_>,
    evaluator: &Evaluator,
    gen: &dyn Generator,
    log: Option<&mut EvalLog>,
    mut pair_log: Option<&mut PairLog<'_>>,
) -> Result<EvalReport> {
    let bar = Mutex::new(super::progress::bar(
        &format!("eval {split}"),
        " pairs",
        source.len(),
    ));
    let mut log_error = None;
    let stop = std::cell::Cell::new(false);
    let mut progress = |done, _| {
        if let Ok(mut b) = bar.lock() {
            let _ = b.update_to(done);
        }
        !stop.get()
    };
    let mut observe = |i, pair: &EvalPair, samples: &[Image]| {
        if log_error.is_some() {
            return;
        }
        if let Some(dir) = &a.save_samples {
            log_error = save_samples(dir, pair, samples)
                .err()
                .map(|e| anyhow!(tactile_derender::error::render(&e)));
        }
        if let (Some(log), Some(sample), None) = (&mut pair_log, samples.first(), &log_error) {
            log_error = log.pair(source.context(), i, pair, sample).err();
        }
        stop.set(log_error.is_some());
    };
    let report = match log {
        Some(log) => {
            announce_resumed(log, split, a.skip, source.len());
            evaluator
                .evaluate_logged(
                    source,
                    gen,
                    a.seed,
                    log,
                    split.as_str(),
                    a.skip,
                    &mut progress,
                    &mut observe,
                )
                .map_err(anyhow::Error::from)
        }
        None => evaluator
            .evaluate_observed(source, gen, a.seed, &mut progress, &mut observe)
            .map_err(anyhow::Error::from),
    };
    if let Some(e) = log_error {
        return Err(e);
    }
    let report = report?;
    if let Some(log) = &mut pair_log {
        log.estimates(source.context(), &report)?;
        log.next_split(source.len());
    }
    if let Ok(mut b) = bar.lock() {
        super::progress::finish(&mut b);
    }
    Ok(report)
}

/// Say how many of the `len` pairs of `split` (from pair `skip` on) `log` already holds from an earlier run.
fn announce_resumed(log: &EvalLog, split: SplitName, skip: usize, len: usize) {
    let resumed = log.scored(split.as_str(), skip..skip + len);
    if resumed == len {
        eprintln!(
            "{}: all {resumed} pairs of {split} scored by an earlier run",
            log.path().display()
        );
    } else if resumed > 0 {
        eprintln!(
            "{}: {resumed} of the {} pairs of {split} scored by an earlier run; scoring the others",
            log.path().display(),
            len
        );
    }
}

/// Show one split's scores: like every command, the result as JSON on stdout and the readable tables beside it on
/// stderr (unless `--json`; the breakdown with `--breakdown`), the pairs that could not be scored; the tables added
/// to `markdown` and the rows to `paper`. Returns how many pairs failed.
fn show_split(
    a: &EvalArgs,
    split: SplitName,
    report: &EvalReport,
    markdown: &mut String,
    paper: &mut Vec<PaperEntry>,
) -> usize {
    let table = markdown_table(split.as_str(), report);
    let breakdown = breakdown_tables(report);
    println!(
        "{}",
        json!({"split": split.as_str(), "generator": report.generator, "pairs": report.pairs,
               "model": report.model, "model_multi": report.model_multi,
               "model_combined": report.model_combined,
               "baseline": report.baseline, "baseline_checked": report.baseline_checked,
               "breakdown": report.breakdown,
               "failed": report.failed})
    );
    if !a.json {
        eprintln!("{table}");
        if a.breakdown {
            eprintln!("{breakdown}");
        }
    }
    markdown.push_str(&table);
    markdown.push_str(&breakdown);
    paper.extend(paper_entries(
        &report.generator,
        split.as_str(),
        report.model.clone(),
        report.model_multi.clone(),
        report.baseline.clone(),
    ));
    for f in &report.failed {
        eprintln!("failed: {} ({}): {}", f.name, f.object, f.reason);
    }
    report.failed.len()
}

/// `report.md` in `dir` (created if needed): a header naming the generator, the dataset `data` and the seed, then
/// `markdown` (every split's tables and uncertainty plots).
fn write_report(dir: &Path, generator: &str, data: &Path, seed: u64, markdown: &str) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| anyhow!("{}: cannot create: {e}", dir.display()))?;
    let mut text = format!(
        "# Evaluation\n\nGenerator `{}`, dataset `{}`, seed {}. Metric definitions: docs/evaluation.md.\n\n",
        generator,
        data.display(),
        seed
    );
    text.push_str(markdown);
    let path = dir.join("report.md");
    tactile_derender::io::write_atomic(&path, text.as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))?;
    eprintln!("report: {}", path.display());
    Ok(())
}

/// The paper-table rows of one split: the model, its multi-sample estimate (if any), the threshold baseline.
fn paper_entries(
    label: &str,
    split: &str,
    model: MethodSummary,
    model_multi: Option<MethodSummary>,
    baseline: MethodSummary,
) -> Vec<PaperEntry> {
    let entry = |label: String, summary| PaperEntry {
        label,
        split: split.to_string(),
        summary,
    };
    let mut out = vec![entry(label.to_string(), model)];
    if let Some(m) = model_multi {
        out.push(entry(format!("{label} (multi-sample)"), m));
    }
    out.push(entry("threshold baseline".into(), baseline));
    out
}

/// Paper-table rows from `tnd eval --json` outputs (`[LABEL=]FILE`, one JSON object per split and line).
fn tables_from(files: &[String]) -> Result<Vec<PaperEntry>> {
    let mut out = Vec::new();
    for spec in files {
        let (label, path) = match spec.split_once('=') {
            Some((l, p)) if !l.is_empty() => (Some(l), p),
            _ => (None, spec.as_str()),
        };
        let text = tactile_derender::io::input::read_text_capped(
            Path::new(path),
            tactile_derender::io::input::MAX_RECORDS_BYTES,
        )
        .map_err(|e| anyhow!("{path}: cannot read: {e}"))?;
        let mut splits = 0;
        for (n, line) in text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
        {
            let v: serde_json::Value = serde_json::from_str(line)
                .map_err(|e| anyhow!("{path}: line {}: not JSON: {e}", n + 1))?;
            let (Some(split), Some(generator)) = (v["split"].as_str(), v["generator"].as_str())
            else {
                continue; // Not a split summary (e.g. a progress or info line).
            };
            let summary = |key: &str| -> Result<MethodSummary> {
                serde_json::from_value(v[key].clone()).map_err(|e| {
                    anyhow!(
                        "{path}: line {}: \"{key}\" is not a tnd eval summary: {e}",
                        n + 1
                    )
                })
            };
            let model_multi = if v["model_multi"].is_null() {
                None
            } else {
                Some(summary("model_multi")?)
            };
            out.extend(paper_entries(
                label.unwrap_or(generator),
                split,
                summary("model")?,
                model_multi,
                summary("baseline")?,
            ));
            splits += 1;
        }
        if splits == 0 {
            bail!("{path}: no split summaries (write them with tnd eval --json > FILE)");
        }
    }
    Ok(out)
}

fn uncertainty_plots(
    dir: &Path,
    split: SplitName,
    source: &DatasetSource<'_>,
    evaluator: &Evaluator,
    gen: &dyn Generator,
    a: &EvalArgs,
    markdown: &mut String,
) -> Result<()> {
    let ctx = source.context();
    for i in 0..a.report_pairs.min(source.len()) {
        let pair = source.pair(i)?;
        let samples = gen.generate(&pair, ctx, a.report_samples, a.seed.wrapping_add(i as u64))?;
        let (samples, _) =
            evaluator
                .estimator
                .anchor(&samples, Some(&pair.signature), &pair.imprint)?;
        let base = threshold_contact(
            &pair.signature,
            &pair.imprint,
            &evaluator.estimator.config.baseline,
        );
        let object = evaluator.object(&ctx.objects, &pair.object)?;
        let sig = Signature {
            t_world_camera: pair.t_world_camera,
            samples: &samples,
            baseline: Some(&base),
            truth: Some(pair.object_pose),
            init: None,
            measured: Some((&pair.signature, &pair.imprint)),
            prior: None,
        };
        let r = analyse(&evaluator.estimator, &object, ctx, &sig, a.seed)?;
        let sub = dir.join(format!("{split}_{i}"));
        r.write(&sub)?;
        let _ = writeln!(
            markdown,
            "Uncertainty, {} ({}): {} samples from the fixed start ({:.4}, {:.4}, {:.3}); ![]({split}_{i}/uncertainty.png)\n",
            pair.name,
            pair.object,
            r.samples.len(),
            r.init.x,
            r.init.y,
            r.init.theta
        );
    }
    Ok(())
}

/// The rerun recording of `tnd eval`: one step per evaluated pair on the timeline "pair", numbered across splits.
struct PairLog<'a> {
    log: &'a tactile_derender::rrd::RrdLog,
    /// Step of the current split's pair 0.
    first_step: usize,
    /// Step of each pair logged in the current split, by name (the records name their pairs).
    steps: std::collections::HashMap<String, usize>,
    /// Meshes already read, by object name.
    meshes: std::collections::HashMap<String, tactile_derender::mesh::Mesh>,
}

impl<'a> PairLog<'a> {
    fn new(log: &'a tactile_derender::rrd::RrdLog) -> Self {
        Self {
            log,
            first_step: 0,
            steps: Default::default(),
            meshes: Default::default(),
        }
    }

    fn mesh(
        &mut self,
        ctx: &tactile_derender::pose::SensorContext,
        name: &str,
    ) -> Result<&tactile_derender::mesh::Mesh> {
        if !self.meshes.contains_key(name) {
            self.meshes
                .insert(name.to_string(), ctx.objects.mesh(name)?);
        }
        self.meshes
            .get(name)
            .ok_or_else(|| anyhow!("object {name}: mesh not loaded"))
    }

    /// Pair `i` of the split: imprint, true and generated X0, the generated contact points and the object at its true
    /// pose.
    fn pair(
        &mut self,
        ctx: &tactile_derender::pose::SensorContext,
        i: usize,
        pair: &tactile_derender::metrics::evaluate::EvalPair,
        sample: &tactile_derender::image::Image,
    ) -> Result<()> {
        use crate::rerun_out::{camera_views, object_at, TRUTH_RGB};
        let step = self.first_step + i;
        self.steps.insert(pair.name.clone(), step);
        let log = self.log;
        log.set_step("pair", step);
        let images = [
            ("imprint", &pair.imprint),
            ("target", &pair.target),
            ("generated", sample),
        ];
        camera_views(
            log,
            &ctx.intrinsics,
            &pair.t_world_camera,
            &images,
            Some(("generated", sample)),
        )?;
        let mesh = self.mesh(ctx, &pair.object)?;
        object_at(log, "world/object", mesh, pair.object_pose, TRUTH_RGB)
    }

    /// The model's estimated pose of every scored pair of the split, at its pair's step.
    fn estimates(
        &mut self,
        ctx: &tactile_derender::pose::SensorContext,
        report: &tactile_derender::metrics::evaluate::EvalReport,
    ) -> Result<()> {
        use crate::rerun_out::{object_at, ESTIMATE_RGB};
        for r in &report.records {
            if let (Some(&step), Some(est)) = (self.steps.get(&r.name), r.model.estimate) {
                let log = self.log;
                log.set_step("pair", step);
                let mesh = self.mesh(ctx, &r.object)?;
                object_at(log, "world/estimate", mesh, est, ESTIMATE_RGB)?;
            }
        }
        Ok(())
    }

    /// The next split's pairs follow this one's `len`.
    fn next_split(&mut self, len: usize) {
        self.first_step += len;
        self.steps.clear();
    }
}
