//! `tnd model verify` and `tnd sample` end to end on the small diffusers fixture (8 × 8 model), the sampling API's
//! determinism, batch layout and cancellation, and resumable runs of `tnd train` and `tnd eval --records`.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::process::Command;

use tactile_derender::image::Image;
use tactile_derender::io::npy;
use tactile_derender::model::{DiffusionModel, ModelError, SamplerKind};

const MODEL: &str = "tests/fixtures/unet_small/unet_ref.safetensors";

fn tnd(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args(args)
        .output()
        .expect("run tnd")
}

/// `tnd` run in `dir`, as a user in that directory would.
fn tnd_in(dir: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tnd")
}

#[test]
fn verify_prints_max_abs_diff() {
    let out = tnd(&[
        "model",
        "verify",
        "--model",
        MODEL,
        "--io",
        "tests/fixtures/unet_small/unet_ref_io.safetensors",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["max_abs_diff"].as_f64().unwrap() <= 1e-4);
    // A mismatched reference (other architecture's io) is reported as an error naming the file, not a panic.
    let out = tnd(&[
        "model",
        "verify",
        "--model",
        MODEL,
        "--io",
        "tests/fixtures/sched_ref.safetensors",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("sched_ref.safetensors"));
}

#[test]
fn sample_writes_deterministic_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let imprint =
        Image::from_vec(8, 8, (0..64).map(|i| 0.0002 * (i % 8) as f32).collect()).unwrap();
    let ip = dir.path().join("imprint.npy");
    npy::write_image(&ip, &imprint).unwrap();
    let run = |out: &str| {
        let o = dir.path().join(out);
        let r = tnd(&[
            "sample",
            "--model",
            MODEL,
            "--imprint",
            ip.to_str().unwrap(),
            "--n",
            "4",
            "--sampler",
            "ddim",
            "--steps",
            "5",
            "--eta",
            "0.5",
            "--seed",
            "3",
            "--out",
            o.to_str().unwrap(),
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        o
    };
    let (a, b) = (run("a"), run("b"));
    for f in [
        "samples.npy",
        "mean.npy",
        "std.npy",
        "contact_probability.npy",
        "grid.png",
        "grid.svg",
    ] {
        assert!(a.join(f).is_file(), "{f}");
    }
    let sa = std::fs::read(a.join("samples.npy")).unwrap();
    assert_eq!(
        sa,
        std::fs::read(b.join("samples.npy")).unwrap(),
        "same seed, same samples"
    );
    let samples = npy::read(&a.join("samples.npy")).unwrap();
    assert_eq!(samples.shape, vec![4, 8, 8]);
    let mean = npy::read_image(&a.join("mean.npy")).unwrap();
    // The mean over the samples that mark the pixel as contact (a positive depth), 0 where none does.
    for p in 0..64 {
        let valid: Vec<f32> = (0..4)
            .map(|k| samples.data[k * 64 + p])
            .filter(|&v| v > 0.0)
            .collect();
        let m = if valid.is_empty() {
            0.0
        } else {
            valid.iter().sum::<f32>() / valid.len() as f32
        };
        assert!(
            (m - mean.data[p]).abs() < 1e-6,
            "pixel {p}: {m} vs {}",
            mean.data[p]
        );
    }
    // Wrong imprint size: a clear error.
    let small = dir.path().join("small.npy");
    npy::write_image(&small, &Image::filled(4, 4, 0.0)).unwrap();
    let r = tnd(&[
        "sample",
        "--model",
        MODEL,
        "--imprint",
        small.to_str().unwrap(),
        "--out",
        "x",
    ]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("8x8"));
}

#[test]
fn sampling_api_batches_seeds_and_cancels() {
    let model = DiffusionModel::load(Path::new(MODEL)).unwrap();
    assert_eq!(model.resolution(), (8, 8));
    let imprint = Image::filled(8, 8, 0.001);
    let kind = SamplerKind::Ddim {
        steps: 4,
        eta: 0.0,
        spacing: Default::default(),
    };
    let mut calls = Vec::new();
    let a = model.sample(&imprint, 3, kind, 7, &mut |i, n| {
        calls.push((i, n));
        true
    });
    let a = a.unwrap();
    assert_eq!(calls, vec![(1, 4), (2, 4), (3, 4), (4, 4)]);
    assert_eq!(a.len(), 3);
    assert_ne!(a[0], a[1], "different samples within a batch");
    let b = model
        .sample(&imprint, 3, kind, 7, &mut |_, _| true)
        .unwrap();
    assert_eq!(a, b, "same seed, same samples");
    let c = model
        .sample(&imprint, 3, kind, 8, &mut |_, _| true)
        .unwrap();
    assert_ne!(a, c, "another seed, other samples");
    let e = model
        .sample(&imprint, 3, SamplerKind::Ddpm, 7, &mut |i, _| i < 2)
        .err()
        .unwrap();
    assert!(matches!(e, ModelError::Cancelled));
    let mut nan = imprint.clone();
    nan.data[5] = f32::NAN;
    let e = model
        .sample(&nan, 1, kind, 7, &mut |_, _| true)
        .err()
        .unwrap();
    assert!(matches!(e, ModelError::NonFinite { .. }), "{e}");
}

#[test]
fn a_batch_larger_than_one_forward_chunk_gives_each_sample_as_drawn_alone() {
    // Deterministic DDIM: a sample depends only on its own initial noise, and the first k samples of a batch of n
    // draw the same noise as a batch of k. Across the U-Net's forward chunks (16 samples) no sample may see another.
    use tactile_derender::model::diffusion::FORWARD_CHUNK;
    let model = DiffusionModel::load(Path::new(MODEL)).unwrap();
    let imprint = Image::filled(8, 8, 0.001);
    let kind = SamplerKind::Ddim {
        steps: 3,
        eta: 0.0,
        spacing: Default::default(),
    };
    let n = FORWARD_CHUNK + 3;
    let many = model
        .sample(&imprint, n, kind, 5, &mut |_, _| true)
        .unwrap();
    let few = model
        .sample(&imprint, FORWARD_CHUNK + 1, kind, 5, &mut |_, _| true)
        .unwrap();
    assert_eq!(many.len(), n);
    for (k, (a, b)) in many.iter().zip(&few).enumerate() {
        let worst = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-6, "sample {k} differs by {worst} m");
    }
}

#[test]
fn model_can_move_to_a_worker_thread() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<DiffusionModel>();
    let model = DiffusionModel::load(Path::new(MODEL)).unwrap();
    let n = std::thread::spawn(move || {
        model.sample(
            &Image::filled(8, 8, 0.0),
            2,
            SamplerKind::Ddim {
                steps: 2,
                eta: 0.0,
                spacing: Default::default(),
            },
            0,
            &mut |_, _| true,
        )
    })
    .join()
    .unwrap()
    .unwrap()
    .len();
    assert_eq!(n, 2);
}

#[test]
fn sample_uses_the_bundled_model_by_default_and_decodes_no_contact_to_zero() {
    let dir = tempfile::tempdir().unwrap();
    // A 10 mm dent in the middle of a 64 x 64 imprint (the bundled model's resolution).
    let imprint = Image::from_vec(
        64,
        64,
        (0..64 * 64)
            .map(|i| {
                let (x, y) = ((i % 64) as f32 - 32.0, (i / 64) as f32 - 32.0);
                if x * x + y * y < 100.0 {
                    0.01
                } else {
                    0.0
                }
            })
            .collect(),
    )
    .unwrap();
    let ip = dir.path().join("imprint.npy");
    npy::write_image(&ip, &imprint).unwrap();
    let out = dir.path().join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_tnd"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["sample", "--imprint", ip.to_str().unwrap(), "--n", "2"])
        .args(["--sampler", "ddim", "--steps", "3", "--seed", "1"])
        .args(["--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let model = DiffusionModel::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/assets/models/default.safetensors"
    )))
    .unwrap();
    let cut = model.config().tactile_derender.contact_min_depth_m;
    let samples = npy::read(&out.join("samples.npy")).unwrap();
    assert_eq!(samples.shape, vec![2, 64, 64]);
    // Every pixel is either "no contact" (exactly 0) or an in-contact depth at or beyond the cut.
    assert!(samples.data.iter().all(|&d| d == 0.0 || d >= cut));
    assert!(samples.data.contains(&0.0));

    // `--model small`, from a directory without such a file: the bundled small model, which is the committed
    // file's weights and its narrower config (the default is stored in f16 and read as f32).
    let small = DiffusionModel::load(Path::new("small")).unwrap();
    let file = DiffusionModel::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/assets/models/small.safetensors"
    )))
    .unwrap();
    assert_eq!(small.config(), file.config());
    assert_eq!(small.config().block_out_channels, vec![16, 32, 64, 64]);
    assert_eq!(model.config().block_out_channels, vec![32, 64, 96, 96]);
    let out = dir.path().join("out_small");
    let o = Command::new(env!("CARGO_BIN_EXE_tnd"))
        .current_dir(dir.path())
        .args([
            "sample",
            "--model",
            "small",
            "--imprint",
            ip.to_str().unwrap(),
        ])
        .args([
            "--n",
            "1",
            "--sampler",
            "ddim",
            "--steps",
            "3",
            "--seed",
            "1",
        ])
        .args(["--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let samples = npy::read(&out.join("samples.npy")).unwrap();
    assert_eq!(samples.shape, vec![1, 64, 64]);
    assert!(samples.data.iter().all(|&d| d == 0.0 || d >= cut));
}

/// `tnd train` as a user runs it: a new run says so and trains the bundled default architecture; the same command
/// resumes (and says so); a resume with other data or another batch is refused, naming what differs.
#[test]
fn train_starts_resumes_and_refuses_other_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| tnd_in(dir.path(), args);
    for (out, seed) in [("ds", "3"), ("ds2", "4")] {
        let o = run(&[
            "dataset", "gen", "-q", "--out", out, "--pairs", "24", "--seed", seed,
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    // (succeeded, stderr) of one `tnd train` in the same run directory.
    let train = |data: &str, steps: &str, batch: &str| {
        let o = run(&[
            "train", "-q", "--data", data, "--out", "run", "--steps", steps, "--batch", batch,
        ]);
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (ok, err) = train("ds", "1", "2");
    assert!(ok, "{err}");
    assert!(
        err.contains("run: no checkpoint there, starting a new run"),
        "{err}"
    );
    let (_, cfg) =
        tactile_derender::model::checkpoint::locate(&dir.path().join("run/model.safetensors"))
            .unwrap();
    let (_, bundled) = tactile_derender::model::checkpoint::locate(Path::new("default")).unwrap();
    assert_eq!(cfg.block_out_channels, bundled.block_out_channels);
    // The run directory given as a model points to the model in it.
    let e = tactile_derender::model::checkpoint::locate(&dir.path().join("run"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("a training run, not a model; its model is ")
            && e.ends_with("run/model.safetensors"),
        "{e}"
    );
    let (ok, err) = train("ds", "2", "2");
    assert!(ok, "{err}");
    assert!(
        err.contains("resuming the run from its last checkpoint"),
        "{err}"
    );
    let (ok, err) = train("ds2", "3", "2");
    assert!(!ok);
    assert!(
        err.contains("started with --data") && err.contains("ds2"),
        "{err}"
    );
    let (ok, err) = train("ds", "3", "1");
    assert!(!ok);
    assert!(err.contains("--batch 2 (now 1)"), "{err}");
    // Two datasets train as one (one sensor's recordings, imported one by one); the run remembers both.
    let o = run(&[
        "train", "-q", "--data", "ds", "ds2", "--out", "both", "--steps", "1", "--batch", "2",
        "--config", "small",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let inputs: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("both/run_inputs.json")).unwrap(),
    )
    .unwrap();
    let data: Vec<&str> = inputs["data"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(
        data.len() == 2 && data[0].ends_with("ds") && data[1].ends_with("ds2"),
        "{data:?}"
    );

    // SIGTERM (a scheduler's kill, Ctrl-C's SIGINT alike) stops a long run after its step with a checkpoint to resume
    // from, long before the minute between checkpoints is up.
    let child = Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args([
            "train",
            "-q",
            "--data",
            "ds",
            "--out",
            "long",
            "--steps",
            "100000",
            "--batch",
            "2",
            "--config",
            "small",
            "--log-every",
            "1",
        ])
        .current_dir(dir.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let log = dir.path().join("long/log.jsonl");
    let t0 = std::time::Instant::now();
    while !log.exists() {
        assert!(t0.elapsed().as_secs() < 120, "no training step logged");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // SAFETY: signals the child started above.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("checkpoint saved in long; the same command resumes"),
        "{err}"
    );
    assert!(t0.elapsed().as_secs() < 60, "{err}");
    let step: u64 = err
        .split("interrupted at step ")
        .nth(1)
        .and_then(|r| r.split(':').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{err}"));
    let o = run(&[
        "train",
        "-q",
        "--data",
        "ds",
        "--out",
        "long",
        "--steps",
        &(step + 1).to_string(),
        "--batch",
        "2",
        "--config",
        "small",
        "--log-every",
        "1",
    ]);
    let resumed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(resumed["resumed_from"].as_u64(), Some(step), "{resumed}");
}

/// `tnd eval --records` as a long run is used: a run stopped after two pairs and started again with a larger
/// `--limit` scores only the others and ends with the very records and tables of an uninterrupted run; a rerun with
/// another seed, or into a records file of an earlier format, is refused and leaves the file as it was.
#[test]
fn eval_records_resume_to_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| tnd_in(dir.path(), args);
    let o = run(&[
        "dataset", "gen", "-q", "--out", "ds", "--pairs", "24", "--seed", "3",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let eval = |limit: &str, seed: &str, records: &str| {
        let o = run(&[
            "eval",
            "-q",
            "--json",
            "--data",
            "ds",
            "--split",
            "train",
            "--model",
            "small",
            "--steps",
            "2",
            "--limit",
            limit,
            "--seed",
            seed,
            "--records",
            records,
        ]);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        let json = serde_json::from_slice::<serde_json::Value>(&o.stdout).ok();
        (o.status.success(), json, err)
    };
    let (ok, _, err) = eval("2", "0", "r.jsonl");
    assert!(ok, "{err}");
    let (ok, resumed, err) = eval("4", "0", "r.jsonl");
    assert!(ok, "{err}");
    assert!(
        err.contains("r.jsonl: 2 of the 4 pairs of train scored by an earlier run"),
        "{err}"
    );
    let (ok, fresh, err) = eval("4", "0", "fresh.jsonl");
    assert!(ok, "{err}");
    assert!(!err.contains("earlier run"), "{err}");
    let (resumed, fresh) = (resumed.unwrap(), fresh.unwrap());
    assert_eq!(resumed["pairs"], 4);
    for key in ["model", "baseline", "breakdown"] {
        assert_eq!(resumed[key], fresh[key], "{key}");
    }
    let read = |name: &str| std::fs::read_to_string(dir.path().join(name)).unwrap();
    let records = read("r.jsonl");
    assert_eq!(records, read("fresh.jsonl"));
    // A settings line and one line per pair, each naming its split and index.
    let lines: Vec<serde_json::Value> = records
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 5);
    assert_eq!(lines[0]["settings"]["seed"], 0);
    assert_eq!(lines[4]["index"], 3);
    assert_eq!(lines[4]["split"], "train");
    assert!(lines[4]["record"]["model"]["depth"]["ssim"].is_number());
    // Another seed: refused, naming it; the records stay.
    let (ok, _, err) = eval("4", "1", "r.jsonl");
    assert!(!ok);
    assert!(
        err.contains("r.jsonl: holds the records of other settings (seed: 0 -> 1)"),
        "{err}"
    );
    assert_eq!(read("r.jsonl"), records);
    // A records file of the earlier format (no settings line) is not overwritten.
    let old = "{\"split\":\"train\",\"record\":{}}\n";
    std::fs::write(dir.path().join("old.jsonl"), old).unwrap();
    let (ok, _, err) = eval("1", "0", "old.jsonl");
    assert!(!ok);
    assert!(
        err.contains("old.jsonl: exists and was not written by this command"),
        "{err}"
    );
    assert_eq!(read("old.jsonl"), old);
}

/// `tnd eval --device`: `cpu` scores exactly as the default does; a name that is no device is refused in one line
/// that names it, and nothing is scored.
#[test]
fn eval_runs_on_the_device_it_is_given() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| tnd_in(dir.path(), args);
    let o = run(&[
        "dataset", "gen", "-q", "--out", "ds", "--pairs", "12", "--seed", "3",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let eval = |device: &[&str]| {
        let mut args = vec![
            "eval", "-q", "--json", "--data", "ds", "--split", "train", "--model", "small",
            "--steps", "2", "--limit", "2",
        ];
        args.extend_from_slice(device);
        run(&args)
    };
    let default = eval(&[]);
    let cpu = eval(&["--device", "cpu"]);
    assert!(default.status.success() && cpu.status.success());
    let json =
        |o: &std::process::Output| serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap();
    for key in ["model", "baseline"] {
        assert_eq!(json(&default)[key], json(&cpu)[key], "{key}");
    }
    let bad = eval(&["--device", "gpu0"]);
    assert!(!bad.status.success());
    assert!(bad.stdout.is_empty());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("gpu0") && err.contains("cuda:N"), "{err}");
}

/// A sensor whose contact lies nearer the camera than the default's (inflation 15 mm, camera 25 mm behind the base):
/// `tnd train` from scratch fits the model's target mapping to it and says so (the default's 50 mm contact cut would
/// make every sample of such a model "no contact"); a fine-tune of the default, whose mapping cannot hold it, is
/// refused before anything is written; `tnd eval` with the default warns that it does not fit.
#[test]
fn train_fits_the_mapping_to_a_shallow_sensor_and_eval_warns_of_a_model_that_does_not() {
    use tactile_derender::dataset::{stats, Dataset, SplitName};
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| tnd_in(dir.path(), args);
    let o = run(&[
        "dataset",
        "gen",
        "-q",
        "--out",
        "ds",
        "--pairs",
        "24",
        "--seed",
        "1",
        "--inflation",
        "0.015",
        "--camera-offset",
        "0.025",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let ds = Dataset::open(dir.path().join("ds")).unwrap();
    let [lo, hi] = stats::target_range_sample(&ds, SplitName::Train, 1000)
        .unwrap()
        .unwrap();
    assert!(
        hi < 0.05,
        "the sensor's contact lies nearer than the default's cut: {lo}–{hi}"
    );

    let o = run(&[
        "train", "-q", "--data", "ds", "--out", "run", "--steps", "1", "--batch", "2",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("fitted to this sensor"), "{err}");
    let model = DiffusionModel::load(&dir.path().join("run/model.safetensors")).unwrap();
    let td = &model.config().tactile_derender;
    assert!(
        td.contact_min_depth_m < lo,
        "cut {} vs contact from {lo}",
        td.contact_min_depth_m
    );
    assert!(td.target.inverse(1.0) > hi && td.target.inverse(-1.0) <= 0.0);

    let o = run(&[
        "train", "-q", "--data", "ds", "--out", "ft", "--steps", "1", "--init", "default",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success()
            && err.contains("does not fit this sensor")
            && err.contains("from scratch"),
        "{err}"
    );
    assert!(!dir.path().join("ft").exists());

    let o = run(&[
        "eval",
        "-q",
        "--data",
        "ds",
        "--split",
        "unseen_objects",
        "--limit",
        "1",
        "--steps",
        "2",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("does not fit this dataset's sensor"), "{err}");
}

/// `tnd model export` into a folder that already holds a model is refused (it may be another model's only copy);
/// `--force` replaces it.
#[test]
fn export_refuses_to_replace_a_model_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| tnd_in(dir.path(), args);
    let o = run(&["model", "export", "--model", "small", "--diffusers", "out"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let first = std::fs::read(dir.path().join("out/diffusion_pytorch_model.safetensors")).unwrap();
    let o = run(&["model", "export", "--diffusers", "out"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("already holds a model") && err.contains("--force"),
        "{err}"
    );
    let kept = std::fs::read(dir.path().join("out/diffusion_pytorch_model.safetensors")).unwrap();
    assert_eq!(first, kept);
    let o = run(&["model", "export", "--diffusers", "out", "--force"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let replaced =
        std::fs::read(dir.path().join("out/diffusion_pytorch_model.safetensors")).unwrap();
    assert_ne!(first, replaced);
}
