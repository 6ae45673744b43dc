//! The smaller ways a run could go wrong for an unlucky user, each with the one-line message that names the file:
//! an MCAP whose depth channel holds no messages, a second import into a finished dataset, a report folder that
//! cannot be written (refused before the evaluation, not after it), a mesh in the wrong units or fitted to an
//! impossible size, a sensor file whose depth camera `tnd dataset gen` does not simulate.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::cli_common;

use std::collections::BTreeMap;

use cli_common::{stderr, tnd_in};
use std::time::{Duration, Instant};

#[test]
fn a_depth_channel_without_messages_is_named_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty_depth.mcap");
    let mut w = mcap::WriteOptions::new()
        .create(std::io::BufWriter::new(
            std::fs::File::create(&path).unwrap(),
        ))
        .unwrap();
    let meta = BTreeMap::new();
    let img = w
        .add_schema("sensor_msgs/msg/Image", "ros2msg", b"")
        .unwrap();
    let pose = w
        .add_schema("geometry_msgs/msg/PoseStamped", "ros2msg", b"")
        .unwrap();
    w.add_channel(img, "/bubble/depth", "cdr", &meta).unwrap();
    let c_pose = w.add_channel(pose, "/object/pose", "cdr", &meta).unwrap();
    let msg = tactile_derender::recording::ros::encode_pose_stamped(7, 0.0, 0.0, 0.0, "world");
    let header = mcap::records::MessageHeader {
        channel_id: c_pose,
        sequence: 0,
        log_time: 7,
        publish_time: 7,
    };
    w.write_to_known_channel(&header, &msg).unwrap();
    w.finish().unwrap();
    drop(w);
    for (args, expected) in [
        (
            vec!["recording", "info", "empty_depth.mcap"],
            "it has no depth topic with messages (messages only on /object/pose)",
        ),
        (
            vec![
                "recording",
                "info",
                "empty_depth.mcap",
                "--topic",
                "/bubble/depth",
            ],
            "topic '/bubble/depth' holds no depth messages (messages only on /object/pose)",
        ),
    ] {
        let o = tnd_in(dir.path(), &args);
        let err = stderr(&o);
        assert!(!o.status.success());
        assert!(err.contains("empty_depth.mcap"), "{err}");
        assert!(err.contains(expected), "{err}");
        assert_eq!(err.matches("no depth").count(), 1, "said twice: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
}

#[test]
fn a_second_import_into_a_finished_dataset_says_it_is_finished() {
    let dir = tempfile::tempdir().unwrap();
    let o = tnd_in(
        dir.path(),
        &[
            "recording",
            "simulate",
            "rec.mcap",
            "--object",
            "cross_w12_s50",
            "--rest",
            "2",
            "--ramp",
            "3",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let import = [
        "dataset",
        "import",
        "-q",
        "--from",
        "rec.mcap",
        "--object",
        "cross_w12_s50",
        "--out",
        "imp",
    ];
    let o = tnd_in(dir.path(), &import);
    assert!(o.status.success(), "{}", stderr(&o));
    let manifest = std::fs::read(dir.path().join("imp/manifest.json")).unwrap();
    let o = tnd_in(dir.path(), &import);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("imp: holds a finished dataset already (manifest.json)"),
        "{err}"
    );
    assert!(!err.contains("holds no"), "{err}");
    assert_eq!(
        std::fs::read(dir.path().join("imp/manifest.json")).unwrap(),
        manifest
    );
}

#[test]
fn an_unwritable_report_folder_is_refused_before_the_evaluation() {
    let dir = tempfile::tempdir().unwrap();
    let o = tnd_in(
        dir.path(),
        &[
            "dataset", "gen", "-q", "--out", "ds", "--pairs", "24", "--seed", "3",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    // A file where the report's folder should be (root can write anywhere, so permissions would not test this).
    std::fs::write(dir.path().join("taken"), "a file").unwrap();
    let t0 = Instant::now();
    let o = tnd_in(
        dir.path(),
        &[
            "eval",
            "-q",
            "--data",
            "ds",
            "--split",
            "train",
            "--model",
            "small",
            "--steps",
            "2",
            "--pose-samples",
            "4",
            "--report",
            "taken/report",
        ],
    );
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(err.contains("taken/report"), "{err}");
    // Refused before the model is loaded or a pair is scored (an evaluation takes far longer).
    assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

/// A millimetre mesh read as metres (a 40 m cube) is refused by `tnd sim` before anything is written, naming the
/// units that fit; with `--units mm` the same file simulates.
#[test]
fn a_mis_scaled_mesh_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let mut obj = String::new();
    for i in 0..8 {
        let c = |bit: usize| if i >> bit & 1 == 1 { 40 } else { 0 };
        obj.push_str(&format!("v {} {} {}\n", c(0), c(1), c(2)));
    }
    for f in [
        "1 3 4 2", "5 6 8 7", "1 2 6 5", "3 7 8 4", "1 5 7 3", "2 4 8 6",
    ] {
        obj.push_str(&format!("f {f}\n"));
    }
    std::fs::write(dir.path().join("cube_mm.obj"), obj).unwrap();
    let sim = |extra: &[&str]| {
        let base = ["sim", "-q", "--object", "cube_mm.obj", "--out", "out"];
        tnd_in(dir.path(), &[&base[..], extra].concat())
    };
    let o = sim(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("probably in mm") && err.contains("a simulation of it would be meaningless"),
        "{err}"
    );
    assert!(!dir.path().join("out").exists());
    let o = sim(&["--units", "mm"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A fit size past any object (the vertices overflowed and the simulation hung), and a set's object, which
    // the set sizes.
    let o = sim(&["--fit-size", "1e308"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("above 10 m"), "{err}");
    let o = tnd_in(
        dir.path(),
        &[
            "sim",
            "--object",
            "cross_w12_s50",
            "--fit-size",
            "0.05",
            "--out",
            "set",
        ],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("mesh files only"),
        "{err}"
    );
}

#[test]
fn a_depth_camera_dataset_gen_simulates_is_said() {
    // A sensor file from `tnd calibrate` of a time-of-flight recording carries its depth_camera; dataset gen renders
    // its pairs through it (tests/dataset.rs checks the pairs) and says so, since they cost more than an ideal
    // camera's.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("tof.json"),
        r#"{"depth_camera": {"dropout": 0.02}}"#,
    )
    .unwrap();
    let gen = |out: &str, sensor: &[&str]| {
        let mut args = vec![
            "dataset", "gen", "-q", "--out", out, "--pairs", "2", "--seed", "3",
        ];
        args.extend_from_slice(sensor);
        tnd_in(dir.path(), &args)
    };
    let o = gen("with", &["--sensor", "tof.json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("artefacts"), "{}", stderr(&o));
    assert!(dir.path().join("with/manifest.json").exists());
    let o = gen(
        "varied",
        &["--camera-artefacts-range", "0,1.5", "--sensor-levels", "2"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("artefacts"), "{}", stderr(&o));
    let o = gen("native", &["--native-frames"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("native resolution"), "{}", stderr(&o));
    let o = gen("without", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("artefacts"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("native resolution"), "{}", stderr(&o));
    let o = gen("bad", &["--camera-artefacts-range", "1"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--camera-artefacts-range"),
        "{}",
        stderr(&o)
    );
}
