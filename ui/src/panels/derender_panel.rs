//! De-render tab (paper IV.B sampling, V.C metrics): choose the model (bundled default or a checkpoint), the sampler
//! (DDPM-250 or DDIM with K steps and η), the number of samples and the seed, and the input (the simulated scene, a
//! dataset pair, or an `.npy` measurement); run in the background with progress and Cancel; show the samples, their
//! per-pixel mean and standard deviation, and L1 / PSNR / SSIM per sample when the ground truth is known.

use crate::analysis_runs::{RunImage, ZoomTarget};
use crate::app::{PathInputs, WorkbenchApp};
use crate::command::Command;
use crate::derender;
use crate::panels::image_card::{self, Scale};
use crate::panels::widgets::path_submit;
use crate::state::{DerenderInput, ModelSettings, SamplerName};
use crate::worker::DialogPurpose;
use tactile_derender::model::{PredictionType, TimestepSpacing};

/// The De-render tab; `inputs` holds the typed checkpoint and measurement paths.
pub fn show(
    app: &WorkbenchApp,
    inputs: &mut PathInputs,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    model_row(app, &mut inputs.model_path, ui, cmds);
    let mut d = app.state.derender.clone();
    ui.horizontal(|ui| {
        ui.label("sampler");
        let s = &mut d.config.sampler;
        ui.radio_value(&mut s.kind, SamplerName::Ddpm, "DDPM (all steps)")
            .on_hover_text(
                "ancestral DDPM over all the model's training steps (the paper's sampler)",
            );
        ui.radio_value(&mut s.kind, SamplerName::Ddim, "DDIM")
            .on_hover_text("DDIM over K steps: about T/K times faster");
        ui.add_enabled_ui(s.kind == SamplerName::Ddim, |ui| {
            ui.add(egui::Slider::new(&mut s.steps, 1..=250).text("steps K"))
                .on_hover_text(
                    "DDIM steps, up to the model's training steps (250 for the shipped model)",
                );
            ui.add(egui::Slider::new(&mut s.eta, 0.0..=1.0).text("η"))
                .on_hover_text("0: deterministic; 1: DDPM-like fresh noise at every step");
            egui::ComboBox::from_id_salt("ddim_spacing")
                .selected_text(format!("{} spacing", s.spacing))
                .show_ui(ui, |ui| {
                    for sp in [TimestepSpacing::Trailing, TimestepSpacing::Leading] {
                        ui.selectable_value(&mut s.spacing, sp, sp.to_string());
                    }
                })
                .response
                .on_hover_text(
                    "trailing: the first step is t = 249, pure noise, as in DDPM (recommended). \
                     leading: diffusers' default, starts at t = 240.",
                );
        });
        ui.separator();
        ui.add(egui::Slider::new(&mut d.config.samples, 1..=64).text("samples"))
            .on_hover_text(
                "samples of X0 drawn for the imprint in one batch: more give a smoother contact probability and a \
                 steadier multi-sample pose (the paper's KDEs use 50)",
            );
        ui.add(egui::DragValue::new(&mut d.config.seed).prefix("seed "))
            .on_hover_text("seed of the sampler's noise and the registration starts: the same seed gives the same samples");
        ui.checkbox(&mut d.config.guidance.enabled, "imprint guidance")
            .on_hover_text(
                "pull each sample towards the imprint it would leave on the sensor while sampling (scenes, dataset \
                 pairs and recordings, whose sensor is known; not a bare .npy imprint): sharper contact outlines on \
                 shapes unlike the training objects",
            );
        egui::ComboBox::from_id_salt("derender_device")
            .selected_text(format!("device {}", d.config.device))
            .show_ui(ui, |ui| {
                for dev in ["cpu", "cuda", "metal"] {
                    ui.selectable_value(&mut d.config.device, dev.to_string(), dev);
                }
            })
            .response
            .on_hover_text(
                "where the model runs: cpu (our fast kernels) or a GPU through candle (a build with the cuda or metal \
                 feature)",
            );
    });
    ui.horizontal(|ui| {
        ui.label("input");
        let scene = matches!(d.input, DerenderInput::Scene);
        if ui.radio(scene, "simulated scene").clicked() {
            d.input = DerenderInput::Scene;
        }
        match &d.input {
            DerenderInput::DatasetPair { split, index, .. } => {
                let _ = ui.radio(true, format!("dataset pair: {split} #{index}"));
            }
            _ => {
                ui.add_enabled(false, egui::RadioButton::new(false, "dataset pair"))
                    .on_disabled_hover_text(
                        "select a pair in the Dataset tab and press 'Send to de-render'",
                    );
            }
        }
        if let Some(path) = path_submit(
            ui,
            "measurement",
            &mut inputs.imprint_path,
            ".npy imprint (m)",
            "Use measurement",
        ) {
            d.input = DerenderInput::Measurement { path: path.into() };
        }
        if ui.button("Browse…").clicked() {
            cmds.push(Command::Browse(DialogPurpose::OpenDerenderImprint));
        }
    });
    if d != app.state.derender {
        cmds.push(Command::SetDerender(d));
    }
    run_row(app, ui, cmds);
    ui.separator();
    results(app, ui, cmds);
}

fn model_row(
    app: &WorkbenchApp,
    model_path: &mut String,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        ui.label("model");
        let bundled = app.state.model.path.is_none();
        if ui
            .radio(bundled, "bundled, matched to the input")
            .on_hover_text(
                "the default model for simulated frames and pairs at the model's resolution; the recording model \
                 (fine-tuned on frames brought to the model's size as an import brings them) for a recording's \
                 frames, imported datasets and native .npy frames — as tnd's --model auto",
            )
            .clicked()
            && !bundled
        {
            cmds.push(Command::SetModel(ModelSettings { path: None }));
        }
        let small_name = tactile_derender::model::checkpoint::BUNDLED_SMALL_MODEL_NAME;
        let small = app.state.model.path.as_deref() == Some(std::path::Path::new(small_name));
        if ui
            .radio(small, "bundled small")
            .on_hover_text(
                "the default until 2026-11-26: about twice as fast to sample, a little worse depth on real meshes \
                 (SSIM 0.80 against 0.81), the same single-sample pose within its noise",
            )
            .clicked()
            && !small
        {
            cmds.push(Command::SetModel(ModelSettings {
                path: Some(small_name.into()),
            }));
        }
        if let Some(path) = path_submit(
            ui,
            "checkpoint",
            model_path,
            "model .safetensors",
            "Use checkpoint",
        ) {
            cmds.push(Command::SetModel(ModelSettings {
                path: Some(path.into()),
            }));
        }
        if ui.button("Open…").clicked() {
            cmds.push(Command::Browse(DialogPurpose::OpenCheckpoint));
        }
    });
    let named = |p: &std::path::Path| match tactile_derender::model::checkpoint::bundled_name(p) {
        Some((name, _)) => format!("the bundled {name} model"),
        None => p.display().to_string(),
    };
    let chosen = app.state.model.path.as_deref();
    // The model loaded last, described where it is the chosen one (or, with none chosen, whichever was matched).
    let loaded = app
        .analysis
        .derender
        .model
        .as_ref()
        .filter(|(q, _, _)| chosen.is_none_or(|p| q == p))
        .map(|(q, _, m)| {
            let (w, h) = m.resolution();
            let predicts = match m.config().tactile_derender.prediction_type {
                PredictionType::Epsilon => "ε",
                PredictionType::VPrediction => "v",
            };
            let which = if chosen.is_none() {
                format!(" {}", named(q))
            } else {
                String::new()
            };
            format!(" · loaded{which}, {w}x{h} px, predicts {predicts}")
        })
        .unwrap_or_default();
    let shown = match chosen {
        Some(p) => named(p),
        None => "the bundled model matched to the input (default; recording for frames resampled from a camera's \
                 own size)"
            .to_string(),
    };
    ui.weak(format!("using {shown}{loaded}"));
}

fn run_row(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let view = &app.analysis.derender;
    ui.horizontal(|ui| {
        if view.running {
            if ui.button("Cancel").clicked() {
                cmds.push(Command::CancelDerender);
            }
            let (done, total) = view.progress.unwrap_or((0, 1));
            let secs = view.started.map_or(0.0, |t| t.elapsed().as_secs_f32());
            ui.add(
                egui::ProgressBar::new(done as f32 / total.max(1) as f32)
                    .desired_width(320.0)
                    .text(format!("step {done}/{total} · {secs:.1} s")),
            );
        } else {
            if ui.button("Run de-rendering").clicked() {
                cmds.push(Command::RunDerender);
            }
            if let Some(i) = &view.pending_input {
                ui.label(format!("input: {} (not sampled yet)", i.label));
            }
        }
    });
}

fn results(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let view = &app.analysis.derender;
    let Some(r) = view.result.as_ref() else {
        ui.weak(if view.running {
            "The samples appear here when the run is done."
        } else {
            "No samples yet: choose the input and press 'Run de-rendering'."
        });
        return;
    };
    let sampler = match r.config.sampler.sampler_kind() {
        tactile_derender::model::SamplerKind::Ddpm => "DDPM-250".to_string(),
        tactile_derender::model::SamplerKind::Ddim {
            steps,
            eta,
            spacing,
        } => format!("DDIM-{steps} η={eta} {spacing}"),
    };
    let guided = if r.guided { " · imprint-guided" } else { "" };
    ui.label(format!(
        "{} · {} samples · {sampler}{guided} · seed {} · {:.2} s ({})",
        r.input.label,
        r.samples.len(),
        r.config.seed,
        r.seconds,
        r.model.source().display()
    ));
    let n_fixed = view.images.len() - r.samples.len();
    egui::ScrollArea::vertical()
        .id_salt("derender_results")
        .auto_shrink([false, false])
        .show(ui, |ui| {
            // Cards grow with the window and wrap rather than run off its edge; a click shows one enlarged.
            let big =
                ((ui.available_width() / n_fixed.max(1) as f32) - CARD_EXTRA).clamp(64.0, 420.0);
            ui.horizontal_wrapped(|ui| {
                for (k, img) in view.images.iter().take(n_fixed).enumerate() {
                    if card(ui, img, fixed_image(r, k), big).clicked() {
                        cmds.push(Command::ZoomImage(Some(ZoomTarget::Derender(k))));
                    }
                }
            });
            if !r.scores.is_empty() {
                scores_table(ui, r);
            } else {
                ui.weak("no ground truth for this input: no scores");
            }
            ui.separator();
            let small = ((ui.available_width() / 6.0) - CARD_EXTRA).clamp(72.0, 240.0);
            let cols = ((ui.available_width() / (small + CARD_EXTRA)).floor() as usize).max(1);
            for (row, chunk) in view.images[n_fixed..].chunks(cols).enumerate() {
                ui.horizontal(|ui| {
                    for (j, img) in chunk.iter().enumerate() {
                        let s = row * cols + j;
                        if card(ui, img, &r.samples[s], small).clicked() {
                            cmds.push(Command::ZoomImage(Some(ZoomTarget::Derender(n_fixed + s))));
                        }
                    }
                });
            }
        });
}

/// Width of a card beside its image: the colour bar with its labels and the spacing, points.
const CARD_EXTRA: f32 = 100.0;

/// The k-th fixed image of a run: Y, X0 (when known), mean, std.
pub(crate) fn fixed_image(r: &derender::RunResult, k: usize) -> &tactile_derender::image::Image {
    let mut list = vec![&r.input.imprint];
    if let Some(t) = &r.input.truth {
        list.push(t);
    }
    list.push(&r.mean);
    list.push(&r.std);
    list.get(k).copied().unwrap_or(&r.mean)
}

pub(crate) fn card(
    ui: &mut egui::Ui,
    img: &RunImage,
    data: &tactile_derender::image::Image,
    side: f32,
) -> egui::Response {
    let scale = Scale {
        range: img.range,
        millimetres: img.millimetres,
        zero_is_missing: img.zero_is_missing,
    };
    image_card::card(ui, &img.title, img.texture.id(), data, &scale, side)
        .on_hover_text("click to enlarge")
}

fn scores_table(ui: &mut egui::Ui, r: &derender::RunResult) {
    let mean = |f: &dyn Fn(&tactile_derender::metrics::DepthMetrics) -> f64| {
        r.scores.iter().map(f).sum::<f64>() / r.scores.len().max(1) as f64
    };
    ui.label(format!(
        "mean over samples: L1 {:.3} mm · PSNR {:.2} dB · SSIM {:.4}",
        mean(&|s| s.l1_mm),
        mean(&|s| s.psnr_db),
        mean(&|s| s.ssim)
    ));
    egui::CollapsingHeader::new("scores per sample")
        .default_open(true)
        .show(ui, |ui| {
            egui::Grid::new("scores").striped(true).show(ui, |ui| {
                ui.strong("sample");
                ui.strong("L1 (mm)");
                ui.strong("PSNR (dB)");
                ui.strong("SSIM");
                ui.end_row();
                for (i, s) in r.scores.iter().enumerate() {
                    ui.label(i.to_string());
                    ui.label(format!("{:.3}", s.l1_mm));
                    ui.label(format!("{:.2}", s.psnr_db));
                    ui.label(format!("{:.4}", s.ssim));
                    ui.end_row();
                }
            });
        });
}
