//! `tnd posterior`: how well the pose posterior's regions cover the truth on `tnd eval --records` files (per method
//! and per contact-size bin: coverage at every level, sharpness and the log density of the truth,
//! [`tactile_derender::metrics::coverage`]; `--figures` draws them), and a calibration fitted to them (`--fit`)
//! that `tnd eval`, `tnd pose` and `tnd recording track` take as `--posterior FILE`: a user with labelled
//! recordings of their own sensor calibrates the uncertainty it reports.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use serde_json::json;
use tactile_derender::io::figure::{write_figure, FigureConfig};
use tactile_derender::metrics::breakdown::{bin_label, CONTACT_BINS};
use tactile_derender::metrics::coverage::{
    calibrated, fit_posterior, reliability, with_posteriors, Coverage, Fit, Reliability, Scored,
    WRONG_MM,
};
use tactile_derender::metrics::eval_log::EvalLog;
use tactile_derender::metrics::evaluate::{MethodResult, PairRecord, REGION_DRAWS};
use tactile_derender::metrics::reliability_figure::ReliabilityFigure;
use tactile_derender::pipeline::track::FrameTrack;
use tactile_derender::pipeline::track_posteriors::TrackPosteriors;
use tactile_derender::pose::posterior::PosteriorConfig;

#[derive(Args, Debug)]
pub struct PosteriorArgs {
    /// Records files of `tnd eval --records` (pairs with a known true pose).
    #[arg(long, num_args = 1.., required_unless_present = "tracks")]
    pub records: Vec<PathBuf>,
    /// Folders of `tnd recording track` scored against recorded poses (track.csv and posteriors.json): their
    /// frames are the "track" rows, and a calibration fitted to them replays each carried frame's fusion with the
    /// frames before it, as the track reports it.
    #[arg(long, num_args = 1.., value_name = "DIR")]
    pub tracks: Vec<PathBuf>,
    /// The rows scored: combined (the default pipeline: the sample and the imprint's proposals, checked), model,
    /// multi, baseline_checked, or all.
    #[arg(long, default_value = "all")]
    pub method: String,
    /// Recalibrate the recorded posteriors with this calibration (JSON, as --fit writes) before scoring.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Fit the calibration (temperatures, floors and heavy tails, and with --tracks how much a frame's predecessors
    /// count; by the mean negative log density of the truth) to the chosen rows of these records, print their
    /// coverage under it, and write it here (JSON) for `--posterior FILE`.
    #[arg(long, value_name = "FILE")]
    pub fit: Option<PathBuf>,
    /// Draw the reliability diagram and sharpness (per contact-size bin, of the first chosen rows) into this folder:
    /// reliability.svg and reliability.png.
    #[arg(long, value_name = "DIR")]
    pub figures: Option<PathBuf>,
    /// JSON lines only (no markdown table on stderr).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
}

/// One row of a record, by name.
type Row = fn(&PairRecord) -> Option<&MethodResult>;

/// The rows of a record by name.
const METHODS: [(&str, Row); 4] = [
    ("combined", |r| r.model_combined.as_ref()),
    ("model", |r| Some(&r.model)),
    ("multi", |r| r.model_multi.as_ref()),
    ("baseline_checked", |r| r.baseline_checked.as_ref()),
];

pub fn run(a: PosteriorArgs) -> Result<()> {
    let methods = chosen_methods(&a.method, a.records.is_empty())?;
    check_records_once(&a.records)?;
    let mut inputs: Vec<&Path> = a.records.iter().map(PathBuf::as_path).collect();
    inputs.extend(a.tracks.iter().map(PathBuf::as_path));
    inputs.extend(a.config.as_deref());
    let fitted_file = |p: &Path| PosteriorConfig::read(p).is_ok();
    let _claim = a
        .fit
        .as_deref()
        .map(|p| crate::outputs::file("--fit", p, a.force.force, &inputs, &fitted_file))
        .transpose()?;
    let figures = a
        .figures
        .as_deref()
        .map(|p| crate::outputs::folder("--figures", p, a.force.force, &inputs))
        .transpose()?;
    let config = a
        .config
        .as_deref()
        .map(|p| PosteriorConfig::read(p).map_err(|e| anyhow!("{}: {e}", p.display())))
        .transpose()?;
    let mut records = Vec::new();
    for path in &a.records {
        records.extend(EvalLog::read(path)?.1);
    }
    let tracks = read_tracks(&a.tracks)?;
    // Each chosen row's pairs: the records' rows, then the tracks' frames.
    let mut rows: Vec<(&str, Vec<Scored<'_>>)> = methods
        .iter()
        .map(|(name, get)| (*name, scored(&records, *get)))
        .collect();
    if !tracks.is_empty() {
        rows.push((TRACK_ROWS, track_scored(&tracks)));
    }
    rows.retain(|(_, r)| !r.is_empty());
    let all = concatenated(rows.iter().map(|(_, r)| r.as_slice()));
    if all.is_empty() {
        bail!(
            "no pair of {} records file(s) and {} track(s) has a posterior of the chosen rows (records of tnd eval with \
             the signature check, tracks scored against recorded poses, from this version on)",
            a.records.len(),
            a.tracks.len()
        );
    }
    let fitted = a
        .fit
        .as_ref()
        .map(|_| fit_posterior(&all, &config.clone().unwrap_or_default()));
    let used = fitted.as_ref().map(|f| &f.config).or(config.as_ref());
    let (table, drawn) = score_groups(&rows, used, figures.is_some());
    if !a.json {
        eprintln!(
            "\nThe truth inside the posterior's regions ({}; confidently wrong: > {WRONG_MM} mm off, outside the 95 % region)\n\n{table}",
            match (&fitted, &a.config) {
                (Some(_), _) => "calibration fitted to these records".to_string(),
                (None, Some(p)) => format!("calibration {}", p.display()),
                (None, None) => "as recorded".into(),
            }
        );
    }
    if let Some(dir) = &figures {
        let calibration = match (&fitted, &a.config) {
            (Some(_), _) => "fitted to these records".to_string(),
            (None, Some(p)) => format!("calibration {}", p.display()),
            (None, None) => "as recorded".into(),
        };
        draw_reliability(dir.path(), rows[0].0, &calibration, &drawn)?;
    }
    if let (Some(f), Some(path)) = (&fitted, &a.fit) {
        let track_frames = rows
            .iter()
            .filter(|(name, _)| *name == TRACK_ROWS)
            .map(|(_, r)| r.len())
            .sum();
        write_fit(f, path, all.len(), track_frames, a.json)?;
    }
    Ok(())
}

/// The name of the tracks' rows.
const TRACK_ROWS: &str = "track";

/// Each `--tracks` folder's rows (track.csv) and posteriors (posteriors.json), or a one-line error naming the
/// folder and what is missing.
fn read_tracks(dirs: &[PathBuf]) -> Result<Vec<(Vec<FrameTrack>, TrackPosteriors)>> {
    dirs.iter()
        .map(|dir| {
            let rows = crate::track_cmd::earlier_rows(dir)?;
            if rows.is_empty() {
                bail!("--tracks {}: no track.csv with rows (a folder of tnd recording track)", dir.display());
            }
            let posteriors = TrackPosteriors::read(dir)?.ok_or_else(|| {
                anyhow!(
                    "--tracks {}: no {} (a track of an earlier version: run tnd recording track into a fresh folder)",
                    dir.display(),
                    TrackPosteriors::FILE
                )
            })?;
            Ok((rows, posteriors))
        })
        .collect()
}

/// The scored frames of every track, one list (each track's fusion links kept); frames whose fusion cannot be
/// replayed (the frame before has no recorded pose) are left out with a warning.
fn track_scored(tracks: &[(Vec<FrameTrack>, TrackPosteriors)]) -> Vec<Scored<'_>> {
    let mut left_out = 0;
    let lists: Vec<Vec<Scored<'_>>> = tracks
        .iter()
        .map(|(rows, posteriors)| {
            let (scored, left) = posteriors.scored(rows);
            left_out += left;
            scored
        })
        .collect();
    if left_out > 0 {
        eprintln!(
            "warning: {left_out} track frame(s) left out: the frame their posterior was fused with has no recorded pose"
        );
    }
    concatenated(lists.iter().map(Vec::as_slice))
}

/// The lists one after another, each pair's [`Scored::prior`] moved with its list.
fn concatenated<'a, 'b>(lists: impl Iterator<Item = &'b [Scored<'a>]>) -> Vec<Scored<'a>>
where
    'a: 'b,
{
    let mut out: Vec<Scored<'a>> = Vec::new();
    for list in lists {
        let offset = out.len();
        out.extend(list.iter().map(|s| Scored {
            prior: s.prior.map(|i| i + offset),
            ..s.clone()
        }));
    }
    out
}

/// The rows `--method` names (all four for "all"), or an error listing the names; none when only tracks are given.
fn chosen_methods(method: &str, no_records: bool) -> Result<Vec<&'static (&'static str, Row)>> {
    if no_records {
        return Ok(Vec::new());
    }
    let methods: Vec<_> = METHODS
        .iter()
        .filter(|(name, _)| method == "all" || method == *name)
        .collect();
    if methods.is_empty() {
        bail!("--method {method}: one of combined, model, multi, baseline_checked or all");
    }
    Ok(methods)
}

/// Each records file once (the same file under two names counts once too), and none an eval is still writing.
fn check_records_once(records: &[PathBuf]) -> Result<()> {
    let mut seen: Vec<(PathBuf, PathBuf)> = Vec::new();
    for path in records {
        let real = tactile_derender::io::output::resolve(path)
            .map_err(|e| anyhow!("{}: {e}", path.display()))?;
        if let Some(first) = seen.iter().find(|(r, _)| *r == real).map(|(_, p)| p) {
            bail!(
                "--records {} is {} again: each records file is given once",
                path.display(),
                first.display()
            );
        }
        tactile_derender::io::lock::check_not_written(path)?;
        seen.push((real, path.clone()));
    }
    Ok(())
}

/// The pairs whose `get` row has a posterior and a pose, ready to score against their truth.
fn scored(records: &[PairRecord], get: Row) -> Vec<Scored<'_>> {
    records
        .iter()
        .filter_map(|r| {
            let m = get(r)?;
            Some(Scored {
                posterior: m.posterior.as_ref()?,
                truth: r.truth,
                symmetry: r.symmetry,
                position_mm: m.pose?.position_mm,
                theta_rad: m.pose?.theta_rad,
                contact_pixels: r.contact_pixels,
                prior: None,
            })
        })
        .collect()
}

/// Score each chosen row over all its pairs and per contact-size bin under the calibration `used` (tracks' fusion
/// replayed over the whole row first): print one JSON line per group and answer the markdown table, with the first
/// row's reliabilities to draw when `drawing`.
fn score_groups(
    rows: &[(&str, Vec<Scored<'_>>)],
    used: Option<&PosteriorConfig>,
    drawing: bool,
) -> (String, Vec<(String, Reliability)>) {
    let mut table = String::from(
        "| rows | contact | pairs | inside 50 % | inside 90 % | inside 95 % | confidently wrong | mean NLL | median σ (±68 %) / error, position [mm] | median σ (core, ±68 %) / error, θ [deg] |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut drawn: Vec<(String, Reliability)> = Vec::new();
    for (i, (name, all)) in rows.iter().enumerate() {
        let posteriors = used.map(|c| calibrated(all, c));
        let all = match &posteriors {
            Some(p) => with_posteriors(all, p),
            None => all.clone(),
        };
        for (group, mine) in contact_groups(all) {
            let Some((c, r)) = reliability(&mine, None, REGION_DRAWS) else {
                continue;
            };
            println!(
                "{}",
                json!({"rows": name, "contact": group, "coverage": c, "wrong_mm": WRONG_MM, "reliability": r})
            );
            table.push_str(&row(name, &group, &c, &r));
            if drawing && i == 0 {
                drawn.push((group, r));
            }
        }
    }
    (table, drawn)
}

/// "all" with every row, then each contact-size bin with its rows (bins without any left out).
fn contact_groups(rows: Vec<Scored<'_>>) -> Vec<(String, Vec<Scored<'_>>)> {
    let mut groups: Vec<(String, Vec<Scored<'_>>)> = vec![("all".into(), rows.clone())];
    for &(lo, hi) in &CONTACT_BINS {
        let mine: Vec<Scored<'_>> = rows
            .iter()
            .filter(|s| (lo..hi).contains(&s.contact_pixels))
            .cloned()
            .collect();
        if !mine.is_empty() {
            groups.push((bin_label((lo, hi)), mine));
        }
    }
    groups
}

/// Draw the reliability diagram of `drawn` (the `method` rows, under `calibration`) into `dir` and print the files
/// as a JSON line.
fn draw_reliability(
    dir: &Path,
    method: &str,
    calibration: &str,
    drawn: &[(String, Reliability)],
) -> Result<()> {
    let title = format!("pose posterior: {method} rows, {calibration}");
    let [svg, png] = write_figure(
        dir,
        "reliability",
        &FigureConfig {
            width_px: 3000,
            height_px: 1000,
        },
        &ReliabilityFigure {
            title: &title,
            groups: drawn,
        },
    )?;
    println!(
        "{}",
        json!({"figures": [crate::path_json(&svg), crate::path_json(&png)]})
    );
    Ok(())
}

/// Write the fitted calibration to `path` (JSON for `--posterior FILE`) and print it with its fit over `pairs` pairs
/// (`track_frames` of them tracked frames); unless `json_only`, say in a line what was fitted.
fn write_fit(
    f: &Fit,
    path: &Path,
    pairs: usize,
    track_frames: usize,
    json_only: bool,
) -> Result<()> {
    tactile_derender::io::write_atomic(path, serde_json::to_string_pretty(&f.config)?.as_bytes())
        .with_context(|| format!("{}: cannot write", path.display()))?;
    if !json_only {
        let c = &f.config;
        // Tracks are of recordings, whose frames the bundled calibration for resampled frames covers.
        let bundled = PosteriorConfig::default().for_frames(true).fusion_weight;
        let fusion = if track_frames > 0 {
            format!(
                "fusion weight {:.2} (fitted to {track_frames} tracked frames; the bundled calibration's for recordings {bundled})",
                c.fusion_weight
            )
        } else {
            format!(
                "fusion weight {:.2} (kept: no tracked frames to fit it to)",
                c.fusion_weight
            )
        };
        eprintln!(
            "\nWrote {}: temperature {:.2}, covariance temperature {:.2}, floors {:.3} mm and {:.2} deg at {} contact \
             px, {fusion}; its objective, the mean negative log density of the truth with each contact-size bin \
             weighing alike, {:.2} over {pairs} pairs (few pairs flatter it: score the file on others with --config)",
            path.display(),
            c.temperature,
            c.covariance_temperature,
            c.floor_position_m * 1e3,
            c.floor_theta_rad.to_degrees(),
            c.floor_contact_px,
            f.mean_nll
        );
    }
    println!(
        "{}",
        json!({"fit": crate::path_json(path), "config": f.config, "mean_nll": f.mean_nll, "pairs": pairs})
    );
    Ok(())
}

fn row(name: &str, group: &str, c: &Coverage, r: &Reliability) -> String {
    let num = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    format!(
        "| {name} | {group} | {} | {:.2} | {:.2} ({}) / {:.2} | {} |\n",
        coverage_cells(c),
        r.mean_nll,
        r.median_sigma_position_mm,
        num(r.median_half_width_position_mm),
        r.median_error_position_mm,
        match r.median_sigma_theta_deg {
            Some(s) => format!(
                "{s:.2} ({}, {}) / {}",
                num(r.median_core_sigma_theta_deg),
                num(r.median_half_width_theta_deg),
                num(r.median_error_theta_deg)
            ),
            None => "-".into(),
        }
    )
}

/// A coverage's markdown cells: pairs, inside 50 / 90 / 95 %, confidently wrong (this table's and `tnd eval`'s).
pub fn coverage_cells(c: &Coverage) -> String {
    format!(
        "{} | {:.0} % | {:.0} % | {:.0} % | {}",
        c.pairs,
        c.inside[0] * 100.0,
        c.inside[1] * 100.0,
        c.inside[2] * 100.0,
        c.confidently_wrong
    )
}
