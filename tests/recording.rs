//! Real sensor recordings: a press sequence made by the simulator at the camera's native resolution and written as an
//! MCAP file (the `mcap` crate's writer), read back as imprints, imported as pairs with X0 simulated from the pose
//! topic (press estimated from the imprint), and scored by the evaluation loop.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use tactile_derender::dataset::import_recording::{
    import_recording, PoseSource, RecordingImportConfig,
};
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

pub(crate) const OBJECT: &str = "cylinder_r12";

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

pub(crate) fn record(dir: &Path, config: &SimConfig, seq: &PressSequence) -> std::path::PathBuf {
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
