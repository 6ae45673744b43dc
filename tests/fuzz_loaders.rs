//! Mutation fuzzing of every file loader users feed (stable Rust, no cargo-fuzz needed): OBJ, STL, PLY, glTF, GLB,
//! `.npy`, `.npz`, safetensors checkpoints and `objects.json`. Each loader is driven with its seed corpus
//! (`tests/fixtures/fuzz/<kind>/`, written by the ignored test `write_fuzz_corpus`) and then with seeded mutations of
//! it: bit flips, interesting bytes, truncation, insertion, deletion, duplicated chunks and huge or malformed numbers
//! spliced in. Every input must come back as `Ok` or `Err` — a panic fails the test, as does one input taking longer
//! than a few seconds (a hang) — and headers claiming 2^62 elements must be refused before anything is allocated.
//!
//! CI runs `TND_FUZZ_ITERS` inputs per loader (default 3 000, a few seconds each); a long run:
//! `TND_FUZZ_ITERS=100000 cargo test --release --test fuzz_loaders`.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::fuzz_common;

use std::path::Path;

use fuzz_common::{corpus_dir, fuzz};
use tactile_derender::mesh::{self, LoadOptions};

/// Loaders that read a path: write each input to one file in a temporary folder.
fn via_file(name: &str, read: impl Fn(&Path) -> bool) -> impl Fn(&[u8]) -> bool {
    let dir = tempfile::tempdir().unwrap().keep();
    let path = dir.join(name);
    move |bytes: &[u8]| {
        std::fs::write(&path, bytes).unwrap();
        read(&path)
    }
}

fn load_mesh(path: &Path) -> bool {
    mesh::load(path, &LoadOptions::default()).is_ok()
}

#[test]
fn obj() {
    fuzz("obj", &via_file("m.obj", load_mesh));
}

#[test]
fn stl() {
    fuzz("stl", &via_file("m.stl", load_mesh));
}

#[test]
fn ply() {
    fuzz("ply", &via_file("m.ply", load_mesh));
}

#[test]
fn gltf_and_glb() {
    fuzz("gltf", &via_file("m.gltf", load_mesh));
    fuzz("glb", &via_file("m.glb", load_mesh));
}

#[test]
fn npy() {
    fuzz("npy", &|b| tactile_derender::io::npy::decode(b).is_ok());
}

#[test]
fn npz() {
    fuzz("npz", &|b| {
        tactile_derender::dataset::npz::NpzIndex::read(
            std::io::Cursor::new(b),
            Path::new("fuzz.npz"),
        )
        .is_ok()
    });
}

#[test]
fn safetensors_checkpoint() {
    fuzz(
        "safetensors",
        &via_file("m.safetensors", |p| {
            tactile_derender::model::checkpoint::locate(p).is_ok()
        }),
    );
}

#[test]
fn objects_json() {
    let dir = tempfile::tempdir().unwrap().keep();
    std::fs::write(
        dir.join("m.obj"),
        std::fs::read(corpus_dir("obj").join("sphere.obj")).unwrap(),
    )
    .unwrap();
    fuzz("objects_json", &|b| {
        std::fs::write(dir.join("objects.json"), b).unwrap();
        match tactile_derender::objects::ObjectSet::load_dir(&dir) {
            Ok(set) => set.entries().iter().all(|e| set.mesh(&e.name).is_ok()),
            Err(_) => false,
        }
    });
}

#[test]
fn pairs_csv() {
    fuzz("pairs_csv", &|b| {
        // The table as `tnd dataset import` reads it (text decoding included), then every number it holds.
        let Ok(text) = std::str::from_utf8(b) else {
            return false;
        };
        match tactile_derender::dataset::import::parse_csv(text) {
            Ok(rows) => rows.iter().all(|r| {
                ["x", "y", "theta"]
                    .iter()
                    .all(|k| r.get(*k).is_some_and(|v| v.parse::<f64>().is_ok()))
            }),
            Err(_) => false,
        }
    });
}

#[test]
fn mcap_recording() {
    // The whole read path of a recording: open, every stream, every depth frame (images and projected clouds) and
    // every pose.
    fuzz(
        "mcap",
        &via_file("r.mcap", |p| {
            use tactile_derender::recording::{FolderOptions, Recording, StreamKind};
            let Ok(rec) = Recording::open(p, &FolderOptions::default()) else {
                return false;
            };
            let k = tactile_derender::sensor::Intrinsics::pico_flexx();
            rec.streams().iter().all(|s| match s.kind {
                StreamKind::DepthImage | StreamKind::PointCloud => {
                    (0..s.messages).all(|i| rec.depth_frame(s, i, &k).is_ok())
                }
                StreamKind::Pose => rec.poses(s).is_ok(),
                StreamKind::Other => true,
            })
        }),
    );
}

/// Regenerate the MCAP seeds: `cargo test --test fuzz_loaders -- --ignored write_mcap_corpus`. Two small recordings
/// (chunked and zstd-compressed, and unchunked) with a 4 x 3 16UC1 depth image, a two-point cloud and a pose.
#[test]
#[ignore]
fn write_mcap_corpus() {
    use std::collections::BTreeMap;
    use tactile_derender::recording::ros::{self, ImageMsg, PointCloudMsg, PointField};
    for (name, chunked) in [("chunked_zstd.mcap", true), ("unchunked.mcap", false)] {
        let mut w = mcap::WriteOptions::new()
            .use_chunks(chunked)
            .create(std::io::Cursor::new(Vec::new()))
            .unwrap();
        let meta = BTreeMap::new();
        let img = w
            .add_schema("sensor_msgs/msg/Image", "ros2msg", b"")
            .unwrap();
        let cloud = w
            .add_schema("sensor_msgs/msg/PointCloud2", "ros2msg", b"")
            .unwrap();
        let pose = w
            .add_schema("geometry_msgs/msg/PoseStamped", "ros2msg", b"")
            .unwrap();
        let c_img = w.add_channel(img, "/depth", "cdr", &meta).unwrap();
        let c_cloud = w.add_channel(cloud, "/points", "cdr", &meta).unwrap();
        let c_pose = w.add_channel(pose, "/pose", "cdr", &meta).unwrap();
        for i in 0..2u32 {
            let t = 1_000_000_000 + u64::from(i) * 33_000_000;
            let header = |channel_id| mcap::records::MessageHeader {
                channel_id,
                sequence: i,
                log_time: t,
                publish_time: t,
            };
            let depth = ImageMsg {
                stamp_ns: t,
                height: 3,
                width: 4,
                encoding: "16UC1".into(),
                is_bigendian: false,
                step: 8,
                data: (0..12u16).flat_map(|v| (85 + v).to_le_bytes()).collect(),
            };
            w.write_to_known_channel(&header(c_img), &ros::encode_image(&depth, "cam"))
                .unwrap();
            let fields = ["x", "y", "z"]
                .iter()
                .enumerate()
                .map(|(j, n)| PointField {
                    name: (*n).into(),
                    offset: 4 * j as u32,
                    datatype: 7,
                    count: 1,
                })
                .collect();
            let pts: Vec<u8> = [0.0f32, 0.0, 0.08, 0.01, -0.01, 0.09]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            let pc = PointCloudMsg {
                stamp_ns: t,
                height: 1,
                width: 2,
                fields,
                is_bigendian: false,
                point_step: 12,
                row_step: 24,
                data: pts,
            };
            w.write_to_known_channel(&header(c_cloud), &ros::encode_point_cloud(&pc, "cam"))
                .unwrap();
            let p = ros::encode_pose_stamped(t, 0.001, 0.002, 0.3, "bubble");
            w.write_to_known_channel(&header(c_pose), &p).unwrap();
        }
        w.finish().unwrap();
        let bytes = w.into_inner().into_inner();
        let dir = corpus_dir("mcap");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(name), bytes).unwrap();
    }
}

/// Regenerate the seed corpus: `cargo test --test fuzz_loaders -- --ignored write_fuzz_corpus`.
#[test]
#[ignore]
fn write_fuzz_corpus() {
    use tactile_derender::objects::shapes;
    let put = |kind: &str, name: &str, bytes: &[u8]| {
        let dir = corpus_dir(kind);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(name), bytes).unwrap();
    };
    let sphere = shapes::sphere(0.01, 1).unwrap();
    put("obj", "sphere.obj", sphere.to_obj_string().as_bytes());
    put(
        "obj",
        "groups_quads_negative.obj",
        b"o a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\ng b\nv 0 0 1\nf -1 -4 -3\n# comment\nvn 0 0 1\nf 1//1 2//1 5//1\n",
    );
    let dir = tempfile::tempdir().unwrap();
    let stl = dir.path().join("s.stl");
    mesh::stl::write_binary(&stl, &sphere).unwrap();
    put("stl", "sphere_binary.stl", &std::fs::read(&stl).unwrap());
    put(
        "stl",
        "ascii.stl",
        b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n",
    );
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        sphere.vertices().len(),
        sphere.triangles().len()
    );
    for v in sphere.vertices() {
        ply.push_str(&format!("{} {} {}\n", v.x, v.y, v.z));
    }
    for t in sphere.triangles() {
        ply.push_str(&format!("3 {} {} {}\n", t[0], t[1], t[2]));
    }
    put("ply", "sphere_ascii.ply", ply.as_bytes());
    let mut bin = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        sphere.vertices().len(),
        sphere.triangles().len()
    )
    .into_bytes();
    for v in sphere.vertices() {
        for c in v.to_array() {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in sphere.triangles() {
        bin.push(3);
        for i in t {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    put("ply", "sphere_binary.ply", &bin);
    // glTF with an embedded buffer, and the same as GLB with a BIN chunk.
    let mut buffer = Vec::new();
    for v in sphere.vertices() {
        for c in v.to_array() {
            buffer.extend_from_slice(&c.to_le_bytes());
        }
    }
    let positions_len = buffer.len();
    for t in sphere.triangles() {
        for i in t {
            buffer.extend_from_slice(&i.to_le_bytes());
        }
    }
    let (lo, hi) = sphere.aabb();
    let json = |uri: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0,"scale":[1,1,2]}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],"buffers":[{{"byteLength":{}{uri}}}],"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{positions_len}}},{{"buffer":0,"byteOffset":{positions_len},"byteLength":{}}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":{},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}},{{"bufferView":1,"componentType":5125,"count":{},"type":"SCALAR"}}]}}"#,
            buffer.len(),
            buffer.len() - positions_len,
            sphere.vertices().len(),
            lo.x,
            lo.y,
            lo.z,
            hi.x,
            hi.y,
            hi.z,
            sphere.triangles().len() * 3
        )
    };
    use base64::Engine;
    let data = base64::engine::general_purpose::STANDARD.encode(&buffer);
    put(
        "gltf",
        "sphere_embedded.gltf",
        json(&format!(
            r#","uri":"data:application/octet-stream;base64,{data}""#
        ))
        .as_bytes(),
    );
    let mut chunk_json = json("").into_bytes();
    while chunk_json.len() % 4 != 0 {
        chunk_json.push(b' ');
    }
    let mut chunk_bin = buffer.clone();
    while chunk_bin.len() % 4 != 0 {
        chunk_bin.push(0);
    }
    let total = 12 + 8 + chunk_json.len() + 8 + chunk_bin.len();
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(total as u32).to_le_bytes());
    glb.extend_from_slice(&(chunk_json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&chunk_json);
    glb.extend_from_slice(&(chunk_bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&chunk_bin);
    put("glb", "sphere.glb", &glb);
    // .npy and .npz.
    let image: Vec<f32> = (0..64).map(|i| i as f32 * 1e-3).collect();
    put(
        "npy",
        "f32_8x8.npy",
        &tactile_derender::io::npy::encode_f32(&[8, 8], &image),
    );
    let mut f64_npy = tactile_derender::io::npy::header("<f8", &[2, 3]);
    for i in 0..6 {
        f64_npy.extend_from_slice(&(i as f64 * 0.01).to_le_bytes());
    }
    put("npy", "f64_2x3.npy", &f64_npy);
    use tactile_derender::dataset::npz::{encode, ArrayData};
    let npz = encode(&[
        ArrayData::f32("imprint", vec![2, 4, 4], (0..32).map(|i| i as f32)),
        ArrayData::u64("seed", vec![2], [1, 2]),
        ArrayData::i32("split", vec![2], [0, 1]),
    ])
    .unwrap();
    put("npz", "shard.npz", &npz);
    // A tiny checkpoint: tests/fixtures/unet_small's weights with its config in the metadata.
    let weights = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/unet_small/unet_ref.safetensors"),
    )
    .unwrap();
    put("safetensors", "unet_small.safetensors", &weights);
    // objects.json naming m.obj (the harness writes the sphere there).
    let manifest = r#"{"version":1,"objects":[{"name":"m","mesh":"m.obj","scale_to_m":1.0,"split":"seen","family":"sphere","symmetry":{"rotation":{"n_fold":4}},"dimensions":{"radius":0.01}}]}"#;
    put("objects_json", "one_object.json", manifest.as_bytes());
    put(
        "pairs_csv",
        "pairs.csv",
        &std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/dataset_import/pairs.csv"),
        )
        .unwrap(),
    );
    put(
        "session",
        "example.json",
        &std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("sessions/example.json"))
            .unwrap(),
    );
    put(
        "session",
        "derender.json",
        br#"{"version": 1, "scene": {"press": 0.004, "object": {"library": {"set": "builtin", "name": "sphere_r20"}}}, "derender": {"sampler": "ddim", "steps": 10, "eta": 0.2, "spacing": "leading", "samples": 4, "input": "scene"}, "view": {"tab": "derender"}}"#,
    );
}

/// Headers that claim more elements than memory holds are errors before anything is allocated.
#[test]
fn huge_headers_are_refused() {
    use tactile_derender::io::npy;
    for shape in [
        vec![1usize << 62],
        vec![1 << 31, 1 << 31, 1 << 4],
        vec![usize::MAX, 2],
    ] {
        let mut b = npy::header("<f4", &shape);
        b.extend_from_slice(&[0; 16]);
        let e = npy::decode(&b).unwrap_err().to_string();
        assert!(
            e.contains("memory") || e.contains("truncated"),
            "{shape:?}: {e}"
        );
    }
    let ply = "ply\nformat binary_little_endian 1.0\nelement vertex 4611686018427387904\nproperty float x\n\
        property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    assert!(tactile_derender::mesh::ply::decode(ply.as_bytes()).is_err());
}
