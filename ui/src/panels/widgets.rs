//! Small input widgets shared by the panels: sliders in display units (mm, degrees) over SI values, each with its
//! typed value box (click the number to type) and a tooltip saying what it sets and in which units.

use std::ops::RangeInclusive;

use egui::{Slider, SliderClamping};

/// A slider in millimetres over a value in metres; returns true when the user changed it.
pub fn mm_slider(
    ui: &mut egui::Ui,
    value_m: &mut f64,
    range_mm: RangeInclusive<f64>,
    label: &str,
    help: &str,
) -> bool {
    let mut mm = *value_m * 1e3;
    let changed = ui
        .add(
            Slider::new(&mut mm, range_mm)
                .text(label)
                .clamping(SliderClamping::Never)
                .max_decimals(2),
        )
        .on_hover_text(help)
        .changed();
    if changed && mm.is_finite() {
        *value_m = mm * 1e-3;
    }
    changed
}

/// A slider in degrees over a value in radians.
pub fn deg_slider(
    ui: &mut egui::Ui,
    value_rad: &mut f64,
    range_deg: RangeInclusive<f64>,
    label: &str,
    help: &str,
) -> bool {
    let mut deg = value_rad.to_degrees();
    let changed = ui
        .add(
            Slider::new(&mut deg, range_deg)
                .text(label)
                .clamping(SliderClamping::Never)
                .max_decimals(1),
        )
        .on_hover_text(help)
        .changed();
    if changed && deg.is_finite() {
        *value_rad = deg.to_radians();
    }
    changed
}

/// A labelled single-line path field; returns the field's response.
pub fn path_field(ui: &mut egui::Ui, label: &str, text: &mut String, hint: &str) -> egui::Response {
    ui.horizontal(|ui| {
        let l = ui.label(label);
        ui.add(
            egui::TextEdit::singleline(text)
                .hint_text(hint)
                .desired_width(220.0),
        )
        .labelled_by(l.id)
    })
    .inner
}

/// A [`path_field`] followed by `button`: the trimmed path when the button is clicked or Enter is pressed in the
/// field, `None` otherwise or when the field is blank.
pub fn path_submit(
    ui: &mut egui::Ui,
    label: &str,
    text: &mut String,
    hint: &str,
    button: &str,
) -> Option<String> {
    let r = path_field(ui, label, text, hint);
    let enter = r.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
    let submit = ui.button(button).clicked() || enter;
    (submit && !text.trim().is_empty()).then(|| text.trim().to_owned())
}

/// A units chooser (m, cm, mm), labelled on its right.
pub fn units_combo(ui: &mut egui::Ui, id: &str, units: &mut tactile_derender::mesh::Units) -> bool {
    use tactile_derender::mesh::Units;
    let before = *units;
    egui::ComboBox::new(id, "units")
        .selected_text(units.to_string())
        .width(60.0)
        .show_ui(ui, |ui| {
            for u in [Units::M, Units::Cm, Units::Mm] {
                ui.selectable_value(units, u, u.to_string());
            }
        });
    *units != before
}
