//! The Recording tab driven through its labels: a press sequence recorded as an MCAP file by the test itself (the
//! core's simulator at the camera's native resolution, written with the `mcap` crate) opens by typing its path and by
//! dropping it on the window, scrubs, and de-renders and registers the frame under the cursor.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use egui::accesskit::Role;
use egui_kittest::kittest::Queryable;
use tactile_derender::objects::ObjectSet;
use tactile_derender::recording::synth::{write_press_recording, PressSequence};
use tactile_derender::sensor::Se2;
use tactile_derender::sim::PreparedObject;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::state::{ObjectSource, State, Tab};

use crate::support;
use support::{drop_file, harness, tiny_model, wait_for};

const OBJECT: &str = "cylinder_r12";

fn sequence() -> PressSequence {
    PressSequence::down_and_up(Se2::new(0.004, -0.003, 0.5), 0.008, 4, 8)
}

fn recording(dir: &Path) -> PathBuf {
    let path = dir.join("press.mcap");
    let mesh = ObjectSet::builtin().mesh(OBJECT).unwrap();
    let object = PreparedObject::new(mesh).unwrap();
    write_press_recording(&path, &State::default().sim, &object, &sequence()).unwrap();
    path
}

#[test]
fn a_recording_opens_scrubs_and_de_renders_the_frame_under_the_cursor() {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(dir.path());
    let mut state = State::default();
    state.scene.object = ObjectSource::Library {
        set: "builtin".into(),
        name: OBJECT.into(),
    };
    state.model.path = Some(tiny_model(dir.path()));
    state.derender.config.samples = 3;
    state.derender.config.sampler.steps = 3;
    let mut h = harness(WorkbenchApp::with_state(state));
    h.run_ok();
    h.get_by_label("Recording").click();
    h.run_ok();
    assert_eq!(h.state().state.view.tab, Tab::Recording);
    h.get_by_role_and_label(Role::TextInput, "recording")
        .click();
    h.run_ok();
    h.get_by_role_and_label(Role::TextInput, "recording")
        .type_text(&rec.display().to_string());
    h.run_ok();
    h.get_by_label("Open recording").click();
    wait_for(&mut h, "the recording", |a| a.recording.loaded.is_some());
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let n = sequence().presses.len();
    assert!(h
        .query_by_label_contains(&format!("frame 0 of {n}"))
        .is_some());
    assert!(h
        .query_by_label_contains("object pose: from the recording's pose topic")
        .is_some());
    // Scrub with the arrow buttons: the label, the images and the cursor follow.
    for _ in 0..11 {
        h.get_by_label("next >").click();
        h.run_ok();
    }
    assert_eq!(h.state().state.recording.frame, 11);
    let deepest = h
        .state()
        .recording
        .loaded
        .as_ref()
        .unwrap()
        .processed
        .contact_px[11];
    assert!(h
        .query_by_label_contains(&format!(
            "frame 11 of {n}, t = 0.367 s, contact {deepest} px"
        ))
        .is_some());
    assert_eq!(h.state().recording.textures.as_ref().unwrap().frame, 11);
    h.get_by_label("< previous").click();
    h.run_ok();
    assert_eq!(h.state().state.recording.frame, 10);

    // De-render and register the frame under the cursor.
    h.get_by_label("De-render and register this frame").click();
    h.run_ok();
    wait_for(&mut h, "the samples and the fit", |a| {
        a.analysis.derender.result.is_some() && a.analysis.pose.result.is_some() && !a.busy()
    });
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let app = h.state();
    let r = app.analysis.derender.result.as_ref().unwrap();
    let p = &app.recording.loaded.as_ref().unwrap().processed;
    assert_eq!(r.input.imprint, p.imprints[10]);
    assert!(
        r.input.label.contains("press.mcap frame 10"),
        "{}",
        r.input.label
    );
    // The recorded pose gives a simulated X0 (press estimated from the imprint) and the fit's truth.
    assert!(r.input.truth.as_ref().unwrap().count_nonzero() > 0);
    let pose = app.analysis.pose.result.as_ref().unwrap();
    assert_eq!(pose.truth, Some(sequence().pose));
    assert_eq!(app.state.view.tab, Tab::Pose);

    // A recording dropped on the window opens in the Recording tab.
    let mut state = State::default();
    state.view.tab = Tab::Scene;
    let mut h = harness(WorkbenchApp::with_state(state));
    h.run_ok();
    drop_file(&mut h, &rec);
    wait_for(&mut h, "the dropped recording", |a| {
        a.recording.loaded.is_some()
    });
    assert_eq!(h.state().state.view.tab, Tab::Recording);
    assert_eq!(
        h.state().state.recording.path.as_deref(),
        Some(rec.as_path())
    );
}

#[test]
fn every_other_contact_frame_is_tracked_in_the_background_and_saved_as_csv() {
    let dir = tempfile::tempdir().unwrap();
    // A short press: a few contact frames.
    let seq = PressSequence::down_and_up(sequence().pose, 0.008, 2, 3);
    let rec = dir.path().join("press.mcap");
    let object = PreparedObject::new(ObjectSet::builtin().mesh(OBJECT).unwrap()).unwrap();
    write_press_recording(&rec, &State::default().sim, &object, &seq).unwrap();
    let mut state = State::default();
    state.scene.object = ObjectSource::Library {
        set: "builtin".into(),
        name: OBJECT.into(),
    };
    // The bundled model (a random one paints contact everywhere, which registers slowly), a few cheap samples.
    state.derender.config.samples = 2;
    state.derender.config.sampler.steps = 5;
    state.recording.path = Some(rec.clone());
    state.view.tab = Tab::Recording;
    let mut h = harness(WorkbenchApp::with_state(state));
    h.run_ok();
    wait_for(&mut h, "the recording", |a| a.recording.loaded.is_some());
    // Every other frame (`tnd recording track --every 2`, kept in the session): the contact frames among 0, 2, 4, ...
    assert_eq!(h.state().state.recording.track.every, 1);
    assert!(!h.state().state.recording.track.tracking.per_frame);
    assert!(h.query_by_label("carry estimates forward").is_some());
    let mut settings = h.state().state.recording.clone();
    settings.track.every = 2;
    h.state_mut()
        .apply(tnd_workbench::command::Command::SetRecording(settings));
    h.run_ok();
    let with_contact: Vec<usize> = {
        let p = &h.state().recording.loaded.as_ref().unwrap().processed;
        (0..p.len())
            .step_by(2)
            .filter(|&k| p.contact_px[k] >= 10)
            .collect()
    };
    assert!(with_contact.len() >= 2, "{with_contact:?}");
    h.get_by_label("Track all frames").click();
    h.run_ok();
    assert!(h.state().recording.track.running);
    assert!(h.query_by_label("Cancel tracking").is_some());
    wait_for(&mut h, "the track", |a| !a.recording.track.running);
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    // One row per contact frame, in frame order, each scored against the recorded pose.
    let rows = &h.state().recording.track.rows;
    let frames: Vec<usize> = rows.iter().map(|r| r.frame).collect();
    assert_eq!(frames, with_contact);
    assert!(rows.iter().all(|r| r.recorded == Some(sequence().pose)));
    assert!(h
        .query_by_label_contains(&format!("track: {} frames", rows.len()))
        .is_some());
    // σ beside the error: each frame's 68 % interval.
    assert!(h
        .query_by_label_contains("median 68 % interval ±")
        .is_some());
    h.get_by_label("Save track CSV").click();
    h.run_ok();
    let csv = std::fs::read_to_string(dir.path().join("press_track.csv")).unwrap();
    assert_eq!(csv.lines().count(), with_contact.len() + 1);
    assert!(csv.starts_with("frame,stamp_ns,contact_px,press_m"));
    // Saved again, its own file is replaced; a file of the user's of that name is not.
    h.get_by_label("Save track CSV").click();
    h.run_ok();
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let users = dir.path().join("press_track.csv");
    std::fs::write(&users, "my notes\n").unwrap();
    h.get_by_label("Save track CSV").click();
    h.run_ok();
    assert!(
        h.state()
            .errors
            .iter()
            .any(|e| e.contains("not a track tnd saved")),
        "{:?}",
        h.state().errors
    );
    assert_eq!(std::fs::read_to_string(&users).unwrap(), "my notes\n");
    h.state_mut().errors.clear();
    // `tnd recording track` with the same settings (the sensor as the workbench has it: not calibrated from the
    // recording) gives the same rows: the same estimate, spread and posterior, bit for bit.
    let out = std::process::Command::new(support::tnd_binary())
        .args(["recording", "track"])
        .arg(&rec)
        .args([
            "--object",
            OBJECT,
            "--samples",
            "2",
            "--steps",
            "5",
            "--every",
            "2",
            "--no-calibrate",
            "--out",
        ])
        .arg(dir.path().join("cli"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cli = std::fs::read_to_string(dir.path().join("cli/track.csv")).unwrap();
    // Everything but the scores (the columns from recorded_x to baseline_theta_err_deg).
    let estimated = |text: &str| -> Vec<Vec<String>> {
        text.lines()
            .map(|l| {
                l.split(',')
                    .enumerate()
                    .filter(|(k, _)| !(18..28).contains(k))
                    .map(|(_, c)| c.to_string())
                    .collect()
            })
            .collect()
    };
    assert_eq!(
        estimated(&csv),
        estimated(&cli),
        "workbench:\n{csv}\ncli:\n{cli}"
    );
    // A second track can be cancelled: it stops and says so.
    h.get_by_label("Track all frames").click();
    h.run_ok();
    h.get_by_label("Cancel tracking").click();
    h.run_ok();
    assert!(!h.state().recording.track.running);
    assert!(h.query_by_label("Track all frames").is_some());
}

#[test]
fn a_frame_without_a_recorded_pose_is_registered_at_the_press_its_samples_say() {
    // Independent truth: the press the recording was simulated at (the recording has no pose topic, so nothing in
    // it says how deep the sensor went).
    let dir = tempfile::tempdir().unwrap();
    let mut seq = PressSequence::down_and_up(sequence().pose, 0.006, 2, 3);
    seq.pose_topic = None;
    let rec = dir.path().join("nopose.mcap");
    let object = PreparedObject::new(ObjectSet::builtin().mesh("cross_w12_s50").unwrap()).unwrap();
    write_press_recording(&rec, &State::default().sim, &object, &seq).unwrap();
    let mut state = State::default();
    state.scene.object = ObjectSource::Library {
        set: "builtin".into(),
        name: "cross_w12_s50".into(),
    };
    state.derender.config.samples = 2;
    state.recording.path = Some(rec);
    state.view.tab = Tab::Recording;
    let deepest = 2 + 3 - 1;
    state.recording.frame = deepest;
    let mut h = harness(WorkbenchApp::with_state(state));
    h.run_ok();
    wait_for(&mut h, "the recording", |a| a.recording.loaded.is_some());
    assert!(h
        .query_by_label_contains("none recorded (registering finds the press from the samples)")
        .is_some());
    h.get_by_label("De-render and register this frame").click();
    h.run_ok();
    wait_for(&mut h, "the fit", |a| {
        a.analysis.pose.result.is_some() && !a.busy()
    });
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let found = h
        .state()
        .analysis
        .pose
        .result
        .as_ref()
        .unwrap()
        .press_found_m
        .unwrap();
    assert!(
        (found - seq.presses[deepest]).abs() < 5e-4,
        "{found} for {}",
        seq.presses[deepest]
    );
    assert!(h
        .query_by_label_contains("found from the samples")
        .is_some());
}

#[test]
fn one_button_calibrates_the_sensor_from_the_recording_and_every_tab_uses_it() {
    // Independent truth: the sensor the recording was simulated with (inflated 2.5 mm over the nominal membrane,
    // noisier); the session starts from the nominal sensor and is never told.
    let dir = tempfile::tempdir().unwrap();
    let mut truth = State::default().sim;
    truth.elastomer.inflation = 0.0325;
    truth.signature.noise_std = 0.002;
    let rec = dir.path().join("drift.mcap");
    let object = PreparedObject::new(ObjectSet::builtin().mesh(OBJECT).unwrap()).unwrap();
    write_press_recording(&rec, &truth, &object, &sequence()).unwrap();
    let mut state = State::default();
    state.recording.path = Some(rec);
    state.view.tab = Tab::Recording;
    let mut h = harness(WorkbenchApp::with_state(state));
    h.run_ok();
    wait_for(&mut h, "the recording", |a| a.recording.loaded.is_some());
    h.get_by_label("Calibrate sensor from this recording")
        .click();
    h.run_ok();
    wait_for(&mut h, "the calibration", |a| {
        !a.recording.sensor_calibration.running
    });
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    // The session's sensor is the calibrated one: the simulation, de-rendering, pose and track use it.
    let sim = &h.state().state.sim;
    assert!((sim.elastomer.inflation - 0.0325).abs() < 3e-4, "{sim:?}");
    assert!((sim.signature.noise_std - 0.002).abs() < 2e-4, "{sim:?}");
    // The fit is shown: what changed and the residual, beside the three images.
    assert!(h
        .query_by_label_contains("elastomer.inflation: 32.")
        .is_some());
    assert!(h
        .query_by_label_contains("membrane residual: RMS")
        .is_some());
    assert!(h.query_by_label("measured - calibrated").is_some());
    // The calibrated sensor saved as a sensor file beside the recording, which the CLI's loader reads back.
    h.get_by_label("Save sensor file").click();
    h.run_ok();
    let saved =
        tactile_derender::sim::sensor_file::load(&dir.path().join("drift_sensor.json")).unwrap();
    assert_eq!(&saved, &h.state().state.sim);
    // Undo restores the sensor it replaced.
    h.state_mut().apply(tnd_workbench::command::Command::Undo);
    h.run_ok();
    assert_eq!(h.state().state.sim, State::default().sim);
}
