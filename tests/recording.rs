//! Real sensor recordings: a press sequence made by the simulator at the camera's native resolution and written as an
//! MCAP file (the `mcap` crate's writer), read back as imprints, imported as pairs with X0 simulated from the pose
//! topic (press estimated from the imprint), and scored by the evaluation loop.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use tactile_derender::dataset::import_recording::{
    import_recording, PoseSource, RecordingImportConfig,
};
use tactile_derender::dataset::npz::NpzIndex;
use tactile_derender::dataset::{Dataset, SplitName};
use tactile_derender::image::Image;
use tactile_derender::metrics::evaluate::{EvalConfig, GroundTruthGenerator};
use tactile_derender::metrics::sources::DatasetSource;
use tactile_derender::objects::ObjectSet;
use tactile_derender::pipeline::evaluate::Evaluator;
use tactile_derender::recording::synth::{write_press_recording, DepthEncoding, PressSequence};
use tactile_derender::recording::{
    process, FolderOptions, ProcessConfig, Recording, RecordingError, ReferenceChoice,
};
use tactile_derender::sensor::{Scene, Se2};
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};

const OBJECT: &str = "cylinder_r12";

fn object() -> PreparedObject {
    PreparedObject::new(ObjectSet::builtin().mesh(OBJECT).unwrap()).unwrap()
}

fn quiet_sim() -> SimConfig {
    let mut c = SimConfig::default();
    c.signature.noise_std = 0.0;
    c
}

fn sequence(encoding: DepthEncoding) -> PressSequence {
    let mut s = PressSequence::down_and_up(Se2::new(0.004, -0.003, 0.5), 0.008, 4, 8);
    s.encoding = encoding;
    s
}

fn record(dir: &Path, config: &SimConfig, seq: &PressSequence) -> std::path::PathBuf {
    let path = dir.join("press.mcap");
    write_press_recording(&path, config, &object(), seq).unwrap();
    path
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
fn recorded_frames_give_the_simulators_model_resolution_imprints() {
    // Independent truth: the simulator rendering the same scenes directly at the model resolution. The recording goes
    // native frame -> 16-bit millimetres -> crop -> area resampling; the two must agree to the millimetre rounding.
    let dir = tempfile::tempdir().unwrap();
    let config = quiet_sim();
    let seq = sequence(DepthEncoding::Mm16);
    let path = record(dir.path(), &config, &seq);
    let rec = Recording::open(&path, &FolderOptions::default()).unwrap();
    let names: Vec<&str> = rec.streams().iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, vec!["/bubble/depth/image_rect_raw", "/object/pose"]);
    let stream = rec.depth_stream(None).unwrap().clone();
    assert_eq!(stream.messages, seq.presses.len());
    let p = process(
        &rec,
        &stream,
        &config.camera,
        &ProcessConfig::default(),
        &mut |_, _| true,
    )
    .unwrap();
    assert_eq!(p.source_size, [224, 171]);
    // Every frame of the reference shows no contact in the simulation itself.
    let sim = Simulator::new(config.clone()).unwrap();
    let obj = object();
    for &k in &p.reference_frames {
        let scene = Scene {
            object: seq.pose,
            sensor: sim.pressing_pose(&obj, 0.0, 0.0, 0.0, seq.presses[k]),
        };
        let out = sim.simulate(&obj, &scene, 0);
        assert!(out.imprint.data.iter().all(|&y| y < 0.003), "frame {k}");
    }
    assert!(p.reference_frames.contains(&0) && p.reference_frames.len() >= 8);
    let deepest = (0..seq.presses.len())
        .max_by(|&a, &b| seq.presses[a].total_cmp(&seq.presses[b]))
        .unwrap();
    assert_eq!(
        (0..p.len()).max_by_key(|&i| p.contact_px[i]).unwrap(),
        deepest
    );
    for i in [deepest - 2, deepest] {
        let scene = Scene {
            object: seq.pose,
            sensor: sim.pressing_pose(&obj, 0.0, 0.0, 0.0, seq.presses[i]),
        };
        let truth = sim.simulate(&obj, &scene, 0).imprint;
        let d = mean_abs_diff(&p.imprints[i], &truth);
        assert!(d < 2.5e-4, "frame {i}: mean |ΔY| = {d} m");
        let above = |y: &Image| y.data.iter().filter(|&&v| v > 0.003).count() as f64;
        let (a, b) = (above(&p.imprints[i]), above(&truth));
        assert!(
            (a - b).abs() <= 0.05 * b,
            "frame {i}: {a} vs {b} contact px"
        );
    }
}

#[test]
fn float_images_point_clouds_and_frame_folders_read_like_millimetre_images() {
    let dir = tempfile::tempdir().unwrap();
    let config = quiet_sim();
    let read = |enc: DepthEncoding, name: &str| {
        let d = dir.path().join(name);
        std::fs::create_dir_all(&d).unwrap();
        let path = record(&d, &config, &sequence(enc));
        let rec = Recording::open(&path, &FolderOptions::default()).unwrap();
        let s = rec.depth_stream(None).unwrap().clone();
        (rec, s)
    };
    let (mm, mm_s) = read(DepthEncoding::Mm16, "mm");
    let (f32_rec, f32_s) = read(DepthEncoding::F32, "f32");
    let (cloud, cloud_s) = read(DepthEncoding::Cloud, "cloud");
    let k = config.camera.native;
    let deepest = 4 + 8 - 1;
    let a = mm.depth_frame(&mm_s, deepest, &k).unwrap().depth;
    let b = f32_rec.depth_frame(&f32_s, deepest, &k).unwrap().depth;
    let c = cloud.depth_frame(&cloud_s, deepest, &k).unwrap().depth;
    // 16UC1 rounds to the millimetre; the float image and the projected cloud keep the float depth.
    assert!(a
        .data
        .iter()
        .zip(&b.data)
        .all(|(x, y)| (x - y).abs() <= 0.0005 + 1e-6));
    assert!(b
        .data
        .iter()
        .zip(&c.data)
        .all(|(x, y)| (x - y).abs() <= 1e-6));
    // The same frames as a folder of 16-bit PNGs (millimetres) give the same imprints as the MCAP file.
    let folder = dir.path().join("frames");
    std::fs::create_dir_all(&folder).unwrap();
    for i in 0..mm_s.messages {
        let d = mm.depth_frame(&mm_s, i, &k).unwrap().depth;
        let px: Vec<u16> = d
            .data
            .iter()
            .map(|&m| (m * 1000.0).round() as u16)
            .collect();
        let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(224, 171, px).unwrap();
        img.save(folder.join(format!("frame{i}.png"))).unwrap();
    }
    let fr = Recording::open(&folder, &FolderOptions::default()).unwrap();
    let fs = fr.depth_stream(None).unwrap().clone();
    assert_eq!(fs.messages, mm_s.messages);
    let pc = ProcessConfig::default();
    let p1 = process(&mm, &mm_s, &config.camera, &pc, &mut |_, _| true).unwrap();
    let p2 = process(&fr, &fs, &config.camera, &pc, &mut |_, _| true).unwrap();
    assert_eq!(p1.imprints, p2.imprints);
    assert_eq!(p1.reference_frames, p2.reference_frames);
    // A chosen reference frame is used as it is.
    let pick = ProcessConfig {
        reference: ReferenceChoice::Frame(2),
        ..pc
    };
    let p3 = process(&mm, &mm_s, &config.camera, &pick, &mut |_, _| true).unwrap();
    assert_eq!(p3.reference, p3.signatures[2]);
}

#[test]
fn imported_recording_has_the_true_presses_and_scores_perfectly_with_the_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = SimConfig::default(); // with measurement noise, as a real sensor
    config.signature.noise_std = 0.001;
    let seq = sequence(DepthEncoding::Mm16);
    let path = record(dir.path(), &config, &seq);
    let out = dir.path().join("ds");
    let mut ic = RecordingImportConfig::new(OBJECT, PoseSource::Topic(None));
    ic.split = Some(SplitName::UnseenObjects);
    // The sensor as given (calibrating it from the frames is checked in tests/recording_calibrate.rs).
    ic.calibrate = false;
    let mut calls = 0;
    let report = import_recording(
        &path,
        &out,
        &config,
        &ObjectSet::builtin(),
        &ic,
        &mut |_, _| {
            calls += 1;
            true
        },
    )
    .unwrap();
    assert_eq!(calls, seq.presses.len());
    assert_eq!(report.frames, seq.presses.len());
    // With a minimum contact above every frame's, the one-line error names the largest contact and what takes it.
    let mut strict = ic.clone();
    strict.min_contact_px = 100_000;
    let err = import_recording(
        &path,
        &dir.path().join("none"),
        &config,
        &ObjectSet::builtin(),
        &strict,
        &mut |_, _| true,
    )
    .unwrap_err()
    .to_string();
    let peak = (0..seq.presses.len())
        .max_by(|&a, &b| seq.presses[a].total_cmp(&seq.presses[b]))
        .unwrap();
    assert!(
        err.contains("no frame became a pair")
            && err.contains(&format!("the largest contact is frame {peak}'s"))
            && err.contains("--min-contact-px"),
        "{err}"
    );
    assert!(report.written.pairs >= 8, "{report:?}");
    assert_eq!(report.press_estimated, report.written.pairs);
    let ds = Dataset::open(&out).unwrap();
    assert_eq!(ds.len(SplitName::UnseenObjects), report.written.pairs);
    let sim = Simulator::new(config.clone()).unwrap();
    let obj = object();
    for i in 0..report.written.pairs {
        let pair = ds.pair(SplitName::UnseenObjects, i).unwrap();
        // The estimated press is one of the recorded presses (to 0.3 mm), and X0 is the simulator's at that press.
        let nearest = seq
            .presses
            .iter()
            .map(|&p| (p - pair.meta.press).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(nearest < 3e-4, "pair {i}: press {} m", pair.meta.press);
        assert_eq!(pair.meta.object, OBJECT);
        let scene = Scene {
            object: seq.pose,
            sensor: sim.pressing_pose(&obj, 0.0, 0.0, 0.0, pair.meta.press),
        };
        let (mask, _) = sim.contact(&sim.render_depth(&obj, &scene));
        assert_eq!(pair.mask, mask);
    }
    // The evaluation loop scores the imported pairs: the ground truth registers to the recorded pose (taken as
    // registered: the signature check would trade the exact depth for the noisy signature's optimum).
    let src = DatasetSource::new(&ds, SplitName::UnseenObjects, None).unwrap();
    let r = Evaluator::new(EvalConfig {
        pose: tactile_derender::pose::PoseConfig {
            check_signature: false,
            ..Default::default()
        },
        ..EvalConfig::default()
    })
    .evaluate(&src, &GroundTruthGenerator, 0, &mut |_, _| true)
    .unwrap();
    assert_eq!(r.pairs, report.written.pairs);
    assert!(r.failed.is_empty());
    assert!(
        r.model.position_mm.median < 0.05,
        "{:?}",
        r.model.position_mm
    );
    // A second import into the same directory is refused, the first dataset kept.
    assert!(import_recording(
        &path,
        &out,
        &config,
        &ObjectSet::builtin(),
        &ic,
        &mut |_, _| true
    )
    .is_err());
    assert!(Dataset::open(&out).is_ok());
}

#[test]
fn csv_poses_with_presses_and_bad_recordings_give_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let config = quiet_sim();
    let mut seq = sequence(DepthEncoding::Mm16);
    seq.pose_topic = None;
    let path = record(dir.path(), &config, &seq);
    let import = |ic: &RecordingImportConfig, out: &str| {
        import_recording(
            &path,
            &dir.path().join(out),
            &config,
            &ObjectSet::builtin(),
            ic,
            &mut |_, _| true,
        )
    };
    // Without a pose topic the import says which topics there are.
    let ic = RecordingImportConfig::new(OBJECT, PoseSource::Topic(None));
    let e = import(&ic, "a").unwrap_err().to_string();
    assert!(
        e.contains("press.mcap") && e.contains("no pose topic"),
        "{e}"
    );
    // A mesh file named as the object: a pair names an object of a set, and the error says how to make one.
    let ic = RecordingImportConfig::new("parts/screw.stl", PoseSource::Topic(None));
    let e = import(&ic, "a").unwrap_err().to_string();
    assert!(
        e.contains("tnd objects import parts") && e.contains("--objects parts --object screw"),
        "{e}"
    );
    // A CSV with the poses and presses of frames 8..=12 (presses of 5..8 mm).
    let mut csv = String::from("frame,x,y,theta,press\n");
    for f in 8..=12 {
        let p = seq.pose;
        csv += &format!("{f},{},{},{},{}\n", p.x, p.y, p.theta, seq.presses[f]);
    }
    let csv_path = dir.path().join("poses.csv");
    std::fs::write(&csv_path, csv).unwrap();
    let ic = RecordingImportConfig::new(OBJECT, PoseSource::Csv(csv_path.clone()));
    let r = import(&ic, "b").unwrap();
    assert_eq!(r.press_estimated, 0);
    assert_eq!(r.written.pairs, 5);
    assert!(r.skipped_no_pose > 0);
    // The same table in millimetres and degrees: refused, naming the row.
    std::fs::write(&csv_path, "frame,x,y,theta\n8,3,-2,23\n").unwrap();
    let ic = RecordingImportConfig::new(OBJECT, PoseSource::Csv(csv_path.clone()));
    let e = import(&ic, "c").unwrap_err().to_string();
    assert!(
        e.contains("poses.csv") && e.contains("row 1") && e.contains("millimetres or degrees"),
        "{e}"
    );
    // Truncated file, wrong topic, not an MCAP: errors naming the file.
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = Recording::open(&cut, &FolderOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.starts_with(&cut.display().to_string()) && !e.contains('\n'),
        "{e}"
    );
    let rec = Recording::open(&path, &FolderOptions::default()).unwrap();
    let e = rec.depth_stream(Some("/nope")).unwrap_err().to_string();
    assert!(
        e.contains("/nope") && e.contains("/bubble/depth/image_rect_raw"),
        "{e}"
    );
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"hello").unwrap();
    assert!(matches!(
        Recording::open(&junk, &FolderOptions::default()),
        Err(RecordingError::Format { .. })
    ));
}

#[test]
fn the_cli_records_imports_and_scores_a_press_sequence() {
    // As a user would: tnd recording simulate -> tnd recording info -> tnd dataset import -> tnd eval.
    let dir = tempfile::tempdir().unwrap();
    let tnd = env!("CARGO_BIN_EXE_tnd");
    let output = |args: &[&str]| {
        std::process::Command::new(tnd)
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap()
    };
    let run = |args: &[&str]| -> serde_json::Value {
        let out = output(args);
        assert!(
            out.status.success(),
            "tnd {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stdout = String::from_utf8(out.stdout).unwrap();
        serde_json::from_str(stdout.lines().last().unwrap()).unwrap()
    };
    let rec = run(&[
        "recording",
        "simulate",
        "press.mcap",
        "--object",
        OBJECT,
        "--pose",
        "0.004,-0.003,0.5",
        "--rest",
        "3",
        "--ramp",
        "6",
        "--encoding",
        "cloud",
    ]);
    assert_eq!(rec["frames"], 3 + 6 + 5 + 3);
    let info = run(&["recording", "info", "press.mcap"]);
    assert_eq!(info["frames"], 17);
    // A folder of frames named by a relative path (docs/recordings.md's `--from frames/`): each frame is read once from
    // that folder, not from frames/frames/.
    let folder = dir.path().join("frames");
    std::fs::create_dir_all(&folder).unwrap();
    let rec_file =
        Recording::open(&dir.path().join("press.mcap"), &FolderOptions::default()).unwrap();
    let stream = rec_file.depth_stream(None).unwrap().clone();
    let k = SimConfig::default().camera.native;
    for i in 0..4 {
        let d = rec_file.depth_frame(&stream, i, &k).unwrap().depth;
        tactile_derender::io::npy::write_image(&folder.join(format!("frame_{i:02}.npy")), &d)
            .unwrap();
    }
    let folder_info = run(&["recording", "info", "frames/"]);
    assert_eq!(folder_info["frames"], 4, "{folder_info}");
    assert_eq!(info["peak_contact_frame"], 8);
    let imported = run(&[
        "dataset",
        "import",
        "--from",
        "press.mcap",
        "--out",
        "ds",
        "--object",
        OBJECT,
        "--split",
        "unseen_objects",
    ]);
    let pairs = imported["pairs"].as_u64().unwrap();
    assert!(pairs >= 6, "{imported}");
    let eval = run(&[
        "eval",
        "--data",
        "ds",
        "--split",
        "unseen_objects",
        "--model",
        "ground-truth",
        "--no-signature-check",
        "--save-samples",
        "saved",
    ]);
    assert_eq!(eval["split"], "unseen_objects");
    assert_eq!(eval["pairs"].as_u64(), Some(pairs));
    assert!(eval["failed"].as_array().unwrap().is_empty());
    assert!(eval["model"]["position_mm"]["median"].as_f64().unwrap() < 0.05);
    // Every pair's samples are saved beside its truth; the ground-truth generator's one sample is the true X0.
    for i in 0..pairs {
        let path = dir.path().join(format!("saved/unseen_objects/{i}.npz"));
        let bytes = std::fs::read(&path).unwrap();
        let index = NpzIndex::read(std::io::Cursor::new(bytes.as_slice()), &path).unwrap();
        let data = |name: &str| {
            let m = index
                .get(name)
                .unwrap_or_else(|| panic!("{name} in {path:?}"));
            (
                m.shape.clone(),
                &bytes[m.data_offset as usize..(m.data_offset + m.data_len) as usize],
            )
        };
        let (target_shape, target) = data("target");
        let (samples_shape, samples) = data("samples");
        assert_eq!(samples_shape, [&[1][..], &target_shape[..]].concat());
        assert_eq!(samples, target);
        assert!(
            target.chunks(4).any(|v| v != [0; 4]),
            "pair {i}: no contact saved"
        );
        assert_eq!(data("imprint").0, target_shape);
        assert_eq!(data("object_pose").0, [3]);
    }
    // With the signature check (the default) the table also sets the model against the baseline with the same check.
    let checked = output(&[
        "eval",
        "--data",
        "ds",
        "--split",
        "unseen_objects",
        "--model",
        "ground-truth",
        "--limit",
        "2",
    ]);
    let table = String::from_utf8_lossy(&checked.stderr);
    assert!(checked.status.success(), "{table}");
    // Every method against both baselines: the pipeline, the samples alone, each over the checked baseline too.
    for line in [
        "| mean position error ratio | / threshold baseline | / (baseline + signature check) |",
        "| pipeline: samples + imprint proposals, checked |",
        "| samples only, checked |",
    ] {
        assert!(table.contains(line), "{line}: {table}");
    }
    // The saved run in the paper's layout: one row for the run (named here), the baseline, θ in radians.
    std::fs::write(dir.path().join("gt.json"), format!("{eval}\n")).unwrap();
    let out = output(&["eval", "--tables-from", "truth=gt.json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let md = String::from_utf8(out.stdout).unwrap();
    assert!(
        md.contains("| configuration | unseen_objects: position [mm] | unseen_objects: θ [rad] |")
    );
    let row = md.lines().rfind(|l| l.starts_with("| truth |")).unwrap();
    let position: f64 = row
        .split('|')
        .nth(2)
        .unwrap()
        .split('±')
        .next()
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let want = eval["model"]["position_mm"]["mean"].as_f64().unwrap();
    assert!((position - want).abs() < 0.006, "{row} vs {want}");
    assert!(md.contains("| threshold baseline |"));
    // A file that is not a tnd eval output is refused with its name.
    std::fs::write(dir.path().join("bad.json"), "{}\n").unwrap();
    let out = output(&["eval", "--tables-from", "bad.json"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.json: no split summaries"));
}

#[test]
fn the_cli_tracks_a_press_sequence_and_resumes_where_it_stopped() {
    // As a user would: tnd recording simulate -> tnd recording track (bundled model, two samples of six DDIM steps a
    // frame: the test is of tracking, resuming and scoring, not of the sampler's default); the
    // recorded pose topic is the truth the rows are scored against, never an input.
    let dir = tempfile::tempdir().unwrap();
    let tnd = env!("CARGO_BIN_EXE_tnd");
    let output = |args: &[&str]| {
        std::process::Command::new(tnd)
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap()
    };
    let run = |args: &[&str]| -> serde_json::Value {
        let out = output(args);
        assert!(
            out.status.success(),
            "tnd {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stdout = String::from_utf8(out.stdout).unwrap();
        serde_json::from_str(stdout.lines().last().unwrap()).unwrap()
    };
    let simulated = run(&[
        "recording",
        "simulate",
        "press.mcap",
        "--object",
        "cross_w12_s50",
        "--pose",
        "0.003,-0.002,0.4",
        "--max-press",
        "0.007",
        "--rest",
        "2",
        "--ramp",
        "5",
    ]);
    let presses: Vec<f64> = simulated["presses_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_f64().unwrap())
        .collect();
    let info = run(&["recording", "info", "press.mcap"]);
    let with_contact = info["contact_px"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c.as_u64().unwrap() >= 10)
        .count();
    let track = [
        "recording",
        "track",
        "press.mcap",
        "--object",
        "cross_w12_s50",
        "--samples",
        "2",
        "--steps",
        "6",
        "--out",
        "track",
    ];
    let summary = run(&track);
    assert_eq!(
        summary["tracked"].as_u64(),
        Some(with_contact as u64),
        "{summary}"
    );
    assert_eq!(summary["scored_against"], "/object/pose");
    assert_eq!(summary["no_estimate"], 0, "{summary}");
    let median = summary["position_err_mm"]["median"].as_f64().unwrap();
    assert!(median < 1.0, "{summary}");
    // Every scored frame has the recorded pose's region in its posterior; the shares inside grow with the level.
    let inside = &summary["truth_inside"];
    assert_eq!(
        inside["frames"].as_u64(),
        Some(with_contact as u64),
        "{summary}"
    );
    let share = |p: &str| inside[p].as_f64().unwrap();
    assert!(share("0.5") <= share("0.9") && share("0.9") <= share("0.95") && share("0.95") <= 1.0);
    let csv = std::fs::read_to_string(dir.path().join("track/track.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), with_contact + 1);
    // Every frame carries its posterior (modes, a positive-definite covariance), and the MCAP one message each.
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for line in &lines[1..] {
        let cells: Vec<&str> = line.split(',').collect();
        assert!(
            cells[col("posterior_modes")].parse::<usize>().unwrap() >= 1,
            "{line}"
        );
        let (xx, yy, tt): (f64, f64, f64) = (
            cells[col("cov_xx")].parse().unwrap(),
            cells[col("cov_yy")].parse().unwrap(),
            cells[col("cov_thetatheta")].parse().unwrap(),
        );
        assert!(xx > 0.0 && yy > 0.0 && tt > 0.0, "{line}");
    }
    // The press's first contact frame is estimated from scratch; the frames after it carry its estimate forward.
    let carried: Vec<&str> = lines[1..]
        .iter()
        .map(|l| l.split(',').nth(col("carried")).unwrap())
        .collect();
    assert_eq!(carried[0], "0", "{csv}");
    assert!(carried[1..].iter().all(|c| *c == "1"), "{csv}");
    assert_eq!(
        summary["pose_track"]["messages"].as_u64(),
        Some(with_contact as u64),
        "{summary}"
    );
    let mcap = std::fs::read(dir.path().join("track/track.mcap")).unwrap();
    let has = |needle: &[u8]| mcap.windows(needle.len()).any(|w| w == needle);
    assert!(has(b"geometry_msgs/msg/PoseWithCovarianceStamped") && has(b"/tnd/object_pose"));
    // The press found for each frame (never given: the sensor does not measure it) is the one simulated.
    for line in &lines[1..] {
        let cells: Vec<&str> = line.split(',').collect();
        let frame: usize = cells[0].parse().unwrap();
        let press: f64 = cells[3].parse().unwrap();
        assert!(
            (press - presses[frame]).abs() < 5e-4,
            "frame {frame}: press {press} against {}",
            presses[frame]
        );
    }
    // A run killed after two frames resumes: the other frames are tracked again, bit for bit as before.
    std::fs::write(dir.path().join("track/track.csv"), lines[..3].join("\n")).unwrap();
    let resumed = run(&track);
    assert_eq!(resumed["this_run"].as_u64(), Some(with_contact as u64 - 2));
    assert_eq!(
        std::fs::read_to_string(dir.path().join("track/track.csv")).unwrap(),
        csv
    );
    // Other settings into the same folder are refused, naming them.
    let mut other = track.to_vec();
    other.extend(["--press", "0.005"]);
    let refused = output(&other);
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("other settings (press: \"auto\" -> \"0.005\")"),
        "{stderr}"
    );
    // Poses given later rescore the finished track without tracking again: the same object 1 mm further along x.
    let mut table = String::from("frame,x,y,theta\n");
    for k in 0..presses.len() {
        table.push_str(&format!("{k},0.004,-0.002,0.4\n"));
    }
    std::fs::write(dir.path().join("shifted.csv"), table).unwrap();
    let mut rescored = track.to_vec();
    rescored.extend(["--poses", "shifted.csv"]);
    let again = run(&rescored);
    assert_eq!(again["this_run"], 0, "{again}");
    assert_eq!(again["scored_against"], "shifted.csv");
    let before = summary["position_err_mm"]["mean"].as_f64().unwrap();
    let after = again["position_err_mm"]["mean"].as_f64().unwrap();
    assert!(after > before + 0.3, "{before} -> {after}");
    // A failed start (an unknown object) leaves nothing behind that would block the corrected command.
    let mut wrong = track.to_vec();
    wrong[4] = "no_such_object";
    wrong[8] = "fresh";
    assert!(!output(&wrong).status.success());
    assert!(!dir.path().join("fresh").exists());
    // Another recording under the same name is not resumed into.
    let resimulated = output(&[
        "recording",
        "simulate",
        "press.mcap",
        "--object",
        "cross_w12_s50",
        "--pose",
        "0.003,-0.002,0.4",
        "--max-press",
        "0.007",
        "--rest",
        "3",
        "--ramp",
        "5",
    ]);
    assert!(resimulated.status.success());
    let refused = output(&track);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && stderr.contains("holds a track of another recording"),
        "{stderr}"
    );
}
