//! 3D view: the object, the membrane (translucent or wireframe), the camera frustum and the contact points, orbited
//! with the mouse. Drawn by a wgpu paint callback when eframe runs on wgpu, else by the CPU fallback.

use egui::{Color32, Sense};

use crate::app::WorkbenchApp;
use crate::command::Command;
use crate::state::{MembraneStyle, OrbitCamera};
use crate::view3d::{camera, cpu, gpu, DrawFlags};

pub fn show(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let mut view = app.state.view.clone();
    ui.horizontal(|ui| {
        ui.strong("3D view");
        ui.label("membrane");
        ui.radio_value(
            &mut view.membrane,
            MembraneStyle::Translucent,
            "translucent",
        )
        .on_hover_text("how the membrane is drawn in the 3D view");
        ui.radio_value(&mut view.membrane, MembraneStyle::Wireframe, "wireframe");
        ui.radio_value(&mut view.membrane, MembraneStyle::Hidden, "hidden");
        ui.checkbox(&mut view.show_frustum, "camera frustum")
            .on_hover_text("draw the depth camera's viewing frustum inside the sensor");
        ui.checkbox(&mut view.show_contacts, "contact points")
            .on_hover_text("draw the back-projected in-contact points (X0), world frame");
        if ui.button("Reset camera").clicked() {
            view.camera = OrbitCamera::default();
        }
        ui.weak("drag: orbit · right-drag: pan · scroll: zoom");
    });
    let size = ui.available_size().max(egui::vec2(100.0, 120.0));
    let (rect, response) = ui.allocate_exact_size(size, Sense::click_and_drag());
    response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Canvas, true, "3D view"));
    camera::handle_input(&mut view.camera, &response, ui);
    ui.painter()
        .rect_filled(rect, 4.0, Color32::from_rgb(24, 26, 32));
    if let Some(result) = &app.sim {
        let (eye, view_proj) =
            camera::view_proj(&view.camera, rect.width() / rect.height().max(1.0));
        let flags = DrawFlags {
            membrane: view.membrane,
            frustum: view.show_frustum,
            contacts: view.show_contacts,
        };
        if app.render_state.is_some() {
            ui.painter().add(
                gpu::ViewCallback {
                    view_proj,
                    light: eye.normalize_or_zero(),
                    flags,
                }
                .shape(rect),
            );
        } else {
            cpu::paint(ui.painter(), rect, &result.geometry, &flags, eye, view_proj);
        }
    }
    if view != app.state.view {
        cmds.push(Command::SetView(view));
    }
}
