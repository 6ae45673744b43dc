//! Elastomer panel: the membrane's footprint, inflation height and tessellation, or a membrane mesh file; and the
//! inflation calibration sweep's settings (the plot is the "Inflation calibration" tab).

use std::path::PathBuf;

use tactile_derender::dataset::SplitName;
use tactile_derender::sensor::ElastomerConfig;
use tactile_derender::sim::calibration::best_by_iou;

use super::widgets::{mm_slider, path_field, units_combo};
use crate::app::{PathInputs, WorkbenchApp};
use crate::command::Command;
use crate::measured::Measured;
use crate::state::CalibrationSettings;
use crate::worker::DialogPurpose;

/// The elastomer panel; `inputs` holds the typed membrane mesh and measured imprint paths.
pub fn show(
    app: &WorkbenchApp,
    inputs: &mut PathInputs,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    let mut sim = app.state.sim.clone();
    dome_settings(ui, &mut sim.elastomer);
    membrane_mesh(ui, &mut sim.elastomer, &mut inputs.elastomer_path, cmds);
    if sim != app.state.sim {
        cmds.push(Command::SetSim(sim));
    }

    ui.add_space(6.0);
    ui.strong("Inflation calibration");
    let mut cal = app.state.calibration.clone();
    sweep_range_row(ui, &mut cal);
    measured_source(ui, &mut cal, &mut inputs.measured_path, cmds);
    measured_actions(ui, &inputs.measured_path, app.measured.as_ref(), cmds);
    mm_slider(
        ui,
        &mut cal.threshold,
        0.0..=10.0,
        "contact threshold (mm)",
        "imprint depth above which a measured pixel counts as contact for the IoU, millimetres",
    );
    if cal != app.state.calibration {
        cmds.push(Command::SetCalibration(cal));
    }
    sweep_run_row(app, ui, cmds);
}

/// The parametric dome's footprint, inflation and tessellation (greyed out while a membrane mesh is used).
fn dome_settings(ui: &mut egui::Ui, e: &mut ElastomerConfig) {
    let parametric = e.mesh_file.is_none();
    ui.add_enabled_ui(parametric, |ui| {
        mm_slider(ui, &mut e.footprint_x, 40.0..=200.0, "footprint x (mm)", "length of the membrane's elliptical footprint along sensor x, millimetres (Soft Bubble: 120)");
        mm_slider(ui, &mut e.footprint_y, 30.0..=150.0, "footprint y (mm)", "width of the membrane's elliptical footprint along sensor y, millimetres (Soft Bubble: 80)");
        mm_slider(ui, &mut e.inflation, 5.0..=60.0, "inflation (mm)", "height of the inflated dome's apex above its base, millimetres: the parameter to calibrate");
        ui.horizontal(|ui| {
            ui.label("tessellation");
            ui.add(
                egui::DragValue::new(&mut e.rings)
                    .range(2..=256)
                    .prefix("rings "),
            )
            .on_hover_text("latitude rings of the membrane mesh from apex to rim (more: smoother, slower to rebuild)");
            ui.add(
                egui::DragValue::new(&mut e.segments)
                    .range(8..=1024)
                    .prefix("segments "),
            )
            .on_hover_text("segments around the membrane's rim");
        });
    });
}

/// A membrane mesh file instead of the dome: its units, browse, the typed path, and the buttons that switch between
/// the mesh and the parametric dome.
fn membrane_mesh(
    ui: &mut egui::Ui,
    e: &mut ElastomerConfig,
    typed_path: &mut String,
    cmds: &mut Vec<Command>,
) {
    let parametric = e.mesh_file.is_none();
    ui.horizontal(|ui| {
        ui.label("or membrane mesh")
            .on_hover_text("a mesh file (OBJ, STL, PLY, glTF/GLB) in the sensor frame");
        units_combo(ui, "membrane_units", &mut e.mesh_units);
        if ui.button("Browse…").clicked() {
            cmds.push(Command::Browse(DialogPurpose::OpenElastomerMesh));
        }
    });
    path_field(ui, "Membrane", typed_path, "bubble.stl");
    ui.horizontal(|ui| {
        let typed = typed_path.trim().to_string();
        if ui
            .add_enabled(!typed.is_empty(), egui::Button::new("Use membrane mesh"))
            .clicked()
        {
            e.mesh_file = Some(PathBuf::from(typed));
        }
        if ui
            .add_enabled(!parametric, egui::Button::new("Parametric dome"))
            .clicked()
        {
            e.mesh_file = None;
        }
    });
}

/// The sweep's lowest and highest inflation (millimetres on screen, metres in `cal`) and its number of steps.
fn sweep_range_row(ui: &mut egui::Ui, cal: &mut CalibrationSettings) {
    ui.horizontal(|ui| {
        let mut lo = cal.lo * 1e3;
        let mut hi = cal.hi * 1e3;
        ui.label("sweep");
        if ui
            .add(
                egui::DragValue::new(&mut lo)
                    .range(1.0..=100.0)
                    .suffix(" mm"),
            )
            .on_hover_text("lowest inflation of the sweep, millimetres")
            .changed()
        {
            cal.lo = lo * 1e-3;
        }
        ui.label("to");
        if ui
            .add(
                egui::DragValue::new(&mut hi)
                    .range(1.0..=100.0)
                    .suffix(" mm"),
            )
            .on_hover_text("highest inflation of the sweep, millimetres")
            .changed()
        {
            cal.hi = hi * 1e-3;
        }
        ui.add(
            egui::DragValue::new(&mut cal.steps)
                .range(1..=200)
                .suffix(" steps"),
        )
        .on_hover_text("number of inflation values simulated between the two");
    });
}

/// Where the measured imprint comes from: browse, the typed path, and for a dataset folder the split and pair.
fn measured_source(
    ui: &mut egui::Ui,
    cal: &mut CalibrationSettings,
    typed_path: &mut String,
    cmds: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        ui.label("measured imprint (.npy or dataset)");
        if ui.button("Browse…").clicked() {
            cmds.push(Command::Browse(DialogPurpose::OpenMeasured));
        }
    });
    path_field(ui, "Imprint", typed_path, "imprint.npy or data/synth");
    let typed_dir = std::path::Path::new(typed_path.trim()).is_dir();
    if typed_dir {
        ui.horizontal(|ui| {
            egui::ComboBox::new("measured_split", "split")
                .selected_text(cal.measured_split.as_str())
                .show_ui(ui, |ui| {
                    for split in SplitName::ALL {
                        ui.selectable_value(&mut cal.measured_split, split, split.as_str());
                    }
                })
                .response
                .on_hover_text("the dataset split the measured pair comes from");
            let l = ui.label("pair");
            ui.add(egui::DragValue::new(&mut cal.measured_index))
                .labelled_by(l.id)
                .on_hover_text(
                    "index of the pair within the split whose imprint is the measurement",
                );
        });
    }
}

/// Load or clear the measured imprint, what is loaded, and (for a dataset pair) taking over its scene.
fn measured_actions(
    ui: &mut egui::Ui,
    typed_path: &str,
    measured: Option<&Measured>,
    cmds: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        let typed = typed_path.trim().to_string();
        if ui
            .add_enabled(!typed.is_empty(), egui::Button::new("Load imprint"))
            .clicked()
        {
            cmds.push(Command::LoadMeasured(PathBuf::from(typed)));
        }
        if ui
            .add_enabled(measured.is_some(), egui::Button::new("Clear"))
            .clicked()
        {
            cmds.push(Command::ClearMeasured);
        }
    });
    if let Some(m) = measured {
        ui.weak(format!("loaded {}", m.description));
        if m.scene.is_some()
            && ui
                .button("Use the pair's object and poses")
                .on_hover_text("object, object pose and sensor position of the measurement; the press keeps the sensor base where it was")
                .clicked()
        {
            cmds.push(Command::UseMeasuredScene);
        }
    }
}

/// Run or cancel the sweep with its progress, and once it has points, a button that takes the best inflation.
fn sweep_run_row(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        if app.calibration.running {
            if ui.button("Cancel sweep").clicked() {
                cmds.push(Command::CancelCalibration);
            }
            let (done, total) = app
                .calibration
                .progress
                .unwrap_or((0, app.state.calibration.steps));
            ui.add(
                egui::ProgressBar::new(done as f32 / total.max(1) as f32)
                    .text(format!("{done}/{total}")),
            );
        } else if ui.button("Run sweep").clicked() {
            cmds.push(Command::RunCalibration);
        }
    });
    if let Some(best) = best_by_iou(&app.calibration.points) {
        let text = format!(
            "Use best: {:.1} mm (IoU {:.3})",
            best.inflation * 1e3,
            best.iou.unwrap_or(0.0)
        );
        if ui.button(text).clicked() {
            cmds.push(Command::PickInflation(best.inflation));
        }
    }
}
