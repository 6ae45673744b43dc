//! End-to-end checks of the dataset stage: determinism across thread counts, resume after an interruption (in
//! process and with kill -9 of the real binary), the paper's splits, reader values against an independent
//! re-simulation, mini-batches, and one error per kind of damage (truncated shard, wrong checksum, wrong dtype,
//! unknown version, other configuration). Also writes the dataset the numpy round trip (`tests/dataset_numpy_check.py`,
//! run by `.ci/run`) reads back.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::dataset_common;

use dataset_common::{gen_config, run, sim_config, small_set};

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use tactile_derender::dataset::manifest::{MANIFEST_FILE, PROGRESS_FILE};
use tactile_derender::dataset::npz::{self, ArrayData};
use tactile_derender::dataset::shard::{sha256_hex, IMAGE_ARRAYS};
use tactile_derender::dataset::{generate, Dataset, DatasetError, GenConfig, SplitName};
use tactile_derender::objects::Split;
use tactile_derender::sensor::Scene;
use tactile_derender::sim::{PreparedObject, Simulator};

/// Every file under `dir`: relative path -> bytes.
fn tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

pub(crate) fn assert_same_tree(a: &Path, b: &Path) {
    let (ta, tb) = (tree(a), tree(b));
    assert_eq!(
        ta.keys().collect::<Vec<_>>(),
        tb.keys().collect::<Vec<_>>(),
        "file lists differ"
    );
    for (k, v) in &ta {
        assert!(v == &tb[k], "{} differs", k.display());
    }
}

#[test]
fn output_is_byte_identical_for_one_and_two_threads() {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let cfg = gen_config(40);
    run(&tmp.path().join("a"), &set, &cfg, 1);
    run(&tmp.path().join("b"), &set, &cfg, 2);
    assert_same_tree(&tmp.path().join("a"), &tmp.path().join("b"));
    // Another seed gives other data.
    let other = GenConfig { seed: 12, ..cfg };
    run(&tmp.path().join("c"), &set, &other, 2);
    assert_ne!(
        std::fs::read(tmp.path().join("a/shards/train-00000.npz")).unwrap(),
        std::fs::read(tmp.path().join("c/shards/train-00000.npz")).unwrap()
    );
}

#[test]
fn interrupted_run_resumes_to_the_uninterrupted_result() {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let cfg = gen_config(56);
    let full = tmp.path().join("full");
    run(&full, &set, &cfg, 2);
    assert!(!full.join(PROGRESS_FILE).exists());

    // Interrupt: the progress callback panics after 40 pairs (mid chunk 2), like a kill between two pairs.
    let part = tmp.path().join("part");
    let done = std::sync::atomic::AtomicUsize::new(0);
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        generate(&part, &sim_config(), &set, &cfg, &|n| {
            if done.fetch_add(n, std::sync::atomic::Ordering::SeqCst) + n >= 40 {
                panic!("simulated interruption");
            }
        })
    }));
    assert!(result.is_err());
    assert!(part.join(PROGRESS_FILE).exists() && !part.join(MANIFEST_FILE).exists());
    assert!(matches!(
        Dataset::open(&part),
        Err(DatasetError::NotADataset { .. })
    ));
    // Damage a finished shard and leave a half-written temporary file, as a kill -9 during a write would.
    let first = part.join("shards/train-00000.npz");
    let bytes = std::fs::read(&first).unwrap();
    std::fs::write(&first, &bytes[..bytes.len() / 2]).unwrap();
    std::fs::write(part.join("shards/.train-00002.npz.tmp.99999"), b"partial").unwrap();

    let report = generate(&part, &sim_config(), &set, &cfg, &|_| {}).unwrap();
    assert!(report.kept_chunks >= 1, "{report:?}");
    assert!(report.generated < cfg.pairs, "{report:?}");
    assert_same_tree(&full, &part);
    // Running the finished command again changes nothing, also after a kill between writing manifest.json and
    // removing progress.json, or during a write.
    std::fs::write(part.join(PROGRESS_FILE), b"{}").unwrap();
    std::fs::write(part.join(".manifest.json.tmp.99999"), b"{").unwrap();
    let again = generate(&part, &sim_config(), &set, &cfg, &|_| {}).unwrap();
    assert!(again.already_complete && again.generated == 0);
    assert_same_tree(&full, &part);
    // A finished dataset with one shard flipped by a byte and another deleted: the same command simulates those
    // two chunks again, and only them, and the dataset is the uninterrupted one again.
    let flipped = part.join("shards/train-00001.npz");
    let mut bytes = std::fs::read(&flipped).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    std::fs::write(&flipped, bytes).unwrap();
    std::fs::remove_file(part.join("shards/train-00002.npz")).unwrap();
    assert!(Dataset::open(&part).and_then(|d| d.verify()).is_err());
    let repaired = generate(&part, &sim_config(), &set, &cfg, &|_| {}).unwrap();
    assert!(!repaired.already_complete);
    assert_eq!(repaired.kept_chunks, cfg.chunks() - 2, "{repaired:?}");
    assert!(
        repaired.generated > 0 && repaired.generated <= 2 * cfg.shard_pairs,
        "{repaired:?}"
    );
    assert_same_tree(&full, &part);
}

#[test]
fn kill_dash_nine_of_the_binary_then_rerun_gives_the_same_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let tnd = env!("CARGO_BIN_EXE_tnd");
    let args = |out: &Path| {
        vec![
            "dataset".to_string(),
            "gen".into(),
            "--out".into(),
            out.display().to_string(),
            "--pairs".into(),
            "600".into(),
            "--shard-pairs".into(),
            "16".into(),
            "--resolution".into(),
            "32x24".into(),
            "--objects".into(),
            tmp.path().join("set").display().to_string(),
            "--seed".into(),
            "5".into(),
        ]
    };
    small_set(&tmp.path().join("set"));
    let full = tmp.path().join("full");
    let status = std::process::Command::new(tnd)
        .args(args(&full))
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let part = tmp.path().join("part");
    // Kill at two moments (whatever has happened by then: a run of 600 pairs takes seconds on 2 cores), re-running
    // the same command in between.
    let mut interrupted = 0;
    for delay_ms in [250, 600] {
        let mut child = std::process::Command::new(tnd)
            .args(args(&part))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        interrupted += usize::from(!part.join(MANIFEST_FILE).exists());
    }
    eprintln!("runs killed before finishing: {interrupted} of 2");
    let status = std::process::Command::new(tnd)
        .args(args(&part))
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    assert_same_tree(&full, &part);
}

#[test]
fn splits_are_disjoint_follow_object_splits_and_hold_out_one_in_ten() {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let cfg = gen_config(150);
    let out = tmp.path().join("d");
    run(&out, &set, &cfg, 2);
    let ds = Dataset::open(&out).unwrap();
    let mut seen_indices = BTreeSet::new();
    let mut per_object: BTreeMap<String, [usize; 3]> = BTreeMap::new();
    for split in SplitName::ALL {
        for i in 0..ds.len(split) {
            let m = ds.pair(split, i).unwrap().meta;
            assert_eq!((m.split, m.split_index), (split, i));
            assert!(
                seen_indices.insert(m.index),
                "pair {} in two splits",
                m.index
            );
            let unseen = set.find(&m.object).unwrap().split == Split::Unseen;
            assert_eq!(
                unseen,
                split == SplitName::UnseenObjects,
                "{} in {split}",
                m.object
            );
            per_object.entry(m.object).or_default()[split.code()] += 1;
        }
    }
    assert_eq!(seen_indices, (0..cfg.pairs).collect::<BTreeSet<_>>());
    for (name, [train, poses, _]) in per_object {
        let n = train + poses;
        if set.find(&name).unwrap().split == Split::Seen {
            assert!(
                poses == n / 10 || poses == n / 10 + 1,
                "{name}: {poses} of {n} held out"
            );
        }
    }
}

#[test]
fn pairs_match_an_independent_resimulation_and_batches_cover_the_split() {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let out = tmp.path().join("d");
    run(&out, &set, &gen_config(40), 2);
    let ds = Dataset::open(&out).unwrap();
    ds.verify().unwrap();
    assert_eq!(ds.sim_config(), &sim_config());
    let objects = ds.object_set().unwrap();
    let sim = Simulator::new(ds.sim_config().clone()).unwrap();
    let (w, h) = (32, 24);
    let min_px = gen_config(40).min_contact_pixels(w, h);
    for split in SplitName::ALL {
        for i in 0..ds.len(split) {
            let p = ds.pair(split, i).unwrap();
            let m = &p.meta;
            // Noise-free images from the stored metadata, by the simulator directly.
            let object = PreparedObject::new(objects.mesh(&m.object).unwrap()).unwrap();
            assert_eq!(m.sensor, sim.pressing_pose(&object, 0.0, 0.0, 0.0, m.press));
            let scene = Scene {
                object: m.object_pose,
                sensor: m.sensor,
            };
            let depth = sim.render_depth(&object, &scene);
            let (mask, target) = sim.contact(&depth);
            assert_eq!(p.mask, mask, "{split} {i}");
            assert_eq!(p.target, target, "{split} {i}");
            assert_eq!(m.contact_pixels, mask.count_nonzero());
            assert!(m.contact_pixels >= min_px, "rejection rule violated");
            assert!((0.003..=0.015).contains(&m.press));
            // Y = R - S where both are seen.
            for k in 0..w * h {
                let (r, s) = (p.reference.data[k], p.signature.data[k]);
                let y = if r > 0.0 && s > 0.0 { r - s } else { 0.0 };
                assert_eq!(p.imprint.data[k], y);
            }
        }
    }
    let split = SplitName::Train;
    let n = ds.len(split);
    let mut got = Vec::new();
    for b in ds.batches(split, 7, 3, 0) {
        let b = b.unwrap();
        assert_eq!((b.width, b.height, b.imprint.len()), (w, h, b.n * w * h));
        for (j, &i) in b.indices.iter().enumerate() {
            let p = ds.pair(split, i).unwrap();
            assert_eq!(&b.imprint[j * w * h..(j + 1) * w * h], &p.imprint.data[..]);
            assert_eq!(&b.target[j * w * h..(j + 1) * w * h], &p.target.data[..]);
        }
        got.extend(b.indices);
    }
    assert_eq!(
        got.iter().copied().collect::<BTreeSet<_>>(),
        (0..n).collect()
    );
    assert_eq!(got.len(), n);
    let order = |epoch| -> Vec<usize> {
        ds.batches(split, 7, 3, epoch)
            .flat_map(|b| b.unwrap().indices)
            .collect()
    };
    assert_eq!(order(0), got);
    assert_ne!(order(1), got, "another epoch, another order");
    assert!(matches!(
        ds.pair(split, n),
        Err(DatasetError::IndexOutOfRange { .. })
    ));
}

#[test]
fn inflation_variation_uses_one_membrane_per_pair_and_leaves_the_rest_alone() {
    use tactile_derender::dataset::config::InflationVariation;
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let variation = InflationVariation {
        range: [0.026, 0.034],
        levels: 3,
    };
    let varied = GenConfig {
        inflation: Some(variation),
        ..gen_config(30)
    };
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    run(&a, &set, &varied, 2);
    run(&b, &set, &gen_config(30), 2);
    let (da, db) = (Dataset::open(&a).unwrap(), Dataset::open(&b).unwrap());
    let objects = da.object_set().unwrap();
    // One simulator per height, built independently of the generator.
    let sims: Vec<Simulator> = variation
        .heights()
        .iter()
        .map(|&h| {
            let mut c = sim_config();
            c.elastomer.inflation = h;
            Simulator::new(c).unwrap()
        })
        .collect();
    let mut used = BTreeSet::new();
    for split in SplitName::ALL {
        assert_eq!(da.len(split), db.len(split));
        for i in 0..da.len(split) {
            let (p, q) = (da.pair(split, i).unwrap(), db.pair(split, i).unwrap());
            // The same objects and splits as without variation (the pair's random stream is untouched; positions
            // differ because the view at the apex height changes with the inflation).
            assert_eq!(p.meta.object, q.meta.object);
            // The membrane of the pair's level made its contact and X0.
            let level = variation.level(p.meta.seed);
            used.insert(level);
            let sim = &sims[level];
            let object = PreparedObject::new(objects.mesh(&p.meta.object).unwrap()).unwrap();
            assert_eq!(
                p.meta.sensor,
                sim.pressing_pose(&object, 0.0, 0.0, 0.0, p.meta.press)
            );
            let scene = Scene {
                object: p.meta.object_pose,
                sensor: p.meta.sensor,
            };
            let (mask, target) = sim.contact(&sim.render_depth(&object, &scene));
            assert_eq!((&p.mask, &p.target), (&mask, &target), "{split} {i}");
        }
    }
    assert_eq!(used.len(), 3, "every height is used");
    // Bad ranges are refused with the flag's meaning.
    let bad = GenConfig {
        inflation: Some(InflationVariation {
            range: [0.03, 0.02],
            levels: 3,
        }),
        ..gen_config(4)
    };
    let e = generate(&tmp.path().join("c"), &sim_config(), &set, &bad, &|_| {}).unwrap_err();
    assert!(e.to_string().contains("inflation range"), "{e}");
}

/// A finished small dataset to damage.
fn damaged_copy(name: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let out = tmp.path().join(name);
    run(&out, &set, &gen_config(20), 2);
    (tmp, out)
}

fn edit_manifest(out: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let path = out.join(MANIFEST_FILE);
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    f(&mut m);
    std::fs::write(&path, serde_json::to_string_pretty(&m).unwrap()).unwrap();
}

#[test]
fn each_kind_of_damage_gives_its_error_naming_the_file() {
    // Truncated shard: caught by open() from the size alone.
    let (_t1, out) = damaged_copy("truncated");
    let shard = out.join("shards/train-00000.npz");
    let bytes = std::fs::read(&shard).unwrap();
    std::fs::write(&shard, &bytes[..bytes.len() - 100]).unwrap();
    let err = Dataset::open(&out).err().unwrap();
    assert!(matches!(err, DatasetError::Truncated { .. }), "{err}");
    assert!(err.to_string().contains("train-00000.npz"), "{err}");

    // Same size, one flipped byte in the imprint data: checksum error on first access.
    let (_t2, out) = damaged_copy("checksum");
    let shard = out.join("shards/train-00000.npz");
    let mut bytes = std::fs::read(&shard).unwrap();
    let mid = bytes.len() / 3;
    bytes[mid] ^= 0x40;
    std::fs::write(&shard, &bytes).unwrap();
    let ds = Dataset::open(&out).unwrap();
    let err = ds.pair(SplitName::Train, 0).unwrap_err();
    assert!(matches!(err, DatasetError::Checksum { .. }), "{err}");
    assert!(err.to_string().contains("train-00000.npz"), "{err}");
    assert!(matches!(ds.verify(), Err(DatasetError::Checksum { .. })));

    // A shard rewritten with float64 images and a manifest updated to match: dtype error.
    let (_t3, out) = damaged_copy("dtype");
    let ds = Dataset::open(&out).unwrap();
    let n = ds.manifest().shards[0].pairs;
    let file = ds.manifest().shards[0].file.clone();
    let (w, h) = ds.resolution();
    let mut arrays = vec![ArrayData::f64(
        "imprint",
        vec![n, h, w],
        vec![0.0; n * w * h],
    )];
    arrays.extend(
        IMAGE_ARRAYS[1..]
            .iter()
            .map(|&a| ArrayData::f32(a, vec![n, h, w], vec![0.0; n * w * h])),
    );
    let bytes = npz::encode(&arrays).unwrap();
    std::fs::write(out.join(&file), &bytes).unwrap();
    edit_manifest(&out, |m| {
        m["shards"][0]["bytes"] = bytes.len().into();
        m["shards"][0]["sha256"] = sha256_hex(&bytes).into();
    });
    let err = Dataset::open(&out)
        .unwrap()
        .pair(SplitName::Train, 0)
        .unwrap_err();
    assert!(
        matches!(&err, DatasetError::Dtype { array, found, .. } if array == "imprint" && found == "<f8"),
        "{err}"
    );
    assert!(err.to_string().contains(&file), "{err}");

    // A newer format version.
    let (_t4, out) = damaged_copy("version");
    edit_manifest(&out, |m| m["version"] = 99.into());
    let err = Dataset::open(&out).err().unwrap();
    assert!(
        matches!(err, DatasetError::UnsupportedVersion { found: 99, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("manifest.json"), "{err}");
}

#[test]
fn resuming_with_another_configuration_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let out = tmp.path().join("d");
    run(&out, &set, &gen_config(20), 2);
    let other = GenConfig {
        press_range: [0.004, 0.015],
        ..gen_config(20)
    };
    let err = generate(&out, &sim_config(), &set, &other, &|_| {}).unwrap_err();
    assert!(
        matches!(&err, DatasetError::ConfigMismatch { field, .. } if field == "generation"),
        "{err}"
    );
    // The refusal names the setting and both values.
    assert!(
        err.to_string()
            .contains("generation.press_range: [0.003,0.015] -> [0.004,0.015]"),
        "{err}"
    );
    let mut sim = sim_config();
    sim.signature.noise_std = 0.001;
    let err = generate(&out, &sim, &set, &gen_config(20), &|_| {}).unwrap_err();
    assert!(
        matches!(&err, DatasetError::ConfigMismatch { field, .. } if field == "sim"),
        "{err}"
    );
    // A directory holding something else is not overwritten.
    let foreign = tmp.path().join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), b"mine").unwrap();
    let err = generate(&foreign, &sim_config(), &set, &gen_config(20), &|_| {}).unwrap_err();
    assert!(matches!(err, DatasetError::NotADataset { .. }), "{err}");
}

/// Writes `<CARGO_TARGET_TMPDIR>/tnd-dataset-numpy/{dataset, expected.json}` for `tests/dataset_numpy_check.py`:
/// the expected values are the re-simulated noise-free target and mask of two pairs plus each pair's stored
/// metadata, so numpy's view of the shards is compared with values computed without the npz reader.
#[test]
fn write_numpy_round_trip_fixture() {
    let root = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("tnd-dataset-numpy");
    let _ = std::fs::remove_dir_all(&root);
    let set = small_set(&root.join("set"));
    let out = root.join("dataset");
    run(&out, &set, &gen_config(24), 2);
    let ds = Dataset::open(&out).unwrap();
    let sim = Simulator::new(ds.sim_config().clone()).unwrap();
    let mut expected = Vec::new();
    for (split, i) in [(SplitName::Train, 1), (SplitName::UnseenObjects, 0)] {
        let m = ds.pair(split, i).unwrap().meta;
        let object =
            PreparedObject::new(ds.object_set().unwrap().mesh(&m.object).unwrap()).unwrap();
        let depth = sim.render_depth(
            &object,
            &Scene {
                object: m.object_pose,
                sensor: m.sensor,
            },
        );
        let (mask, target) = sim.contact(&depth);
        expected.push(serde_json::json!({
            "split": split, "split_index": i, "index": m.index, "seed": m.seed.to_string(),
            "object": m.object, "pose": [m.object_pose.x, m.object_pose.y, m.object_pose.theta],
            "press": m.press, "target": target.data, "mask": mask.data,
        }));
    }
    let json = serde_json::json!({"dataset": out, "pairs": expected});
    std::fs::write(
        root.join("expected.json"),
        serde_json::to_string(&json).unwrap(),
    )
    .unwrap();
}

#[test]
fn the_stored_seed_reproduces_the_pair_with_noise() {
    use tactile_derender::dataset::sample::Sampler;
    use tactile_derender::dataset::split::{pair_stream, ObjectDraw, PlannedPair};
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let cfg = gen_config(20);
    let out = tmp.path().join("d");
    run(&out, &set, &cfg, 2);
    let ds = Dataset::open(&out).unwrap();
    let sim = Simulator::new(ds.sim_config().clone()).unwrap();
    let names: Vec<String> = set.entries().iter().map(|e| e.name.clone()).collect();
    let objects: Vec<PreparedObject> = names
        .iter()
        .map(|n| PreparedObject::new(set.mesh(n).unwrap()).unwrap())
        .collect();
    let draw = ObjectDraw::uniform(names.len());
    let sampler = Sampler::new(std::slice::from_ref(&sim), &objects, &names, &draw, &cfg);
    for (split, i) in [(SplitName::Train, 0), (SplitName::UnseenObjects, 1)] {
        let p = ds.pair(split, i).unwrap();
        let (_, object) = pair_stream(p.meta.seed, &draw);
        assert_eq!(names[object], p.meta.object);
        let plan = PlannedPair {
            index: p.meta.index,
            seed: p.meta.seed,
            object,
            split,
        };
        let (r, _) = sampler.sample(&plan).unwrap();
        assert_eq!(
            (r.imprint, r.signature, r.reference),
            (p.imprint, p.signature, p.reference)
        );
        assert_eq!((r.pose, r.press), (p.meta.object_pose, p.meta.press));
    }
}

#[test]
fn cli_stats_and_show_describe_the_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let out = tmp.path().join("d");
    run(&out, &set, &gen_config(30), 2);
    let tnd = env!("CARGO_BIN_EXE_tnd");
    let o = std::process::Command::new(tnd)
        .args(["dataset", "stats", "--json", "--verify"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let ds = Dataset::open(&out).unwrap();
    assert_eq!(
        s["counts"],
        serde_json::to_value(ds.manifest().counts).unwrap()
    );
    let per_object: usize = s["per_object"]
        .as_object()
        .unwrap()
        .values()
        .map(|c| {
            (0..3)
                .map(|k| {
                    c[["train", "unseen_poses", "unseen_objects"][k]]
                        .as_u64()
                        .unwrap() as usize
                })
                .sum::<usize>()
        })
        .sum();
    assert_eq!(per_object, 30);
    assert_eq!(
        s["area_hist"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_u64().unwrap())
            .sum::<u64>(),
        30
    );
    let [lo, hi] = [0, 1].map(|k| s["press_range_m"][k].as_f64().unwrap());
    assert!(0.003 <= lo && lo <= hi && hi <= 0.015);

    let png = tmp.path().join("pair.png");
    let o = std::process::Command::new(tnd)
        .args([
            "dataset",
            "show",
            "--index",
            "0",
            "--split",
            "unseen_objects",
            "--out",
        ])
        .arg(&png)
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = image::open(&png).unwrap();
    assert!(img.width() > 4 * 4 * 32 && img.height() > 4 * 24);
    let o = std::process::Command::new(tnd)
        .args(["dataset", "show", "--index", "100000", "--out"])
        .arg(&png)
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("out of range"), "{err}");
}
