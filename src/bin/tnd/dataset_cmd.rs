//! `tnd dataset`: generate synthetic datasets, import real sensor pairs, print statistics, preview one pair.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{anyhow, Context, Result};
use clap::{Args, Subcommand};
use kdam::BarExt;
use serde_json::json;
use tactile_derender::dataset::import::{self, ImportConfig};
use tactile_derender::dataset::import_recording::{self, PoseSource, RecordingImportConfig};
use tactile_derender::dataset::{self, Dataset, GenConfig, SplitName};
use tactile_derender::io::preview;
use tactile_derender::mesh::Units;
use tactile_derender::objects::ObjectSet;

use crate::args::SensorArgs;
use tactile_derender::recording::ReadConfig;

#[derive(Args, Debug)]
pub struct DatasetArgs {
    #[command(subcommand)]
    pub command: DatasetCommand,
}

#[derive(Subcommand, Debug)]
pub enum DatasetCommand {
    /// Generate synthetic pairs (resumable: re-run the same command after an interruption).
    Gen(Box<GenArgs>),
    /// Import real sensor pairs (npy/npz or 16-bit PNG, a CSV or JSON pair table), or a recording (MCAP, a folder of
    /// depth frames) with the object's pose per frame, into the dataset format.
    Import(Box<ImportArgs>),
    /// Counts per split and object, depth/imprint ranges and a contact-area histogram.
    Stats {
        /// Dataset directory (`tnd dataset gen` or `tnd dataset import`).
        dir: PathBuf,
        /// JSON only: leave out the readable summary (on stderr) beside the JSON object (on stdout).
        #[arg(long)]
        json: bool,
        /// Also verify every shard's checksum, dtype and shape (always done for the pairs read).
        #[arg(long)]
        verify: bool,
    },
    /// Write one pair as a PNG: imprint, signature, target and mask with colour bars in mm, and its metadata.
    Show {
        /// Dataset directory (`tnd dataset gen` or `tnd dataset import`).
        dir: PathBuf,
        /// Index of the pair within its split.
        #[arg(long)]
        index: usize,
        /// train, unseen_poses or unseen_objects.
        #[arg(long, default_value = "train")]
        split: String,
        /// Output PNG (an existing file is replaced only if tnd wrote it, or with --force).
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        force: crate::args::ForceArg,
    },
}

#[derive(Args, Debug)]
pub struct GenArgs {
    /// Output directory (created; an unfinished run there is resumed).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of pairs.
    #[arg(long, value_parser = crate::args::at_most::<10_000_000>, default_value_t = GenConfig::default().pairs)]
    pub pairs: usize,
    /// Global seed.
    #[arg(long, default_value_t = GenConfig::default().seed)]
    pub seed: u64,
    /// Object set: "builtin" or a directory with objects.json.
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// Press depth range MIN,MAX in metres [default: 0.003,0.015].
    #[arg(long)]
    pub press: Option<String>,
    /// Object positions: fraction of the camera's view at the apex height (0..1).
    #[arg(long, default_value_t = GenConfig::default().offset_fraction)]
    pub offset_fraction: f64,
    /// Rejection rule: minimum fraction of the image in contact; fewer -> redraw pose and press.
    #[arg(long, default_value_t = GenConfig::default().min_contact_fraction)]
    pub min_contact: f64,
    /// Draws per pair before giving up.
    #[arg(long, default_value_t = GenConfig::default().max_attempts)]
    pub max_attempts: usize,
    /// Pairs per chunk (one shard per split per chunk).
    #[arg(long, default_value_t = GenConfig::default().shard_pairs)]
    pub shard_pairs: usize,
    /// Worker threads (default: all cores). The output does not depend on it.
    #[arg(long, value_parser = crate::args::at_most::<1024>)]
    pub threads: Option<usize>,
    /// Vary the membrane's inflation per pair: MIN,MAX height in metres (e.g. 0.027,0.033 around a calibrated 0.030);
    /// each pair uses one of --inflation-levels evenly spaced heights. Default: the sensor's inflation for every pair.
    #[arg(long)]
    pub inflation_range: Option<String>,
    /// Number of inflation heights of --inflation-range (2..=64).
    #[arg(long, default_value_t = 5)]
    pub inflation_levels: usize,
    /// Vary the camera's distance behind the membrane base per pair: MIN,MAX metres (e.g. 0.057,0.063). With any of
    /// the ranges below, the pairs come from --sensor-levels sensors spread over all given ranges (--inflation-range
    /// among them).
    #[arg(long)]
    pub camera_offset_range: Option<String>,
    /// Vary the footprint per pair: MIN,MAX scale of the sensor's (e.g. 0.95,1.05).
    #[arg(long)]
    pub footprint_scale_range: Option<String>,
    /// Vary the tactile-shadow width per pair: MIN,MAX native pixels (e.g. 15,30).
    #[arg(long)]
    pub shadow_range: Option<String>,
    /// Vary the depth noise per pair: MIN,MAX standard deviation in metres (e.g. 0.001,0.0025).
    #[arg(long)]
    pub noise_range: Option<String>,
    /// Vary the depth camera's artefacts per pair: MIN,MAX strength (0: an ideal camera, 1: the sensor file's
    /// depth_camera, or the time-of-flight preset where the file has none; e.g. 0,1.5). Pairs with artefacts are
    /// rendered at the camera's native resolution and brought to the model's as an import brings a recording.
    #[arg(long)]
    pub camera_artefacts_range: Option<String>,
    /// Render every pair at the camera's native resolution and bring it to the model's as `tnd dataset import` brings
    /// a recording (with an ideal camera too; a sensor with a depth_camera always is): inputs like imported frames,
    /// several times quieter than model-resolution pairs.
    #[arg(long)]
    pub native_frames: bool,
    /// Number of sensors a sensor variation spreads over its ranges (2..=64).
    #[arg(long, default_value_t = 16)]
    pub sensor_levels: usize,
}

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// A directory holding a pair table (pairs.csv or pairs.json) and the image files it names, or a recording: an
    /// .mcap file or a folder of depth frames (then --object and the poses are needed).
    #[arg(long)]
    pub from: PathBuf,
    /// Output dataset directory (must be new or empty).
    #[arg(long)]
    pub out: PathBuf,
    /// Object set the table's object names refer to: "builtin" or a directory with objects.json.
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// Split for rows without a split column: "auto" (unseen objects -> unseen_objects, seen objects 9:1), or a split.
    #[arg(long, default_value = "auto")]
    pub split: String,
    /// Seed of the automatic 9:1 split.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub read: ReadConfig,
    /// Recordings: the pressed object (an entry of --objects).
    #[arg(long)]
    pub object: Option<String>,
    /// Recordings: CSV of the object's pose per frame (columns frame or stamp_ns, x, y, theta, optional press).
    #[arg(long, conflicts_with = "pose_topic")]
    pub poses: Option<PathBuf>,
    /// Recordings: the object-pose topic (geometry_msgs PoseStamped or Pose2D); default: the only pose topic.
    #[arg(long)]
    pub pose_topic: Option<String>,
    /// Recordings: keep every n-th frame.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// Recordings: frames with fewer contact pixels (imprint over --contact-threshold) are skipped.
    #[arg(long, default_value_t = 10)]
    pub min_contact_px: usize,
    /// Recordings: use the given sensor as it is, instead of calibrating it from the recording's no-contact frames
    /// (membrane inflation and footprint, camera position, noise; see tnd calibrate).
    #[arg(long)]
    pub no_calibrate: bool,
    /// Recordings: where no frame has --min-contact-px over --contact-threshold, fail instead of taking the press
    /// in as a light one (frames chosen at 4x the no-contact frames' noise, at least 1 mm; said on stderr).
    #[arg(long)]
    pub no_light_press: bool,
}

pub fn run(a: DatasetArgs) -> Result<()> {
    match a.command {
        DatasetCommand::Gen(g) => gen(*g),
        DatasetCommand::Import(i) => run_import(*i),
        DatasetCommand::Stats { dir, json, verify } => stats(dir, json, verify),
        DatasetCommand::Show {
            dir,
            index,
            split,
            out,
            force,
        } => show(dir, index, &split, out, force.force),
    }
}

fn bar(total: usize, desc: &str) -> Result<Mutex<kdam::Bar>> {
    Ok(Mutex::new(super::progress::bar(desc, " pairs", total)))
}

fn tick(b: &Mutex<kdam::Bar>, n: usize) {
    if let Ok(mut b) = b.lock() {
        let _ = b.update(n);
    }
}

fn finish(b: &Mutex<kdam::Bar>) {
    if let Ok(mut b) = b.lock() {
        super::progress::finish(&mut b);
    }
}

/// Ctrl-C or `kill` (SIGINT, SIGTERM) during generation: say that the same command resumes, then exit as the signal
/// would (status 130 / 143). Every file is written atomically and each finished chunk is recorded, so stopping at
/// any instant is as safe as `kill -9`.
fn say_how_to_resume_when_interrupted() {
    #[cfg(unix)]
    {
        extern "C" fn on_signal(signal: libc::c_int) {
            const MESSAGE: &[u8] =
                b"\ninterrupted: finished chunks are kept; run the same command again to resume\n";
            // SAFETY: write(2) and _exit(2) are async-signal-safe; MESSAGE is a static buffer.
            unsafe {
                libc::write(2, MESSAGE.as_ptr().cast(), MESSAGE.len());
                libc::_exit(128 + signal);
            }
        }
        for signal in [libc::SIGINT, libc::SIGTERM] {
            // SAFETY: installs a handler that only calls async-signal-safe functions.
            unsafe {
                libc::signal(signal, on_signal as *const () as libc::sighandler_t);
            }
        }
    }
}

fn gen(a: GenArgs) -> Result<()> {
    let mut inputs = a.sensor.inputs();
    inputs.push(Path::new(&a.objects));
    let _out = crate::outputs::folder("--out", &a.out, false, &inputs)?;
    let pair = |flag: &str, s: &str, example: &str| {
        s.split_once(',')
            .and_then(|(x, y)| Some([x.trim().parse::<f64>().ok()?, y.trim().parse::<f64>().ok()?]))
            .ok_or_else(|| anyhow!("--{flag} '{s}' must be MIN,MAX in metres, e.g. {example}"))
    };
    let press_range = match &a.press {
        None => GenConfig::default().press_range,
        Some(p) => pair("press", p, "0.003,0.015")?,
    };
    for p in press_range {
        crate::args::check_press("--press", p, false)?;
    }
    let inflation_range = a
        .inflation_range
        .as_deref()
        .map(|s| pair("inflation-range", s, "0.027,0.033"))
        .transpose()?;
    // The other sensor ranges are not all lengths (shadow in pixels, footprint a scale): the example gives the unit.
    let range = |flag: &str, v: &Option<String>, example: &str| -> Result<Option<[f64; 2]>> {
        v.as_deref()
            .map(|s| {
                pair(flag, s, example)
                    .map_err(|_| anyhow!("--{flag} '{s}' must be MIN,MAX, e.g. {example}"))
            })
            .transpose()
    };
    let variation = dataset::sensor_variation::SensorVariation {
        inflation: inflation_range,
        camera_offset: range("camera-offset-range", &a.camera_offset_range, "0.057,0.063")?,
        footprint_scale: range(
            "footprint-scale-range",
            &a.footprint_scale_range,
            "0.95,1.05",
        )?,
        shadow_px: range("shadow-range", &a.shadow_range, "15,30")?,
        noise_std: range("noise-range", &a.noise_range, "0.001,0.0025")?,
        camera_artefacts: range("camera-artefacts-range", &a.camera_artefacts_range, "0,1")?,
        levels: a.sensor_levels,
    };
    let whole_sensor = variation.camera_offset.is_some()
        || variation.footprint_scale.is_some()
        || variation.shadow_px.is_some()
        || variation.noise_std.is_some()
        || variation.camera_artefacts.is_some();
    let (inflation, sensor_variation) = if whole_sensor {
        (None, Some(variation))
    } else {
        let inflation = inflation_range.map(|range| dataset::config::InflationVariation {
            range,
            levels: a.inflation_levels,
        });
        (inflation, None)
    };
    let config = GenConfig {
        pairs: a.pairs,
        seed: a.seed,
        press_range,
        offset_fraction: a.offset_fraction,
        min_contact_fraction: a.min_contact,
        max_attempts: a.max_attempts,
        shard_pairs: a.shard_pairs,
        inflation,
        sensor_variation,
        native_frames: a.native_frames,
        ..GenConfig::default()
    };
    let sim = a.sensor.sim_config()?;
    let artefacts = !sim.depth_camera.is_ideal() || variation.camera_artefacts.is_some();
    if artefacts || a.native_frames {
        eprintln!(
            "pairs are rendered at the camera's native resolution{} and brought to the model's as `tnd dataset \
             import` brings a recording (slower than model-resolution pairs)",
            if artefacts {
                " with the depth camera's artefacts (missing returns, depth-dependent noise, flying pixels, a fixed \
                 pattern)"
            } else {
                ""
            }
        );
    }
    let set = ObjectSet::open(&a.objects).with_context(|| format!("--objects {}", a.objects))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    let pb = bar(config.pairs, "gen")?;
    say_how_to_resume_when_interrupted();
    let report = pool.install(|| dataset::generate(&a.out, &sim, &set, &config, &|n| tick(&pb, n)));
    finish(&pb);
    let report = report?;
    if !report.excluded_objects.is_empty() {
        eprintln!(
            "warning: {} of {} objects left out: none of {} draws of pose and press gave a contact of at least {:.1} % \
             of the image (lower --min-contact or widen --press to keep them): {}",
            report.excluded_objects.len(),
            set.entries().len(),
            config.max_attempts,
            100.0 * config.min_contact_fraction,
            report.excluded_objects.join(", ")
        );
        // An object of implausible size is not helped by either: say so.
        for name in &report.excluded_objects {
            let Ok(mesh) = set.mesh(name) else { continue };
            let largest = mesh.largest_extent();
            if let Some(note) =
                tactile_derender::objects::inspect::size_note(largest, Units::M, None)
            {
                eprintln!("warning: {name}: {note}");
            }
        }
    }
    println!(
        "{}",
        json!({
            "out": crate::path_json(&a.out),
            "pairs": report.pairs,
            "generated": report.generated,
            "kept_chunks": report.kept_chunks,
            "redraws": report.redraws,
            "already_complete": report.already_complete,
            "excluded_objects": report.excluded_objects,
            "counts": report.counts,
            "elapsed_s": report.elapsed_s,
            "pairs_per_s": report.generated as f64 / report.elapsed_s.max(1e-9),
            "threads": pool.current_num_threads(),
        })
    );
    Ok(())
}

fn run_import(a: ImportArgs) -> Result<()> {
    let mut inputs = a.sensor.inputs();
    inputs.extend([a.from.as_path(), Path::new(&a.objects)]);
    let _out = crate::outputs::folder("--out", &a.out, false, &inputs)?;
    let sim = a.sensor.sim_config()?;
    let set = ObjectSet::open(&a.objects).with_context(|| format!("--objects {}", a.objects))?;
    let split = match a.split.as_str() {
        "auto" => None,
        s => Some(
            s.parse::<SplitName>()
                .map_err(|e| anyhow!(e))
                .context("--split")?,
        ),
    };
    let is_table = a.from.join("pairs.csv").is_file() || a.from.join("pairs.json").is_file();
    if is_table {
        let config = ImportConfig {
            npy_scale: a.read.npy_scale,
            png_scale: a.read.png_scale,
            split,
            seed: a.seed,
        };
        let report = import::import(&a.from, &a.out, &sim, &set, &config)?;
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    let object = a.object.clone().ok_or_else(|| {
        anyhow!(
            "{}: no pairs.csv or pairs.json, so it is read as a recording; name the pressed object with --object",
            a.from.display()
        )
    })?;
    let poses = match &a.poses {
        Some(csv) => PoseSource::Csv(csv.clone()),
        None => PoseSource::Topic(a.pose_topic.clone()),
    };
    let mut config = RecordingImportConfig::new(&object, poses);
    config.topic = a.read.topic.clone();
    config.process = a.read.process();
    config.folder = a.read.folder();
    config.every = a.every;
    config.min_contact_px = a.min_contact_px;
    config.split = split;
    config.seed = a.seed;
    config.calibrate = !a.no_calibrate;
    config.light_press = !a.no_light_press;
    let mut bar = crate::progress::bar("frames", "frame", 0);
    let report = import_recording::import_recording(
        &a.from,
        &a.out,
        &sim,
        &set,
        &config,
        &mut crate::progress::callback(&mut bar),
    );
    crate::progress::finish(&mut bar);
    let report = report?;
    crate::calibrate_cmd::tell_calibration(
        &a.from,
        report.calibration.as_ref(),
        report.calibration_failed.as_deref(),
    );
    crate::calibrate_cmd::tell_drift(&a.from, report.drift_m, &[]);
    for why in &report.skipped_missing {
        eprintln!("{}: {why}", a.from.display());
    }
    if let Some(light) = &report.light_press {
        eprintln!(
            "{}: warning: {} (--no-light-press refuses instead); {} pair(s)",
            a.from.display(),
            light.describe(a.min_contact_px),
            report.written.pairs
        );
    }
    println!("{}", serde_json::to_string(&report)?);
    Ok(())
}

fn stats(dir: PathBuf, as_json: bool, verify: bool) -> Result<()> {
    tactile_derender::io::lock::check_not_written(&dir)?;
    let ds = Dataset::open(&dir)?;
    if verify {
        ds.verify()?;
        eprintln!(
            "{}: all {} shards verified (sha256, dtype, shape)",
            dir.display(),
            ds.manifest().shards.len()
        );
    }
    let total = ds.manifest().counts.total();
    let pb = bar(total, "stats")?;
    let s = dataset::stats::compute(&ds, &|n| tick(&pb, n));
    finish(&pb);
    let s = s?;
    // Like every command: the result as JSON on stdout; the readable summary beside it on stderr.
    println!("{}", serde_json::to_string(&s)?);
    if as_json {
        return Ok(());
    }
    let mm = |r: Option<[f32; 2]>| {
        r.map_or("-".to_string(), |[a, b]| {
            format!("{:.2} .. {:.2} mm", a * 1e3, b * 1e3)
        })
    };
    eprintln!(
        "{}: {:?} dataset, {}x{}",
        dir.display(),
        ds.manifest().kind,
        ds.resolution().0,
        ds.resolution().1
    );
    eprintln!(
        "pairs: train {}, unseen_poses {}, unseen_objects {} (total {})",
        s.counts.train, s.counts.unseen_poses, s.counts.unseen_objects, total
    );
    eprintln!(
        "{:<28} {:>7} {:>13} {:>15}",
        "object", "train", "unseen_poses", "unseen_objects"
    );
    for (name, c) in &s.per_object {
        eprintln!(
            "{name:<28} {:>7} {:>13} {:>15}",
            c.train, c.unseen_poses, c.unseen_objects
        );
    }
    eprintln!("target X0 (contact pixels): {}", mm(s.target_range_m));
    eprintln!("signature S:                {}", mm(s.signature_range_m));
    eprintln!("imprint Y:                  {}", mm(s.imprint_range_m));
    if let Some([a, b]) = s.press_range_m {
        eprintln!(
            "press:                      {:.2} .. {:.2} mm",
            a * 1e3,
            b * 1e3
        );
    }
    eprintln!(
        "contact area: mean {:.1} px ({:.2} % of the image); histogram over 0..{:.2} % of the image:",
        s.contact_pixels_mean,
        s.contact_fraction_mean * 100.0,
        s.area_hist_max_fraction * 100.0
    );
    let peak = s.area_hist.iter().copied().max().unwrap_or(1).max(1);
    for (i, &c) in s.area_hist.iter().enumerate() {
        let lo = s.area_hist_max_fraction * 100.0 * i as f64 / s.area_hist.len() as f64;
        let hi = s.area_hist_max_fraction * 100.0 * (i + 1) as f64 / s.area_hist.len() as f64;
        eprintln!("  {lo:6.2}-{hi:6.2} % {c:>7} {}", "#".repeat(c * 50 / peak));
    }
    Ok(())
}

fn show(dir: PathBuf, index: usize, split: &str, out: PathBuf, force: bool) -> Result<()> {
    tactile_derender::io::lock::check_not_written(&dir)?;
    let claimed = crate::outputs::file(
        "--out",
        &out,
        force,
        &[&dir],
        &tactile_derender::io::preview::written_by_tnd,
    )?;
    let out = claimed.path();
    let split: SplitName = split.parse().context("--split")?;
    let ds = Dataset::open(&dir)?;
    let pair = ds.pair(split, index)?;
    let panels: Vec<_> = [
        ("imprint", "Y imprint", &pair.imprint),
        ("signature", "S signature", &pair.signature),
        ("target", "X0 target", &pair.target),
        ("mask", "M mask", &pair.mask),
    ]
    .iter()
    .map(|(f, t, img)| preview::render_panel(img, &crate::sim_cmd::preview_style(f, t)))
    .collect();
    let m = &pair.meta;
    let press = if m.press.is_finite() {
        format!("{:.2}mm", m.press * 1e3)
    } else {
        "unknown".into()
    };
    let caption = vec![
        format!(
            "{} #{} (pair {})  object {}  pose x={:.2}mm y={:.2}mm theta={:.1}deg",
            split,
            index,
            m.index,
            m.object,
            m.object_pose.x * 1e3,
            m.object_pose.y * 1e3,
            m.object_pose.theta.to_degrees()
        ),
        format!(
            "press={press}  contact={} px  seed={}  {}",
            m.contact_pixels,
            m.seed,
            dir.display()
        ),
    ];
    preview::save_png(out, &preview::side_by_side(&panels, &caption))?;
    println!("{}", json!({"out": crate::path_json(out), "meta": m}));
    Ok(())
}
