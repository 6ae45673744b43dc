//! Status bar: contact-pixel count, simulation and frame timings, the 3D renderer in use, and the errors (shown here
//! until dismissed: the workbench never blocks on a dialog).

use crate::app::WorkbenchApp;
use crate::command::Command;

pub fn show(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    for e in &app.errors {
        ui.colored_label(app.status_color(), format!("Error: {e}"));
    }
    let current = app.sim.as_ref().filter(|_| !app.sim_failed_for_latest());
    for w in current.iter().flat_map(|s| &s.object_warnings) {
        ui.colored_label(ui.visuals().warn_fg_color, format!("Warning: {w}"));
    }
    if let Some(s) = current.filter(|s| s.output.contact_pixels == 0) {
        ui.horizontal_wrapped(|ui| {
            ui.colored_label(
                ui.visuals().warn_fg_color,
                format!("No contact: {}.", s.contact_hint),
            );
            if s.contact_hint.press_m > 0.0
                && ui
                    .button("Move the object there")
                    .on_hover_text("place the object so that its highest point is under the membrane's apex (undo with Ctrl+Z)")
                    .clicked()
            {
                let mut scene = app.state.scene.clone();
                scene.object_pose = s.contact_hint.centred;
                cmds.push(Command::SetScene(scene));
            }
        });
    }
    ui.horizontal(|ui| {
        if !app.errors.is_empty() && ui.button("Dismiss errors").clicked() {
            cmds.push(Command::DismissErrors);
        }
        ui.label(format!(
            "scene: {}, press {:.1} mm",
            app.state.scene.object.display_name(),
            app.state.scene.press * 1e3
        ));
        ui.separator();
        match &app.sim {
            _ if app.sim_failed_for_latest() => {
                ui.label("simulation failed");
            }
            Some(s) => {
                ui.label(format!("contact pixels: {}", s.output.contact_pixels));
                ui.separator();
                ui.label(format!(
                    "simulated {}x{} in {:.1} ms ({:.1} ms with rebuilds)",
                    s.output.depth.width, s.output.depth.height, s.simulate_ms, s.total_ms
                ));
            }
            None => {
                ui.label("simulating…");
            }
        }
        if app.busy() {
            ui.spinner();
        }
        ui.separator();
        let t = &app.timings;
        let ms = |s: &crate::timings::Samples, q: f64| {
            if s.is_empty() {
                "–".to_string()
            } else {
                format!("{:.0} ms", s.quantile(q))
            }
        };
        ui.label(format!(
            "update {} (p90 {}), frame {}, UI {:.1} ms",
            ms(&t.update, 0.5),
            ms(&t.update, 0.9),
            ms(&t.frame, 0.5),
            t.ui.median()
        ))
        .on_hover_text("medians over the last frames: parameter change to image, frame interval, UI build time");
        ui.separator();
        match &app.adapter_name {
            Some(name) => ui.weak(format!("3D: wgpu on {name}")),
            None => ui.weak("3D: CPU fallback (no wgpu)"),
        };
    });
}
