//! Recordings through the command line as a user runs it: `tnd recording simulate`, `info`, `dataset import`,
//! `eval` and `recording track` (with resuming), on press sequences written by the simulator.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use tactile_derender::dataset::npz::NpzIndex;
use tactile_derender::recording::{FolderOptions, Recording};
use tactile_derender::sim::SimConfig;

use crate::cli_common::{stderr, tnd_in, tnd_json};
use crate::recording::OBJECT;

#[test]
fn the_cli_records_imports_and_scores_a_press_sequence() {
    // As a user would: tnd recording simulate -> tnd recording info -> tnd dataset import -> tnd eval.
    let dir = tempfile::tempdir().unwrap();
    let output = |args: &[&str]| tnd_in(dir.path(), args);
    let run = |args: &[&str]| tnd_json(dir.path(), args);
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
    let output = |args: &[&str]| tnd_in(dir.path(), args);
    let run = |args: &[&str]| tnd_json(dir.path(), args);
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
    // tnd posterior scores the track from its folder (posteriors.json beside track.csv) as the track scored itself,
    // and fits a calibration to it, replaying each carried frame's fusion.
    let scored = output(&["posterior", "--tracks", "track", "--json"]);
    assert!(scored.status.success(), "{scored:?}");
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&scored.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let all = lines
        .iter()
        .find(|l| l["rows"] == "track" && l["contact"] == "all")
        .unwrap();
    assert_eq!(all["coverage"]["pairs"].as_u64(), Some(with_contact as u64));
    for (i, p) in ["0.5", "0.9", "0.95"].iter().enumerate() {
        let theirs = all["coverage"]["inside"][i].as_f64().unwrap();
        assert!((theirs - share(p)).abs() < 1e-12, "{all} vs {summary}");
    }
    let fitted = run(&[
        "posterior",
        "--tracks",
        "track",
        "--fit",
        "fit.json",
        "--json",
    ]);
    assert_eq!(
        fitted["pairs"].as_u64(),
        Some(with_contact as u64),
        "{fitted}"
    );
    assert!(
        tactile_derender::pose::posterior::PosteriorConfig::read(&dir.path().join("fit.json"))
            .is_ok()
    );
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
        // The ±68 % half-widths beside it: positive, θ within half a turn.
        let half: Vec<f64> = ["half_x_68", "half_y_68", "half_theta_68"]
            .map(|c| cells[col(c)].parse().unwrap())
            .to_vec();
        assert!(
            half.iter().all(|h| *h > 0.0) && half[2] <= std::f64::consts::PI,
            "{line}"
        );
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
    // Other settings into the same folder are refused in one line, naming them; so is another posterior
    // calibration, setting by setting against the bundled one it was tracked with.
    let refused_with = |extra: &[&str]| {
        let mut other = track.to_vec();
        other.extend(extra);
        let refused = output(&other);
        assert!(!refused.status.success());
        String::from_utf8_lossy(&refused.stderr).into_owned()
    };
    let stderr = refused_with(&["--press", "0.005"]);
    assert!(
        stderr.contains("other settings (press: \"auto\" -> \"0.005\")"),
        "{stderr}"
    );
    std::fs::write(dir.path().join("kappa.json"), r#"{"fusion_weight": 0.5}"#).unwrap();
    let stderr = refused_with(&["--posterior", "kappa.json"]);
    assert!(
        stderr.contains("pose.posterior.fusion_weight: 0.15 -> 0.5") && stderr.lines().count() == 1,
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
    // Its posteriors are kept beside the rows, so every frame's region is scored against the new poses too.
    assert_eq!(
        again["truth_inside"]["frames"].as_u64(),
        Some(with_contact as u64),
        "{again}"
    );
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

#[test]
fn a_recording_that_never_touches_the_object_is_refused_with_a_reason() {
    // The object 200 mm beside the sensor, through a time-of-flight camera: `recording simulate` warns, and
    // `recording track` refuses in one line (no frame to track) instead of tracking the noise.
    let dir = tempfile::tempdir().unwrap();
    let sim = tnd_in(
        dir.path(),
        &[
            "recording",
            "simulate",
            "far.mcap",
            "--object",
            OBJECT,
            "--pose",
            "0.2,0,0",
            "--rest",
            "1",
            "--ramp",
            "2",
            "--tof",
        ],
    );
    let warned = stderr(&sim);
    assert!(sim.status.success(), "{warned}");
    assert!(
        warned.contains("warning: no contact in any frame"),
        "{warned}"
    );
    let track = tnd_in(
        dir.path(),
        &[
            "recording",
            "track",
            "far.mcap",
            "--object",
            OBJECT,
            "--samples",
            "2",
            "--steps",
            "2",
            "--out",
            "trk",
        ],
    );
    let err = stderr(&track);
    assert!(!track.status.success(), "{err}");
    let last = err.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: far.mcap: no frame shows contact") && last.contains("never touch"),
        "{err}"
    );
    assert!(!dir.path().join("trk/track.csv").exists());
}
