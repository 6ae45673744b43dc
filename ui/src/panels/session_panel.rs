//! Session bar: New / Open / Save / Save As of `sessions/*.json`, with a typed path as the fallback where no file
//! dialog is available.

use std::path::PathBuf;

use crate::app::{PathInputs, WorkbenchApp};
use crate::command::Command;
use crate::worker::DialogPurpose;

/// The session bar; `inputs.session_path` is the typed session file.
pub fn show(
    app: &WorkbenchApp,
    inputs: &mut PathInputs,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        ui.strong("tactile-derender workbench");
        ui.separator();
        if ui
            .button("New")
            .on_hover_text("start over from the default scene")
            .clicked()
        {
            cmds.push(Command::NewSession);
        }
        if ui
            .button("Open…")
            .on_hover_text("open a session with a file dialog")
            .clicked()
        {
            cmds.push(Command::Browse(DialogPurpose::OpenSession));
        }
        ui.add_enabled_ui(!app.recent.is_empty(), |ui| {
            ui.menu_button("Recent", |ui| {
                for path in &app.recent {
                    let name = path
                        .file_name()
                        .map(|n| n.to_string_lossy().into_owned())
                        .unwrap_or_else(|| path.display().to_string());
                    if ui
                        .button(name)
                        .on_hover_text(path.display().to_string())
                        .clicked()
                    {
                        cmds.push(Command::OpenSession(path.clone()));
                        ui.close();
                    }
                }
            })
            .response
            .on_hover_text("recently opened or saved sessions");
        });
        if ui
            .button("Save As…")
            .on_hover_text("save the session with a file dialog")
            .clicked()
        {
            cmds.push(Command::Browse(DialogPurpose::SaveSessionAs));
        }
        if ui
            .add_enabled(app.history.can_undo(), egui::Button::new("Undo"))
            .on_hover_text("undo the last scene, sensor or elastomer edit (Ctrl+Z)")
            .clicked()
        {
            cmds.push(Command::Undo);
        }
        if ui
            .add_enabled(app.history.can_redo(), egui::Button::new("Redo"))
            .on_hover_text("redo (Ctrl+Shift+Z or Ctrl+Y)")
            .clicked()
        {
            cmds.push(Command::Redo);
        }
        ui.menu_button("Help", |ui| {
            ui.strong("Keyboard shortcuts (Cmd on macOS)");
            egui::Grid::new("shortcuts").striped(true).show(ui, |ui| {
                for (keys, what) in crate::shortcuts::SHORTCUTS {
                    ui.monospace(keys);
                    ui.label(what);
                    ui.end_row();
                }
            });
        });
        ui.separator();
        let label = ui.label("Session file");
        ui.add(
            egui::TextEdit::singleline(&mut inputs.session_path)
                .hint_text("sessions/example.json")
                .desired_width(260.0),
        )
        .labelled_by(label.id);
        let typed = inputs.session_path.trim().to_string();
        if ui
            .add_enabled(!typed.is_empty(), egui::Button::new("Open"))
            .on_hover_text("open the session file typed on the left")
            .clicked()
        {
            cmds.push(Command::OpenSession(PathBuf::from(&typed)));
        }
        if ui
            .add_enabled(!typed.is_empty(), egui::Button::new("Save"))
            .on_hover_text("save to the session file typed on the left (atomic write)")
            .clicked()
        {
            cmds.push(Command::SaveSession(PathBuf::from(&typed)));
        }
        if let Some(n) = &app.notice {
            ui.separator();
            ui.weak(n);
        }
    });
}
