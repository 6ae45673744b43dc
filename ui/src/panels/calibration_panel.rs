//! Inflation calibration tab: contact area and (with a measured imprint) IoU against inflation, from the background
//! sweep of [`tactile_derender::sim::calibration`]; one click uses the best value.

use egui_plot::{Legend, Line, Plot, PlotPoints, Points, VLine};
use tactile_derender::sim::calibration::best_by_iou;

use crate::app::WorkbenchApp;
use crate::command::Command;

pub fn show(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let cal = &app.calibration;
    ui.horizontal(|ui| {
        if cal.running {
            let (done, total) = cal.progress.unwrap_or((0, app.state.calibration.steps));
            ui.label(format!("sweeping… {done}/{total}"));
            ui.spinner();
            if ui.button("Cancel sweep").clicked() {
                cmds.push(Command::CancelCalibration);
            }
        } else if ui.button("Run sweep").clicked() {
            cmds.push(Command::RunCalibration);
        }
        ui.label(format!(
            "current inflation {:.1} mm",
            app.state.sim.elastomer.inflation * 1e3
        ));
        if let Some(best) = best_by_iou(&cal.points) {
            if ui
                .button(format!(
                    "Use best: {:.1} mm (IoU {:.3})",
                    best.inflation * 1e3,
                    best.iou.unwrap_or(0.0)
                ))
                .clicked()
            {
                cmds.push(Command::PickInflation(best.inflation));
            }
        } else if !cal.points.is_empty() {
            ui.weak("load a measured imprint (Elastomer panel) to rank inflations by IoU");
        }
    });
    if cal.points.is_empty() && !cal.running {
        ui.label(
            "Sweep the membrane's inflation with the sensor held where it is: the plot shows the contact area and, with \
             a measured imprint, the IoU of the simulated contact mask with the imprint's thresholded region.",
        );
        return;
    }
    let area: Vec<[f64; 2]> = cal
        .points
        .iter()
        .map(|p| [p.inflation * 1e3, p.contact_area_m2 * 1e6])
        .collect();
    let iou: Vec<[f64; 2]> = cal
        .points
        .iter()
        .filter_map(|p| p.iou.map(|v| [p.inflation * 1e3, v]))
        .collect();
    let half = (ui.available_height() / 2.0 - 8.0).max(120.0);
    let current = app.state.sim.elastomer.inflation * 1e3;
    Plot::new("contact_area")
        .height(if iou.is_empty() { 2.0 * half } else { half })
        .x_axis_label("inflation (mm)")
        .y_axis_label("contact area (mm²)")
        .legend(Legend::default())
        .show(ui, |p| {
            p.line(Line::new("contact area", PlotPoints::from(area.clone())));
            p.points(Points::new("", PlotPoints::from(area)).radius(3.0));
            p.vline(VLine::new("current inflation", current));
        });
    if !iou.is_empty() {
        Plot::new("iou")
            .height(half)
            .x_axis_label("inflation (mm)")
            .y_axis_label("IoU with measured imprint")
            .legend(Legend::default())
            .show(ui, |p| {
                p.line(Line::new("IoU", PlotPoints::from(iou.clone())));
                p.points(Points::new("", PlotPoints::from(iou)).radius(3.0));
                p.vline(VLine::new("current inflation", current));
            });
    }
}
