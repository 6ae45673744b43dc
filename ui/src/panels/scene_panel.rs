//! Scene panel: the object (built-in library or a mesh file (OBJ, STL, PLY, glTF/GLB) with its units), its SE(2) pose on the table, and
//! the sensor's pose and press depth (paper IV.A inputs).

use std::path::PathBuf;

use tactile_derender::objects::ObjectSet;

use super::widgets::{deg_slider, mm_slider, path_field, units_combo};
use crate::app::{PathInputs, WorkbenchApp};
use crate::command::Command;
use crate::state::ObjectSource;
use crate::worker::DialogPurpose;

/// The scene panel; `inputs` holds the typed mesh path and its units.
pub fn show(
    app: &WorkbenchApp,
    inputs: &mut PathInputs,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    let mut scene = app.state.scene.clone();

    let library_name = match &scene.object {
        ObjectSource::Library { name, .. } => name.clone(),
        ObjectSource::File { .. } => "(mesh file)".to_string(),
    };
    let set = ObjectSet::builtin();
    egui::ComboBox::from_label("Object")
        .selected_text(library_name)
        .height(400.0)
        .show_ui(ui, |ui| {
            for e in set.entries() {
                let selected =
                    matches!(&scene.object, ObjectSource::Library { name, .. } if *name == e.name);
                let family = e.family.map_or("custom", |f| f.as_str());
                let text = format!("{} ({family}, {:?})", e.name, e.split).to_lowercase();
                if ui.selectable_label(selected, text).clicked() {
                    scene.object = ObjectSource::Library {
                        set: "builtin".into(),
                        name: e.name.clone(),
                    };
                }
            }
        });

    ui.horizontal(|ui| {
        ui.label("or mesh file");
        units_combo(ui, "object_units", &mut inputs.object_units);
        if ui.button("Browse…").clicked() {
            cmds.push(Command::Browse(DialogPurpose::OpenObjectMesh));
        }
    });
    ui.horizontal(|ui| {
        path_field(ui, "Mesh", &mut inputs.object_path, "part.stl");
    });
    let typed = inputs.object_path.trim().to_string();
    if ui
        .add_enabled(!typed.is_empty(), egui::Button::new("Load mesh file"))
        .clicked()
    {
        scene.object = ObjectSource::File {
            path: PathBuf::from(&typed),
            units: inputs.object_units,
        };
    }
    if let ObjectSource::File { path, units } = &scene.object {
        ui.weak(format!("using {} ({units})", path.display()));
    }

    ui.add_space(4.0);
    ui.label("Object pose on the table");
    mm_slider(
        ui,
        &mut scene.object_pose.x,
        -40.0..=40.0,
        "object x (mm)",
        "object position on the table along the sensor's x axis, millimetres (stored in metres)",
    );
    mm_slider(
        ui,
        &mut scene.object_pose.y,
        -40.0..=40.0,
        "object y (mm)",
        "object position on the table along the sensor's y axis, millimetres (stored in metres)",
    );
    deg_slider(
        ui,
        &mut scene.object_pose.theta,
        -180.0..=180.0,
        "object θ (deg)",
        "object rotation about the vertical, degrees (stored in radians)",
    );
    ui.add_space(4.0);
    ui.label("Sensor");
    mm_slider(
        ui,
        &mut scene.sensor_x,
        -40.0..=40.0,
        "sensor x (mm)",
        "sensor axis position on the table, x, millimetres",
    );
    mm_slider(
        ui,
        &mut scene.sensor_y,
        -40.0..=40.0,
        "sensor y (mm)",
        "sensor axis position on the table, y, millimetres",
    );
    deg_slider(
        ui,
        &mut scene.sensor_yaw,
        -180.0..=180.0,
        "sensor yaw (deg)",
        "sensor rotation about the vertical, degrees (stored in radians)",
    );
    mm_slider(
        ui,
        &mut scene.press,
        0.0..=20.0,
        "press (mm)",
        "press depth: how far the membrane apex goes below the object's highest point, millimetres",
    );
    if scene.press < 0.0 {
        scene.press = 0.0;
    }

    if scene != app.state.scene {
        cmds.push(Command::SetScene(scene));
    }
}
