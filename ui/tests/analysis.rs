//! The analysis tabs driven by egui_kittest through their labels: open a small generated dataset, filter and select a
//! pair, send it to de-rendering, sample it with a tiny random model saved to a temporary checkpoint, cancel a run.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use egui_kittest::kittest::Queryable;
use tactile_derender::dataset::{Dataset, SplitName};
use tactile_derender::model::{DiffusionModel, SamplerKind};
use tactile_derender::objects::ObjectSet;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::state::{State, Tab};

use crate::support;
use support::{
    harness, open_dataset, select_pair, small_dataset, tiny_model, type_into, use_checkpoint,
    wait_for,
};

#[test]
fn dataset_inspector_shows_filters_and_selects_pairs() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_dataset(dir.path());
    let ds = Dataset::open(&data).unwrap();
    let n_train = ds.len(SplitName::Train);
    assert!(
        n_train >= 2,
        "the generated dataset has {n_train} train pairs"
    );
    let first = ds.pair(SplitName::Train, 0).unwrap();

    let mut h = harness(WorkbenchApp::default());
    open_dataset(&mut h, &data);
    assert_eq!(h.state().state.view.tab, Tab::Dataset);
    // Every thumbnail on screen gets decoded (the grid holds them all at this size).
    wait_for(&mut h, "thumbnails", |a| {
        a.analysis
            .dataset
            .as_ref()
            .is_some_and(|b| b.cached() == n_train)
    });
    assert!(h
        .query_by_label(&format!(
            "{n_train} of {n_train} pairs shown · {n_train} thumbnails cached"
        ))
        .is_some());

    // Select pair 0: metadata and the four full-size images.
    select_pair(&mut h, "train pair 0");
    let sel = h
        .state()
        .analysis
        .dataset
        .as_ref()
        .unwrap()
        .selected
        .as_ref()
        .unwrap();
    assert_eq!(
        sel.pair, first,
        "the shown pair is not the dataset's pair 0"
    );
    for title in [
        "Y imprint",
        "S signature",
        "X0 = M·D target",
        "M contact mask",
    ] {
        assert!(h.query_by_label(title).is_some(), "no {title}");
    }
    assert!(h
        .query_by_label_contains(&format!("object {} at", first.meta.object))
        .is_some());

    // Filter by pair 0's object: exactly the train pairs of that object are listed.
    let want: Vec<usize> = (0..n_train)
        .filter(|&i| ds.pair(SplitName::Train, i).unwrap().meta.object == first.meta.object)
        .collect();
    let mut s = h.state().state.dataset.clone();
    s.object = Some(first.meta.object.clone());
    h.state_mut()
        .apply(tnd_workbench::command::Command::SetDataset(s));
    h.run_ok();
    let shown: Vec<usize> = h
        .state_mut()
        .analysis
        .dataset
        .as_mut()
        .unwrap()
        .filtered(SplitName::Train, Some(&first.meta.object))
        .to_vec();
    assert_eq!(shown, want);
    assert!(h
        .query_by_label_contains(&format!("{} of {n_train} pairs shown", want.len()))
        .is_some());

    // Place the scene where pair 0 was taken: its object (from the dataset's object set) at its pose.
    h.get_by_label("Place the scene").click();
    h.run_ok();
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let scene = &h.state().state.scene;
    assert!(
        matches!(&scene.object, tnd_workbench::state::ObjectSource::Library { name, .. } if *name == first.meta.object)
    );
    assert_eq!(scene.object_pose, first.meta.object_pose);
    assert_eq!(h.state().state.view.tab, Tab::Scene);
    h.get_by_label("Dataset").click();
    h.run_ok();

    // A directory that is not a dataset: one error naming it.
    let bogus = dir.path().join("not-a-dataset");
    std::fs::create_dir_all(&bogus).unwrap();
    h.state_mut().inputs.dataset_path = bogus.display().to_string();
    h.run_ok();
    h.get_by_label("Open dataset").click();
    h.run_ok();
    let errors = &h.state().errors;
    assert!(
        errors
            .iter()
            .any(|e| e.contains("not-a-dataset") && e.contains("manifest.json")),
        "{errors:?}"
    );
}

#[test]
fn de_rendering_a_dataset_pair_with_a_tiny_model_matches_the_core_sampler() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_dataset(dir.path());
    let model_path = tiny_model(dir.path());
    let pair = Dataset::open(&data)
        .unwrap()
        .pair(SplitName::Train, 1)
        .unwrap();

    let mut h = harness(WorkbenchApp::default());
    open_dataset(&mut h, &data);
    select_pair(&mut h, "train pair 1");
    h.get_by_label("Send to de-render").click();
    h.run_ok();
    assert_eq!(h.state().state.view.tab, Tab::Derender);
    assert!(h.query_by_label("dataset pair: train #1").is_some());

    use_checkpoint(&mut h, &model_path);
    h.run_ok();
    let mut d = h.state().state.derender.clone();
    d.config.sampler.steps = 4;
    d.config.samples = 3;
    d.config.seed = 7;
    h.state_mut()
        .apply(tnd_workbench::command::Command::SetDerender(d.clone()));
    h.run_ok();
    h.get_by_label("Run de-rendering").click();
    h.run_ok();
    wait_for(&mut h, "the samples", |a| !a.analysis.derender.running);
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let r = h.state().analysis.derender.result.as_ref().unwrap();

    // The same samples as the core's sampler with the same model, input, sampler and seed, guided towards the
    // pair's imprint on the dataset's sensor (a dataset pair's sensor is known).
    assert!(r.guided);
    assert!(h.query_by_label("imprint guidance").is_some());
    let ds = Dataset::open(&data).unwrap();
    let sim = tactile_derender::sim::Simulator::new(ds.sim_config().clone()).unwrap();
    let guidance = tactile_derender::pipeline::imprint_guidance(
        &d.config,
        &sim,
        &pair.imprint,
        Some(&pair.signature),
    )
    .unwrap();
    assert!(guidance.is_some());
    let model = DiffusionModel::load(&model_path).unwrap();
    let want = model
        .sample_guided(
            &pair.imprint,
            guidance.as_ref(),
            3,
            SamplerKind::Ddim {
                steps: 4,
                eta: 0.0,
                spacing: Default::default(),
            },
            7,
            &mut |_, _| true,
        )
        .unwrap();
    assert_eq!(r.samples, want);
    // Per-pixel mean and std over the samples in contact there (checked at one pixel by hand).
    let k = 64 * 32 + 30;
    let v: Vec<f64> = want
        .iter()
        .map(|s| f64::from(s.data[k]))
        .filter(|&x| x > 0.0)
        .collect();
    assert!(!v.is_empty(), "pixel {k} is in no sample's contact");
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!((f64::from(r.mean.data[k]) - mean).abs() < 1e-6);
    assert!((f64::from(r.std.data[k]) - std).abs() < 1e-6);
    // Scores against the pair's X0: L1 is the mean absolute difference in mm.
    assert_eq!(r.scores.len(), 3);
    let l1: f64 = want[0]
        .data
        .iter()
        .zip(&pair.target.data)
        .map(|(a, b)| f64::from((a - b).abs()))
        .sum::<f64>()
        / want[0].data.len() as f64
        * 1e3;
    assert!(
        (r.scores[0].l1_mm - l1).abs() < 1e-6,
        "{} vs {l1}",
        r.scores[0].l1_mm
    );
    for title in [
        "Y imprint",
        "X0 ground truth",
        "sample mean",
        "sample std",
        "contact probability",
        "consensus (multi-sample)",
        "sample 2",
    ] {
        assert!(h.query_by_label(title).is_some(), "no {title}");
    }
    assert!(h.query_by_label_contains("mean over samples: L1").is_some());
    // The contact probability is the fraction of samples in contact at each pixel.
    let p = &r.contact_probability;
    for i in [0, p.data.len() / 2, p.data.len() - 1] {
        let in_contact = r.samples.iter().filter(|s| s.data[i] > 0.0).count() as f32;
        assert_eq!(p.data[i], in_contact / r.samples.len() as f32);
    }
}

#[test]
fn a_long_run_can_be_cancelled_and_a_bad_checkpoint_shows_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let model_path = tiny_model(dir.path());
    let mut state = State::default();
    state.view.tab = Tab::Derender;
    state.derender.config.sampler.kind = tnd_workbench::state::SamplerName::Ddpm;
    state.derender.config.samples = 16;
    state.model.path = Some(model_path);
    let mut h = harness(WorkbenchApp::with_state(state));
    wait_for(&mut h, "the simulation", |a| a.sim.is_some());
    h.get_by_label("Run de-rendering").click();
    h.run_ok();
    wait_for(&mut h, "progress", |a| {
        a.analysis.derender.progress.is_some()
    });
    h.get_by_label("Cancel").click();
    wait_for(&mut h, "the cancel", |a| !a.analysis.derender.running);
    let app = h.state();
    assert!(app.analysis.derender.result.is_none());
    assert!(app.errors.is_empty(), "{:?}", app.errors);
    assert_eq!(app.notice.as_deref(), Some("de-rendering cancelled"));
    let (done, total) = app.analysis.derender.progress.unwrap();
    assert!(done < total && total == 250, "{done}/{total}");

    // A truncated checkpoint: one error naming the file.
    let bad = dir.path().join("bad.safetensors");
    std::fs::write(&bad, b"\x10\x00\x00\x00").unwrap();
    use_checkpoint(&mut h, &bad);
    h.run_ok();
    h.get_by_label("Run de-rendering").click();
    wait_for(&mut h, "the error", |a| !a.analysis.derender.running);
    let errors = &h.state().errors;
    assert!(
        errors.iter().any(|e| e.contains("bad.safetensors")),
        "{errors:?}"
    );
}

#[test]
fn without_a_checkpoint_the_bundled_model_is_used() {
    let mut state = State::default();
    state.view.tab = Tab::Derender;
    let mut h = harness(WorkbenchApp::with_state(state));
    h.run_ok();
    // With none chosen, the bundled model matched to the input (as `--model auto`), and the panel says so.
    assert!(h
        .query_by_label_contains("using the bundled model matched to the input")
        .is_some());
    let (default, recording) = (
        tnd_workbench::derender::matched_model_path(false),
        tnd_workbench::derender::matched_model_path(true),
    );
    assert!(default.ends_with("default") || default.ends_with("default.safetensors"));
    assert!(recording.ends_with("recording") || recording.ends_with("recording.safetensors"));
    // The bundled small model is one click away, and named as such.
    h.get_by_label("bundled small").click();
    h.run_ok();
    assert_eq!(
        h.state().state.model.path.as_deref(),
        Some(std::path::Path::new("small"))
    );
    assert!(h
        .query_by_label_contains("using the bundled small model")
        .is_some());
    h.get_by_label("bundled, matched to the input").click();
    h.run_ok();
    assert_eq!(h.state().state.model.path, None);
}

#[test]
fn an_imported_dataset_is_indexed_by_object_in_the_background() {
    use tactile_derender::dataset::import::{import, ImportConfig};
    // The dataset module's import fixture (three real-format pairs, no generation plan to read objects from).
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/dataset_import");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("real");
    import(
        &fixture,
        &out,
        &State::default().sim,
        &ObjectSet::builtin(),
        &ImportConfig::default(),
    )
    .unwrap();
    let ds = Dataset::open(&out).unwrap();
    assert!(ds.manifest().generation.is_none());

    let mut h = harness(WorkbenchApp::default());
    open_dataset(&mut h, &out);
    for split in SplitName::ALL {
        wait_for(&mut h, "the object index", |a| {
            a.analysis
                .dataset
                .as_ref()
                .is_some_and(|b| !b.indexing(split))
        });
        for i in 0..ds.len(split) {
            let want = ds.pair(split, i).unwrap().meta.object;
            let b = h.state().analysis.dataset.as_ref().unwrap();
            assert_eq!(b.object_name(split, i), Some(want.as_str()), "{split} {i}");
        }
    }
}

#[test]
fn an_imported_measurement_is_de_rendered_without_scores() {
    let dir = tempfile::tempdir().unwrap();
    let model_path = tiny_model(dir.path());
    let npy = dir.path().join("imprint.npy");
    let imprint = tactile_derender::image::Image::filled(64, 64, 0.001);
    tactile_derender::io::npy::write_image(&npy, &imprint).unwrap();
    let mut state = State::default();
    state.view.tab = Tab::Derender;
    state.model.path = Some(model_path.clone());
    state.derender.config.sampler.steps = 2;
    state.derender.config.samples = 2;
    let mut h = harness(WorkbenchApp::with_state(state));
    h.run_ok();
    type_into(&mut h, "measurement", &npy.display().to_string());
    h.get_by_label("Use measurement").click();
    h.run_ok();
    h.get_by_label("Run de-rendering").click();
    wait_for(&mut h, "the samples", |a| !a.analysis.derender.running);
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let r = h.state().analysis.derender.result.as_ref().unwrap();
    assert_eq!(r.input.imprint, imprint);
    assert!(r.input.truth.is_none() && r.scores.is_empty());
    let want = DiffusionModel::load(&model_path)
        .unwrap()
        .sample(
            &imprint,
            2,
            SamplerKind::Ddim {
                steps: 2,
                eta: 0.0,
                spacing: Default::default(),
            },
            0,
            &mut |_, _| true,
        )
        .unwrap();
    assert_eq!(r.samples, want);
    assert!(h
        .query_by_label("no ground truth for this input: no scores")
        .is_some());
    // A card's image enlarges in its own window (clicking it pushes this command) and closes again.
    let title = h.state().analysis.derender.images[0].title.clone();
    let before = h.query_all_by_label(&title).count();
    h.state_mut()
        .apply(tnd_workbench::command::Command::ZoomImage(Some(
            tnd_workbench::analysis_runs::ZoomTarget::Derender(0),
        )));
    h.run_ok();
    assert_eq!(h.query_all_by_label(&title).count(), before + 1);
    h.state_mut()
        .apply(tnd_workbench::command::Command::ZoomImage(None));
    h.run_ok();
    assert_eq!(h.query_all_by_label(&title).count(), before);
    // Registration needs the object and sensor pose, which a measurement does not carry.
    h.get_by_label("Pose").click();
    h.run_ok();
    h.get_by_label("Register samples").click();
    h.run_ok();
    assert!(
        h.state()
            .errors
            .iter()
            .any(|e| e.contains("no object or sensor pose")),
        "{:?}",
        h.state().errors
    );
}
