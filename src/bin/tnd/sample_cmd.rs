//! `tnd sample`: de-render one imprint — N samples of the in-contact depth X0 in one batched reverse-diffusion run,
//! written as `.npy` (metres) with their per-pixel mean, standard deviation and contact probability and a figure
//! (grid.svg, grid.png)
//! ([`tactile_derender::pipeline::derender`], the same use case as the workbench's De-render tab).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;
use tactile_derender::image::Image;
use tactile_derender::io::figure::{write_figure, FigureConfig, ImageGrid};
use tactile_derender::io::preview::PanelStyle;
use tactile_derender::io::{npy, write_atomic};
use tactile_derender::model::DiffusionModel;
use tactile_derender::pipeline::{self, DerenderConfig};
use tactile_derender::pose::estimator::DEFAULT_CONSENSUS_PROBABILITY;

#[derive(Args, Debug)]
pub struct SampleArgs {
    /// Model checkpoint (.safetensors with config, or a diffusers directory) or a bundled model (`auto`:
    /// `recording` for frames resampled from a camera's native or cropped size, `default` for frames at the model
    /// resolution; `small`: twice as fast).
    #[arg(long, default_value = "auto")]
    pub model: PathBuf,
    /// The imprint, or the signature and its reference; with the signature the samples are guided towards the
    /// imprint on the sensor below (its membrane and tactile-shadow cloak); without it they are not.
    #[command(flatten)]
    pub measured: crate::measured::MeasuredArgs,
    #[command(flatten)]
    pub sensor: super::args::SensorArgs,
    #[command(flatten)]
    pub derender: DerenderConfig,
    /// Size of the grid figure (grid.svg, grid.png), pixels WxH (default: 2400 wide, as tall as its rows of four
    /// panels need).
    #[arg(long, value_parser = super::args::parse_figure_size)]
    pub figure_size: Option<FigureConfig>,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
    /// The rerun recording shows the images in the frame of the default sensor's camera (`tnd sample` has no scene).
    #[command(flatten)]
    pub rerun: crate::rerun_out::RerunArgs,
}

pub fn run(a: SampleArgs) -> Result<()> {
    let mut inputs = a.measured.inputs();
    inputs.extend(a.sensor.inputs());
    inputs.push(&a.model);
    let _out = crate::outputs::folder("--out", &a.out, a.force.force, &inputs)?;
    let device = tactile_derender::model::device::open_device(&a.derender.device)?;
    // A named model is checked before the input is read; `auto` is picked by the input.
    let auto = a.model.as_os_str() == tactile_derender::model::checkpoint::AUTO_MODEL_NAME;
    let named = if auto {
        None
    } else {
        Some(DiffusionModel::load_on(&a.model, &device)?)
    };
    let measured = a
        .measured
        .read(a.sensor.sim_config()?, a.sensor.sensor.is_some(), true)?;
    let model = match named {
        Some(m) => m,
        None => {
            let what = a
                .measured
                .inputs()
                .first()
                .map_or_else(String::new, |p| p.display().to_string());
            let model = crate::args::resolve_model(
                &a.model.display().to_string(),
                measured.resampled,
                &what,
            );
            DiffusionModel::load_on(Path::new(&model), &device)?
        }
    };
    let imprint = measured.imprint;
    let rrd = a.rerun.open("tnd sample", a.force.force, &inputs)?;
    let mut bar = super::progress::bar("sampling", " steps", 0);
    // Imprint guidance needs the membrane the imprint was measured against: the signature says where it was.
    let guidance = match &measured.signature {
        Some(signature) => {
            let sim = tactile_derender::sim::Simulator::new(measured.sim.clone())?;
            pipeline::imprint_guidance(&a.derender, &sim, &imprint, Some(signature))?
        }
        None => {
            if a.derender.guidance.active() {
                eprintln!(
                    "note: no --signature, so no imprint guidance (it needs the membrane the imprint was measured against)"
                );
            }
            None
        }
    };
    let guided = guidance.is_some();
    let out = pipeline::derender(
        &model,
        &imprint,
        guidance.as_ref(),
        &a.derender,
        DEFAULT_CONSENSUS_PROBABILITY,
        &mut super::progress::callback(&mut bar),
    )?;
    super::progress::finish(&mut bar);
    let samples = &out.samples;
    let (w, h) = (imprint.width, imprint.height);
    std::fs::create_dir_all(&a.out).with_context(|| a.out.display().to_string())?;
    let all: Vec<f32> = samples
        .iter()
        .flat_map(|s| s.data.iter().copied())
        .collect();
    write(
        &a.out.join("samples.npy"),
        &npy::encode_f32(&[samples.len(), h, w], &all),
    )?;
    npy::write_image(&a.out.join("mean.npy"), &out.mean)?;
    npy::write_image(&a.out.join("std.npy"), &out.std)?;
    npy::write_image(
        &a.out.join("contact_probability.npy"),
        &out.contact_probability,
    )?;
    let figure = grid(&imprint, &out, a.derender.seed);
    // Square images of ~350 px in cells 600 px wide (the colour bar beside them) with their titles: 460 px a row.
    let size = a.figure_size.unwrap_or(FigureConfig {
        width_px: 2400,
        height_px: (90 + 460 * figure.panels.len().div_ceil(figure.columns)) as u32,
    });
    write_figure(&a.out, "grid", &size, &figure)?;
    if let Some(log) = &rrd {
        use crate::rerun_out::camera_views;
        let k = tactile_derender::sim::SimConfig::default()
            .camera
            .intrinsics()
            .resized(w, h);
        let at = glam::DAffine3::IDENTITY;
        log.set_step("sample", 0);
        let fixed = [
            ("imprint", &imprint),
            ("mean", &out.mean),
            ("std", &out.std),
            ("contact_probability", &out.contact_probability),
        ];
        camera_views(log, &k, &at, &fixed, None)?;
        for (i, s) in samples.iter().enumerate() {
            log.set_step("sample", i);
            camera_views(log, &k, &at, &[("sample", s)], Some(("sample", s)))?;
        }
    }
    let rerun = crate::rerun_out::finish(rrd)?;
    println!(
        "{}",
        json!({"samples": samples.len(), "sampler": a.derender.sampler, "seed": a.derender.seed, "out": crate::path_json(&a.out),
            "imprint_guided": guided,
            "seconds": out.seconds, "rerun": rerun.as_deref().map(crate::path_json),
            "mean_std_m": out.std.data.iter().map(|&v| f64::from(v)).sum::<f64>() / out.std.data.len() as f64})
    );
    Ok(())
}

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, bytes).with_context(|| path.display().to_string())
}

/// The figure of a run: imprint, mean, std and contact probability, then the first samples (at most 16), four per
/// row, each with its colour bar (mm, or 0..1 for the probability).
fn grid<'a>(imprint: &'a Image, out: &'a pipeline::Derendered, seed: u64) -> ImageGrid<'a> {
    let style = |title: String, zero_missing: bool| PanelStyle {
        title,
        zero_is_missing: zero_missing,
        ..PanelStyle::default()
    };
    // The in-contact depths of the samples (decoded no contact is 0), 2nd to 98th percentile: a few stray edge
    // pixels would otherwise stretch the colour bar until the contact is one flat colour.
    let mut depths: Vec<f32> = out
        .samples
        .iter()
        .flat_map(|s| s.data.iter().copied().filter(|&v| v > 0.0))
        .collect();
    depths.sort_by(f32::total_cmp);
    let at = |q: f64| depths[((depths.len() - 1) as f64 * q).round() as usize];
    let range = (!depths.is_empty())
        .then(|| (at(0.02), at(0.98)))
        .filter(|(lo, hi)| hi > lo);
    let mut panels = vec![
        (imprint, style("imprint Y".into(), false)),
        (
            &out.mean,
            PanelStyle {
                range_m: range,
                ..style("mean X0".into(), true)
            },
        ),
        (&out.std, style("std".into(), false)),
        (
            &out.contact_probability,
            PanelStyle {
                range_m: Some((0.0, 1.0)),
                millimetres: false,
                ..style("contact probability".into(), false)
            },
        ),
    ];
    for (i, s) in out.samples.iter().take(16).enumerate() {
        panels.push((
            s,
            PanelStyle {
                range_m: range,
                ..style(format!("sample {i}"), true)
            },
        ));
    }
    ImageGrid {
        title: match out.samples.len() {
            n if n > 16 => format!("16 of {n} samples of X0 (all in samples.npy), seed {seed}"),
            n => format!("{n} samples of X0, seed {seed}"),
        },
        panels,
        columns: 4,
    }
}
