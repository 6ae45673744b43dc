//! One writer per output, end to end: a second `tnd` run on an output another run is writing is refused at once,
//! naming the output and the first run's pid, and the first run's results stay complete; readers of a dataset being
//! written are told so; two processes killed at random points leave a dataset that the next run completes to the
//! very bytes of an uninterrupted one. Also: paths that are not UTF-8 go through.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::cli_common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use cli_common::{stderr, tnd_in, tree};
use tactile_derender::io::lock::OutputLock;

/// A second `tnd train` on the run folder of a running one is refused within a second naming the folder and the
/// first's pid; the first run ends normally (here: stopped by SIGTERM with its checkpoint) and its log holds only
/// its own steps; afterwards the folder is free again.
#[cfg(unix)]
#[test]
fn a_second_train_on_a_running_output_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let o = tnd_in(
        dir.path(),
        &[
            "dataset", "gen", "-q", "--out", "ds", "--pairs", "24", "--seed", "3",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let train = |seed: &str| {
        vec![
            "train",
            "-q",
            "--data",
            "ds",
            "--out",
            "run",
            "--steps",
            "100000",
            "--batch",
            "2",
            "--config",
            "small",
            "--log-every",
            "1",
            "--seed",
            seed,
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>()
    };
    let first = Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args(train("1"))
        .current_dir(dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let log = dir.path().join("run/log.jsonl");
    let t0 = Instant::now();
    while !log.exists() {
        assert!(t0.elapsed().as_secs() < 120, "no training step logged");
        std::thread::sleep(Duration::from_millis(50));
    }
    let t1 = Instant::now();
    let args = train("2");
    let second = tnd_in(
        dir.path(),
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    let refused_in = t1.elapsed();
    let err = stderr(&second);
    assert!(!second.status.success(), "{err}");
    assert!(
        err.contains(&format!(
            "run: in use by another tnd run (pid {})",
            first.id()
        )),
        "{err}"
    );
    assert!(refused_in < Duration::from_secs(5), "{refused_in:?}");
    assert!(!err.contains("starting a new run"), "{err}");
    // SAFETY: signals the child started above.
    unsafe {
        libc::kill(first.id() as libc::pid_t, libc::SIGTERM);
    }
    let out = first.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(err.contains("checkpoint saved in run"), "{err}");
    // One run's steps only: 1, 2, 3, … without a restart from 1 in the middle.
    let steps: Vec<u64> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["step"]
                .as_u64()
                .unwrap()
        })
        .collect();
    assert!(!steps.is_empty());
    assert!(steps.windows(2).all(|w| w[1] == w[0] + 1), "{steps:?}");
    assert!(
        !dir.path().join(".run.tnd-lock").exists(),
        "the lock file outlived its run"
    );
}

/// While another process writes an output (the test holds its lock), every writer command on it is refused at once
/// naming it, and `tnd eval` of a dataset being written says so instead of failing on missing files.
#[test]
fn writers_and_readers_of_an_output_in_use_are_told_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| tnd_in(dir.path(), args);
    let o = run(&[
        "dataset", "gen", "-q", "--out", "ds", "--pairs", "24", "--seed", "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let pid = std::process::id();
    let eval = [
        "eval", "-q", "--data", "ds", "--split", "train", "--model", "small", "--steps", "2",
        "--limit", "1",
    ];
    let cases: Vec<(&str, Vec<&str>)> = vec![
        ("r.jsonl", [&eval[..], &["--records", "r.jsonl"]].concat()),
        ("report", [&eval[..], &["--report", "report"]].concat()),
        (
            "ds2",
            vec!["dataset", "gen", "-q", "--out", "ds2", "--pairs", "24"],
        ),
        (
            "run",
            vec![
                "train", "-q", "--data", "ds", "--out", "run", "--steps", "1",
            ],
        ),
        (
            "sim",
            vec!["sim", "-q", "--object", "cross_w12_s50", "--out", "sim"],
        ),
        (
            "exported",
            vec![
                "model",
                "export",
                "--model",
                "small",
                "--diffusers",
                "exported",
            ],
        ),
        (
            "m.safetensors",
            vec![
                "model",
                "import",
                "--diffusers",
                "exported",
                "--out",
                "m.safetensors",
            ],
        ),
    ];
    for (output, args) in &cases {
        let lock = OutputLock::acquire(&dir.path().join(output)).unwrap();
        let t0 = Instant::now();
        let o = run(args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{output}: {err}");
        assert!(
            err.contains(&format!("{output}: in use by another tnd run (pid {pid})")),
            "{output}: {err}"
        );
        assert!(t0.elapsed() < Duration::from_secs(10), "{output}");
        assert!(!dir.path().join(output).exists(), "{output} written anyway");
        drop(lock);
    }
    // A reader of a dataset being written.
    let lock = OutputLock::acquire(&dir.path().join("ds")).unwrap();
    let o = run(&eval);
    let err = stderr(&o);
    assert!(
        !o.status.success()
            && err.contains(&format!("ds: being written by another tnd run (pid {pid})")),
        "{err}"
    );
    drop(lock);
    let o = run(&eval);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// Property: two `tnd dataset gen` processes on one folder, the first killed (SIGKILL) at a pseudo-random point and
/// the second started at another, never corrupt it: the second is refused while the first lives, or resumes after
/// it died, and one more run completes the dataset to the bytes of an uninterrupted run.
#[cfg(unix)]
#[test]
fn concurrent_writers_killed_at_random_points_leave_a_dataset_that_completes_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let gen = |out: &str| {
        vec![
            "dataset".to_string(),
            "gen".into(),
            "-q".into(),
            "--out".into(),
            out.into(),
            "--pairs".into(),
            "1500".into(),
            "--seed".into(),
            "11".into(),
        ]
    };
    let o = tnd_in(
        dir.path(),
        &gen("clean").iter().map(String::as_str).collect::<Vec<_>>(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let clean = tree(&dir.path().join("clean"));
    // A fixed LCG: the kill points differ between trials and are the same on every run of the test.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next_ms = |max: u64| {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 33) % max
    };
    for trial in 0..4 {
        let out = format!("t{trial}");
        let args = gen(&out);
        let spawn = || {
            Command::new(env!("CARGO_BIN_EXE_tnd"))
                .args(&args)
                .current_dir(dir.path())
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let mut first = spawn();
        std::thread::sleep(Duration::from_millis(next_ms(300)));
        let mut second = spawn();
        std::thread::sleep(Duration::from_millis(next_ms(300)));
        let _ = first.kill();
        let first_out = first.wait_with_output().unwrap();
        std::thread::sleep(Duration::from_millis(next_ms(200)));
        let _ = second.kill();
        let second_out = second.wait_with_output().unwrap();
        for o in [&first_out, &second_out] {
            let err = stderr(o);
            // Refused, killed, or finished: never another failure.
            assert!(
                o.status.success()
                    || o.status.code().is_none()
                    || err.contains("in use by another tnd run"),
                "trial {trial}: {err}"
            );
        }
        let o = tnd_in(
            dir.path(),
            &args.iter().map(String::as_str).collect::<Vec<_>>(),
        );
        assert!(o.status.success(), "trial {trial}: {}", stderr(&o));
        assert!(
            tree(&dir.path().join(&out)) == clean,
            "trial {trial}: the completed dataset differs from an uninterrupted run"
        );
        let leftovers: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.'))
            .collect();
        assert!(leftovers.is_empty(), "trial {trial}: {leftovers:?}");
    }
}

/// An output path that is not UTF-8 (Linux allows any bytes but '/' and NUL): the command writes there and prints
/// its summary instead of panicking after the work is done.
#[cfg(target_os = "linux")]
#[test]
fn outputs_with_non_utf8_names_go_through() {
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().unwrap();
    let name = std::ffi::OsStr::from_bytes(b"out\xff");
    let o = Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args(["sim", "-q", "--object", "cross_w12_s50", "--out"])
        .arg(name)
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join(name).join("imprint.npy").is_file());
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["out"], "out\u{fffd}");
    let o = Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args(["objects", "export"])
        .arg(dir.path().join(name).join("objects"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
}
