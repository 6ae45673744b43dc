//! Desktop habits driven through egui_kittest: undo/redo of scene and sensor edits (buttons and Ctrl+Z /
//! Ctrl+Shift+Z / Ctrl+Y), Ctrl+S, the Help menu's shortcut list, and files dropped on the window.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use egui::{Key, Modifiers};
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::command::Command;
use tnd_workbench::state::{DerenderInput, ObjectSource, State, Tab};

use crate::support;
use support::{drop_file, harness};

fn press(h: &mut Harness<'_, WorkbenchApp>, modifiers: Modifiers, key: Key) {
    h.key_press_modifiers(modifiers, key);
    h.run_ok();
}

#[test]
fn scene_and_sensor_edits_undo_and_redo() {
    let mut h = harness(WorkbenchApp::with_state(State::default()));
    h.run_ok();
    h.state_mut().history.coalesce = std::time::Duration::ZERO;
    let original = h.state().state.clone();
    let mut scene = original.scene.clone();
    scene.press = 0.009;
    h.state_mut().apply(Command::SetScene(scene.clone()));
    let mut sim = original.sim.clone();
    sim.elastomer.inflation = 0.025;
    h.state_mut().apply(Command::SetSim(sim.clone()));
    h.run_ok();

    press(&mut h, Modifiers::COMMAND, Key::Z);
    assert_eq!(h.state().state.sim, original.sim);
    assert_eq!(h.state().state.scene, scene);
    h.get_by_label("Undo").click();
    h.run_ok();
    assert_eq!(h.state().state.scene, original.scene);
    assert!(!h.state().history.can_undo());

    press(&mut h, Modifiers::COMMAND | Modifiers::SHIFT, Key::Z);
    assert_eq!(h.state().state.scene, scene);
    press(&mut h, Modifiers::COMMAND, Key::Y);
    assert_eq!(h.state().state.sim, sim);
    assert!(!h.state().history.can_redo());

    // A new edit after an undo drops the redo branch.
    press(&mut h, Modifiers::COMMAND, Key::Z);
    assert!(h.state().history.can_redo());
    h.state_mut().apply(Command::SetSeed(99));
    assert!(!h.state().history.can_redo());
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
}

#[test]
fn a_slider_drag_is_one_undo_step() {
    let mut h = harness(WorkbenchApp::with_state(State::default()));
    h.run_ok();
    let original = h.state().state.scene.clone();
    // Consecutive edits of one kind within the coalescing window (a drag emits one per frame).
    for press_mm in 1..=8 {
        let mut scene = h.state().state.scene.clone();
        scene.press = f64::from(press_mm) * 1e-3;
        h.state_mut().apply(Command::SetScene(scene));
    }
    press(&mut h, Modifiers::COMMAND, Key::Z);
    assert_eq!(h.state().state.scene, original);
    assert!(!h.state().history.can_undo());
}

#[test]
fn ctrl_s_saves_to_the_session_file_and_help_lists_the_shortcuts() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.json");
    let mut h = harness(WorkbenchApp::with_state(State::default()));
    h.run_ok();
    h.state_mut().apply(Command::SaveSession(path.clone()));
    let mut scene = h.state().state.scene.clone();
    scene.press = 0.0042;
    h.state_mut().apply(Command::SetScene(scene));
    h.run_ok();
    press(&mut h, Modifiers::COMMAND, Key::S);
    let saved = std::fs::read_to_string(&path).unwrap();
    assert!(saved.contains("0.0042"), "{saved}");

    h.get_by_label("Help").click();
    h.run_ok();
    assert!(h.query_by_label("Ctrl+Z").is_some());
    assert!(h.query_by_label("Ctrl+Shift+Z / Ctrl+Y").is_some());
}

#[test]
fn dropped_files_open_as_what_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(WorkbenchApp::with_state(State::default()));
    h.run_ok();

    // A mesh becomes the object (and the drop is undoable like any scene edit).
    let mesh = dir.path().join("wedge.obj");
    std::fs::write(
        &mesh,
        "v 0 0 0\nv 0.02 0 0\nv 0 0.02 0\nv 0 0 0.01\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
    drop_file(&mut h, &mesh);
    match &h.state().state.scene.object {
        ObjectSource::File { path, .. } => assert_eq!(path, &mesh),
        other => panic!("the object is {other:?}"),
    }
    assert!(h.state().history.can_undo());

    // An imprint on the De-render tab becomes its input.
    let npy = dir.path().join("imprint.npy");
    tactile_derender::io::npy::write_image(
        &npy,
        &tactile_derender::image::Image::filled(64, 64, 0.0),
    )
    .unwrap();
    let mut view = h.state().state.view.clone();
    view.tab = Tab::Derender;
    h.state_mut().apply(Command::SetView(view));
    drop_file(&mut h, &npy);
    assert_eq!(
        h.state().state.derender.input,
        DerenderInput::Measurement { path: npy.clone() }
    );

    // A session replaces the state.
    let session = dir.path().join("other.json");
    let mut other = State::default();
    other.scene.press = 0.0031;
    tnd_workbench::session::write(&session, &other).unwrap();
    drop_file(&mut h, &session);
    assert_eq!(h.state().state.scene.press, 0.0031);

    // Anything else is one error line naming the file.
    let txt = dir.path().join("notes.txt");
    std::fs::write(&txt, "hello").unwrap();
    drop_file(&mut h, &txt);
    let errors = &h.state().errors;
    assert!(
        errors
            .iter()
            .any(|e| e.contains("notes.txt") && e.contains("cannot open")),
        "{errors:?}"
    );
}

#[test]
fn recent_sessions_list_the_newest_first_and_reopen() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    let mut first = State::default();
    first.scene.press = 0.0041;
    tnd_workbench::session::write(&a, &first).unwrap();
    let mut h = harness(WorkbenchApp::with_state(State::default()));
    h.run_ok();
    h.state_mut().apply(Command::OpenSession(a.clone()));
    h.state_mut().apply(Command::SaveSession(b.clone()));
    h.state_mut().apply(Command::OpenSession(a.clone()));
    assert_eq!(h.state().recent, vec![a.clone(), b.clone()]);
    // Open b from the menu, then a again from it.
    h.get_by_label("Recent").click();
    h.run_ok();
    h.get_by_label("b.json").click();
    h.run_ok();
    assert_eq!(h.state().session_path.as_deref(), Some(b.as_path()));
    assert_eq!(h.state().recent, vec![b, a]);
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
}

#[test]
fn a_missing_session_or_mesh_on_the_command_line_fails_before_any_window_opens() {
    // No display is needed: the files are checked first, and a typo fails like any command, with one line.
    for (flag, path) in [
        ("--session", "no_such_session.json"),
        ("--object", "no_such_part.stl"),
    ] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_tnd-workbench"))
            .args([flag, path, "--screenshot", "never.png"])
            .output()
            .unwrap();
        assert!(!out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.trim(), format!("error: {flag} {path}: no such file"));
    }
}

#[test]
fn an_invalid_session_on_the_command_line_fails_before_any_window_opens() {
    // A screenshot run of a session that does not load must not render the default scene and exit 0.
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\"version\": 1, \"scene\": {\"press\": -1.0}").unwrap();
    let shot = dir.path().join("shot.png");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_tnd-workbench"))
        .arg("--session")
        .arg(&bad)
        .arg("--screenshot")
        .arg(&shot)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("bad.json: not a valid session file"),
        "{stderr}"
    );
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(!shot.exists());
}
