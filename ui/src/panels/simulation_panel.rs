//! Simulation view: D, E, M, M⊙D, S and Y side by side with the JET colour map, a colour bar in mm, automatic or
//! fixed ranges, a hover read-out (pixel and depth in mm) and export of each image as PNG (with its colour bar) or
//! `.npy`.

use egui::{Color32, Pos2, Rect, Sense, Vec2};

use crate::app::WorkbenchApp;
use crate::command::Command;
use crate::images::{format_value, jet_color, ImageKind, ShownImage};
use crate::state::RangeMode;
use crate::worker::DialogPurpose;

const BAR_W: f32 = 12.0;
const LABEL_W: f32 = 58.0;
/// Height of a card's title and button rows, points.
const CARD_TEXT_H: f32 = 48.0;

pub fn show(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    toolbar(app, ui, cmds);
    let Some(result) = &app.sim else {
        ui.label(if app.sim_failed_for_latest() {
            "the scene could not be simulated: see the error below"
        } else {
            "simulating the scene…"
        });
        return;
    };
    if app.sim_failed_for_latest() && result.generation != app.generation {
        ui.colored_label(
            ui.visuals().warn_fg_color,
            "The current scene could not be simulated (see the error below); these are the last scene's images.",
        );
    }
    let out = &result.output;
    let avail = ui.available_size();
    let spacing = ui.spacing().item_spacing;
    let card_extra = BAR_W + LABEL_W + 3.0 * spacing.x;
    // Six in a row when they fit at a useful size, else two rows of three; half the height is for the 3D view.
    let cols = if avail.x / 6.0 - card_extra >= 120.0 {
        6
    } else {
        3
    };
    let rows = ImageKind::ALL.len().div_ceil(cols);
    let by_width = avail.x / cols as f32 - card_extra;
    let by_height = avail.y * 0.5 / rows as f32 - CARD_TEXT_H;
    let side = by_width.min(by_height).clamp(64.0, 320.0);
    for row in app.textures.shown.chunks(cols) {
        ui.horizontal(|ui| {
            for shown in row {
                ui.vertical(|ui| card(ui, shown, shown.kind.image(out), side, cmds));
            }
        });
    }
}

fn toolbar(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let mut view = app.state.view.clone();
    ui.horizontal(|ui| {
        ui.label("colour range");
        ui.radio_value(&mut view.range, RangeMode::Auto, "auto");
        ui.radio_value(&mut view.range, RangeMode::Fixed, "fixed");
        ui.add_enabled_ui(view.range == RangeMode::Fixed, |ui| {
            range_mm(ui, "depth", &mut view.depth_range);
            range_mm(ui, "imprint", &mut view.imprint_range);
        });
        ui.separator();
        let l = ui.label("export to");
        let mut dir = view.export_dir.display().to_string();
        if ui
            .add(egui::TextEdit::singleline(&mut dir).desired_width(120.0))
            .labelled_by(l.id)
            .changed()
        {
            view.export_dir = dir.into();
        }
        if ui.button("Choose…").clicked() {
            cmds.push(Command::Browse(DialogPurpose::ExportDir));
        }
    });
    if view != app.state.view {
        cmds.push(Command::SetView(view));
    }
}

fn range_mm(ui: &mut egui::Ui, name: &str, range: &mut (f32, f32)) {
    let (mut lo, mut hi) = (range.0 * 1e3, range.1 * 1e3);
    ui.label(name);
    let a = ui.add(egui::DragValue::new(&mut lo).speed(0.1).suffix(" mm"));
    let b = ui.add(egui::DragValue::new(&mut hi).speed(0.1).suffix(" mm"));
    if (a.changed() || b.changed()) && lo.is_finite() && hi.is_finite() && hi > lo {
        *range = (lo * 1e-3, hi * 1e-3);
    }
}

fn card(
    ui: &mut egui::Ui,
    shown: &ShownImage,
    img: &tactile_derender::image::Image,
    side: f32,
    cmds: &mut Vec<Command>,
) {
    ui.strong(shown.kind.title());
    let aspect = img.height as f32 / img.width.max(1) as f32;
    let size = Vec2::new(side, side * aspect);
    let mut readout = String::from(" ");
    ui.horizontal(|ui| {
        let response = ui.add(egui::Image::new((shown.texture.id(), size)).sense(Sense::hover()));
        if let Some(pos) = response.hover_pos() {
            let rel = (pos - response.rect.min) / response.rect.size();
            let u = ((rel.x * img.width as f32) as usize).min(img.width.saturating_sub(1));
            let v = ((rel.y * img.height as f32) as usize).min(img.height.saturating_sub(1));
            let value = img.get(u, v);
            readout = if shown.kind.zero_is_missing() && value == 0.0 {
                format!("({u}, {v}): no value")
            } else {
                format!("({u}, {v}): {}", format_value(shown.kind, value))
            };
        }
        colour_bar(ui, shown, size.y);
    });
    ui.horizontal(|ui| {
        if ui
            .small_button("PNG")
            .on_hover_text("export with colour bar")
            .clicked()
        {
            cmds.push(Command::Export {
                image: shown.kind,
                png: true,
            });
        }
        if ui
            .small_button("npy")
            .on_hover_text("export the values (metres)")
            .clicked()
        {
            cmds.push(Command::Export {
                image: shown.kind,
                png: false,
            });
        }
        ui.label(readout);
    });
}

/// A vertical JET gradient with the range's top, middle and bottom labelled.
fn colour_bar(ui: &mut egui::Ui, shown: &ShownImage, height: f32) {
    let (rect, _) = ui.allocate_exact_size(Vec2::new(BAR_W + LABEL_W, height), Sense::hover());
    let bar = Rect::from_min_size(rect.min, Vec2::new(BAR_W, height));
    let mut mesh = egui::Mesh::default();
    let steps = 32;
    for i in 0..steps {
        let t0 = i as f32 / steps as f32;
        let t1 = (i + 1) as f32 / steps as f32;
        // Top is the maximum.
        let y0 = bar.bottom() - t0 * height;
        let y1 = bar.bottom() - t1 * height;
        let r = Rect::from_min_max(Pos2::new(bar.left(), y1), Pos2::new(bar.right(), y0));
        mesh.add_colored_rect(r, jet_color(0.5 * (t0 + t1)));
    }
    let painter = ui.painter();
    painter.add(egui::Shape::mesh(mesh));
    let (lo, hi) = shown.range;
    let font = egui::FontId::proportional(11.0);
    let color = ui.visuals().text_color();
    let x = bar.right() + 3.0;
    let label = |v: f32| format_value(shown.kind, v);
    painter.text(
        Pos2::new(x, bar.top()),
        egui::Align2::LEFT_TOP,
        label(hi),
        font.clone(),
        color,
    );
    painter.text(
        Pos2::new(x, bar.center().y),
        egui::Align2::LEFT_CENTER,
        label(0.5 * (lo + hi)),
        font.clone(),
        color,
    );
    painter.text(
        Pos2::new(x, bar.bottom()),
        egui::Align2::LEFT_BOTTOM,
        label(lo),
        font,
        color,
    );
    painter.rect_stroke(
        bar,
        0.0,
        egui::Stroke::new(1.0, Color32::DARK_GRAY),
        egui::StrokeKind::Inside,
    );
}
