//! Tests of [`ObjectSet`]: the built-in catalogue's invariants, export/load round trip and manifest validation.
#![allow(clippy::unwrap_used)]

use std::collections::HashSet;

use super::*;
use crate::objects::{Family, RotationSymmetry, Split};

#[test]
fn builtin_catalogue_invariants() {
    let set = ObjectSet::builtin();
    let entries = set.entries();
    assert!(entries.len() >= 24, "{} objects", entries.len());
    let names: HashSet<&str> = entries.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names.len(), entries.len(), "names are not unique");
    let unseen = set.entries_in(Split::Unseen).count() as f64 / entries.len() as f64;
    assert!((0.2..=0.35).contains(&unseen), "unseen fraction {unseen}");
    for family in Family::ALL {
        for split in [Split::Seen, Split::Unseen] {
            assert!(
                entries
                    .iter()
                    .any(|e| e.family == Some(family) && e.split == split),
                "{family} has no {split:?} object"
            );
        }
    }
    for e in entries {
        assert!(!e.dimensions.is_empty(), "{}", e.name);
        assert!(
            e.dimensions.values().all(|&v| v > 0.0 && v < 0.2),
            "{}: {:?}",
            e.name,
            e.dimensions
        );
        let mesh = set.mesh(&e.name).unwrap();
        assert!(
            mesh.report().closed && mesh.report().volume_m3 > 0.0,
            "{}",
            e.name
        );
        assert!(mesh.aabb().0.z.abs() < 1e-6, "{}", e.name);
    }
    let cylinder = set.find("cylinder_r15").unwrap();
    assert_eq!(cylinder.symmetry.rotation, RotationSymmetry::NFold(2));
    assert_eq!(cylinder.symmetry.translation_axis, Some([1.0, 0.0]));
    assert_eq!(
        set.find("sphere_r20").unwrap().symmetry.rotation,
        RotationSymmetry::Continuous
    );
    assert_eq!(
        set.find("cross_w12_s50").unwrap().symmetry.rotation,
        RotationSymmetry::NFold(4)
    );
    assert!(set.find("nope").is_none());
    let err = set.mesh("nope").unwrap_err().to_string();
    assert!(err.contains("nope") && err.contains("cylinder_r8"), "{err}");
}

#[test]
fn open_accepts_builtin_and_empty() {
    assert_eq!(ObjectSet::open("builtin").unwrap().spec(), "builtin");
    assert!(ObjectSet::open("").unwrap().dir().is_none());
    let err = ObjectSet::open("/definitely/not/a/set")
        .unwrap_err()
        .to_string();
    assert!(err.contains("objects.json"), "{err}");
}

#[test]
fn export_then_load_round_trips() {
    let tmp = tempfile::tempdir().unwrap();
    let builtin = ObjectSet::builtin();
    builtin.export(tmp.path()).unwrap();
    let loaded = ObjectSet::load_dir(tmp.path()).unwrap();
    assert_eq!(loaded.entries(), builtin.entries());
    assert_eq!(loaded.dir(), Some(tmp.path()));
    for e in builtin.entries() {
        let (a, b) = (
            builtin.mesh(&e.name).unwrap(),
            loaded.mesh(&e.name).unwrap(),
        );
        assert_eq!(a.triangles().len(), b.triangles().len(), "{}", e.name);
        for i in 0..a.triangles().len() {
            for (p, q) in a.triangle(i).iter().zip(b.triangle(i)) {
                assert!(
                    (*p - q).abs().max_element() < 1e-6,
                    "{}: {p} vs {q}",
                    e.name
                );
            }
        }
    }
    // Exporting a directory set again (onto itself) keeps it loadable and equal.
    loaded.export(tmp.path()).unwrap();
    assert_eq!(
        ObjectSet::load_dir(tmp.path()).unwrap().entries(),
        builtin.entries()
    );
}

/// A temporary set directory with `manifest` as `objects.json` and a 10 x 20 x 30 file-unit box in `cube.obj`.
fn user_set(manifest: &str) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let cube = crate::objects::shapes::extrude_z(
        &[(0.0, 0.0), (10.0, 0.0), (10.0, 20.0), (0.0, 20.0)].map(|(x, y)| glam::Vec2::new(x, y)),
        30.0,
    )
    .unwrap();
    std::fs::write(tmp.path().join("cube.obj"), cube.to_obj_string()).unwrap();
    std::fs::write(tmp.path().join(MANIFEST_FILE), manifest).unwrap();
    tmp
}

#[test]
fn user_set_applies_scale_and_rotation_then_rests() {
    // 10 x 20 x 30 mm box, rotated 90 degrees about x: y and z swap extents.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let manifest = format!(
        r#"{{"version": 1, "objects": [{{"name": "box", "mesh": "cube.obj", "scale_to_m": 0.001,
        "rotation": [{h}, 0, 0, {h}], "symmetry": {{"rotation": {{"n_fold": 2}}}}}}]}}"#
    );
    let tmp = user_set(&manifest);
    let set = ObjectSet::open(&tmp.path().display().to_string()).unwrap();
    let e = set.find("box").unwrap();
    assert_eq!((e.family, e.split), (None, Split::Seen));
    assert_eq!(e.symmetry.rotation, RotationSymmetry::NFold(2));
    let mesh = set.mesh("box").unwrap();
    let (lo, hi) = mesh.aabb();
    let extent = hi - lo;
    assert!(
        (extent - glam::Vec3::new(0.010, 0.030, 0.020))
            .abs()
            .max_element()
            < 1e-6,
        "{extent}"
    );
    assert!(lo.z.abs() < 1e-7 && (lo.x + hi.x).abs() < 1e-7 && (lo.y + hi.y).abs() < 1e-7);
}

fn load_error(manifest: &str) -> String {
    let tmp = user_set(manifest);
    let err = ObjectSet::load_dir(tmp.path()).unwrap_err().to_string();
    assert!(
        err.contains(MANIFEST_FILE),
        "error does not name the manifest: {err}"
    );
    err
}

#[test]
fn load_dir_rejects_bad_manifests() {
    let err = load_error(r#"{"version": 1, "objects": [{"name": "a", "mesh": "missing.obj"}]}"#);
    assert!(
        err.contains("missing.obj") && err.contains("does not exist"),
        "{err}"
    );
    let err = load_error(
        r#"{"version": 1, "objects": [{"name": "a", "mesh": "cube.obj"}, {"name": "a", "mesh": "cube.obj"}]}"#,
    );
    assert!(
        err.contains("'a'") && err.contains("more than once"),
        "{err}"
    );
    let err = load_error(r#"{"version": 1, "objects": [{"name": "a", "mesh": "cube.obj",}"#);
    assert!(err.contains("malformed"), "{err}");
    let err = load_error(
        r#"{"version": 1, "objects": [{"name": "a", "mesh": "cube.obj", "scale_to_m": 0}]}"#,
    );
    assert!(err.contains("scale_to_m"), "{err}");
    let err = load_error(
        r#"{"version": 1, "objects": [{"name": "a", "mesh": "cube.obj", "rotation": [0, 0, 0, 2]}]}"#,
    );
    assert!(err.contains("unit quaternion"), "{err}");
    let err = load_error(r#"{"version": 7, "objects": []}"#);
    assert!(err.contains("version 7"), "{err}");
    // A misspelt key is named, not ignored (the mesh would have been read in metres).
    let err = load_error(
        r#"{"version": 1, "objects": [{"name": "a", "mesh": "cube.obj", "scale_to_mm": 1}]}"#,
    );
    assert!(err.contains("unknown field `scale_to_mm`"), "{err}");
}

#[test]
fn a_scale_that_makes_the_object_implausible_is_named_when_its_mesh_is_read() {
    // The box of 10 x 20 x 30 file units read as metres: 30 m across; at 1e-6 m per unit: 0.03 mm.
    for (scale, across) in [(1.0, "30.00 m"), (1e-6, "0.030 mm")] {
        let tmp = user_set(&format!(
            r#"{{"version": 1, "objects": [{{"name": "box", "mesh": "cube.obj", "scale_to_m": {scale}}}]}}"#
        ));
        let set = ObjectSet::load_dir(tmp.path()).unwrap();
        let err = set.mesh("box").unwrap_err().to_string();
        assert!(
            err.contains(MANIFEST_FILE)
                && err.contains("'box'")
                && err.contains(across)
                && err.contains("implausible"),
            "{err}"
        );
    }
    let tmp = user_set(
        r#"{"version": 1, "objects": [{"name": "box", "mesh": "cube.obj", "scale_to_m": 0.001}]}"#,
    );
    assert!(ObjectSet::load_dir(tmp.path()).unwrap().mesh("box").is_ok());
}
