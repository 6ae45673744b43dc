//! Pose tab (paper V.C, VI.B): SE(2) registration of the current samples and the threshold baseline to the object,
//! and the KDE uncertainty view. It is built on the evaluation stage (`tactile_derender::{recon, pose, metrics,
//! uncertainty}`), which is not in main yet; until it lands this tab says so and shows what would be registered.

use crate::app::WorkbenchApp;
use crate::command::Command;

pub fn show(app: &mut WorkbenchApp, ui: &mut egui::Ui, _cmds: &mut Vec<Command>) {
    ui.heading("Pose estimation and uncertainty");
    ui.label(
        "Registration, pose metrics and the KDE uncertainty view need the evaluation modules \
         (recon, pose, metrics, uncertainty), which are not in this build yet.",
    );
    match &app.analysis.derender.result {
        Some(r) => ui.label(format!(
            "Ready to register: {} samples of {}.",
            r.samples.len(),
            r.input.label
        )),
        None => ui.weak("Run de-rendering first: its samples are what this tab registers."),
    };
}
