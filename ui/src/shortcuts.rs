//! Desktop habits: keyboard shortcuts (Ctrl on Linux and Windows, Cmd on macOS) and files dropped on the window, both
//! turned into [`Command`]s. The Help menu lists [`SHORTCUTS`].

use std::path::Path;

use egui::{Key, KeyboardShortcut, Modifiers};

use crate::command::Command;
use crate::worker::DialogPurpose;

/// Every shortcut with what it does (the Help menu shows this list).
pub const SHORTCUTS: [(&str, &str); 6] = [
    ("Ctrl+O", "open a session"),
    ("Ctrl+S", "save the session (to its file, else Save As)"),
    ("Ctrl+Shift+S", "save the session as…"),
    ("Ctrl+Z", "undo a scene, sensor or elastomer edit"),
    ("Ctrl+Shift+Z / Ctrl+Y", "redo"),
    ("drop a file", "mesh: the object; .json: a session; .npy: an imprint; .safetensors / model folder: the model; dataset folder: the inspector"),
];

/// The commands of the shortcuts pressed this frame (consumed, so text fields do not see them).
pub fn pressed(ctx: &egui::Context, session_path: Option<&Path>) -> Vec<Command> {
    let cmd = Modifiers::COMMAND;
    let cmd_shift = Modifiers::COMMAND | Modifiers::SHIFT;
    let mut out = Vec::new();
    ctx.input_mut(|i| {
        // Shift variants first: a shortcut without Shift also matches a press with it.
        if i.consume_shortcut(&KeyboardShortcut::new(cmd_shift, Key::Z))
            || i.consume_shortcut(&KeyboardShortcut::new(cmd, Key::Y))
        {
            out.push(Command::Redo);
        }
        if i.consume_shortcut(&KeyboardShortcut::new(cmd, Key::Z)) {
            out.push(Command::Undo);
        }
        if i.consume_shortcut(&KeyboardShortcut::new(cmd_shift, Key::S)) {
            out.push(Command::Browse(DialogPurpose::SaveSessionAs));
        }
        if i.consume_shortcut(&KeyboardShortcut::new(cmd, Key::S)) {
            out.push(match session_path {
                Some(p) => Command::SaveSession(p.to_path_buf()),
                None => Command::Browse(DialogPurpose::SaveSessionAs),
            });
        }
        if i.consume_shortcut(&KeyboardShortcut::new(cmd, Key::O)) {
            out.push(Command::Browse(DialogPurpose::OpenSession));
        }
        for f in &i.raw.dropped_files {
            let p = f.path();
            if !p.as_os_str().is_empty() {
                out.push(Command::OpenDropped(p.to_path_buf()));
            }
        }
    });
    out
}

/// What a dropped path is opened as (`de_render_tab`: an `.npy` becomes the de-rendering input rather than the
/// calibration's measured imprint); `None`: nothing the workbench opens.
pub fn purpose_of(path: &Path, de_render_tab: bool) -> Option<DialogPurpose> {
    if path.is_dir() {
        if path.join("manifest.json").is_file() {
            return Some(DialogPurpose::OpenDataset);
        }
        if path.join("diffusion_pytorch_model.safetensors").is_file() {
            return Some(DialogPurpose::OpenCheckpoint);
        }
        if has_depth_frames(path) {
            return Some(DialogPurpose::OpenRecordingFolder);
        }
        return None;
    }
    if tactile_derender::mesh::is_mesh_file(path) {
        return Some(DialogPurpose::OpenObjectMesh);
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "json" => Some(DialogPurpose::OpenSession),
        "npy" if de_render_tab => Some(DialogPurpose::OpenDerenderImprint),
        "npy" => Some(DialogPurpose::OpenMeasured),
        "safetensors" => Some(DialogPurpose::OpenCheckpoint),
        "mcap" => Some(DialogPurpose::OpenRecording),
        _ => None,
    }
}

/// A folder holding depth frames (a recording), without a pair table (that is an import source, not a recording).
fn has_depth_frames(dir: &Path) -> bool {
    use tactile_derender::recording::source::FRAME_EXTENSIONS;
    if dir.join("pairs.csv").is_file() || dir.join("pairs.json").is_file() {
        return false;
    }
    std::fs::read_dir(dir).is_ok_and(|entries| {
        entries.flatten().any(|e| {
            let p = e.path();
            p.extension()
                .and_then(|x| x.to_str())
                .is_some_and(|x| FRAME_EXTENSIONS.contains(&x.to_ascii_lowercase().as_str()))
        })
    })
}

/// The message for a dropped path the workbench cannot open.
pub fn unknown(path: &Path) -> String {
    format!(
        "{}: cannot open a dropped file of this kind (meshes .obj .stl .ply .gltf .glb, sessions .json, imprints .npy, \
         models .safetensors or folders, dataset folders, recordings .mcap or depth-frame folders)",
        path.display()
    )
}
