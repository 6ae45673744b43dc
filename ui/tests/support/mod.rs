//! Helpers the workbench's egui_kittest tests share (`mod support;` in each test file): the harness at the window
//! size the tests lay out for, waiting for background jobs, a tiny random model checkpoint, dropped files, and a small
//! generated dataset opened in the Dataset tab.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui::accesskit::Role;
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use tactile_derender::dataset::{generate, GenConfig};
use tactile_derender::model::checkpoint::{build, save_model};
use tactile_derender::model::init::init_params;
use tactile_derender::model::UNet2DConfig;
use tactile_derender::objects::ObjectSet;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::state::State;

/// The app in a 1500 x 950 window.
pub fn harness(app: WorkbenchApp) -> Harness<'static, WorkbenchApp> {
    Harness::builder()
        .with_size([1500.0, 950.0])
        .build_ui_state(|ui, app: &mut WorkbenchApp| app.show(ui), app)
}

/// Step until `done` holds (90 s at most), then let the UI settle.
pub fn wait_for(
    h: &mut Harness<'_, WorkbenchApp>,
    what: &str,
    done: impl Fn(&WorkbenchApp) -> bool,
) {
    wait_for_within(h, what, Duration::from_secs(90), done);
}

/// [`wait_for`] with another time limit.
pub fn wait_for_within(
    h: &mut Harness<'_, WorkbenchApp>,
    what: &str,
    limit: Duration,
    done: impl Fn(&WorkbenchApp) -> bool,
) {
    let t0 = Instant::now();
    loop {
        h.step();
        if done(h.state()) {
            break;
        }
        assert!(
            t0.elapsed() < limit,
            "timed out waiting for {what}: {:?}",
            h.state().errors
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    h.run_ok();
}

/// A tiny randomly initialised model at 64 x 64 saved as `dir/tiny.safetensors`.
pub fn tiny_model(dir: &Path) -> PathBuf {
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

/// A file dropped on the window.
#[derive(Debug)]
pub struct Dropped(pub PathBuf);

impl egui::DroppedFile for Dropped {
    fn path(&self) -> &Path {
        &self.0
    }
    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

/// Drop `path` on the window and run the frame that handles it.
pub fn drop_file(h: &mut Harness<'_, WorkbenchApp>, path: &Path) {
    h.input_mut()
        .dropped_files
        .push(Arc::new(Dropped(path.to_path_buf())));
    h.run_ok();
}

/// A small noiseless dataset (64 x 64, 8 pairs) in `dir`.
pub fn small_dataset(dir: &Path) -> PathBuf {
    let data = dir.join("synth");
    let mut sim = State::default().sim;
    sim.signature.noise_std = 0.0;
    let cfg = GenConfig {
        pairs: 8,
        seed: 3,
        shard_pairs: 8,
        ..GenConfig::default()
    };
    generate(&data, &sim, &ObjectSet::builtin(), &cfg, &|_| {}).unwrap();
    data
}

/// Click the dataset inspector's pair `label` ("train pair 0") and wait until the pair is selected.
pub fn select_pair(h: &mut Harness<'_, WorkbenchApp>, label: &str) {
    h.get_by_label(label).click();
    wait_for(h, "the selected pair", |a| {
        a.analysis
            .dataset
            .as_ref()
            .is_some_and(|b| b.selected.is_some())
    });
}

/// Point the De-render tab at the checkpoint `path` ("Use checkpoint").
pub fn use_checkpoint(h: &mut Harness<'_, WorkbenchApp>, path: &Path) {
    type_into(h, "checkpoint", &path.display().to_string());
    h.get_by_label("Use checkpoint").click();
}

pub fn type_into(h: &mut Harness<'_, WorkbenchApp>, field: &str, text: &str) {
    h.get_by_role_and_label(Role::TextInput, field).click();
    h.run_ok();
    h.get_by_role_and_label(Role::TextInput, field)
        .type_text(text);
    h.run_ok();
}

pub fn open_dataset(h: &mut Harness<'_, WorkbenchApp>, data: &Path) {
    h.get_by_label("Dataset").click();
    h.run_ok();
    type_into(h, "Dataset", &data.display().to_string());
    h.get_by_label("Open dataset").click();
    h.run_ok();
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
}

/// `target/<profile>/tnd`, beside this test's `deps/` directory (`cargo test --workspace` builds it).
#[allow(dead_code)] // not every test binary runs the CLI
pub fn tnd_binary() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let dir = exe.parent().and_then(Path::parent).unwrap();
    let tnd = dir.join(format!("tnd{}", std::env::consts::EXE_SUFFIX));
    assert!(
        tnd.is_file(),
        "{} is missing: run the workspace's tests (`cargo test --workspace`), which build the tnd binary",
        tnd.display()
    );
    tnd
}
