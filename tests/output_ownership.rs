//! A command writes only what it owns (issue 53), end to end: for every writer command, user files beside the
//! output and, for an output folder, inside it survive byte for byte — the command refused without `--force`, run
//! with it (the user's files kept, never replaced), and killed with SIGKILL part-way; an output that is one of the
//! command's inputs is refused; two names of one output (a symbolic link) share its lock; impossible sensors and
//! overflowing posterior settings are refused in one line naming the setting.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::cli_common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use cli_common::{stderr, tnd_in, tree};

const OBJECT: &str = "cross_w12_s50";

/// A user's files in `dir`: notes, data, a subfolder.
fn user_files(dir: &Path) {
    std::fs::create_dir_all(dir.join("notes")).unwrap();
    std::fs::write(dir.join("NOTES.txt"), "my notes\n").unwrap();
    std::fs::write(dir.join("notes/run1.txt"), "keep me\n").unwrap();
    std::fs::write(dir.join("data.bin"), [0u8, 1, 2, 3, 255]).unwrap();
}

/// The user's files `before` still there, byte for byte, in `dir`.
fn assert_kept(dir: &Path, before: &[(PathBuf, Vec<u8>)], what: &str) {
    let now = tree(dir);
    for (path, bytes) in before {
        let found = now.iter().find(|(p, _)| p == path);
        assert!(
            found.is_some_and(|(_, b)| b == bytes),
            "{what}: the user's {} was lost or changed",
            path.display()
        );
    }
}

fn ok(dir: &Path, args: &[&str]) {
    let o = tnd_in(dir, args);
    assert!(o.status.success(), "tnd {args:?}: {}", stderr(&o));
}

/// Shared inputs: a short press recording, a 4-pair dataset, one simulated contact, an exported model, records.
fn inputs(dir: &Path) {
    ok(
        dir,
        &[
            "recording",
            "simulate",
            "rec.mcap",
            "--object",
            OBJECT,
            "--rest",
            "2",
            "--ramp",
            "1",
        ],
    );
    ok(
        dir,
        &["dataset", "gen", "-q", "--pairs", "4", "--out", "ds"],
    );
    ok(dir, &["sim", "--object", OBJECT, "--out", "sim0"]);
}

/// `tnd eval` of the first `limit` training pairs of `data` by the ground-truth generator, writing `flag OUT`.
fn eval_args(
    data: &'static str,
    limit: &'static str,
    flag: &'static str,
    out: &'static str,
) -> Vec<&'static str> {
    vec![
        "eval",
        "-q",
        "--data",
        data,
        "--split",
        "train",
        "--limit",
        limit,
        "--model",
        "ground-truth",
        "--no-signature-check",
        flag,
        out,
    ]
}

/// The writer commands with `OUT` for their output folder.
fn folder_commands() -> Vec<(&'static str, Vec<&'static str>)> {
    vec![
        ("sim", vec!["sim", "--object", OBJECT, "--out", "OUT"]),
        (
            "pose",
            vec![
                "pose",
                "--imprint",
                "sim0/imprint.npy",
                "--object",
                OBJECT,
                "--model",
                "small",
                "--samples",
                "2",
                "--steps",
                "2",
                "--out",
                "OUT",
            ],
        ),
        (
            "sample",
            vec![
                "sample",
                "--imprint",
                "sim0/imprint.npy",
                "--model",
                "small",
                "--n",
                "1",
                "--steps",
                "2",
                "--out",
                "OUT",
            ],
        ),
        (
            "frames",
            vec!["recording", "frames", "rec.mcap", "--out", "OUT"],
        ),
        (
            "track",
            vec![
                "recording",
                "track",
                "rec.mcap",
                "--object",
                OBJECT,
                "--model",
                "small",
                "--samples",
                "1",
                "--steps",
                "1",
                "--every",
                "2",
                "--out",
                "OUT",
            ],
        ),
        ("objects export", vec!["objects", "export", "OUT"]),
        (
            "objects generate",
            vec!["objects", "generate", "OUT", "--count", "2"],
        ),
        (
            "model export",
            vec!["model", "export", "--model", "small", "--diffusers", "OUT"],
        ),
        ("eval report", eval_args("ds", "1", "--report", "OUT")),
        (
            "train",
            vec![
                "train", "-q", "--data", "ds", "--steps", "1", "--batch", "2", "--config", "small",
                "--out", "OUT",
            ],
        ),
    ]
}

fn with_out<'a>(args: &[&'a str], out: &'a str) -> Vec<&'a str> {
    args.iter()
        .map(|a| if *a == "OUT" { out } else { a })
        .collect()
}

/// For every command writing a folder: into a folder of the user's it is refused without --force (nothing
/// written), runs with --force beside the user's files and keeps them; the user's files beside the output are
/// untouched throughout; a rerun into its own folder needs no --force.
#[test]
fn every_output_folder_keeps_the_users_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    inputs(d);
    user_files(&d.join("beside"));
    let beside = tree(&d.join("beside"));
    for (name, args) in folder_commands() {
        let out = format!("out_{}", name.replace(' ', "_"));
        let o = d.join(&out);
        user_files(&o);
        let before = tree(&o);
        let refused = tnd_in(d, &with_out(&args, &out));
        assert!(
            !refused.status.success(),
            "{name}: wrote into a user's folder"
        );
        let said = stderr(&refused);
        assert!(
            said.contains("NOTES.txt") && said.contains("--force"),
            "{name}: {said}"
        );
        assert_eq!(tree(&o), before, "{name}: a refused run wrote");
        let mut forced = with_out(&args, &out);
        forced.push("--force");
        let run = tnd_in(d, &forced);
        assert!(run.status.success(), "{name} --force: {}", stderr(&run));
        assert_kept(&o, &before, name);
        assert!(tree(&o).len() > before.len(), "{name}: wrote nothing");
        assert_kept(&d.join("beside"), &beside, name);
    }
    // A rerun into a folder the command made needs no --force (here: one with the user's files recorded).
    ok(d, &with_out(&folder_commands()[0].1, "out_sim"));
    // A user's file with the name of one the command writes is never replaced, even with --force.
    let o = d.join("clash");
    std::fs::create_dir_all(&o).unwrap();
    std::fs::write(o.join("config.json"), "{\"mine\": 1}").unwrap();
    let e = tnd_in(
        d,
        &[
            "model",
            "export",
            "--model",
            "small",
            "--diffusers",
            "clash",
            "--force",
        ],
    );
    assert!(!e.status.success());
    assert!(stderr(&e).contains("config.json"), "{}", stderr(&e));
    assert_eq!(
        std::fs::read(o.join("config.json")).unwrap(),
        b"{\"mine\": 1}"
    );
}

/// For every command writing one file: a file tnd did not write is refused without --force (and never when it is
/// the command's input); the command's own output is replaced without it; user files beside it are untouched.
#[test]
fn every_output_file_replaces_only_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    inputs(d);
    ok(
        d,
        &[
            "model",
            "export",
            "--model",
            "small",
            "--diffusers",
            "exported",
        ],
    );
    let eval = |out: &'static str| eval_args("ds", "1", "--records", out);
    ok(d, &eval("records.jsonl"));
    let files: Vec<(&str, Vec<&str>)> = vec![
        (
            "recording simulate",
            vec![
                "recording",
                "simulate",
                "OUT",
                "--object",
                OBJECT,
                "--rest",
                "1",
                "--ramp",
                "0",
            ],
        ),
        (
            "calibrate",
            vec!["calibrate", "--from", "rec.mcap", "--out", "OUT"],
        ),
        (
            "dataset show",
            vec!["dataset", "show", "ds", "--index", "0", "--out", "OUT"],
        ),
        (
            "model import",
            vec!["model", "import", "--diffusers", "exported", "--out", "OUT"],
        ),
        ("eval records", eval("OUT")),
        (
            "posterior fit",
            vec!["posterior", "--records", "records.jsonl", "--fit", "OUT"],
        ),
    ];
    user_files(&d.join("beside"));
    let beside = tree(&d.join("beside"));
    for (name, args) in files {
        let out = format!("beside/{}.out", name.replace(' ', "_"));
        std::fs::write(d.join(&out), "a user's file\n").unwrap();
        let refused = tnd_in(d, &with_out(&args, &out));
        assert!(!refused.status.success(), "{name}: replaced a user's file");
        assert!(
            stderr(&refused).contains("--force"),
            "{name}: {}",
            stderr(&refused)
        );
        assert_eq!(std::fs::read(d.join(&out)).unwrap(), b"a user's file\n");
        // Its own output, written and then written again, needs no --force.
        let own = format!("{}.own", name.replace(' ', "_"));
        for _ in 0..2 {
            let run = tnd_in(d, &with_out(&args, &own));
            // The posterior fit of one record may fail after the claim; what matters is the claim.
            if name != "posterior fit" {
                assert!(run.status.success(), "{name}: {}", stderr(&run));
            }
        }
        assert_kept(&d.join("beside"), &beside, name);
    }
    // An output that is the command's input is refused, with --force too, and the input stays.
    let rec = std::fs::read(d.join("rec.mcap")).unwrap();
    let e = tnd_in(
        d,
        &[
            "calibrate",
            "--from",
            "rec.mcap",
            "--out",
            "rec.mcap",
            "--force",
        ],
    );
    assert!(
        !e.status.success() && stderr(&e).contains("also an input"),
        "{}",
        stderr(&e)
    );
    assert_eq!(std::fs::read(d.join("rec.mcap")).unwrap(), rec);
    // A real recording (no tnd header) is not replaced by a simulated one without --force.
    std::fs::write(d.join("real.mcap"), b"\x89MCAP0\r\n not ours").unwrap();
    let e = tnd_in(
        d,
        &["recording", "simulate", "real.mcap", "--object", OBJECT],
    );
    assert!(!e.status.success(), "{}", stderr(&e));
    // The same records file twice is one input given twice.
    let e = tnd_in(
        d,
        &["posterior", "--records", "records.jsonl", "records.jsonl"],
    );
    assert!(
        !e.status.success() && stderr(&e).contains("given once"),
        "{}",
        stderr(&e)
    );
}

/// Killed with SIGKILL at several points, a writer leaves the user's files beside and inside its output as they
/// were, and the next run (with --force where the folder held the user's files) completes.
#[cfg(unix)]
#[test]
fn a_killed_writer_never_loses_the_users_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["sim", "--object", OBJECT, "--out", "sim0"]);
    user_files(&d.join("beside"));
    let beside = tree(&d.join("beside"));
    let commands: Vec<Vec<&str>> = vec![
        vec!["dataset", "gen", "-q", "--pairs", "24", "--out", "OUT"],
        vec![
            "model",
            "export",
            "--model",
            "small",
            "--diffusers",
            "OUT",
            "--force",
        ],
        vec!["objects", "generate", "OUT", "--count", "6", "--force"],
    ];
    for (k, args) in commands.iter().enumerate() {
        for (j, ms) in [30u64, 150, 400].iter().enumerate() {
            let out = format!("killed_{k}_{j}");
            let o = d.join(&out);
            let folder_of_user = args.contains(&"--force");
            if folder_of_user {
                user_files(&o);
            }
            let before = if folder_of_user { tree(&o) } else { Vec::new() };
            let mut child = Command::new(env!("CARGO_BIN_EXE_tnd"))
                .args(with_out(args, &out))
                .current_dir(d)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap();
            std::thread::sleep(Duration::from_millis(*ms));
            let _ = child.kill();
            let _ = child.wait();
            assert_kept(&d.join("beside"), &beside, "killed run");
            if folder_of_user {
                assert_kept(&o, &before, "killed run");
            }
            ok(d, &with_out(args, &out));
            if folder_of_user {
                assert_kept(&o, &before, "the run after a kill");
            }
        }
    }
}

/// Two names of one output — the folder and a symbolic link to it — are one output: the second writer is refused
/// while the first holds it, and a records file given through a link stays a link.
#[cfg(unix)]
#[test]
fn a_symbolic_link_is_the_output_it_names() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("dsC")).unwrap();
    std::os::unix::fs::symlink(d.join("dsC"), d.join("lnkC")).unwrap();
    let held = tactile_derender::io::lock::OutputLock::acquire(&d.join("dsC")).unwrap();
    let o = tnd_in(
        d,
        &["dataset", "gen", "-q", "--pairs", "2", "--out", "lnkC"],
    );
    assert!(!o.status.success(), "written through a link while in use");
    assert!(stderr(&o).contains("in use"), "{}", stderr(&o));
    drop(held);
    ok(
        d,
        &["dataset", "gen", "-q", "--pairs", "4", "--out", "lnkC"],
    );
    assert!(d.join("dsC/manifest.json").is_file());
    let eval =
        |records: &'static str, limit: &'static str| eval_args("dsC", limit, "--records", records);
    ok(d, &eval("r_real.jsonl", "1"));
    std::os::unix::fs::symlink(d.join("r_real.jsonl"), d.join("r_link.jsonl")).unwrap();
    // Resumed (one more pair) through the link.
    ok(d, &eval("r_link.jsonl", "2"));
    assert!(std::fs::symlink_metadata(d.join("r_link.jsonl"))
        .unwrap()
        .file_type()
        .is_symlink());
    // A reader of a records file an evaluation is still writing is told so, not given the partial file.
    let held = tactile_derender::io::lock::OutputLock::acquire(&d.join("r_real.jsonl")).unwrap();
    let o = tnd_in(d, &["posterior", "--records", "r_link.jsonl"]);
    assert!(
        !o.status.success() && stderr(&o).contains("being written"),
        "{}",
        stderr(&o)
    );
    drop(held);
    // An empty records file says it is empty.
    std::fs::write(d.join("empty.jsonl"), "").unwrap();
    let o = tnd_in(d, &["posterior", "--records", "empty.jsonl"]);
    assert!(
        !o.status.success() && stderr(&o).contains("empty"),
        "{}",
        stderr(&o)
    );
    assert!(std::fs::read_to_string(d.join("r_real.jsonl"))
        .unwrap()
        .contains("settings"));
}

/// Sensors that cannot exist are refused in one line naming the setting, from flags and from sensor files alike;
/// so are posterior settings that overflow.
#[test]
fn impossible_sensors_and_overflowing_posteriors_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: [(&[&str], &str); 8] = [
        (
            &["--resolution", "18446744073709551615x8"],
            "must look like 64x64",
        ),
        (&["--inflation", "10"], "elastomer.inflation"),
        (&["--camera-offset", "100"], "mount.position"),
        (&["--noise-std", "10"], "signature.noise_std"),
        (&["--shadow-px", "100000"], "signature.shadow_px"),
        (&["--footprint=1e308x0.08"], "1e308 m"),
        (&["--sensor-yaw", "NaN"], "--sensor-yaw"),
        (&["--resolution", "2048x2048"], "larger than 1024"),
    ];
    for (flags, setting) in cases {
        let mut args = vec!["sim", "--object", OBJECT, "--out", "s"];
        args.extend_from_slice(flags);
        let o = tnd_in(d, &args);
        assert!(!o.status.success(), "{flags:?} accepted");
        let said = stderr(&o);
        assert!(
            said.contains(setting) && said.lines().count() <= 2,
            "{flags:?}: {said}"
        );
    }
    // The camera inside the membrane, and a shadow of 1e9 pixels (it used to spin for minutes), from sensor files.
    let files = [
        (
            r#"{"mount": {"position": [0, 0, 0.01]}}"#,
            "behind the membrane's base",
        ),
        (r#"{"signature": {"shadow_px": 1e9}}"#, "shadow_px"),
    ];
    for (text, expected) in files {
        std::fs::write(d.join("sensor.json"), text).unwrap();
        let o = tnd_in(
            d,
            &[
                "sim",
                "--object",
                OBJECT,
                "--sensor",
                "sensor.json",
                "--out",
                "s",
            ],
        );
        assert!(
            !o.status.success() && stderr(&o).contains(expected),
            "{}",
            stderr(&o)
        );
    }
}

/// What a fresh round of hostile probes found, each refused in a line instead of data loss, a hang or a blow-up:
/// a user's folder that merely holds files of tnd's names is not taken for tnd's (and a refused run does not mark it
/// so), a model import may not replace its input's weights, a FIFO is no recording or records file, and a press
/// sequence is not an hour of frames.
#[cfg(unix)]
#[test]
fn hostile_inputs_are_refused_in_a_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let users = d.join("mine");
    std::fs::create_dir(&users).unwrap();
    std::fs::write(users.join("objects.json"), "precious").unwrap();
    std::fs::write(users.join("manifest.json"), "{}").unwrap();
    std::fs::write(users.join("depth.npy"), "precious").unwrap();
    let before = tree(&users);
    for args in [
        vec!["objects", "export", "mine"],
        vec!["dataset", "gen", "-q", "--pairs", "4", "--out", "mine"],
        vec!["sim", "--object", OBJECT, "--out", "mine"],
    ] {
        let o = tnd_in(d, &args);
        assert!(!o.status.success(), "{args:?} wrote into the user's folder");
        assert!(stderr(&o).contains("did not write"), "{}", stderr(&o));
        assert_eq!(tree(&users), before, "{args:?}");
    }
    ok(
        d,
        &["model", "export", "--model", "small", "--diffusers", "m"],
    );
    let weights = d.join("m/diffusion_pytorch_model.safetensors");
    let kept = std::fs::read(&weights).unwrap();
    let o = tnd_in(
        d,
        &[
            "model",
            "import",
            "--diffusers",
            "m",
            "--out",
            "m/diffusion_pytorch_model.safetensors",
            "--force",
        ],
    );
    assert!(
        !o.status.success() && stderr(&o).contains("part of an input"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(&weights).unwrap(), kept);
    let fifo = d.join("fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    for args in [
        vec!["recording", "info", "fifo"],
        vec!["posterior", "--records", "fifo"],
    ] {
        let o = tnd_in(d, &args);
        assert!(
            !o.status.success() && stderr(&o).contains("FIFO"),
            "{args:?}: {}",
            stderr(&o)
        );
    }
    let o = tnd_in(
        d,
        &[
            "recording",
            "simulate",
            "big.mcap",
            "--object",
            OBJECT,
            "--rest",
            "100000000",
        ],
    );
    assert!(
        !o.status.success() && stderr(&o).contains("3000 frames"),
        "{}",
        stderr(&o)
    );
    // --rerun FILE is an output like --out: not a user's file, not the command's input.
    std::fs::write(d.join("mine.rrd"), "mine").unwrap();
    std::fs::write(d.join("notes.txt"), "mine").unwrap();
    for file in ["mine.rrd", "notes.txt"] {
        let o = tnd_in(
            d,
            &["sim", "--object", OBJECT, "--out", "s", "--rerun", file],
        );
        assert!(
            !o.status.success() && stderr(&o).contains("--force"),
            "{}",
            stderr(&o)
        );
        assert_eq!(std::fs::read(d.join(file)).unwrap(), b"mine");
    }
    // `new/..` is the folder it names: the current folder, refused (it was written into, --force and all).
    let o = tnd_in(
        d,
        &[
            "sim",
            "--object",
            OBJECT,
            "--out",
            "nothing_here/..",
            "--force",
        ],
    );
    assert!(
        !o.status.success() && stderr(&o).contains("current folder"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("nothing_here").exists());
    // A count that only exhausts memory (10^12 pairs allocated terabytes up front).
    let o = tnd_in(
        d,
        &["dataset", "gen", "--pairs", "1000000000000", "--out", "big"],
    );
    assert!(
        !o.status.success() && stderr(&o).contains("more than"),
        "{}",
        stderr(&o)
    );
}
