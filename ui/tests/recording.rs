//! The Recording tab driven through its labels: a press sequence recorded as an MCAP file by the test itself (the
//! core's simulator at the camera's native resolution, written with the `mcap` crate) opens by typing its path and by
//! dropping it on the window, scrubs, and de-renders and registers the frame under the cursor.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui::accesskit::Role;
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use tactile_derender::model::checkpoint::{build, save_model};
use tactile_derender::model::init::init_params;
use tactile_derender::model::UNet2DConfig;
use tactile_derender::objects::ObjectSet;
use tactile_derender::recording::synth::{write_press_recording, PressSequence};
use tactile_derender::sensor::Se2;
use tactile_derender::sim::PreparedObject;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::state::{ObjectSource, State, Tab};

fn harness(app: WorkbenchApp) -> Harness<'static, WorkbenchApp> {
    Harness::builder()
        .with_size([1500.0, 950.0])
        .build_ui_state(|ui, app: &mut WorkbenchApp| app.show(ui), app)
}

fn wait_for(h: &mut Harness<'_, WorkbenchApp>, what: &str, done: impl Fn(&WorkbenchApp) -> bool) {
    let t0 = Instant::now();
    loop {
        h.step();
        if done(h.state()) {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(90),
            "timed out waiting for {what}: {:?}",
            h.state().errors
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    h.run_ok();
}

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

fn tiny_model(dir: &Path) -> PathBuf {
    let cfg = UNet2DConfig {
        sample_size: 64,
        block_out_channels: vec![4, 8],
        down_block_types: vec!["DownBlock2D".into(), "DownBlock2D".into()],
        up_block_types: vec!["UpBlock2D".into(), "UpBlock2D".into()],
        layers_per_block: 1,
        norm_num_groups: 2,
        attention_head_dim: Some(4),
        ..UNet2DConfig::default()
    };
    let vars = build(&cfg, &candle_core::Device::Cpu).unwrap();
    init_params(&vars.varmap, 11).unwrap();
    let path = dir.join("tiny.safetensors");
    save_model(&path, &vars.varmap, &cfg, Default::default()).unwrap();
    path
}

#[derive(Debug)]
struct Dropped(PathBuf);

impl egui::DroppedFile for Dropped {
    fn path(&self) -> &Path {
        &self.0
    }
    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
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
    h.input_mut()
        .dropped_files
        .push(Arc::new(Dropped(rec.clone())));
    h.run_ok();
    wait_for(&mut h, "the dropped recording", |a| {
        a.recording.loaded.is_some()
    });
    assert_eq!(h.state().state.view.tab, Tab::Recording);
    assert_eq!(
        h.state().state.recording.path.as_deref(),
        Some(rec.as_path())
    );
}
