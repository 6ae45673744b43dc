//! The workbench's panels, one file each (`*_panel.rs`). The layout: a session bar on top, a status bar at the bottom,
//! the parameter panels (scene, elastomer, sensor) on the left and the central view with one tab per [`Tab`]. Panels
//! read the app (`&WorkbenchApp`) and push [`Command`]s; the only thing they write is the text typed into path fields
//! ([`PathInputs`], lent to them apart from the app). The dataset and recording tabs still take `&mut WorkbenchApp`:
//! their textures and thumbnails are caches filled while drawing. The analysis panels (dataset inspector,
//! de-rendering, pose) are more tabs, added like this:
//!
//! 1. a [`Tab`] variant and a `*_panel.rs` file whose `show(app, ui, cmds)` draws it (matched below), with
//!    `inputs: &mut PathInputs` beside `app` when it has a path field;
//! 2. its settings (paths, sampler, seeds; e.g. [`crate::state::ModelSettings`]) in [`crate::state::State`] with
//!    `#[serde(default)]`, so old sessions still open;
//! 3. one [`Command`] variant per user intent, applied in [`WorkbenchApp::apply`];
//! 4. background work as a [`crate::worker::JobKind`] reporting through [`crate::worker::WorkerMsg`] (progress,
//!    result, error) with a cancel flag, like the inflation sweep.

pub mod calibration_panel;
pub mod dataset_panel;
pub mod derender_panel;
pub mod elastomer_panel;
pub mod image_card;
pub mod pose_panel;
pub mod pose_posterior;
pub mod recording_panel;
pub mod scene_panel;
pub mod sensor_panel;
pub mod session_panel;
pub mod simulation_panel;
pub mod status_panel;
pub mod view3d_panel;
pub mod widgets;

use crate::app::{PathInputs, WorkbenchApp};
use crate::command::Command;
use crate::state::Tab;

/// Draw every panel of the window. The typed-in paths are lent to the panels apart from the app, so that those that
/// only read the app get `&WorkbenchApp`; they are back in `app.inputs` when this returns.
pub fn show_all(app: &mut WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let mut inputs = std::mem::take(&mut app.inputs);
    draw(app, &mut inputs, ui, cmds);
    app.inputs = inputs;
}

/// [`show_all`] with the typed-in paths apart from the app (`app.inputs` is empty meanwhile: read `inputs`).
fn draw(
    app: &mut WorkbenchApp,
    inputs: &mut PathInputs,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    egui::Panel::top("session").show(ui, |ui| session_panel::show(app, inputs, ui, cmds));
    egui::Panel::bottom("status").show(ui, |ui| status_panel::show(app, ui, cmds));
    egui::Panel::left("parameters")
        .resizable(true)
        .default_size(330.0)
        .show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| {
                egui::CollapsingHeader::new("Scene")
                    .default_open(true)
                    .show(ui, |ui| scene_panel::show(app, inputs, ui, cmds));
                egui::CollapsingHeader::new("Elastomer")
                    .default_open(true)
                    .show(ui, |ui| elastomer_panel::show(app, inputs, ui, cmds));
                egui::CollapsingHeader::new("Sensor")
                    .default_open(true)
                    .show(ui, |ui| sensor_panel::show(app, ui, cmds));
            });
        });
    egui::CentralPanel::default().show(ui, |ui| {
        let mut view = app.state.view.clone();
        ui.horizontal(|ui| {
            ui.selectable_value(&mut view.tab, Tab::Scene, "Scene view");
            ui.selectable_value(&mut view.tab, Tab::Calibration, "Inflation calibration");
            ui.selectable_value(&mut view.tab, Tab::Dataset, "Dataset");
            ui.selectable_value(&mut view.tab, Tab::Derender, "De-render");
            ui.selectable_value(&mut view.tab, Tab::Pose, "Pose");
            ui.selectable_value(&mut view.tab, Tab::Recording, "Recording");
        });
        if view != app.state.view {
            cmds.push(Command::SetView(view));
        }
        ui.separator();
        match app.state.view.tab {
            Tab::Scene => {
                simulation_panel::show(app, ui, cmds);
                ui.separator();
                view3d_panel::show(app, ui, cmds);
            }
            Tab::Calibration => calibration_panel::show(app, ui, cmds),
            Tab::Dataset => dataset_panel::show(app, inputs, ui, cmds),
            Tab::Derender => derender_panel::show(app, inputs, ui, cmds),
            Tab::Pose => pose_panel::show(app, ui, cmds),
            Tab::Recording => recording_panel::show(app, inputs, ui, cmds),
        }
    });
    if let Some(target) = app.analysis.zoom {
        zoom_window(app, ui.ctx(), target, cmds);
    }
}

/// The enlarged image of an analysis tab, in its own window sized to the screen.
fn zoom_window(
    app: &WorkbenchApp,
    ctx: &egui::Context,
    target: crate::analysis_runs::ZoomTarget,
    cmds: &mut Vec<Command>,
) {
    use crate::analysis_runs::ZoomTarget;
    let screen = ctx.content_rect();
    let side = (screen.height() * 0.7).min(screen.width() * 0.6).max(128.0);
    let mut open = true;
    let mut shown = false;
    egui::Window::new("Image")
        .open(&mut open)
        .collapsible(false)
        .resizable(false)
        .show(ctx, |ui| match target {
            ZoomTarget::Derender(k) => {
                let view = &app.analysis.derender;
                if let (Some(r), Some(img)) = (view.result.as_ref(), view.images.get(k)) {
                    let n_fixed = view.images.len() - r.samples.len();
                    let data = match k.checked_sub(n_fixed) {
                        Some(s) => &r.samples[s],
                        None => derender_panel::fixed_image(r, k),
                    };
                    derender_panel::card(ui, img, data, side);
                    shown = true;
                }
            }
            ZoomTarget::DatasetPair(i) => {
                let sel = app
                    .analysis
                    .dataset
                    .as_ref()
                    .and_then(|b| b.selected.as_ref());
                if let Some((sel, s)) = sel.and_then(|sel| sel.shown.get(i).map(|s| (sel, s))) {
                    let scale = image_card::Scale {
                        range: s.range,
                        millimetres: s.millimetres,
                        zero_is_missing: s.zero_is_missing,
                    };
                    image_card::card(ui, s.title, s.texture.id(), sel.image(i), &scale, side);
                    shown = true;
                }
            }
        });
    if !open || !shown {
        cmds.push(Command::ZoomImage(None));
    }
}
