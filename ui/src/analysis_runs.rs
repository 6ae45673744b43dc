//! The analysis tabs' runs (dataset inspector, de-rendering and pose runs; paper V.A, IV.B, IV.C): the open dataset
//! browser, the running or finished runs with their textures and the cached model, the methods the one command
//! dispatcher ([`crate::command`]) calls to start, cancel and export them, and how worker messages update them.
//! Nothing here is saved; the settings are in [`crate::analysis_settings`].

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, Result};
use egui::{TextureHandle, TextureOptions};
use tactile_derender::image::Image;
use tactile_derender::io::preview::{self, PanelStyle};
use tactile_derender::model::DiffusionModel;

use crate::colormap::to_color_image;
use crate::dataset_view::DatasetBrowser;
use crate::derender::{RunInput, RunResult};
use crate::pose_view::PoseAnalysis;

/// One shown image of a run.
pub struct RunImage {
    pub title: String,
    pub texture: TextureHandle,
    /// Colour range, metres (or 0..1 for the contact probability).
    pub range: (f32, f32),
    pub zero_is_missing: bool,
    /// Values are lengths (shown in mm); false for the contact probability (a fraction).
    pub millimetres: bool,
}

/// A de-rendering run as the UI sees it.
#[derive(Default)]
pub struct DerenderView {
    pub generation: u64,
    pub running: bool,
    pub progress: Option<(usize, usize)>,
    pub started: Option<Instant>,
    pub(crate) cancel: Option<Arc<AtomicBool>>,
    /// The loaded model with the checkpoint and the device it was loaded from and onto.
    pub model: Option<(PathBuf, String, Arc<DiffusionModel>)>,
    pub result: Option<Box<RunResult>>,
    /// Input Y, truth X0 (if known), mean, std, contact probability, consensus, then the samples.
    pub images: Vec<RunImage>,
    /// A dataset pair (or scene) made the current input; shown until a run replaces it.
    pub pending_input: Option<RunInput>,
}

/// The pose analysis as the UI sees it.
#[derive(Default)]
pub struct PoseView {
    pub generation: u64,
    pub running: bool,
    /// `(done, total)` registrations of the running analysis.
    pub progress: Option<(usize, usize)>,
    /// Set to stop the running analysis at its next registration.
    pub cancel: Option<Arc<AtomicBool>>,
    pub result: Option<Box<PoseAnalysis>>,
    /// The sample highlighted by hovering the KDE plots.
    pub highlight: Option<usize>,
}

/// Live state of the analysis tabs.
#[derive(Default)]
pub struct AnalysisViews {
    pub dataset: Option<DatasetBrowser>,
    pub(crate) dataset_generation: u64,
    pub derender: DerenderView,
    pub pose: PoseView,
    /// The image shown enlarged in its own window, if any.
    pub zoom: Option<ZoomTarget>,
}

/// An image of an analysis tab that can be shown enlarged (clicking its card).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ZoomTarget {
    /// Image `k` of the de-rendering run (Y, X0, mean, std, …, then the samples).
    Derender(usize),
    /// Image `k` of the selected dataset pair.
    DatasetPair(usize),
}

/// The open dataset and its loaded selected pair.
pub(crate) fn selected_pair(
    views: &AnalysisViews,
) -> Result<(&DatasetBrowser, &crate::dataset_view::SelectedPair)> {
    let b = views
        .dataset
        .as_ref()
        .ok_or_else(|| anyhow!("open a dataset first"))?;
    let sel = b
        .selected
        .as_ref()
        .ok_or_else(|| anyhow!("select a pair first (it may still be loading)"))?;
    Ok((b, sel))
}

fn texture(
    ctx: &egui::Context,
    name: &str,
    img: &Image,
    range: (f32, f32),
    zim: bool,
) -> TextureHandle {
    ctx.load_texture(
        name,
        to_color_image(img, range, zim),
        TextureOptions::NEAREST,
    )
}

/// Narrowest colour range of the depth maps, metres: a flat contact (a box's top) would otherwise stretch float noise
/// over the whole colour map.
const MIN_DEPTH_SPAN: f32 = 0.004;

fn depth_range(images: &[&Image]) -> (f32, f32) {
    let mut lo = f32::INFINITY;
    let mut hi = f32::NEG_INFINITY;
    for img in images {
        if let Some((a, b)) = img.range_where(|v| v != 0.0 && v.is_finite()) {
            lo = lo.min(a);
            hi = hi.max(b);
        }
    }
    if !lo.is_finite() {
        return (0.0, 0.1);
    }
    let mid = 0.5 * (lo + hi);
    let half = 0.5 * (hi - lo).max(MIN_DEPTH_SPAN);
    (mid - half, mid + half)
}

/// Textures of a finished run: one depth range for truth, mean and samples so they compare by colour.
pub(crate) fn run_images(ctx: &egui::Context, r: &RunResult) -> Vec<RunImage> {
    let mut depths: Vec<&Image> = r.samples.iter().collect();
    depths.push(&r.mean);
    if let Some(t) = &r.input.truth {
        depths.push(t);
    }
    // With a ground truth, its range (samples outside it saturate); else the range of all samples.
    let range = match &r.input.truth {
        Some(t) => depth_range(&[t]),
        None => depth_range(&depths),
    };
    let own = |img: &Image, zim: bool| {
        preview::display_range(
            img,
            &PanelStyle {
                zero_is_missing: zim,
                ..Default::default()
            },
        )
    };
    let mut out = Vec::new();
    let mut add = |title: String, img: &Image, range: (f32, f32), zim: bool| {
        out.push(RunImage {
            texture: texture(ctx, &format!("run-{title}"), img, range, zim),
            millimetres: title != "contact probability",
            title,
            range,
            zero_is_missing: zim,
        });
    };
    add(
        "Y imprint".into(),
        &r.input.imprint,
        own(&r.input.imprint, false),
        false,
    );
    if let Some(t) = &r.input.truth {
        add("X0 ground truth".into(), t, range, true);
    }
    add("sample mean".into(), &r.mean, range, true);
    add("sample std".into(), &r.std, own(&r.std, false), false);
    add(
        "contact probability".into(),
        &r.contact_probability,
        (0.0, 1.0),
        false,
    );
    add("consensus (multi-sample)".into(), &r.consensus, range, true);
    for (i, s) in r.samples.iter().enumerate() {
        add(format!("sample {i}"), s, range, true);
    }
    out
}
