//! One image with its JET colour bar and a hover read-out, used by the analysis tabs (dataset pairs, samples,
//! mean/std maps). Values are metres, shown in millimetres; masks are 0/1.

use egui::{Color32, Pos2, Rect, Sense, TextureId, Vec2};
use tactile_derender::image::Image;

use crate::images::jet_color;

const BAR_W: f32 = 10.0;
const LABEL_W: f32 = 54.0;

/// How an image's values are shown.
#[derive(Clone, Copy, Debug)]
pub struct Scale {
    /// Colour range, metres (or 0..1 for masks).
    pub range: (f32, f32),
    /// Values are lengths shown in mm.
    pub millimetres: bool,
    /// Zero means "no value" (depth images).
    pub zero_is_missing: bool,
}

fn format(scale: &Scale, v: f32) -> String {
    if scale.millimetres {
        format!("{:.2} mm", v * 1e3)
    } else {
        format!("{v:.2}")
    }
}

/// Title, image of `side` points with its colour bar, and the hovered pixel's value below; returns the image's
/// response.
pub fn card(
    ui: &mut egui::Ui,
    title: &str,
    texture: TextureId,
    img: &Image,
    scale: &Scale,
    side: f32,
) -> egui::Response {
    ui.vertical(|ui| {
        ui.strong(title);
        let aspect = img.height as f32 / img.width.max(1) as f32;
        let size = Vec2::new(side, side * aspect);
        let mut readout = String::from(" ");
        let response = ui
            .horizontal(|ui| {
                let r = ui.add(egui::Image::new((texture, size)).sense(Sense::click()));
                if let Some(pos) = r.hover_pos() {
                    let rel = (pos - r.rect.min) / r.rect.size();
                    let u = ((rel.x * img.width as f32) as usize).min(img.width.saturating_sub(1));
                    let v =
                        ((rel.y * img.height as f32) as usize).min(img.height.saturating_sub(1));
                    let value = img.get(u, v);
                    readout = if scale.zero_is_missing && value == 0.0 {
                        format!("({u}, {v}): no value")
                    } else {
                        format!("({u}, {v}): {}", format(scale, value))
                    };
                }
                colour_bar(ui, scale, size.y);
                r
            })
            .inner;
        ui.small(readout);
        response
    })
    .inner
}

/// A vertical JET gradient with its top, middle and bottom values.
pub fn colour_bar(ui: &mut egui::Ui, scale: &Scale, height: f32) {
    let (rect, _) = ui.allocate_exact_size(Vec2::new(BAR_W + LABEL_W, height), Sense::hover());
    let bar = Rect::from_min_size(rect.min, Vec2::new(BAR_W, height));
    let mut mesh = egui::Mesh::default();
    let steps = 24;
    for i in 0..steps {
        let t0 = i as f32 / steps as f32;
        let t1 = (i + 1) as f32 / steps as f32;
        let r = Rect::from_min_max(
            Pos2::new(bar.left(), bar.bottom() - t1 * height),
            Pos2::new(bar.right(), bar.bottom() - t0 * height),
        );
        mesh.add_colored_rect(r, jet_color(0.5 * (t0 + t1)));
    }
    let painter = ui.painter();
    painter.add(egui::Shape::mesh(mesh));
    let (lo, hi) = scale.range;
    let font = egui::FontId::proportional(10.0);
    let color = ui.visuals().text_color();
    let x = bar.right() + 3.0;
    for (y, v, align) in [
        (bar.top(), hi, egui::Align2::LEFT_TOP),
        (bar.center().y, 0.5 * (lo + hi), egui::Align2::LEFT_CENTER),
        (bar.bottom(), lo, egui::Align2::LEFT_BOTTOM),
    ] {
        painter.text(
            Pos2::new(x, y),
            align,
            format(scale, v),
            font.clone(),
            color,
        );
    }
    painter.rect_stroke(
        bar,
        0.0,
        egui::Stroke::new(1.0, Color32::DARK_GRAY),
        egui::StrokeKind::Inside,
    );
}
