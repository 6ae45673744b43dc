//! The workbench driven by egui_kittest through its widget labels (no GPU: the 3D view uses its CPU fallback).

use std::time::{Duration, Instant};

use egui::accesskit::Role;
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::state::State;

use crate::support;
use support::harness;

/// Step until the background simulation has answered the latest request.
fn settle(h: &mut Harness<'_, WorkbenchApp>) {
    let t0 = Instant::now();
    loop {
        h.step();
        if !h.state().busy() {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the worker did not answer"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    h.run_ok();
}

/// Type `p` into the text field `field` and press `button`.
fn type_path_and_press(
    h: &mut Harness<'_, WorkbenchApp>,
    field: &str,
    p: &std::path::Path,
    button: &str,
) {
    h.get_by_role_and_label(Role::TextInput, field).click();
    h.run_ok();
    h.get_by_role_and_label(Role::TextInput, field)
        .type_text(&p.display().to_string());
    h.run_ok();
    h.get_by_label(button).click();
}

/// Type `p` into the scene's mesh field, press "Load mesh file" and wait for the simulation.
fn type_mesh_path(h: &mut Harness<'_, WorkbenchApp>, p: &std::path::Path) {
    type_path_and_press(h, "Mesh", p, "Load mesh file");
    settle(h);
}

fn shown_contact_pixels(h: &Harness<'_, WorkbenchApp>) -> usize {
    let Some(n) = h.state().contact_pixels() else {
        panic!("no simulation result: {:?}", h.state().errors);
    };
    // The count the test reads from the app is the one on screen.
    assert!(
        h.query_by_label(&format!("contact pixels: {n}")).is_some(),
        "status bar does not show {n} contact pixels"
    );
    n
}

#[test]
fn starts_on_the_default_scene_with_contact() {
    let mut h = harness(WorkbenchApp::default());
    settle(&mut h);
    assert_eq!(h.state().state, State::default());
    assert!(h.query_by_label_contains("scene: cross_w12_s50").is_some());
    let n = shown_contact_pixels(&h);
    assert!(
        n > 50,
        "default scene should press the object visibly, got {n} contact pixels"
    );
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    for title in [
        "D object depth",
        "E elastomer",
        "M contact mask",
        "S signature",
        "Y imprint",
    ] {
        assert!(h.query_by_label(title).is_some(), "missing image {title}");
    }
}

#[test]
fn inflation_slider_changes_the_contact_pixel_count() {
    let mut h = harness(WorkbenchApp::default());
    settle(&mut h);
    let before = shown_contact_pixels(&h);
    // The press depth is measured from the apex, so a taller (30 -> 45 mm), pointier dome pressed the same 6 mm
    // cuts a smaller cap: pi a b (2p/h - p^2/h^2) shrinks as h grows.
    h.get_by_role_and_label(Role::Slider, "inflation (mm)")
        .set_value_accesskit(45.0);
    settle(&mut h);
    assert!((h.state().state.sim.elastomer.inflation - 0.045).abs() < 1e-9);
    let after = shown_contact_pixels(&h);
    assert!(
        after < before,
        "contact pixels {before} -> {after}: a taller dome should touch less"
    );
}

#[test]
fn saving_then_opening_a_session_restores_the_state() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sessions/mine.json");
    let mut h = harness(WorkbenchApp::default());
    settle(&mut h);
    h.get_by_role_and_label(Role::Slider, "press (mm)")
        .set_value_accesskit(4.5);
    h.get_by_role_and_label(Role::Slider, "noise σ (mm)")
        .set_value_accesskit(0.5);
    settle(&mut h);
    let saved = h.state().state.clone();
    assert!((saved.scene.press - 0.0045).abs() < 1e-9);

    type_path_and_press(&mut h, "Session file", &path, "Save");
    h.run_ok();
    assert!(path.exists(), "no session written: {:?}", h.state().errors);

    h.get_by_label("New").click();
    settle(&mut h);
    assert_eq!(h.state().state, State::default());

    type_path_and_press(&mut h, "Session file", &path, "Open");
    settle(&mut h);
    assert_eq!(h.state().state, saved);
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
}

#[test]
fn opening_a_corrupt_session_shows_an_error_and_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.json");
    std::fs::write(&path, "{ \"scene\": { \"press\": ").unwrap();
    let mut h = harness(WorkbenchApp::default());
    settle(&mut h);
    let before = h.state().state.clone();
    let pixels = shown_contact_pixels(&h);
    type_path_and_press(&mut h, "Session file", &path, "Open");
    settle(&mut h);
    assert!(
        h.query_by_label_contains("broken.json: not a valid session file")
            .is_some(),
        "no error shown: {:?}",
        h.state().errors
    );
    assert_eq!(h.state().state, before);
    assert_eq!(shown_contact_pixels(&h), pixels);
}

#[test]
fn exports_the_depth_image_as_png_and_npy() {
    let dir = tempfile::tempdir().unwrap();
    let mut state = State::default();
    state.view.export_dir = dir.path().join("out");
    let mut h = harness(WorkbenchApp::with_state(state));
    settle(&mut h);
    // The first card is D.
    h.get_all_by_label("PNG").next().unwrap().click();
    h.run_ok();
    h.get_all_by_label("npy").next().unwrap().click();
    h.run_ok();
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let png = image::open(dir.path().join("out/depth.png")).unwrap();
    assert!(
        png.width() > 4 * 64 && png.height() > 4 * 64,
        "{}x{}",
        png.width(),
        png.height()
    );
    let npy = tactile_derender::io::npy::read_image(&dir.path().join("out/depth.npy")).unwrap();
    assert_eq!(npy, h.state().sim.as_ref().unwrap().output.depth);
    // Exported again, its own files are replaced. Into a folder of the user's, the user's file of that name is
    // kept and the export says so; the user's other files stay too.
    h.get_all_by_label("PNG").next().unwrap().click();
    h.run_ok();
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let mine = dir.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("depth.png"), "my picture").unwrap();
    std::fs::write(mine.join("notes.txt"), "notes").unwrap();
    h.state_mut().state.view.export_dir = mine.clone();
    h.get_all_by_label("PNG").next().unwrap().click();
    h.run_ok();
    assert!(
        h.state()
            .errors
            .iter()
            .any(|e| e.contains("not written by tnd")),
        "{:?}",
        h.state().errors
    );
    assert_eq!(
        std::fs::read(mine.join("depth.png")).unwrap(),
        b"my picture"
    );
    h.get_all_by_label("npy").next().unwrap().click();
    h.run_ok();
    assert!(mine.join("depth.npy").is_file());
    assert_eq!(std::fs::read(mine.join("notes.txt")).unwrap(), b"notes");
}

#[test]
fn inflation_sweep_finds_the_inflation_of_a_measured_imprint_and_picks_it() {
    use tactile_derender::objects::ObjectSet;
    use tactile_derender::sensor::Scene;
    use tactile_derender::sim::{PreparedObject, Simulator};

    // A "measurement": the default scene's object under a 26 mm membrane whose base is where the default 30 mm
    // membrane pressing 6 mm puts it (apex 2 mm into the object), without noise.
    let dir = tempfile::tempdir().unwrap();
    let measured_path = dir.path().join("measured.npy");
    let mut state = State::default();
    let mut truth = state.sim.clone();
    truth.elastomer.inflation = 0.026;
    truth.signature.noise_std = 0.0;
    let sim = Simulator::new(truth).unwrap();
    let object = PreparedObject::new(ObjectSet::builtin().mesh("cross_w12_s50").unwrap()).unwrap();
    let scene = Scene {
        object: state.scene.object_pose,
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, 0.002),
    };
    let measured = sim.simulate(&object, &scene, 0).imprint;
    tactile_derender::io::npy::write_image(&measured_path, &measured).unwrap();

    state.calibration.lo = 0.022;
    state.calibration.hi = 0.030;
    state.calibration.steps = 5;
    state.calibration.threshold = 0.0005;
    state.calibration.measured = Some(measured_path);
    let mut h = harness(WorkbenchApp::with_state(state));
    settle(&mut h);
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    h.get_all_by_label("Run sweep").next().unwrap().click();
    settle(&mut h);
    let points = &h.state().calibration.points;
    assert_eq!(points.len(), 5, "{:?}", h.state().errors);
    // No contact below 24 mm (the apex stays above the object's top), growing area above.
    assert_eq!(points[0].contact_pixels, 0);
    assert!(points[2].contact_area_m2 < points[4].contact_area_m2);
    h.get_all_by_label_contains("Use best: 26.0 mm")
        .next()
        .unwrap()
        .click();
    settle(&mut h);
    assert!((h.state().state.sim.elastomer.inflation - 0.026).abs() < 1e-9);
    shown_contact_pixels(&h);
}

#[test]
fn a_typed_mesh_path_in_millimetres_replaces_the_object_and_a_missing_one_shows_an_error() {
    use tactile_derender::mesh::Units;
    use tnd_workbench::state::ObjectSource;

    // The library's sphere (metres) rewritten in millimetres.
    let dir = tempfile::tempdir().unwrap();
    let src =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/objects/sphere_r20.obj");
    let obj: String = std::fs::read_to_string(src)
        .unwrap()
        .lines()
        .map(|l| match l.strip_prefix("v ") {
            Some(v) => {
                let mm: Vec<String> = v
                    .split_whitespace()
                    .map(|x| format!("{}", x.parse::<f64>().unwrap() * 1000.0))
                    .collect();
                format!("v {}\n", mm.join(" "))
            }
            None => format!("{l}\n"),
        })
        .collect();
    let path = dir.path().join("ball_mm.obj");
    std::fs::write(&path, obj).unwrap();

    let mut h = harness(WorkbenchApp::default());
    settle(&mut h);
    type_mesh_path(&mut h, &path);
    assert_eq!(
        h.state().state.scene.object,
        ObjectSource::File {
            path: path.clone(),
            units: Units::Mm
        }
    );
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    // A 20 mm sphere pressed 6 mm: a cap of radius sqrt(2 r p - p^2) = 14.3 mm, hundreds of pixels.
    let n = shown_contact_pixels(&h);
    assert!(n > 100, "{n}");

    // Clear the field, then a file that does not exist.
    h.get_by_role_and_label(Role::TextInput, "Mesh").click();
    h.run_ok();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.key_press(egui::Key::Backspace);
    h.run_ok();
    type_mesh_path(&mut h, &dir.path().join("nope.stl"));
    assert!(
        h.query_by_label_contains("Error: simulation: object nope.stl")
            .is_some(),
        "no error naming the file: {:?}",
        h.state().errors
    );
    // The images on screen are the last good scene's, and the workbench says so instead of "simulating…".
    assert!(h
        .query_by_label_contains("The current scene could not be simulated")
        .is_some());
    assert!(h.query_by_label("simulating…").is_none());
    assert!(h.query_by_label("simulation failed").is_some());
}

#[test]
fn a_dataset_pair_as_measurement_places_the_scene_and_calibrates_the_inflation() {
    use tactile_derender::dataset::{generate, GenConfig};
    use tactile_derender::objects::ObjectSet;
    use tnd_workbench::state::ObjectSource;

    // A tiny synthetic dataset made with a 26 mm membrane, no noise and no shadow cloak.
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("synth");
    let mut sim = State::default().sim;
    sim.elastomer.inflation = 0.026;
    sim.signature.noise_std = 0.0;
    sim.signature.shadow_px = 0.0;
    let cfg = GenConfig {
        pairs: 4,
        seed: 5,
        shard_pairs: 4,
        ..GenConfig::default()
    };
    generate(&data, &sim, &ObjectSet::builtin(), &cfg, &|_| {}).unwrap();

    let mut state = State::default();
    state.calibration.lo = 0.022;
    state.calibration.hi = 0.030;
    state.calibration.steps = 9;
    state.calibration.threshold = 0.0002;
    let mut h = harness(WorkbenchApp::with_state(state));
    settle(&mut h);
    type_path_and_press(&mut h, "Imprint", &data, "Load imprint");
    h.run_ok();
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    assert!(h
        .query_by_label_contains("loaded train pair 0 of")
        .is_some());

    h.get_by_label("Use the pair's object and poses").click();
    settle(&mut h);
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    assert!(
        matches!(&h.state().state.scene.object, ObjectSource::Library { set, .. } if set != "builtin")
    );

    h.get_all_by_label("Run sweep").next().unwrap().click();
    settle(&mut h);
    let points = &h.state().calibration.points;
    assert_eq!(points.len(), 9, "{:?}", h.state().errors);
    // The sensor base is where the pair's was, so the 26 mm membrane reproduces its contact (up to the contact
    // pixels whose imprint is below the 0.2 mm threshold, at the rim).
    let best = tactile_derender::sim::calibration::best_by_iou(points).unwrap();
    assert!(
        (best.inflation - 0.026).abs() < 1e-9 && best.iou.unwrap() > 0.95,
        "{points:?}"
    );
    h.get_all_by_label_contains("Use best: 26.0 mm")
        .next()
        .unwrap()
        .click();
    settle(&mut h);
    assert!((h.state().state.sim.elastomer.inflation - 0.026).abs() < 1e-9);
}

#[test]
fn moving_the_object_off_the_membrane_says_why_there_is_no_contact() {
    let mut h = harness(WorkbenchApp::default());
    settle(&mut h);
    assert!(h.query_by_label_contains("No contact").is_none());
    // The default cross is 50 mm across; 150 mm sideways its highest point is far outside the membrane.
    h.get_by_role_and_label(Role::Slider, "object x (mm)")
        .set_value_accesskit(150.0);
    settle(&mut h);
    assert_eq!(shown_contact_pixels(&h), 0);
    let hint = h
        .query_by_label_contains("No contact: the object's highest point is")
        .expect("no hint for a scene without contact");
    assert!(format!("{hint:?}").contains("x = "));
    // The hint's pose puts the object back under the apex (x within the cross's half-extent of 0).
    let centred = h.state().sim.as_ref().unwrap().contact_hint.centred;
    assert!(centred.x.abs() < 0.03, "{centred:?}");
    // One click takes the hint: the object moves there and presses the membrane again.
    h.get_by_label("Move the object there").click();
    settle(&mut h);
    assert_eq!(h.state().state.scene.object_pose, centred);
    assert!(shown_contact_pixels(&h) > 50);
    assert!(h.query_by_label_contains("No contact").is_none());
}

#[test]
fn a_mesh_in_other_units_than_chosen_is_flagged() {
    // The library's 20 mm sphere is stored in metres; the workbench's units box starts at mm, so read as mm it is a
    // 40 µm speck, and the status bar says which unit makes it plausible.
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/objects/sphere_r20.obj");
    let mut h = harness(WorkbenchApp::default());
    settle(&mut h);
    assert!(h.query_by_label_contains("Warning:").is_none());
    type_mesh_path(&mut h, &path);
    assert!(
        h.query_by_label_contains(
            "is implausible for a pressed object; the file is probably in m "
        )
        .is_some(),
        "no unit warning: {:?}",
        h.state().sim.as_ref().map(|s| &s.object_warnings)
    );
}
