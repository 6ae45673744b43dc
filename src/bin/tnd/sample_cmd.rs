//! `tnd sample`: de-render one imprint — N samples of the in-contact depth X0 in one batched reverse-diffusion run,
//! written as `.npy` (metres) with their per-pixel mean, standard deviation and contact probability and a PNG grid
//! ([`tactile_derender::pipeline::derender`], the same use case as the workbench's De-render tab).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use image::RgbImage;
use serde_json::json;
use tactile_derender::image::Image;
use tactile_derender::io::preview::{render_panel, save_png, side_by_side, PanelStyle};
use tactile_derender::io::{npy, write_atomic};
use tactile_derender::metrics::evaluate::EvalConfig;
use tactile_derender::model::DiffusionModel;
use tactile_derender::pipeline::{self, DerenderConfig};

#[derive(Args, Debug)]
pub struct SampleArgs {
    /// Model checkpoint (.safetensors with config, or a diffusers directory); default: the bundled model.
    #[arg(long, default_value = "default")]
    pub model: PathBuf,
    /// Imprint Y as a 2-D .npy array in metres, at the model's resolution.
    #[arg(long)]
    pub imprint: PathBuf,
    #[command(flatten)]
    pub derender: DerenderConfig,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(a: SampleArgs) -> Result<()> {
    let model = DiffusionModel::load(&a.model)?;
    let imprint = npy::read_metres_image(&a.imprint)?;
    let mut bar = super::progress::bar("sampling", " steps", 0);
    let out = pipeline::derender(
        &model,
        &imprint,
        &a.derender,
        EvalConfig::default().consensus_probability,
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
    let grid = grid_png(&imprint, samples, &out.mean, &out.std);
    let png = a.out.join("grid.png");
    save_png(&png, &grid).with_context(|| png.display().to_string())?;
    let kind = a.derender.sampler.sampler_kind();
    println!(
        "{}",
        json!({"samples": samples.len(), "sampler": format!("{kind:?}"), "seed": a.derender.seed, "out": a.out,
            "seconds": out.seconds,
            "mean_std_m": out.std.data.iter().map(|&v| f64::from(v)).sum::<f64>() / out.std.data.len() as f64})
    );
    Ok(())
}

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, bytes).with_context(|| path.display().to_string())
}

/// Rows of up to 8 panels: imprint, mean, std, then the first samples (at most 16).
fn grid_png(imprint: &Image, samples: &[Image], mean: &Image, std: &Image) -> RgbImage {
    let style = |title: &str, zero_missing: bool| PanelStyle {
        title: title.into(),
        zero_is_missing: zero_missing,
        ..PanelStyle::default()
    };
    let range = mean.range_where(|v| v > 0.003).filter(|(lo, hi)| hi > lo);
    let mut panels = vec![
        render_panel(imprint, &style("imprint Y", false)),
        render_panel(
            mean,
            &PanelStyle {
                range_m: range,
                ..style("mean X0", true)
            },
        ),
        render_panel(std, &style("std", false)),
    ];
    for (i, s) in samples.iter().take(16).enumerate() {
        panels.push(render_panel(
            s,
            &PanelStyle {
                range_m: range,
                ..style(&format!("sample {i}"), true)
            },
        ));
    }
    let rows: Vec<RgbImage> = panels.chunks(8).map(|c| side_by_side(c, &[])).collect();
    let width = rows.iter().map(|r| r.width()).max().unwrap_or(1);
    let height = rows.iter().map(|r| r.height()).sum::<u32>().max(1);
    let mut out = RgbImage::from_pixel(width, height, image::Rgb([255, 255, 255]));
    let mut y0 = 0;
    for r in &rows {
        image::imageops::overlay(&mut out, r, 0, i64::from(y0));
        y0 += r.height();
    }
    out
}
