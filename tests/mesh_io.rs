//! End-to-end tests of mesh loading (OBJ, STL), units, fit-to-size and error reporting, through the public API only.
//! Every input file is generated here, in a temporary directory.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::Vec3;
use tactile_derender::mesh::{self, stl, LoadOptions, Mesh, Units};

/// Unit cube [0, 1]³: eight corners, then six outward-facing (counter-clockwise from outside) quads.
const CUBE_VERTICES: &str =
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n";
const CUBE_QUADS: [[i32; 4]; 6] = [
    [1, 4, 3, 2],
    [5, 6, 7, 8],
    [1, 2, 6, 5],
    [4, 8, 7, 3],
    [1, 5, 8, 4],
    [2, 3, 7, 6],
];

fn write(dir: &Path, name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, contents).unwrap();
    path
}

/// The cube as OBJ text, each quad written by `face` (e.g. to add texture/normal indices).
fn cube_obj(face: impl Fn(usize, &[i32; 4]) -> String) -> String {
    let mut s = String::from(CUBE_VERTICES);
    for (i, q) in CUBE_QUADS.iter().enumerate() {
        writeln!(s, "{}", face(i, q)).unwrap();
    }
    s
}

fn plain_face(_: usize, q: &[i32; 4]) -> String {
    format!("f {} {} {} {}", q[0], q[1], q[2], q[3])
}

fn load(path: &Path) -> Mesh {
    mesh::load(path, &LoadOptions::default()).unwrap()
}

fn assert_unit_cube(m: &Mesh) {
    let report = m.report();
    assert_eq!(report.triangles, 12);
    assert!(report.closed, "{report:?}");
    assert!((report.volume_m3 - 1.0).abs() < 1e-6, "{report:?}");
}

#[test]
fn obj_quad_cube_is_closed_with_unit_volume() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "cube.obj", cube_obj(plain_face));
    let m = load(&path);
    assert_eq!(m.vertices().len(), 8);
    assert_unit_cube(&m);
}

#[test]
fn obj_units_scale_to_metres() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "cube.obj", cube_obj(plain_face));
    for (units, side) in [(Units::Cm, 0.01), (Units::Mm, 0.001), (Units::M, 1.0)] {
        let options = LoadOptions {
            units,
            fit_to_size: None,
        };
        let m = mesh::load(&path, &options).unwrap();
        let (lo, hi) = m.aabb();
        assert!(
            ((hi - lo).max_element() as f64 - side).abs() < 1e-9 * side.max(1.0),
            "{units}"
        );
        let volume = m.report().volume_m3;
        assert!(
            (volume - side.powi(3)).abs() < 1e-6 * side.powi(3),
            "{units}: {volume}"
        );
    }
    let cm: Units = "cm".parse().unwrap();
    assert_eq!(cm.to_metres(), 0.01);
}

#[test]
fn obj_hexagon_is_fan_triangulated() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::new();
    for k in 0..6 {
        let a = std::f32::consts::FRAC_PI_3 * k as f32;
        writeln!(text, "v {} {} 0", a.cos(), a.sin()).unwrap();
    }
    text.push_str("f 1 2 3 4 5 6\n");
    let m = load(&write(dir.path(), "hex.obj", text));
    assert_eq!(m.triangles().len(), 4);
    let area: f32 = (0..4)
        .map(|i| {
            let [a, b, c] = m.triangle(i);
            0.5 * (b - a).cross(c - a).z
        })
        .sum();
    assert!((area - 1.5 * 3f32.sqrt()).abs() < 1e-5, "area {area}");
}

#[test]
fn obj_missing_and_broken_material_files_are_ignored() {
    let dir = tempfile::tempdir().unwrap();
    let missing = format!("mtllib missing.mtl\nusemtl red\n{}", cube_obj(plain_face));
    assert_unit_cube(&load(&write(dir.path(), "missing.obj", missing)));
    write(dir.path(), "broken.mtl", "newmtl red\nKd 1 1\nNs\n");
    let broken = format!("mtllib broken.mtl\nusemtl red\n{}", cube_obj(plain_face));
    assert_unit_cube(&load(&write(dir.path(), "broken.obj", broken)));
}

#[test]
fn obj_with_texture_coordinates_and_normals() {
    let dir = tempfile::tempdir().unwrap();
    let header = "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 -1\nvn 0 0 1\nvn 0 -1 0\nvn 0 1 0\nvn -1 0 0\nvn 1 0 0\n";
    let full = |i: usize, q: &[i32; 4]| {
        let n = i + 1;
        format!(
            "f {}/1/{n} {}/2/{n} {}/3/{n} {}/4/{n}",
            q[0], q[1], q[2], q[3]
        )
    };
    assert_unit_cube(&load(&write(
        dir.path(),
        "full.obj",
        format!("{header}{}", cube_obj(full)),
    )));
    let normals_only = |i: usize, q: &[i32; 4]| {
        let n = i + 1;
        format!("f {}//{n} {}//{n} {}//{n} {}//{n}", q[0], q[1], q[2], q[3])
    };
    assert_unit_cube(&load(&write(
        dir.path(),
        "vn.obj",
        format!("{header}{}", cube_obj(normals_only)),
    )));
    let texture_only =
        |_: usize, q: &[i32; 4]| format!("f {}/1 {}/2 {}/3 {}/4", q[0], q[1], q[2], q[3]);
    assert_unit_cube(&load(&write(
        dir.path(),
        "vt.obj",
        format!("{header}{}", cube_obj(texture_only)),
    )));
}

#[test]
fn obj_objects_and_groups_are_merged_into_one_closed_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let grouped = |i: usize, q: &[i32; 4]| {
        let tag = match i {
            0 => "o first\n",
            3 => "g second\n",
            _ => "",
        };
        format!("{tag}{}", plain_face(i, q))
    };
    let m = load(&write(dir.path(), "groups.obj", cube_obj(grouped)));
    // Groups share the file's vertex list: the cube stays watertight without welding.
    assert_eq!(m.vertices().len(), 8);
    assert_unit_cube(&m);
}

#[test]
fn obj_negative_indices() {
    let dir = tempfile::tempdir().unwrap();
    let relative = |_: usize, q: &[i32; 4]| {
        let r = q.map(|i| i - 9);
        format!("f {} {} {} {}", r[0], r[1], r[2], r[3])
    };
    let text = cube_obj(relative);
    assert!(text.contains("f -8 -5 -6 -7"));
    assert_unit_cube(&load(&write(dir.path(), "negative.obj", text)));
}

#[test]
fn obj_write_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let m = load(&write(dir.path(), "cube.obj", cube_obj(plain_face)));
    let out = dir.path().join("written.obj");
    mesh::obj::write(&out, &m).unwrap();
    assert_eq!(load(&out), m);
}

fn ascii_stl(m: &Mesh) -> String {
    let mut s = String::from("solid Cube exported\n");
    for i in 0..m.triangles().len() {
        let [a, b, c] = m.triangle(i);
        let n = (b - a).cross(c - a).normalize();
        // Mixed case and irregular whitespace, as found in the wild.
        writeln!(s, "  FACET normal {} {} {}\n\touter  loop", n.x, n.y, n.z).unwrap();
        for v in [a, b, c] {
            writeln!(s, "      vertex\t{:e} {} {}  ", v.x, v.y, v.z).unwrap();
        }
        s.push_str("    endloop\r\n  EndFacet\n");
    }
    s.push_str("endsolid Cube exported\n");
    s
}

#[test]
fn stl_ascii_cube_welds_to_a_closed_unit_cube() {
    let dir = tempfile::tempdir().unwrap();
    let cube = load(&write(dir.path(), "cube.obj", cube_obj(plain_face)));
    let m = load(&write(dir.path(), "cube.stl", ascii_stl(&cube)));
    assert_eq!(m.vertices().len(), 36, "STL facets are not welded on load");
    let welded = m.welded(1e-9);
    assert_eq!(welded.vertices().len(), 8);
    assert_unit_cube(&welded);
    // What `tnd objects list` and `check` report: open as stored, closed once welded at the extent's scale.
    assert!(!m.report().closed);
    let topology = m.welded_for_topology();
    assert_eq!(topology.vertices().len(), 8);
    assert!(topology.report().closed);
}

#[test]
fn stl_binary_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let cube = load(&write(dir.path(), "cube.obj", cube_obj(plain_face)));
    let path = dir.path().join("cube.stl");
    stl::write_binary(&path, &cube).unwrap();
    assert_eq!(std::fs::metadata(&path).unwrap().len(), 84 + 50 * 12);
    let m = load(&path);
    assert_eq!(m.triangles().len(), cube.triangles().len());
    for i in 0..cube.triangles().len() {
        assert_eq!(m.triangle(i), cube.triangle(i));
    }
    assert_unit_cube(&m.welded(1e-9));
    // Upper-case extension and raw reader agree.
    let upper = dir.path().join("CUBE.STL");
    std::fs::copy(&path, &upper).unwrap();
    assert_eq!(load(&upper), m);
    assert_eq!(stl::read(&path).unwrap().0.len(), 36);
}

#[test]
fn fit_to_size_scales_the_largest_extent() {
    let dir = tempfile::tempdir().unwrap();
    let text = "v 0 0 0\nv 2 0 0\nv 0 1 0\nv 0 0 0.5\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    let path = write(dir.path(), "tet.obj", text);
    let options = LoadOptions {
        units: Units::Cm,
        fit_to_size: Some(0.05),
    };
    let m = mesh::load(&path, &options).unwrap();
    let extent = {
        let (lo, hi) = m.aabb();
        hi - lo
    };
    assert!((extent.x - 0.05).abs() < 1e-7, "{extent}");
    assert!((extent.y - 0.025).abs() < 1e-7, "{extent}");
    assert!((extent.z - 0.0125).abs() < 1e-7, "{extent}");
}

/// `load` must fail without panicking, and the message must name the file.
fn assert_fails_naming_file(path: &Path) -> String {
    let err = mesh::load(path, &LoadOptions::default()).expect_err("bad input was accepted");
    let message = err.to_string();
    let name = path.file_name().unwrap().to_string_lossy();
    assert!(
        message.contains(name.as_ref()),
        "'{message}' does not name {name}"
    );
    message
}

#[test]
fn bad_inputs_give_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    assert_fails_naming_file(&write(d, "empty.obj", ""));
    assert_fails_naming_file(&write(d, "comments_only.obj", "# nothing\n\n"));
    assert_fails_naming_file(&write(d, "empty.stl", ""));
    assert_fails_naming_file(&write(
        d,
        "nan.obj",
        "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    ));
    let message = assert_fails_naming_file(&write(d, "range.obj", format!("{tri}f 1 2 99\n")));
    assert!(
        message.contains("99") && message.contains("line 4"),
        "{message}"
    );
    assert_fails_naming_file(&write(
        d,
        "range_negative.obj",
        format!("{tri}f -1 -2 -7\n"),
    ));
    // Normal and texture indices are not needed and not checked: a bad one (which panics inside tobj) is ignored.
    let bad_normal = write(
        d,
        "range_normal.obj",
        format!("{tri}vn 0 0 1\nf 1//-9 2//1 3//1\n"),
    );
    assert_eq!(load(&bad_normal).triangles().len(), 1);
    assert_fails_naming_file(&write(d, "bad_number.obj", "v 0 zero 0\n"));
    assert_fails_naming_file(&write(
        d,
        "collinear.obj",
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
    ));
    assert_fails_naming_file(&d.join("does_not_exist.obj"));
    assert_fails_naming_file(&d.join("does_not_exist.stl"));
    std::fs::create_dir(d.join("directory.obj")).unwrap();
    assert_fails_naming_file(&d.join("directory.obj"));
    assert_fails_naming_file(&write(d, "model.ply", "ply\nformat ascii 1.0\n"));
    // Not a PLY at all: one line (the parser's first), not its multi-line dump.
    let message = assert_fails_naming_file(&write(d, "junk.ply", "junk text\nmore\n"));
    assert!(
        message.contains("Expected magic number") && !message.contains('\n'),
        "{message}"
    );
    // A file cut inside its last face is truncated, not a mesh with a face fewer.
    let message = assert_fails_naming_file(&write(
        d,
        "truncated.obj",
        format!("{tri}v 1 1 0\nf 1 2 3\nf 2 4//"),
    ));
    assert!(
        message.contains("line 6") && message.contains("truncated"),
        "{message}"
    );
    assert_fails_naming_file(&write(d, "no_extension", tri));
    let bad_vertex = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\nvertex 0 1 0\nendloop\nendfacet\n";
    let message = assert_fails_naming_file(&write(d, "bad_vertex.stl", bad_vertex));
    assert!(message.contains("line 5"), "{message}");
}

#[test]
fn truncated_binary_stl_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let cube = load(&write(dir.path(), "cube.obj", cube_obj(plain_face)));
    let path = dir.path().join("truncated.stl");
    stl::write_binary(&path, &cube).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 30]).unwrap();
    let message = assert_fails_naming_file(&path);
    assert!(message.contains("12 triangles"), "{message}");
    // Same with a header starting with "solid", as many binary exporters write.
    let mut solid = bytes.clone();
    solid[..6].copy_from_slice(b"solid ");
    std::fs::write(&path, &solid[..solid.len() - 30]).unwrap();
    assert_fails_naming_file(&path);
    std::fs::write(&path, &solid).unwrap();
    assert_eq!(load(&path).triangles().len(), 12);
}

#[test]
fn bad_units_are_rejected() {
    let err = "furlong".parse::<Units>().unwrap_err();
    assert!(err.to_string().contains("furlong"));
    assert!("-1".parse::<Units>().is_err());
    assert!("0".parse::<Units>().is_err());
    assert_eq!("0.0254".parse::<Units>().unwrap(), Units::Scale(0.0254));
    assert_eq!(" MM ".parse::<Units>().unwrap(), Units::Mm);
}

#[test]
fn raw_readers_return_file_units() {
    let dir = tempfile::tempdir().unwrap();
    let (v, t) = mesh::obj::read(&write(dir.path(), "cube.obj", cube_obj(plain_face))).unwrap();
    assert_eq!((v.len(), t.len()), (8, 12));
    assert!(v.contains(&Vec3::ONE));
}
