//! A light press (no frame with enough contact over the contact threshold) imported at the recording's own noise,
//! and refused with the fallback off; a recording that touches nothing is no light press.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use tactile_derender::dataset::import_recording::{
    import_recording, PoseSource, RecordingImportConfig,
};
use tactile_derender::dataset::{Dataset, SplitName};
use tactile_derender::objects::ObjectSet;
use tactile_derender::pipeline::tracker::TrackingConfig;
use tactile_derender::recording::process::{LIGHT_PRESS_MIN_M, LIGHT_PRESS_SIGMAS};
use tactile_derender::recording::synth::{DepthEncoding, PressSequence};
use tactile_derender::recording::{process, FolderOptions, ProcessConfig, Recording};
use tactile_derender::sensor::Se2;
use tactile_derender::sim::{DepthCameraConfig, SimConfig};

use crate::recording::{record, OBJECT};

/// The import of the recording at `path` into `out` beside it, as `tnd dataset import` does with `ic` (the object
/// known, its poses from the pose topic, uncalibrated unless `ic` says otherwise).
fn import(
    path: &std::path::Path,
    out: &str,
    config: &SimConfig,
    ic: &RecordingImportConfig,
) -> Result<tactile_derender::dataset::import_recording::RecordingImportReport, String> {
    let dir = path.parent().unwrap();
    import_recording(
        path,
        &dir.join(out),
        config,
        &ObjectSet::builtin(),
        ic,
        &mut |_, _| true,
    )
    .map_err(|e| e.to_string())
}

/// The import settings of these tests: the known object, poses from the pose topic, not calibrated.
fn settings() -> RecordingImportConfig {
    let mut ic = RecordingImportConfig::new(OBJECT, PoseSource::Topic(None));
    ic.split = Some(SplitName::UnseenObjects);
    ic.calibrate = false;
    ic
}

#[test]
fn a_light_press_is_taken_in_at_the_recordings_own_noise() {
    // A press of 2.5 mm never puts an imprint 3 mm deep: no frame passes the default contact threshold. The import
    // takes it in at 4x the no-contact frames' noise (at least 1 mm) and says so; every pair it makes is a frame
    // that touches, at its true press. With the fallback off, the one-line error stands.
    let dir = tempfile::tempdir().unwrap();
    let mut config = SimConfig::default();
    config.signature.noise_std = 0.0005;
    let mut seq = PressSequence::down_and_up(Se2::new(0.002, 0.001, 0.3), 0.0025, 4, 5);
    seq.encoding = DepthEncoding::F32;
    let path = record(dir.path(), &config, &seq);
    let mut ic = settings();
    let report = import(&path, "light", &config, &ic).unwrap();
    let light = report.light_press.expect("taken in as a light press");
    assert!(light.noise_m > 0.0 && light.noise_m < 5e-4, "{light:?}");
    let expected = (LIGHT_PRESS_SIGMAS * light.noise_m).max(LIGHT_PRESS_MIN_M);
    assert!((light.threshold_m - expected).abs() < 1e-12, "{light:?}");
    assert!(light.threshold_m < 0.003 && light.contact_threshold_m == 0.003);
    let touching = seq.presses.iter().filter(|&&p| p > 0.0).count();
    assert!(
        report.written.pairs >= 1 && report.written.pairs <= touching,
        "{report:?}"
    );
    let ds = Dataset::open(dir.path().join("light")).unwrap();
    for i in 0..report.written.pairs {
        let press = ds.pair(SplitName::UnseenObjects, i).unwrap().meta.press;
        let nearest = seq
            .presses
            .iter()
            .map(|&p| (p - press).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(press > 0.0 && nearest < 3e-4, "pair {i}: press {press} m");
    }
    ic.light_press = false;
    let err = import(&path, "refused", &config, &ic).unwrap_err();
    assert!(err.contains("no frame became a pair"), "{err}");
}

#[test]
fn a_recording_that_touches_nothing_is_no_light_press() {
    // Independent truth: the object lies 200 mm to the side, so no frame touches it. Through a time-of-flight camera
    // (dropouts, flying pixels, noise growing with depth) the noise's tail still puts a few pixels of each frame over
    // a threshold set by the noise: the frames found to touch nothing are never a light press's contact, so the
    // track has no frame and the import no pair, each with its one-line error, instead of poses of nothing.
    let dir = tempfile::tempdir().unwrap();
    let config = SimConfig {
        depth_camera: DepthCameraConfig::time_of_flight(),
        ..SimConfig::default()
    };
    let seq = PressSequence::down_and_up(Se2::new(0.2, 0.0, 0.0), 0.006, 1, 2);
    let path = record(dir.path(), &config, &seq);
    let rec = Recording::open(&path, &FolderOptions::default()).unwrap();
    let stream = rec.depth_stream(None).unwrap().clone();
    let processed = process(
        &rec,
        &stream,
        &config.camera,
        &ProcessConfig::default(),
        &mut |_, _| true,
    )
    .unwrap();
    assert!(
        processed.contact_px.iter().all(|&px| px == 0),
        "{:?}",
        processed.contact_px
    );
    let tracking = TrackingConfig::default();
    let (todo, light) = tracking.frames(&processed, 1, 0.003, &mut |_, _| {});
    assert!(todo.is_empty() && light.is_none(), "{todo:?} {light:?}");
    let err = import(&path, "nothing", &config, &settings()).unwrap_err();
    assert!(err.contains("no frame became a pair"), "{err}");
}
