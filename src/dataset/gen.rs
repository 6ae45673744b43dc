//! Synthetic **dataset generation** (paper V.A): plan every pair ([`super::split`]), simulate them in parallel
//! (rayon) chunk by chunk, and write each chunk's shards atomically while the next chunk is simulated.
//!
//! Determinism: a pair depends only on the configuration, the global seed and its index, and a chunk's shards hold
//! its pairs in index order, so the output is byte-identical whatever the thread count.
//!
//! Resume: `progress.json` records the configuration and the chunks whose shards are written (with their sha256). A
//! re-run of the same command (after kill -9 at any moment) keeps the chunks whose files still verify, regenerates
//! the others (identical bytes), and finally writes `manifest.json` and removes `progress.json`. A run with another
//! configuration in the same directory is refused. Temporary files of a killed run are removed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::camera_pass::CameraPass;
use super::manifest::{
    DatasetKind, DatasetManifest, ObjectSetInfo, ShardEntry, SplitCounts, FORMAT_NAME,
    FORMAT_VERSION, MANIFEST_FILE, OBJECTS_DIR, PROGRESS_FILE,
};
use super::sample::Sampler;
use super::shard::{self, Record, SHARDS_DIR};
use super::split::{self, PlannedPair};
use super::{DatasetError, GenConfig, SplitName};
use crate::objects::ObjectSet;
use crate::sim::{PreparedObject, SimConfig, Simulator};

/// Mixed into the dataset seed for the streams that check each object can make a contact (apart from the pairs').
const PROBE_SALT: u64 = 0x7072_6f62_655f_6f62;

/// What a generation run did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GenReport {
    /// Pairs in the dataset.
    pub pairs: usize,
    /// Pairs simulated by this run (the rest were already on disk).
    pub generated: usize,
    /// Chunks found complete on disk and kept.
    pub kept_chunks: usize,
    /// Rejected draws (redraws) of the pairs simulated by this run.
    pub redraws: usize,
    pub counts: SplitCounts,
    /// True when the directory already held the finished dataset.
    pub already_complete: bool,
    /// Objects left out of the draw: none of `max_attempts` draws of pose and press gave them a contact of the
    /// minimum size ([`Sampler::can_contact`]).
    pub excluded_objects: Vec<String>,
    /// Wall time of this run, seconds.
    pub elapsed_s: f64,
}

/// `progress.json`: the dataset being made (without shards) and the chunks already written.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Progress {
    format: String,
    version: u32,
    dataset: DatasetManifest,
    done: BTreeMap<usize, Vec<ShardEntry>>,
}

/// Generate (or resume generating) a dataset of `config.pairs` pairs into `out`. `progress(n)` is called from worker
/// threads each time `n` more pairs are done (including pairs found on disk).
pub fn generate(
    out: &Path,
    sim_config: &SimConfig,
    set: &ObjectSet,
    config: &GenConfig,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<GenReport, DatasetError> {
    let t0 = Instant::now();
    config.validate()?;
    if set.entries().is_empty() {
        return Err(DatasetError::Config("the object set is empty".into()));
    }
    // The sensor, or one per inflation level (a parametric membrane rebuilt at each height), or one per level of a
    // sensor variation.
    let sims: Vec<Simulator> = match (&config.inflation, &config.sensor_variation) {
        (None, Some(v)) => {
            v.validate(sim_config)?;
            v.sensors(sim_config)
                .into_par_iter()
                .map(Simulator::new)
                .collect::<Result<_, _>>()?
        }
        (None, None) => vec![Simulator::new(sim_config.clone())?],
        (Some(_), _) if sim_config.elastomer.mesh_file.is_some() => {
            return Err(DatasetError::Config(
                "an inflation range needs the parametric membrane; the elastomer is a mesh file"
                    .into(),
            ))
        }
        (Some(v), _) => v
            .heights()
            .par_iter()
            .map(|&h| {
                let mut c = sim_config.clone();
                c.elastomer.inflation = h;
                Simulator::new(c)
            })
            .collect::<Result<_, _>>()?,
    };
    let names: Vec<String> = set.entries().iter().map(|e| e.name.clone()).collect();
    let objects: Vec<PreparedObject> = names
        .par_iter()
        .map(|n| Ok(PreparedObject::new(set.mesh(n)?)?))
        .collect::<Result<_, DatasetError>>()?;
    // Objects that cannot make a large enough contact are left out of the draw (weight 0) before planning, so
    // that the plan, its splits and a resumed run agree, and one such object does not end a long run.
    let probe_draw = split::ObjectDraw::uniform(objects.len());
    let probe = Sampler::new(&sims, &objects, &names, &probe_draw, config);
    let pressable: Vec<bool> = (0..objects.len())
        .into_par_iter()
        .map(|i| probe.can_contact(i, split::mix64(config.seed ^ PROBE_SALT ^ i as u64)))
        .collect();
    if !pressable.contains(&true) {
        return Err(DatasetError::NoPressableObject {
            min_pixels: probe.min_pixels,
            attempts: config.max_attempts,
        });
    }
    let excluded_objects: Vec<String> = names
        .iter()
        .zip(&pressable)
        .filter(|(_, &ok)| !ok)
        .map(|(n, _)| n.clone())
        .collect();
    let object_splits: Vec<_> = set.entries().iter().map(|e| e.split).collect();
    let weights: Vec<f64> = set
        .entries()
        .iter()
        .zip(&pressable)
        .map(|(e, &ok)| if ok { e.weight } else { 0.0 })
        .collect();
    let draw = split::ObjectDraw::new(&weights);
    let plan = split::plan(
        config.seed,
        config.pairs,
        &object_splits,
        &draw,
        config.holdout_every,
    );
    // A membrane mesh file travels with the dataset, named by its content, so that the dataset opens anywhere and
    // a resume with another mesh under the same path is refused.
    let membrane = membrane_copy(sim_config)?;
    let stored_sim = match &membrane {
        Some((name, _)) => {
            let mut c = sim_config.clone();
            c.elastomer.mesh_file = Some(PathBuf::from(name));
            c
        }
        None => sim_config.clone(),
    };
    let dataset = planned_manifest(&stored_sim, set, config, &plan)?;
    let mut report = GenReport {
        pairs: config.pairs,
        generated: 0,
        kept_chunks: 0,
        redraws: 0,
        counts: dataset.counts,
        already_complete: false,
        excluded_objects,
        elapsed_s: 0.0,
    };
    if out.join(MANIFEST_FILE).exists() {
        if check_finished(out, &dataset)? {
            progress(config.pairs);
            report.already_complete = true;
            report.kept_chunks = config.chunks();
            report.elapsed_s = t0.elapsed().as_secs_f64();
            return Ok(report);
        }
        // A damaged or missing shard: back to an unfinished run whose intact chunks are kept, so that only the
        // damaged chunks are simulated again (bit for bit what they were: every pair depends only on its seed).
        reopen_finished(out, &dataset)?;
    }
    let mut state = start_or_resume(out, dataset)?;
    // progress.json is the first thing a fresh run writes, so that a run killed at any later point leaves a folder
    // the next run resumes instead of refusing as foreign.
    state.save(&out.join(PROGRESS_FILE))?;
    set.export(&out.join(OBJECTS_DIR))?;
    if let Some((name, bytes)) = &membrane {
        crate::io::write_atomic(&out.join(name), bytes)
            .map_err(|e| DatasetError::io(out.join(name), e))?;
    }
    remove_all_stale_temp_files(out)?;
    let todo = keep_intact_chunks(out, config, &mut state, progress);
    report.kept_chunks = config.chunks() - todo.len();

    // Each sensor's depth camera, where it has one (or every sensor's with `native_frames`): its pairs are rendered
    // natively and brought to the model's size as an import brings a recording's frames.
    let cameras: Vec<Option<CameraPass>> = sims
        .par_iter()
        .map(|s| CameraPass::new(s.config(), config.native_frames))
        .collect::<Result<_, _>>()?;
    let sampler = Sampler::new(&sims, &objects, &names, &draw, config).with_cameras(&cameras);
    let state = simulate_and_write(out, &plan, &todo, &sampler, state, &mut report, progress)?;

    let manifest_path = out.join(MANIFEST_FILE);
    let mut manifest = state.dataset;
    manifest.shards = state.done.into_values().flatten().collect();
    manifest.validate(&manifest_path)?;
    manifest.save(&manifest_path)?;
    let progress_path = out.join(PROGRESS_FILE);
    std::fs::remove_file(&progress_path).map_err(|e| DatasetError::io(&progress_path, e))?;
    report.elapsed_s = t0.elapsed().as_secs_f64();
    Ok(report)
}

/// The membrane mesh file of `sim_config`, if any: the name of its copy in the dataset (`elastomer-<sha256 prefix>.<ext>`,
/// relative to the dataset directory; [`crate::dataset::Dataset::open`] resolves it there) and its bytes.
fn membrane_copy(sim_config: &SimConfig) -> Result<Option<(String, Vec<u8>)>, DatasetError> {
    let Some(path) = &sim_config.elastomer.mesh_file else {
        return Ok(None);
    };
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("obj")
        .to_ascii_lowercase();
    let digest = shard::sha256_hex(&bytes);
    Ok(Some((format!("elastomer-{}.{ext}", &digest[..12]), bytes)))
}

/// The manifest the finished dataset will have, without its shard list.
fn planned_manifest(
    sim_config: &SimConfig,
    set: &ObjectSet,
    config: &GenConfig,
    plan: &[PlannedPair],
) -> Result<DatasetManifest, DatasetError> {
    let mut counts = SplitCounts::default();
    for p in plan {
        counts.add(p.split, 1);
    }
    Ok(DatasetManifest {
        format: FORMAT_NAME.into(),
        version: FORMAT_VERSION,
        kind: DatasetKind::Synthetic,
        resolution: [
            sim_config.camera.resolution.0,
            sim_config.camera.resolution.1,
        ],
        sim: sim_config.clone(),
        generation: Some(config.clone()),
        import: None,
        object_set: ObjectSetInfo {
            source: set.spec(),
            dir: OBJECTS_DIR.into(),
            manifest: set.exported_manifest(),
        },
        counts,
        arrays: DatasetManifest::array_table(),
        shards: Vec::new(),
    })
}

/// `out` holds a finished dataset, which must be this one: `true` when it is intact (leftovers of a run killed after
/// writing `manifest.json`, `progress.json` and temporary files, are removed), `false` when a shard is damaged or
/// missing.
fn check_finished(out: &Path, dataset: &DatasetManifest) -> Result<bool, DatasetError> {
    let manifest_path = out.join(MANIFEST_FILE);
    let existing = DatasetManifest::load(&manifest_path)?;
    if let Some(field) = existing.identity_difference(dataset) {
        return Err(DatasetError::ConfigMismatch {
            path: manifest_path,
            differing: existing.field_differences(dataset, &field),
            field,
        });
    }
    if existing
        .shards
        .iter()
        .any(|s| shard::verify_file(out, s).is_err())
    {
        return Ok(false);
    }
    let progress_path = out.join(PROGRESS_FILE);
    if progress_path.exists() {
        std::fs::remove_file(&progress_path).map_err(|e| DatasetError::io(&progress_path, e))?;
    }
    remove_all_stale_temp_files(out)?;
    Ok(true)
}

/// Turn the finished dataset in `out` (this configuration's, checked by [`check_finished`]) back into an unfinished
/// run that holds all its shards, intact or not: `progress.json` is written before `manifest.json` is removed, so a
/// kill in between leaves a finished dataset that is reopened again.
fn reopen_finished(out: &Path, dataset: &DatasetManifest) -> Result<(), DatasetError> {
    let manifest_path = out.join(MANIFEST_FILE);
    let existing = DatasetManifest::load(&manifest_path)?;
    let mut done: BTreeMap<usize, Vec<ShardEntry>> = BTreeMap::new();
    for s in existing.shards {
        done.entry(s.chunk).or_default().push(s);
    }
    let state = Progress {
        format: FORMAT_NAME.into(),
        version: FORMAT_VERSION,
        dataset: dataset.clone(),
        done,
    };
    state.save(&out.join(PROGRESS_FILE))?;
    std::fs::remove_file(&manifest_path).map_err(|e| DatasetError::io(&manifest_path, e))
}

/// The progress of an unfinished run of the same configuration, or a fresh start in a missing or empty directory.
fn start_or_resume(out: &Path, dataset: DatasetManifest) -> Result<Progress, DatasetError> {
    let progress_path = out.join(PROGRESS_FILE);
    if progress_path.exists() {
        let p = load_progress(&progress_path)?;
        if let Some(field) = p.dataset.identity_difference(&dataset) {
            return Err(DatasetError::ConfigMismatch {
                path: progress_path,
                differing: p.dataset.field_differences(&dataset, &field),
                field,
            });
        }
        return Ok(Progress { dataset, ..p });
    }
    refuse_foreign_dir(out)?;
    Ok(Progress {
        format: FORMAT_NAME.into(),
        version: FORMAT_VERSION,
        dataset,
        done: BTreeMap::new(),
    })
}

/// Keep the recorded chunks whose shards still verify (reporting their pairs as done); return the others.
fn keep_intact_chunks(
    out: &Path,
    config: &GenConfig,
    state: &mut Progress,
    progress: &(dyn Fn(usize) + Sync),
) -> Vec<usize> {
    let recorded = std::mem::take(&mut state.done);
    let mut todo = Vec::new();
    for chunk in 0..config.chunks() {
        match recorded.get(&chunk) {
            Some(shards) if shards.iter().all(|s| shard::verify_file(out, s).is_ok()) => {
                state.done.insert(chunk, shards.clone());
                progress(chunk_range(config, chunk).len());
            }
            _ => todo.push(chunk),
        }
    }
    todo
}

/// Simulate the `todo` chunks in parallel, one after the other, while a writer thread stores the previous chunk's
/// shards and records it in `progress.json`. Returns the final progress.
fn simulate_and_write(
    out: &Path,
    plan: &[PlannedPair],
    todo: &[usize],
    sampler: &Sampler<'_>,
    state: Progress,
    report: &mut GenReport,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Progress, DatasetError> {
    let config = sampler.config;
    let (w, h) = state.dataset.sim.camera.resolution;
    let progress_path = out.join(PROGRESS_FILE);
    let (tx, rx) = mpsc::sync_channel::<(usize, Vec<Record>)>(1);
    std::thread::scope(|scope| {
        let writer = scope.spawn(|| -> Result<Progress, DatasetError> {
            let mut state = state;
            for (chunk, records) in rx {
                let mut entries = Vec::new();
                for split in SplitName::ALL {
                    let mine: Vec<&Record> = records.iter().filter(|r| r.split == split).collect();
                    if !mine.is_empty() {
                        entries.push(shard::write(out, split, chunk, &mine, w, h)?);
                    }
                }
                state.done.insert(chunk, entries);
                state.save(&progress_path)?;
            }
            Ok(state)
        });
        let mut sim_result = Ok(());
        for &chunk in todo {
            let simulated: Result<Vec<(Record, usize)>, DatasetError> = plan
                [chunk_range(config, chunk)]
            .par_iter()
            .map(|p| {
                let r = sampler.sample(p);
                progress(1);
                r
            })
            .collect();
            match simulated {
                Ok(v) => {
                    report.generated += v.len();
                    report.redraws += v.iter().map(|(_, a)| a - 1).sum::<usize>();
                    let records = v.into_iter().map(|(r, _)| r).collect();
                    if tx.send((chunk, records)).is_err() {
                        break; // the writer failed; its error is returned below
                    }
                }
                Err(e) => {
                    sim_result = Err(e);
                    break;
                }
            }
        }
        drop(tx);
        let written = writer
            .join()
            .map_err(|_| DatasetError::Config("the shard writer thread panicked".into()))?;
        sim_result.and(written)
    })
}

/// Pair indices of chunk `chunk`.
fn chunk_range(config: &GenConfig, chunk: usize) -> std::ops::Range<usize> {
    let start = chunk * config.shard_pairs;
    start..(start + config.shard_pairs).min(config.pairs)
}

impl Progress {
    fn save(&self, path: &Path) -> Result<(), DatasetError> {
        let json =
            serde_json::to_string_pretty(self).map_err(|source| DatasetError::Serialize {
                what: "the generation progress",
                source,
            })?;
        crate::io::write_atomic(path, json.as_bytes()).map_err(|e| DatasetError::io(path, e))
    }
}

fn load_progress(path: &Path) -> Result<Progress, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
    let p: Progress = serde_json::from_str(&text).map_err(|e| DatasetError::Manifest {
        path: path.to_path_buf(),
        message: format!("{e} (delete it and the directory to start over)"),
    })?;
    if p.version != FORMAT_VERSION {
        return Err(DatasetError::UnsupportedVersion {
            path: path.to_path_buf(),
            found: p.version,
            supported: FORMAT_VERSION,
        });
    }
    Ok(p)
}

/// A new dataset goes into a missing or empty directory only.
pub(crate) fn refuse_foreign_dir(out: &Path) -> Result<(), DatasetError> {
    match std::fs::read_dir(out) {
        Ok(entries) => {
            // The ledger of the output claim (crate::io::output) is not content.
            let mut entries = entries
                .flatten()
                .filter(|e| e.file_name() != crate::io::output::LEDGER_FILE);
            if entries.next().is_some() {
                if out.join(MANIFEST_FILE).is_file() {
                    return Err(DatasetError::Exists {
                        path: out.to_path_buf(),
                    });
                }
                return Err(DatasetError::NotADataset {
                    path: out.to_path_buf(),
                    message: format!(
                        "the directory is not empty and holds no {PROGRESS_FILE} or {MANIFEST_FILE}; choose a new --out"
                    ),
                });
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(DatasetError::io(out, e)),
    }
}

/// [`remove_stale_temp_files`] in the dataset root, `shards/` and `objects/`.
pub(crate) fn remove_all_stale_temp_files(out: &Path) -> Result<(), DatasetError> {
    for dir in [
        out.to_path_buf(),
        out.join(SHARDS_DIR),
        out.join(OBJECTS_DIR),
    ] {
        remove_stale_temp_files(&dir)?;
    }
    Ok(())
}

/// Remove `.<name>.tmp.<pid>[_<n>]` files left by a killed run (see [`crate::io::write_atomic`]).
fn remove_stale_temp_files(dir: &Path) -> Result<(), DatasetError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(DatasetError::io(dir, e)),
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') && name.contains(".tmp.") {
            let path: PathBuf = entry.path();
            std::fs::remove_file(&path).map_err(|e| DatasetError::io(&path, e))?;
        }
    }
    Ok(())
}
