//! Import of real sensor pairs against the analytic fixture of `tests/fixtures/dataset_import/` (written by numpy
//! and Pillow with `make_fixture.py`): a flat membrane at 90 mm pressed by a flat disc at 80 mm, given once at the
//! model resolution (.npy, metres), once as native 16-bit PNGs (mm) and once as a cropped compressed .npz, plus the
//! errors for bad input.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use tactile_derender::dataset::import::{import, ImportConfig};
use tactile_derender::dataset::{Dataset, DatasetError, Pair, SplitName};
use tactile_derender::objects::ObjectSet;
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/dataset_import")
}

fn pair_with_index(ds: &Dataset, index: usize) -> Pair {
    SplitName::ALL
        .iter()
        .flat_map(|&s| (0..ds.len(s)).map(move |i| (s, i)))
        .map(|(s, i)| ds.pair(s, i).unwrap())
        .find(|p| p.meta.index == index)
        .unwrap()
}

/// For the model pixel (u, v) resampled from a `w x h` frame: `Some(true)` if every source pixel of its block is on
/// the disc, `Some(false)` if none is, `None` on the boundary. `(ox, oy)` maps frame pixels to the disc's pixels.
fn block_on_disc(
    u: usize,
    v: usize,
    (w, h): (usize, usize),
    disc: (f64, f64, f64),
    (ox, oy): (f64, f64),
) -> Option<bool> {
    let (sx, sy) = (w as f64 / 64.0, h as f64 / 64.0);
    let (cx, cy, r) = disc;
    let cols = (u as f64 * sx).floor() as usize..((u + 1) as f64 * sx).ceil() as usize;
    let rows = (v as f64 * sy).floor() as usize..((v + 1) as f64 * sy).ceil() as usize;
    let inside: Vec<bool> = rows
        .flat_map(|j| cols.clone().map(move |i| (i, j)))
        .map(|(i, j)| (i as f64 + ox - cx).powi(2) + (j as f64 + oy - cy).powi(2) <= r * r)
        .collect();
    if inside.iter().all(|&b| b) {
        Some(true)
    } else if inside.iter().all(|&b| !b) {
        Some(false)
    } else {
        None
    }
}

fn check_disc(p: &Pair, frame: (usize, usize), disc: (f64, f64, f64), offset: (f64, f64)) {
    let (mut on, mut off) = (0, 0);
    for v in 0..64 {
        for u in 0..64 {
            let (t, y, m) = (p.target.get(u, v), p.imprint.get(u, v), p.mask.get(u, v));
            match block_on_disc(u, v, frame, disc, offset) {
                Some(true) => {
                    on += 1;
                    assert!(
                        (t - 0.08).abs() < 1e-6 && (y - 0.01).abs() < 1e-6 && m == 1.0,
                        "({u},{v}) {t} {y}"
                    );
                }
                Some(false) => {
                    off += 1;
                    assert!(t == 0.0 && y.abs() < 1e-6 && m == 0.0, "({u},{v}) {t} {y}");
                }
                // Boundary: the target is the mean of the disc pixels it covers (all 80 mm) or missing.
                None => assert!(t == 0.0 || (t - 0.08).abs() < 1e-6, "({u},{v}) {t}"),
            }
            assert!((p.reference.get(u, v) - 0.09).abs() < 1e-6);
        }
    }
    assert!(on > 20 && off > 1000, "{on} on, {off} off");
    assert_eq!(p.meta.contact_pixels, p.mask.count_nonzero());
}

#[test]
fn imports_npy_png_and_npz_through_the_camera_model() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("real");
    let sim = SimConfig::default();
    let set = ObjectSet::builtin();
    let report = import(&fixture(), &out, &sim, &set, &ImportConfig::default()).unwrap();
    assert_eq!(report.pairs, 3);
    let ds = Dataset::open(&out).unwrap();
    ds.verify().unwrap();
    assert_eq!(ds.len(SplitName::UnseenPoses), report.counts.unseen_poses);
    assert_eq!(ds.manifest().counts.total(), 3);

    // p1: model resolution, used as is.
    let p1 = pair_with_index(&ds, 0);
    assert_eq!(p1.meta.object, "sphere_r20");
    assert_eq!(
        (
            p1.meta.object_pose.x,
            p1.meta.object_pose.y,
            p1.meta.object_pose.theta
        ),
        (0.001, -0.002, 0.3)
    );
    check_disc(&p1, (64, 64), (30.0, 34.0, 12.0), (0.0, 0.0));
    let simulator = Simulator::new(sim.clone()).unwrap();
    let object = PreparedObject::new(set.mesh("sphere_r20").unwrap()).unwrap();
    assert_eq!(
        p1.meta.sensor,
        simulator.pressing_pose(&object, 0.0, 0.0, 0.0, 0.005)
    );

    // p2: native PNGs in mm; crop rows 20.., columns 25.. then resample; explicit split; no press.
    let p2 = pair_with_index(&ds, 1);
    assert_eq!(p2.meta.split, SplitName::UnseenPoses);
    check_disc(&p2, (175, 140), (112.0, 90.0, 30.0), (25.0, 20.0));
    assert!(p2.meta.press.is_nan() && p2.meta.sensor.position[2].is_nan());

    // p3: cropped frames in a compressed npz, imprint instead of signature.
    let p3 = pair_with_index(&ds, 2);
    check_disc(&p3, (175, 140), (60.0, 50.0, 25.0), (0.0, 0.0));
    assert!((p3.signature.get(0, 0) - 0.09).abs() < 1e-6);
}

/// Copy the fixture into a temporary directory with `pairs.csv` replaced.
fn fixture_with_table(csv: &str) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(fixture()).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, tmp.path().join(p.file_name().unwrap())).unwrap();
    }
    std::fs::write(tmp.path().join("pairs.csv"), csv).unwrap();
    tmp
}

fn import_err(csv: &str) -> String {
    let from = fixture_with_table(csv);
    let out = tempfile::tempdir().unwrap();
    let err = import(
        from.path(),
        &out.path().join("d"),
        &SimConfig::default(),
        &ObjectSet::builtin(),
        &ImportConfig::default(),
    )
    .unwrap_err();
    assert!(matches!(err, DatasetError::Import { .. }), "{err}");
    err.to_string()
}

#[test]
fn bad_input_gives_one_clear_error_naming_the_file() {
    let head = "object,x,y,theta,signature,target,reference\n";
    let err = import_err(&format!(
        "{head}no_such_object,0,0,0,p2_signature.png,p2_target.png,\n"
    ));
    assert!(
        err.contains("pairs.csv") && err.contains("row 1") && err.contains("no_such_object"),
        "{err}"
    );
    let err = import_err(&format!(
        "{head}sphere_r20,0,0,0,missing.npy,p1_target.npy,p1_reference.npy\n"
    ));
    assert!(err.contains("missing.npy"), "{err}");
    // A 64x64 reference with native-size frames.
    let err = import_err(&format!(
        "{head}sphere_r20,0,0,0,p2_signature.png,p2_target.png,p1_reference.npy\n"
    ));
    assert!(err.contains("same size"), "{err}");
    let err = import_err(&format!(
        "{head}sphere_r20,0,nan,0,p2_signature.png,p2_target.png,\n"
    ));
    assert!(
        err.contains("y is not finite") || err.contains("'nan'"),
        "{err}"
    );
    let err = import_err(&format!(
        "{head}sphere_r20,0,0,0,p3.npz,p1_target.npy,p1_reference.npy\n"
    ));
    assert!(err.contains("p3.npz") && err.contains("name one"), "{err}");
    let err = import_err("object,x,y,theta,target\nsphere_r20,0,0,0,p1_target.npy\n");
    assert!(
        err.contains("signature or an imprint") || err.contains("reference"),
        "{err}"
    );

    // An 8-bit PNG is refused (depth needs 16 bits).
    let from = fixture_with_table(&format!(
        "{head}sphere_r20,0,0,0,eight.png,p2_target.png,\n"
    ));
    image::GrayImage::from_pixel(224, 171, image::Luma([90]))
        .save(from.path().join("eight.png"))
        .unwrap();
    let out = tempfile::tempdir().unwrap();
    let err = import(
        from.path(),
        &out.path().join("d"),
        &SimConfig::default(),
        &ObjectSet::builtin(),
        &ImportConfig::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("eight.png") && err.contains("16-bit"), "{err}");

    // A frame of an unexpected size names the accepted sizes.
    let from = fixture_with_table(&format!("{head}sphere_r20,0,0,0,odd.png,odd.png,odd.png\n"));
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(100, 100, image::Luma([90]))
        .save(from.path().join("odd.png"))
        .unwrap();
    let err = import(
        from.path(),
        &out.path().join("e"),
        &SimConfig::default(),
        &ObjectSet::builtin(),
        &ImportConfig::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("100x100") && err.contains("224x171"), "{err}");
}

#[test]
fn an_interrupted_import_is_redone_by_the_same_command_and_a_finished_one_is_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("real");
    let (sim, set) = (SimConfig::default(), ObjectSet::builtin());
    import(&fixture(), &out, &sim, &set, &ImportConfig::default()).unwrap();
    let shard = out.join("shards/train-00000.npz");
    let before = std::fs::read(&shard).unwrap();
    // Killed before manifest.json: shards and objects only, one shard half written.
    std::fs::remove_file(out.join("manifest.json")).unwrap();
    std::fs::write(&shard, &before[..100]).unwrap();
    import(&fixture(), &out, &sim, &set, &ImportConfig::default()).unwrap();
    assert_eq!(std::fs::read(&shard).unwrap(), before);
    Dataset::open(&out).unwrap().verify().unwrap();
    // A finished dataset is not overwritten.
    let err = import(&fixture(), &out, &sim, &set, &ImportConfig::default()).unwrap_err();
    assert!(matches!(err, DatasetError::Exists { .. }), "{err}");
}
