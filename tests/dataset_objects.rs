//! Object sets in dataset generation: objects that cannot make a large enough contact are left out (or, when none
//! can, the run fails saying what to change), and `tnd objects generate --kinds` picks procedural kinds.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod dataset_common;

use dataset_common::{gen_config, sim_config, small_set};
use tactile_derender::dataset::{generate, Dataset, DatasetError, GenConfig, SplitName};
use tactile_derender::objects::ObjectSet;

#[test]
fn impossible_rejection_rule_fails_saying_what_to_change() {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let cfg = GenConfig {
        min_contact_fraction: 0.99,
        max_attempts: 3,
        ..gen_config(4)
    };
    let err = generate(&tmp.path().join("d"), &sim_config(), &set, &cfg, &|_| {}).unwrap_err();
    assert!(
        matches!(err, DatasetError::NoPressableObject { attempts: 3, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("lower --min-contact"), "{err}");
}

#[test]
fn objects_that_cannot_make_a_contact_are_left_out_and_named() {
    // A 2 mm copy of a sphere covers a few pixels at most: below the 1 % (41 px) rule whatever the press.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("set");
    small_set(&dir);
    let path = dir.join("objects.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let objects = m["objects"].as_array_mut().unwrap();
    let mut speck = objects
        .iter()
        .find(|o| o["name"] == "sphere_r20")
        .unwrap()
        .clone();
    speck["name"] = "speck".into();
    speck["scale_to_m"] = (speck["scale_to_m"].as_f64().unwrap() * 0.05).into();
    objects.push(speck);
    std::fs::write(&path, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    let set = ObjectSet::load_dir(&dir).unwrap();
    let out = tmp.path().join("d");
    let cfg = GenConfig {
        max_attempts: 20,
        ..gen_config(40)
    };
    let report = generate(&out, &sim_config(), &set, &cfg, &|_| {}).unwrap();
    assert_eq!(report.excluded_objects, vec!["speck".to_string()]);
    let ds = Dataset::open(&out).unwrap();
    let mut pairs = 0;
    for split in [
        SplitName::Train,
        SplitName::UnseenPoses,
        SplitName::UnseenObjects,
    ] {
        for i in 0..ds.len(split) {
            let pair = ds.pair(split, i).unwrap();
            assert_ne!(pair.meta.object, "speck");
            assert!(pair.meta.contact_pixels >= 41);
            pairs += 1;
        }
    }
    assert_eq!(pairs, 40);
    // Resuming the finished run plans the same pairs (the exclusion is part of the plan).
    let again = generate(&out, &sim_config(), &set, &cfg, &|_| {}).unwrap();
    assert!(again.already_complete);
    assert_eq!(again.excluded_objects, report.excluded_objects);
}

#[test]
fn cli_objects_generate_picks_kinds_and_names_a_bad_one() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("objects");
    let tnd = env!("CARGO_BIN_EXE_tnd");
    let o = std::process::Command::new(tnd)
        .args(["-q", "objects", "generate", "--count", "12", "--seed", "3"])
        .args(["--builtin-share", "0", "--kinds", "plate,limbs"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let set = tactile_derender::objects::ObjectSet::open(dir.to_str().unwrap()).unwrap();
    assert_eq!(set.entries().len(), 12);
    for e in set.entries() {
        assert!(
            e.name.starts_with("proc_plate_") || e.name.starts_with("proc_limbs_"),
            "{}",
            e.name
        );
        let (lo, hi) = set.mesh(&e.name).unwrap().aabb();
        assert!(lo.z.abs() < 1e-6 && (hi - lo).max_element() <= 0.065 + 1e-6);
    }
    let o = std::process::Command::new(tnd)
        .args(["objects", "generate", "--kinds", "plate,bogus"])
        .arg(tmp.path().join("other"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("unknown kind 'bogus'"),
        "{err}"
    );
}
