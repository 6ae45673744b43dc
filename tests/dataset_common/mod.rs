//! Helpers shared by `tests/dataset.rs` and `tests/dataset_objects.rs`: a small object set, a small sensor and
//! generation settings.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use tactile_derender::dataset::{generate, GenConfig};
use tactile_derender::objects::{ObjectSet, Split};
use tactile_derender::sim::SimConfig;

/// A 5-object set (3 seen, 2 unseen) exported from the built-in library into `dir`.
pub fn small_set(dir: &Path) -> ObjectSet {
    ObjectSet::builtin().export(dir).unwrap();
    let path = dir.join("objects.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let keep = [
        "sphere_r20",
        "cylinder_r12",
        "cross_w12_s50",
        "sphere_r15",
        "cylinder_r15",
    ];
    let objects = m["objects"].as_array().unwrap().clone();
    m["objects"] = objects
        .into_iter()
        .filter(|o| keep.contains(&o["name"].as_str().unwrap()))
        .collect();
    std::fs::write(&path, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    let set = ObjectSet::load_dir(dir).unwrap();
    assert_eq!(
        set.entries_in(Split::Unseen).count(),
        2,
        "sphere_r15 and cylinder_r15 are unseen"
    );
    set
}

pub fn sim_config() -> SimConfig {
    let mut c = SimConfig::default();
    c.camera.resolution = (32, 24);
    c
}

pub fn gen_config(pairs: usize) -> GenConfig {
    GenConfig {
        pairs,
        seed: 11,
        shard_pairs: 16,
        ..GenConfig::default()
    }
}

pub fn run(out: &Path, set: &ObjectSet, cfg: &GenConfig, threads: usize) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| generate(out, &sim_config(), set, cfg, &|_| {}))
        .unwrap();
}
