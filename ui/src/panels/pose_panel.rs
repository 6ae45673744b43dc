//! Pose tab (paper IV.C registration, V.D uncertainty): register the de-rendering samples (and the threshold
//! baseline) to the object, then show a top view with the object's outline at the true and estimated poses and the
//! contact points, the registration hypotheses with their costs, and KDE curves of the position and yaw errors over
//! the samples with the baseline's errors as points; hovering a curve highlights the nearest sample. The numbers
//! export as CSV, the plot as PNG.

use egui::Color32;
use egui_plot::{Legend, Line, Plot, PlotPoints, Points, VLine};

use crate::app::WorkbenchApp;
use crate::command::Command;
use crate::pose_view::{placed_mm, PoseAnalysis};

const TRUE_COLOUR: Color32 = Color32::from_rgb(90, 200, 90);
const ESTIMATE_COLOUR: Color32 = Color32::from_rgb(240, 150, 40);
const BASELINE_COLOUR: Color32 = Color32::from_rgb(230, 70, 70);
const HIGHLIGHT_COLOUR: Color32 = Color32::from_rgb(80, 170, 255);

pub fn show(app: &mut WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let pose = &app.analysis.pose;
    let has_samples = app.analysis.derender.result.is_some();
    ui.horizontal(|ui| {
        if pose.running {
            if ui.button("Cancel registration").clicked() {
                cmds.push(Command::CancelPose);
            }
            let (done, total) = pose.progress.unwrap_or((0, 1));
            ui.add(
                egui::ProgressBar::new(done as f32 / total.max(1) as f32)
                    .desired_width(260.0)
                    .text(format!("registered {done}/{total}")),
            );
        } else if ui
            .add_enabled(has_samples, egui::Button::new("Register samples"))
            .on_disabled_hover_text("run de-rendering first: its samples are what this tab registers")
            .clicked()
        {
            cmds.push(Command::RunPose);
        }
        if pose.result.is_some() {
            if ui.button("Export CSV").clicked() {
                cmds.push(Command::ExportPose { png: false });
            }
            if ui.button("Export plot PNG").clicked() {
                cmds.push(Command::ExportPose { png: true });
            }
        }
    });
    let Some(r) = pose.result.as_ref() else {
        match &app.analysis.derender.result {
            Some(d) => ui.label(format!(
                "{} samples of {} ready to register.",
                d.samples.len(),
                d.input.label
            )),
            None => ui.weak("Run de-rendering first: its samples are what this tab registers."),
        };
        return;
    };
    let mut highlight = pose.highlight;
    let half = (ui.available_height() * 0.5).max(200.0);
    ui.horizontal(|ui| {
        ui.vertical(|ui| {
            ui.set_width((ui.available_width() * 0.55).max(300.0));
            top_view(ui, r, highlight, half);
        });
        ui.vertical(|ui| hypotheses(ui, r));
    });
    ui.horizontal(|ui| {
        let w = ui.available_width() / 2.0 - 8.0;
        ui.vertical(|ui| {
            ui.set_width(w);
            kde_plot(ui, r, false, &mut highlight);
        });
        ui.vertical(|ui| {
            ui.set_width(w);
            kde_plot(ui, r, true, &mut highlight);
        });
    });
    app.analysis.pose.highlight = highlight;
}

fn top_view(ui: &mut egui::Ui, r: &PoseAnalysis, highlight: Option<usize>, height: f32) {
    Plot::new("pose_top_view")
        .height(height)
        .data_aspect(1.0)
        .x_axis_label("world x (mm)")
        .y_axis_label("world y (mm)")
        .legend(Legend::default())
        .show(ui, |p| {
            for s in &r.samples {
                let bold = highlight == s.sample;
                for l in placed_mm(&r.outline, &s.pose) {
                    let (name, colour, width) = if bold {
                        ("highlighted sample", HIGHLIGHT_COLOUR, 2.5)
                    } else {
                        ("sample estimates", ESTIMATE_COLOUR.gamma_multiply(0.35), 1.0)
                    };
                    p.line(Line::new(name, PlotPoints::from(l)).color(colour).width(width));
                }
            }
            if let Some(best) = r.hypotheses.first() {
                for l in placed_mm(&r.outline, &best.pose) {
                    p.line(Line::new("best hypothesis", PlotPoints::from(l)).color(ESTIMATE_COLOUR).width(2.0));
                }
            }
            if let Some(b) = &r.baseline {
                for l in placed_mm(&r.outline, &b.pose) {
                    p.line(Line::new("baseline", PlotPoints::from(l)).color(BASELINE_COLOUR).width(1.5));
                }
            }
            if let Some(t) = &r.truth {
                for l in placed_mm(&r.outline, t) {
                    p.line(Line::new("true pose", PlotPoints::from(l)).color(TRUE_COLOUR).width(2.0));
                }
            }
            let contacts: Vec<[f64; 2]> = r.contacts.iter().map(|c| [c[0] * 1e3, c[1] * 1e3]).collect();
            p.points(Points::new("contact points", PlotPoints::from(contacts)).radius(1.5).color(Color32::LIGHT_GRAY));
        });
}

fn hypotheses(ui: &mut egui::Ui, r: &PoseAnalysis) {
    ui.strong(format!("{} — registration hypotheses (best first)", r.object));
    egui::ScrollArea::vertical().id_salt("hypotheses").max_height(260.0).show(ui, |ui| {
        egui::Grid::new("hypotheses_grid").striped(true).show(ui, |ui| {
            for h in ["#", "x (mm)", "y (mm)", "θ (deg)", "cost"] {
                ui.strong(h);
            }
            ui.end_row();
            for (i, h) in r.hypotheses.iter().enumerate() {
                ui.label(i.to_string());
                ui.label(format!("{:.2}", h.pose.x * 1e3));
                ui.label(format!("{:.2}", h.pose.y * 1e3));
                ui.label(format!("{:.1}", h.pose.theta.to_degrees()));
                ui.label(format!("{:.4e}", h.cost));
                ui.end_row();
            }
        });
    });
    if let Some(t) = &r.truth {
        ui.label(format!(
            "true pose: x {:.2} mm, y {:.2} mm, θ {:.1}°",
            t.x * 1e3,
            t.y * 1e3,
            t.theta.to_degrees()
        ));
    }
    let n = r.samples.len().max(1) as f64;
    let mean_pos = r.samples.iter().map(|s| s.position_error_m).sum::<f64>() / n * 1e3;
    let mean_th = r.samples.iter().map(|s| s.theta_error_rad.abs()).sum::<f64>() / n;
    ui.label(format!(
        "samples: mean position error {mean_pos:.2} mm, mean |θ error| {:.1}°",
        mean_th.to_degrees()
    ));
    if let Some(b) = &r.baseline {
        ui.label(format!(
            "baseline: position error {:.2} mm, θ error {:.1}°",
            b.position_error_m * 1e3,
            b.theta_error_rad.to_degrees()
        ));
    }
}

/// KDE of the position (mm) or yaw (degrees) errors, the samples as a rug, the baseline as a point; hovering picks
/// the nearest sample.
fn kde_plot(ui: &mut egui::Ui, r: &PoseAnalysis, theta: bool, highlight: &mut Option<usize>) {
    let value = |s: &crate::pose_view::PoseRow| {
        if theta {
            s.theta_error_rad.to_degrees()
        } else {
            s.position_error_m * 1e3
        }
    };
    let (id, label, curve) = if theta {
        ("kde_theta", "θ error (deg)", &r.kde_theta)
    } else {
        ("kde_position", "position error (mm)", &r.kde_position)
    };
    let rug: Vec<[f64; 2]> = r.samples.iter().map(|s| [value(s), 0.0]).collect();
    let shown = *highlight;
    let response = Plot::new(id)
        .height(ui.available_height().max(180.0))
        .x_axis_label(label)
        .y_axis_label("density")
        .legend(Legend::default())
        .show(ui, |p| {
            p.line(Line::new("KDE over samples", PlotPoints::from(curve.clone())).width(2.0));
            p.points(Points::new("samples", PlotPoints::from(rug)).radius(3.0).color(ESTIMATE_COLOUR));
            if let Some(b) = &r.baseline {
                p.points(
                    Points::new("baseline", PlotPoints::from(vec![[value(b), 0.0]]))
                        .radius(6.0)
                        .shape(egui_plot::MarkerShape::Diamond)
                        .color(BASELINE_COLOUR),
                );
            }
            if let Some(s) = shown.and_then(|i| r.samples.iter().find(|s| s.sample == Some(i))) {
                p.vline(VLine::new("highlighted sample", value(s)).color(HIGHLIGHT_COLOUR));
            }
            p.pointer_coordinate()
        });
    if let Some(pos) = response.inner {
        *highlight = r
            .samples
            .iter()
            .min_by(|a, b| (value(a) - pos.x).abs().total_cmp(&(value(b) - pos.x).abs()))
            .and_then(|s| s.sample);
    }
}
