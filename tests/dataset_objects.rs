//! Object sets in dataset generation: objects that cannot make a large enough contact are left out (or, when none
//! can, the run fails saying what to change), `tnd objects generate --kinds` picks procedural kinds and `--include`
//! mixes in a user's own set at its share; a membrane mesh file travels with the dataset.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::dataset_common;

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
    // A 3.2 mm copy of a sphere (just above the smallest plausible object) covers a few pixels at most: below the
    // 1 % (41 px) rule whatever the press.
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
    speck["scale_to_m"] = (speck["scale_to_m"].as_f64().unwrap() * 0.08).into();
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

/// `tnd objects generate --include DIR=SHARE`, as a user mixes their own meshes into a training set: the included
/// objects keep their shape (in metres, resting on the table), split and symmetry, and carry exactly SHARE of the
/// weight beside the built-in catalogue's share; an unseen set is named as never trained on; a name clash and a
/// share that leaves nothing to the procedural objects are refused.
#[test]
fn cli_objects_generate_mixes_in_an_imported_set_at_its_share() {
    let tmp = tempfile::tempdir().unwrap();
    let mine = tmp.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    // A 20 x 10 x 4 mm block and a 6 mm tall tetrahedron, in millimetres.
    let block: String = (0..8)
        .map(|i| {
            let c = |bit: usize, size: f64| if i >> bit & 1 == 1 { size } else { 0.0 };
            format!("v {} {} {}\n", c(0, 20.0), c(1, 10.0), c(2, 4.0))
        })
        .chain(
            [
                "1 3 4 2", "5 6 8 7", "1 2 6 5", "3 7 8 4", "1 5 7 3", "2 4 8 6",
            ]
            .iter()
            .map(|f| format!("f {f}\n")),
        )
        .collect();
    std::fs::write(mine.join("block.obj"), block).unwrap();
    std::fs::write(
        mine.join("tetra.obj"),
        "v 0 0 0\nv 8 0 0\nv 0 8 0\nv 0 0 6\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n",
    )
    .unwrap();
    let tnd = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_tnd"))
            .args(args)
            .current_dir(tmp.path())
            .output()
            .unwrap()
    };
    let o = tnd(&["-q", "objects", "import", "mine", "--units", "mm"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = tnd(&[
        "-q",
        "objects",
        "generate",
        "out",
        "--count",
        "10",
        "--seed",
        "1",
        "--builtin-share",
        "0.25",
        "--include",
        "mine=0.3",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let set = ObjectSet::open(tmp.path().join("out").to_str().unwrap()).unwrap();
    let builtin = ObjectSet::builtin();
    assert_eq!(set.entries().len(), 10 + builtin.entries().len() + 2);
    let total: f64 = set.entries().iter().map(|e| e.weight).sum();
    let share = |pick: &dyn Fn(&str) -> bool| -> f64 {
        let w: f64 = set
            .entries()
            .iter()
            .filter(|e| pick(&e.name))
            .map(|e| e.weight)
            .sum();
        w / total
    };
    assert!((share(&|n| n == "block" || n == "tetra") - 0.3).abs() < 1e-12);
    assert!((share(&|n| builtin.find(n).is_some()) - 0.25).abs() < 1e-12);
    assert!((share(&|n| n.starts_with("proc_")) - 0.45).abs() < 1e-12);
    // The block comes out in metres, resting on the table, with the split the import gave it.
    let (lo, hi) = set.mesh("block").unwrap().aabb();
    let size = hi - lo;
    assert!(lo.z.abs() < 1e-7, "{lo:?}");
    assert!(
        (size.x - 0.020).abs() < 1e-6
            && (size.y - 0.010).abs() < 1e-6
            && (size.z - 0.004).abs() < 1e-6
    );
    let imported = ObjectSet::open(mine.to_str().unwrap()).unwrap();
    assert_eq!(
        set.find("block").unwrap().split,
        imported.find("block").unwrap().split
    );
    assert_eq!(
        set.find("tetra").unwrap().symmetry,
        imported.find("tetra").unwrap().symmetry
    );

    // Imported as unseen: generated all the same, and the user is told those objects are never trained on.
    let o = tnd(&[
        "-q", "objects", "import", "mine", "--units", "mm", "--split", "unseen", "--force",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = tnd(&[
        "-q",
        "objects",
        "generate",
        "out2",
        "--count",
        "4",
        "--include",
        "mine=0.2",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("2 of its 2 objects are unseen") && err.contains("never trained on"),
        "{err}"
    );
    // The same set twice: its names clash. Shares that leave nothing to the procedural objects. A bad spelling.
    for (args, says) in [
        (
            &["--include", "mine=0.2", "--include", "mine=0.2"][..],
            "has the name of an object already",
        ),
        (
            &["--builtin-share", "0.5", "--include", "mine=0.5"][..],
            "leave no pairs to the procedural",
        ),
        (&["--include", "mine"][..], "DIR=SHARE"),
        (&["--include", "mine=1.5"][..], "in (0, 1)"),
    ] {
        let o = tnd(&[
            &["-q", "objects", "generate", "out3", "--count", "4"][..],
            args,
        ]
        .concat());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(says), "{args:?}: {err}");
        assert!(!tmp.path().join("out3").join("objects.json").exists());
    }
}

/// `--elastomer-mesh`: the membrane mesh is stored in the dataset (named by its content), so the dataset opens and
/// simulates from any directory after the original file is gone; a resume with another mesh at the same path is
/// refused, naming the membrane.
#[test]
fn a_membrane_mesh_file_travels_with_the_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let mut sim = sim_config();
    let bubble = tmp.path().join("bubble.obj");
    let text = sim.elastomer.build().unwrap().to_obj_string();
    std::fs::write(&bubble, &text).unwrap();
    sim.elastomer.mesh_file = Some(bubble.clone());
    let cfg = gen_config(24);
    let out = tmp.path().join("ds");
    generate(&out, &sim, &set, &cfg, &|_| {}).unwrap();
    std::fs::remove_file(&bubble).unwrap();
    let ds = Dataset::open(&out).unwrap();
    let stored = ds.sim_config().elastomer.mesh_file.clone().unwrap();
    assert!(stored.starts_with(&out), "{}", stored.display());
    assert_eq!(std::fs::read_to_string(&stored).unwrap(), text);
    tactile_derender::sim::Simulator::new(ds.sim_config().clone()).unwrap();
    // Another membrane under the same name: refused, as a changed configuration.
    std::fs::write(&bubble, text + "# edited\n").unwrap();
    let err = generate(&out, &sim, &set, &cfg, &|_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("elastomer"), "{err}");
}
