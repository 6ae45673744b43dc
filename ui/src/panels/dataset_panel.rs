//! Dataset inspector tab (paper V.A): open a dataset directory, browse a virtualised grid of (imprint, target)
//! thumbnails filtered by split and object — only the rows on screen are laid out and only their missing thumbnails
//! are decoded, on the loader thread — and show the selected pair's Y, S, X0 and M at full size with colour bars and
//! its metadata; "Send to de-render" makes it the De-render tab's input.

use egui::{Color32, Sense, Stroke, Vec2};
use tactile_derender::dataset::SplitName;

use crate::app::{PathInputs, WorkbenchApp};
use crate::command::Command;
use crate::panels::image_card::{self, Scale};
use crate::panels::widgets::path_submit;
use crate::worker::DialogPurpose;

/// The Dataset tab; `inputs.dataset_path` is the typed dataset directory. Takes `&mut WorkbenchApp` because the
/// thumbnail grid fills the browser's thumbnail cache (and asks its loader for missing ones) while it is drawn.
pub fn show(
    app: &mut WorkbenchApp,
    inputs: &mut PathInputs,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        if let Some(path) = path_submit(
            ui,
            "Dataset",
            &mut inputs.dataset_path,
            "directory made by tnd dataset gen / import",
            "Open dataset",
        ) {
            cmds.push(Command::OpenDataset(path.into()));
        }
        if ui.button("Browse…").clicked() {
            cmds.push(Command::Browse(DialogPurpose::OpenDataset));
        }
    });
    let mut settings = app.state.dataset.clone();
    let Some(browser) = app.analysis.dataset.as_mut() else {
        ui.label(match &settings.path {
            Some(p) => format!("opening {} …", p.display()),
            None => "Open a dataset directory to browse its pairs.".into(),
        });
        return;
    };
    ui.horizontal(|ui| {
        ui.label("split");
        for s in SplitName::ALL {
            let n = browser.dataset.len(s);
            ui.selectable_value(&mut settings.split, s, format!("{s} ({n})"));
        }
        ui.separator();
        let none = "all objects".to_string();
        egui::ComboBox::new("object_filter", "object")
            .selected_text(settings.object.clone().unwrap_or_else(|| none.clone()))
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut settings.object, None, none);
                for o in &browser.objects {
                    ui.selectable_value(&mut settings.object, Some(o.clone()), o);
                }
            });
        if browser.indexing(settings.split) {
            ui.spinner();
            ui.weak("reading object names…");
        }
        ui.separator();
        ui.add(egui::Slider::new(&mut settings.thumb_size, 32.0..=128.0).text("thumbnail"));
    });
    if settings.split != app.state.dataset.split || settings.object != app.state.dataset.object {
        settings.selected = None;
    }
    let split = settings.split;
    let list = browser.filtered(split, settings.object.as_ref()).to_vec();
    ui.label(format!(
        "{} of {} pairs shown · {} thumbnails cached",
        list.len(),
        browser.dataset.len(split),
        browser.cached()
    ));
    let avail = ui.available_size();
    let grid_h = if browser.selected.is_some() || settings.selected.is_some() {
        (avail.y * 0.45).max(120.0)
    } else {
        avail.y
    };
    let mut clicked = None;
    ui.push_id("dataset_grid", |ui| {
        ui.set_max_height(grid_h);
        clicked = grid(browser, ui, &list, split, &settings);
    });
    if let Some(i) = clicked {
        settings.selected = Some(i);
    }
    if settings != app.state.dataset {
        cmds.push(Command::SetDataset(settings));
    }
    ui.separator();
    selected_view(app, ui, cmds);
}

/// The virtualised thumbnail grid; returns the clicked pair.
fn grid(
    browser: &mut crate::dataset_view::DatasetBrowser,
    ui: &mut egui::Ui,
    list: &[usize],
    split: SplitName,
    settings: &crate::state::DatasetSettings,
) -> Option<usize> {
    browser.begin_frame();
    let side = settings.thumb_size;
    let spacing = ui.spacing().item_spacing;
    let cell_w = 2.0 * side + 3.0 * spacing.x;
    let cols = ((ui.available_width() / cell_w).floor() as usize).max(1);
    let label_h = 14.0;
    let row_h = side + label_h + 6.0;
    let rows = list.len().div_ceil(cols);
    let mut missing = Vec::new();
    let mut clicked = None;
    egui::ScrollArea::vertical()
        .auto_shrink([false, false])
        .show_rows(ui, row_h, rows, |ui, range| {
            for row in range {
                ui.horizontal(|ui| {
                    for &index in list.iter().skip(row * cols).take(cols) {
                        let selected = settings.selected == Some(index);
                        let (rect, resp) = ui.allocate_exact_size(
                            Vec2::new(cell_w - spacing.x, row_h - spacing.y),
                            Sense::click(),
                        );
                        let painter = ui.painter_at(rect);
                        let y_rect = egui::Rect::from_min_size(
                            rect.min + Vec2::new(2.0, 2.0),
                            Vec2::splat(side),
                        );
                        let x_rect = y_rect.translate(Vec2::new(side + 2.0, 0.0));
                        match browser.thumb((split, index)) {
                            Some(t) => {
                                let uv = egui::Rect::from_min_max(
                                    egui::pos2(0.0, 0.0),
                                    egui::pos2(1.0, 1.0),
                                );
                                painter.image(t.imprint.id(), y_rect, uv, Color32::WHITE);
                                painter.image(t.target.id(), x_rect, uv, Color32::WHITE);
                            }
                            None => {
                                missing.push((split, index));
                                painter.rect_filled(
                                    y_rect.union(x_rect),
                                    2.0,
                                    Color32::from_gray(40),
                                );
                            }
                        }
                        painter.text(
                            egui::pos2(rect.left() + 2.0, y_rect.bottom() + 1.0),
                            egui::Align2::LEFT_TOP,
                            format!("#{index}"),
                            egui::FontId::proportional(10.0),
                            ui.visuals().text_color(),
                        );
                        if selected || resp.hovered() {
                            let c = if selected {
                                Color32::YELLOW
                            } else {
                                Color32::GRAY
                            };
                            painter.rect_stroke(
                                rect,
                                2.0,
                                Stroke::new(2.0, c),
                                egui::StrokeKind::Inside,
                            );
                        }
                        let name = format!("{split} pair {index}");
                        resp.widget_info(|| {
                            egui::WidgetInfo::selected(egui::Role::Button, true, selected, &name)
                        });
                        let resp = resp.on_hover_text(format!(
                            "{split} pair {index}{}",
                            browser
                                .object_name(split, index)
                                .map(|o| format!(" · {o}"))
                                .unwrap_or_default()
                        ));
                        if resp.clicked() {
                            clicked = Some(index);
                        }
                    }
                });
            }
        });
    browser.request_thumbs(missing);
    clicked
}

fn selected_view(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let Some(b) = app.analysis.dataset.as_ref() else {
        return;
    };
    let Some(sel) = b.selected.as_ref() else {
        if app.state.dataset.selected.is_some() {
            ui.horizontal(|ui| {
                ui.spinner();
                ui.label("loading the pair…");
            });
        } else {
            ui.weak("Click a pair to see its images at full size.");
        }
        return;
    };
    let m = &sel.pair.meta;
    ui.horizontal(|ui| {
        ui.strong(format!(
            "{} pair {} (global #{})",
            m.split, m.split_index, m.index
        ));
        if ui.button("Send to de-render").clicked() {
            cmds.push(Command::SendPairToDerender);
        }
        if ui
            .button("Place the scene")
            .on_hover_text("move the simulated object and sensor to where this pair was taken")
            .clicked()
        {
            cmds.push(Command::PlacePairScene);
        }
    });
    let press = if m.press.is_finite() {
        format!("{:.2} mm", m.press * 1e3)
    } else {
        "unknown".into()
    };
    ui.label(format!(
        "object {} at x {:.2} mm, y {:.2} mm, θ {:.1}° · sensor ({:.2}, {:.2}, {:.2}) mm, yaw {:.1}° · press {press} · \
         {} contact px · seed {}",
        m.object,
        m.object_pose.x * 1e3,
        m.object_pose.y * 1e3,
        m.object_pose.theta.to_degrees(),
        m.sensor.position[0] * 1e3,
        m.sensor.position[1] * 1e3,
        m.sensor.position[2] * 1e3,
        m.sensor.yaw.to_degrees(),
        m.contact_pixels,
        m.seed
    ));
    let side = ((ui.available_width() / 4.0) - 90.0)
        .min(ui.available_height() - 50.0)
        .clamp(64.0, 480.0);
    ui.horizontal(|ui| {
        for (i, shown) in sel.shown.iter().enumerate() {
            let scale = Scale {
                range: shown.range,
                millimetres: shown.millimetres,
                zero_is_missing: shown.zero_is_missing,
            };
            let r = image_card::card(
                ui,
                shown.title,
                shown.texture.id(),
                sel.image(i),
                &scale,
                side,
            )
            .on_hover_text("click to enlarge");
            if r.clicked() {
                cmds.push(Command::ZoomImage(Some(
                    crate::analysis_runs::ZoomTarget::DatasetPair(i),
                )));
            }
        }
    });
}
