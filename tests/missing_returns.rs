//! Real depth-camera frames: pixels without a return (NaN in 32FC1 and in numpy dumps, 0 in 16UC1) are missing data
//! in every input path — MCAP, frame folders, `tnd pose`'s single frames, dataset import, tracking — and a membrane
//! that drifts between no-contact stretches gets each contact the references around it blended by its time. Truths: the same presses
//! recorded without the artefacts (the simulator's own frames), and the artefacts' definitions.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::cli_common;

use std::path::Path;

use tactile_derender::image::Image;
use tactile_derender::objects::ObjectSet;
use tactile_derender::pose::posterior::PosteriorConfig;
use tactile_derender::recording::frames_out::write_frames;
use tactile_derender::recording::synth::{write_press_recording, DepthEncoding, PressSequence};
use tactile_derender::recording::{process, FolderOptions, ProcessConfig, Recording};
use tactile_derender::sensor::Se2;
use tactile_derender::sim::{DepthCameraConfig, PreparedObject, SimConfig};

use cli_common::{stderr, tnd_in};

const OBJECT: &str = "cylinder_r12";

fn object() -> PreparedObject {
    PreparedObject::new(ObjectSet::builtin().mesh(OBJECT).unwrap()).unwrap()
}

fn processed(path: &Path, config: &SimConfig) -> tactile_derender::recording::ProcessedRecording {
    let rec = Recording::open(path, &FolderOptions::default()).unwrap();
    let s = rec.depth_stream(None).unwrap().clone();
    process(
        &rec,
        &s,
        &config.camera,
        &ProcessConfig::default(),
        &mut |_, _| true,
    )
    .unwrap()
}

fn mean_abs_diff(a: &Image, b: &Image) -> f64 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(&x, &y)| f64::from((x - y).abs()))
        .sum::<f64>()
        / a.data.len() as f64
}

#[test]
fn no_returns_stored_as_nan_or_zero_are_missing_and_the_imprint_has_no_holes() {
    let dir = tempfile::tempdir().unwrap();
    let mut clean = SimConfig::default();
    clean.signature.noise_std = 0.0;
    // Nearly half the native pixels without a return: about a third of the model's pixels have too few returns to
    // be measured (the area resampling needs half of a pixel's area).
    let mut holed = clean.clone();
    holed.depth_camera = DepthCameraConfig {
        dropout: 0.45,
        ..DepthCameraConfig::default()
    };
    let seq = |encoding| {
        let mut s = PressSequence::down_and_up(Se2::new(0.004, -0.003, 0.5), 0.008, 4, 6);
        s.encoding = encoding;
        s
    };
    let record = |name: &str, config: &SimConfig, encoding| {
        let path = dir.path().join(name);
        write_press_recording(&path, config, &object(), &seq(encoding)).unwrap();
        path
    };
    let truth = processed(&record("clean.mcap", &clean, DepthEncoding::F32), &clean);
    let nan = processed(&record("nan.mcap", &holed, DepthEncoding::F32), &clean);
    let zero = processed(&record("zero.mcap", &holed, DepthEncoding::Mm16), &clean);
    let deepest = 4 + 6 - 1;
    let seen = truth.measured_px[deepest];
    let missing = seen.saturating_sub(nan.measured_px[deepest]);
    assert!(
        missing > seen / 5 && missing < seen / 2,
        "{missing} of {seen} missing"
    );
    // NaN and 0 mark the same pixels; 16UC1 rounds depths to the millimetre.
    assert_eq!(nan.measured_px, zero.measured_px);
    assert!(mean_abs_diff(&nan.imprints[deepest], &zero.imprints[deepest]) < 6e-4);
    // The imprint is filled in where the frame has no return: the contact keeps its area (a hole would count as no
    // contact) and its depth (the clean frame's, to the interpolation's error).
    let (with, without) = (nan.contact_px[deepest], truth.contact_px[deepest]);
    assert!(
        (with as f64 - without as f64).abs() < 0.1 * without as f64,
        "contact {with} px with holes, {without} without"
    );
    // Over the contact (truth imprint over 3 mm): filled pixels within a millimetre on average; a hole would be
    // off by the whole imprint there.
    let (t, y) = (&truth.imprints[deepest], &nan.imprints[deepest]);
    let contact: Vec<usize> = (0..t.data.len()).filter(|&i| t.data[i] > 0.003).collect();
    let err = contact
        .iter()
        .map(|&i| f64::from((y.data[i] - t.data[i]).abs()))
        .sum::<f64>()
        / contact.len() as f64;
    assert!(
        err < 1e-3,
        "imprint off by {err} m on average over the contact"
    );
    assert!(
        contact.iter().all(|&i| y.data[i] > 0.0),
        "a hole in the contact"
    );
    // Every frame is usable (more than half the membrane measured).
    assert!((0..nan.len()).all(|k| nan.unusable(k).is_none()));

    // The frames out as a user's folder (NaN where no return) read back as the same recording.
    let rec = Recording::open(&dir.path().join("nan.mcap"), &FolderOptions::default()).unwrap();
    let stream = rec.depth_stream(None).unwrap().clone();
    let folder = dir.path().join("frames");
    let rows = write_frames(
        &rec,
        &stream,
        &nan,
        &clean.camera.native,
        &[],
        &folder,
        &mut |_, _| true,
    )
    .unwrap();
    assert_eq!(rows.len(), nan.len());
    let first = tactile_derender::io::npy::read(&rows[deepest].file).unwrap();
    assert!(first.data.iter().any(|v| v.is_nan()), "NaN where no return");
    let again = processed(&folder, &clean);
    assert_eq!(again.imprints, nan.imprints);
    assert_eq!(again.reference_frames, nan.reference_frames);
}

#[test]
fn a_drifting_membrane_gives_each_contact_the_references_around_it_blended_at_its_time() {
    // Three presses with no-contact stretches before, between and after them; the membrane deflates by 1.5 mm over
    // the recording, steadily. Truth: the same presses on a membrane that does not drift.
    let dir = tempfile::tempdir().unwrap();
    let mut config = SimConfig::default();
    config.signature.noise_std = 0.0;
    let mut seq = PressSequence::down_and_up(Se2::new(0.003, 0.002, 0.3), 0.007, 5, 4);
    let one = seq.presses.clone();
    for _ in 0..2 {
        seq.presses.extend(one.iter().skip(5));
    }
    let drifting = PressSequence {
        drift_m: -0.0015,
        ..seq.clone()
    };
    let write = |name: &str, s: &PressSequence| {
        let path = dir.path().join(name);
        write_press_recording(&path, &config, &object(), s).unwrap();
        processed(&path, &config)
    };
    let still = write("still.mcap", &seq);
    let drift = write("drift.mcap", &drifting);
    assert!(still.reference_of.is_none() && still.drift_m() < 1e-4);
    assert_eq!(drift.stretches.len(), 4, "{:?}", drift.stretches);
    let of = drift.reference_of.as_ref().expect("local references");
    // Each stretch drifts further from the first (central half of the apex's drift).
    let d: Vec<f64> = drift.stretches.iter().map(|s| s.drift_m).collect();
    assert!(
        d[0] == 0.0 && d[1] < -2e-4 && d[2] < d[1] && d[3] < d[2],
        "{d:?}"
    );
    // The truth of each frame's reference: the drifting membrane at that frame touching nothing.
    let empty = PressSequence {
        presses: vec![-0.002; drifting.presses.len()],
        ..drifting.clone()
    };
    let membrane_at = write("empty.mcap", &empty);
    // The deepest frame of the first and of the last press: its imprint against the references of the stretches
    // before and after it blended at its time, far nearer the imprint against its own moment's membrane than
    // against the stretch before it alone, or against one reference for the whole recording (the median of its
    // no-contact frames).
    for (press, deepest) in [(0, 5 + 3), (2, 5 + 2 * 12 + 3)] {
        let l = of[deepest];
        assert_eq!((l.before, l.after), (press, press + 1), "frame {deepest}");
        assert!(l.weight > 0.2 && l.weight < 0.8, "frame {deepest}: {l:?}");
        let s = &drift.signatures[deepest];
        let imprint = tactile_derender::sim::signature::imprint;
        let truth = imprint(&membrane_at.signatures[deepest], s);
        let local = mean_abs_diff(&drift.imprints[deepest], &truth);
        let before = mean_abs_diff(&imprint(&drift.stretches[press].reference, s), &truth);
        let global = mean_abs_diff(&imprint(&drift.reference, s), &truth);
        assert!(
            local < 0.75 * before && before < global,
            "frame {deepest}: blended {local}, stretch before {before}, one reference {global}"
        );
    }
    // Written out as frames, a blended frame names its own reference file, and that file with the frame gives the
    // frame's imprint as the recording was processed (the single-frame `tnd pose --signature F --reference R`).
    let rec = Recording::open(&dir.path().join("drift.mcap"), &FolderOptions::default()).unwrap();
    let stream = rec.depth_stream(None).unwrap().clone();
    let folder = dir.path().join("frames");
    let k = 5 + 3;
    let rows = write_frames(
        &rec,
        &stream,
        &drift,
        &config.camera.native,
        &[k],
        &folder,
        &mut |_, _| true,
    )
    .unwrap();
    assert_eq!(rows[0].reference_file, format!("reference_for_{k:06}.npy"));
    let read = |name: &str| {
        let img = tactile_derender::io::npy::read_image(&folder.join(name)).unwrap();
        tactile_derender::sensor::resample::to_model(&config.camera, &img).unwrap()
    };
    let y = tactile_derender::sim::signature::imprint(
        &read(&rows[0].reference_file),
        &read(&tactile_derender::recording::frames_out::frame_name(k)),
    );
    assert!(
        mean_abs_diff(&y, &drift.imprints[k]) < 2e-5,
        "{}",
        mean_abs_diff(&y, &drift.imprints[k])
    );
    // The same frames of the membrane that does not drift need no local reference.
    assert!(still.stretches.iter().all(|s| s.drift_m.abs() < 1e-4));
}

#[test]
fn nan_frames_go_through_frames_import_pose_and_track_from_the_cli() {
    // As a user with a time-of-flight camera would: a recording whose frames miss returns (NaN in 32FC1), its frames
    // written out, imported as a folder with a pose table, one frame's pose, and the track of the MCAP file.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ok = |args: &[&str]| -> serde_json::Value {
        let out = tnd_in(d, args);
        assert!(out.status.success(), "tnd {args:?}: {}", stderr(&out));
        let text = String::from_utf8(out.stdout).unwrap();
        serde_json::from_str(text.lines().last().unwrap()).unwrap()
    };
    std::fs::write(
        d.join("tof.json"),
        r#"{"depth_camera": {"dropout": 0.05, "edge_missing_px": 3, "noise_exponent": 2}}"#,
    )
    .unwrap();
    let pose = "0.003,-0.002,0.4";
    for (name, encoding) in [("nan.mcap", "f32"), ("zero.mcap", "mm16")] {
        ok(&[
            "recording",
            "simulate",
            name,
            "--object",
            OBJECT,
            "--pose",
            pose,
            "--rest",
            "3",
            "--ramp",
            "4",
            "--encoding",
            encoding,
            "--sensor",
            "tof.json",
        ]);
    }
    let frames = ok(&["recording", "frames", "nan.mcap", "--out", "frames"]);
    let rows = frames["frames"].as_array().unwrap();
    assert_eq!(rows.len(), 3 + 4 + 3 + 3);
    let peak = rows
        .iter()
        .max_by_key(|r| r["contact_px"].as_u64().unwrap())
        .unwrap()["frame"]
        .as_u64()
        .unwrap();
    // A pose table by frame, as a user writes one.
    let mut csv = String::from("frame,x,y,theta\n");
    for r in rows {
        csv += &format!("{},{}\n", r["frame"], pose);
    }
    std::fs::write(d.join("poses.csv"), csv).unwrap();
    // Both conventions import (calibrated from the recording, the default): the folder of NaN frames and the MCAP
    // file of 0s give pairs.
    let a = ok(&[
        "dataset",
        "import",
        "--from",
        "frames",
        "--poses",
        "poses.csv",
        "--object",
        OBJECT,
        "--split",
        "unseen_objects",
        "--out",
        "ds_nan",
    ]);
    let b = ok(&[
        "dataset",
        "import",
        "--from",
        "zero.mcap",
        "--object",
        OBJECT,
        "--split",
        "unseen_objects",
        "--out",
        "ds_zero",
    ]);
    for r in [&a, &b] {
        assert!(r["pairs"].as_u64().unwrap() >= 3, "{r}");
    }
    // Their frames were resampled from the camera's 224 x 171: `--model auto` de-renders them with the recording
    // model.
    for ds in ["ds_nan", "ds_zero"] {
        let ds = tactile_derender::dataset::Dataset::open(d.join(ds)).unwrap();
        assert!(ds.manifest().frames_resampled());
    }
    // README's single-frame step on the exported frames, as written (the sensor calibrated from the reference).
    let frame = format!("frames/frame_{peak:06}.npy");
    let readme_step = [
        "pose",
        "--signature",
        &frame,
        "--reference",
        "frames/reference.npy",
        "--object",
        OBJECT,
        "--samples",
        "2",
        "--steps",
        "3",
        "--truth",
        pose,
    ];
    let pose_out = ok(&[&readme_step[..], &["--out", "pose"]].concat());
    let err = pose_out["estimate_error"]["position_mm"].as_f64();
    assert!(err.is_some_and(f64::is_finite), "{pose_out}");
    // Native frames are resampled to the model's size: `--model auto` (the default) takes the recording model.
    assert!(
        pose_out["generator"]
            .as_str()
            .is_some_and(|g| g.starts_with("model recording")),
        "{pose_out}"
    );
    assert!(
        pose_out["calibration"].is_object(),
        "calibrated from the reference"
    );
    // Such frames get the bundled posterior calibration for resampled frames: given as a file it changes nothing,
    // while the one for frames made at the model's resolution gives another posterior.
    let calibration = |name: &str, c: &PosteriorConfig| {
        std::fs::write(d.join(name), serde_json::to_string(c).unwrap()).unwrap();
    };
    calibration(
        "resampled.json",
        &PosteriorConfig::resampled_frames_bundled(),
    );
    let model_resolution = PosteriorConfig {
        resampled_frames: None,
        ..PosteriorConfig::default()
    };
    calibration("model_resolution.json", &model_resolution);
    let posterior_with = |file: &str| {
        let out = format!("pose_{file}");
        ok(&[&readme_step[..], &["--posterior", file, "--out", &out]].concat())["posterior"].clone()
    };
    assert!(pose_out["posterior"].is_object(), "{pose_out}");
    assert_eq!(posterior_with("resampled.json"), pose_out["posterior"]);
    assert_ne!(
        posterior_with("model_resolution.json"),
        pose_out["posterior"]
    );
    // A sensor file is used as it is, unless --calibrate asks for the re-fit from one frame.
    let calibrated = tnd_in(
        d,
        &["calibrate", "--from", "zero.mcap", "--out", "sensor.json"],
    );
    assert!(calibrated.status.success(), "{}", stderr(&calibrated));
    let single = [
        "pose",
        "--signature",
        &frame,
        "--reference",
        "frames/reference.npy",
        "--object",
        OBJECT,
        "--samples",
        "1",
        "--steps",
        "2",
        "--sensor",
        "sensor.json",
    ];
    let given = ok(&[&single[..], &["--out", "pose_given"]].concat());
    assert!(given["calibration"].is_null(), "{given}");
    let refit = ok(&[&single[..], &["--calibrate", "--out", "pose_refit"]].concat());
    assert!(refit["calibration"].is_object(), "{refit}");
    // A frame that lost most of its returns is named and skipped, not the recording refused.
    let mut broken = tactile_derender::io::npy::read_image(&d.join(&frame)).unwrap();
    let keep = broken.data.len() / 4;
    for v in broken.data.iter_mut().skip(keep) {
        *v = f32::NAN;
    }
    tactile_derender::io::npy::write_image(&d.join(&frame), &broken).unwrap();
    let out = tnd_in(
        d,
        &[
            "recording",
            "track",
            "frames",
            "--object",
            OBJECT,
            "--samples",
            "2",
            "--steps",
            "3",
            "--every",
            "1",
            "--out",
            "track",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let said = stderr(&out);
    assert!(
        said.contains(&format!("frame {peak}: only")) && said.contains("skipped"),
        "{said}"
    );
    let track = std::fs::read_to_string(d.join("track/track.csv")).unwrap();
    let tracked: Vec<&str> = track.lines().skip(1).collect();
    assert!(tracked.len() >= 3, "{track}");
    assert!(
        !tracked.iter().any(|l| l.starts_with(&format!("{peak},"))),
        "{track}"
    );
}
