//! Sensor panel: the depth camera's intrinsics, crop and model resolution, its mount behind the membrane, the
//! tactile-shadow width and noise of the synthetic signature (paper V.A), and the noise seed.

use super::widgets::mm_slider;
use crate::app::WorkbenchApp;
use crate::command::Command;

pub fn show(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let mut sim = app.state.sim.clone();
    let cam = &mut sim.camera;
    ui.horizontal(|ui| {
        ui.label("resolution");
        ui.add(
            egui::DragValue::new(&mut cam.resolution.0)
                .range(8..=1024)
                .speed(8.0)
                .suffix(" px"),
        )
        .on_hover_text(
            "rendered (model) image width, pixels; a multiple of 8 (the shipped model: 64)",
        );
        ui.label("x");
        ui.add(
            egui::DragValue::new(&mut cam.resolution.1)
                .range(8..=1024)
                .speed(8.0)
                .suffix(" px"),
        )
        .on_hover_text("rendered (model) image height, pixels; a multiple of 8");
    });
    // Keep multiples of 8 (the simulator's requirement) while dragging.
    cam.resolution.0 = (cam.resolution.0 / 8).max(1) * 8;
    cam.resolution.1 = (cam.resolution.1 / 8).max(1) * 8;
    egui::Grid::new("intrinsics").num_columns(4).show(ui, |ui| {
        let n = &mut cam.native;
        let l = ui.label("fx");
        ui.add(
            egui::DragValue::new(&mut n.fx)
                .speed(0.5)
                .range(1.0..=5000.0),
        )
        .labelled_by(l.id)
        .on_hover_text("native camera focal length along x, pixels (Pico Flexx: 216.43)");
        let l = ui.label("fy");
        ui.add(
            egui::DragValue::new(&mut n.fy)
                .speed(0.5)
                .range(1.0..=5000.0),
        )
        .labelled_by(l.id)
        .on_hover_text("native camera focal length along y, pixels");
        ui.end_row();
        let l = ui.label("cx");
        ui.add(egui::DragValue::new(&mut n.cx).speed(0.5))
            .labelled_by(l.id)
            .on_hover_text("native principal point, column, pixels");
        let l = ui.label("cy");
        ui.add(egui::DragValue::new(&mut n.cy).speed(0.5))
            .labelled_by(l.id)
            .on_hover_text("native principal point, row, pixels");
        ui.end_row();
    });
    ui.label(format!(
        "native {} x {} px, crop rows {}..{}, cols {}..{}",
        cam.native.width,
        cam.native.height,
        cam.crop_rows.0,
        cam.crop_rows.1,
        cam.crop_cols.0,
        cam.crop_cols.1
    ));
    let mut offset = -sim.mount.position[2];
    if mm_slider(
        ui,
        &mut offset,
        20.0..=120.0,
        "camera behind base (mm)",
        "distance of the depth camera behind the membrane's base plane, millimetres",
    ) {
        sim.mount.position[2] = -offset;
    }
    ui.add(
        egui::Slider::new(&mut sim.signature.shadow_px, 0.0..=60.0)
            .text("shadow width (native px)")
            .max_decimals(1),
    )
    .on_hover_text(
        "width of the tactile-shadow cloak around the contact, native camera pixels (paper: 21)",
    );
    mm_slider(ui, &mut sim.signature.noise_std, 0.0..=5.0, "noise σ (mm)", "standard deviation of the Gaussian depth noise of the synthetic signature (paper: 1.38 mm); 0 disables it");
    if sim.signature.noise_std < 0.0 {
        sim.signature.noise_std = 0.0;
    }
    let mut seed = app.state.seed;
    ui.horizontal(|ui| {
        let l = ui.label("seed");
        ui.add(egui::DragValue::new(&mut seed))
            .labelled_by(l.id)
            .on_hover_text("seed of the signature's noise: the same seed gives the same images");
    });
    if sim != app.state.sim {
        cmds.push(Command::SetSim(sim));
    }
    if seed != app.state.seed {
        cmds.push(Command::SetSeed(seed));
    }
}
