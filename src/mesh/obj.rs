//! Wavefront OBJ reader and writer: object geometry for the simulator (paper IV.A, input of step 1).
//!
//! Parsing is done by `tobj`, behind a small pre-pass ([`sanitize`]) that reduces the file to what the simulator
//! needs (positions and faces) and validates every face index with its line number. The pre-pass exists because
//! `tobj` 4.0.5 has sharp edges on real-world files:
//!
//! - a broken `.mtl` (e.g. `Kd 1 1`) panics inside `tobj`, so `mtllib`/`usemtl` are dropped and no material file is
//!   ever opened;
//! - a relative texture/normal index that points before the first `vt`/`vn` (`f 1/-5 ...`) overflows and panics in
//!   debug builds, and a one-component `vt u` is rejected, so `vt`/`vn` lines and the texture/normal parts of face
//!   corners are dropped;
//! - polylines (`l 1 2 3`) are turned into triangles, so `l` lines are dropped;
//! - each `o`/`g`/`usemtl` section becomes a model with its own vertex numbering, which duplicates vertices shared
//!   between groups (a cube exported one group per side would no longer be closed), so those lines are dropped and
//!   the whole file is one model over the global vertex list;
//! - vertex colours on only some vertices (`v x y z r g b`) make loading fail, so colours are dropped.
//!
//! Relative (negative) position indices are handled by `tobj` (resolved against the vertices defined so far); the
//! pre-pass checks them first so that an out-of-range index is a clear error naming the line.

/// The first line of every OBJ tnd writes ([`super::Mesh::to_obj_string`]): how a command knows a mesh it may replace.
pub const OBJ_MARK: &str = "# written by tactile-derender";

/// Whether `path` is an OBJ file tnd wrote (its first line is [`OBJ_MARK`]).
pub fn written_by_tnd(path: &std::path::Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; OBJ_MARK.len()];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|()| head == *OBJ_MARK.as_bytes())
}

use std::path::Path;

use glam::Vec3;

use super::{Mesh, MeshError};

/// Read an OBJ file: raw vertex positions in file units and triangle indices (quads and n-gons fan-triangulated,
/// all objects and groups merged into one mesh). Validation of the geometry is left to [`Mesh::from_raw`].
pub fn read(path: &Path) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), MeshError> {
    let bytes = crate::io::input::read_capped(path, crate::io::input::MAX_MESH_BYTES).map_err(
        |source| MeshError::Io {
            path: path.to_path_buf(),
            source,
        },
    )?;
    // Non-UTF-8 bytes (e.g. Latin-1 in comments or names) must not reject the file; they never matter for v/f lines.
    let text = String::from_utf8_lossy(&bytes);
    let clean = sanitize(&text).map_err(|message| parse_error(path, message))?;
    // `..Default::default()` covers the fields that exist only with tobj's optional features (merging, reordering).
    #[allow(clippy::needless_update)]
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    // The sanitized text has no `mtllib`; the loader refuses anyway so that no material file is ever parsed.
    let (models, _materials) = tobj::load_obj_buf(&mut clean.as_bytes(), &options, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| parse_error(path, format!("{e}")))?;
    let (vertices, triangles) = merge(&models).map_err(|message| parse_error(path, message))?;
    if triangles.is_empty() {
        return Err(MeshError::Empty {
            context: path.display().to_string(),
        });
    }
    Ok((vertices, triangles))
}

/// Write `mesh` as OBJ text (metres, one-based indices), atomically (a crash never leaves a half-written file).
pub fn write(path: &Path, mesh: &Mesh) -> Result<(), MeshError> {
    crate::io::write_atomic(path, mesh.to_obj_string().as_bytes()).map_err(|source| {
        MeshError::Write {
            path: path.to_path_buf(),
            source,
        }
    })
}

fn parse_error(path: &Path, message: String) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        format: "OBJ",
        message,
    }
}

/// Concatenate `tobj` models into one indexed mesh, offsetting each model's indices by the vertices before it.
fn merge(models: &[tobj::Model]) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), String> {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for model in models {
        let base =
            u32::try_from(vertices.len()).map_err(|_| "more than 2^32 vertices".to_string())?;
        let count = model.mesh.positions.len() / 3;
        vertices.extend(
            model
                .mesh
                .positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2])),
        );
        for t in model.mesh.indices.chunks_exact(3) {
            if let Some(&bad) = t.iter().find(|&&i| i as usize >= count) {
                return Err(format!(
                    "internal: triangle index {bad} out of range in object '{}'",
                    model.name
                ));
            }
            let shifted = [t[0], t[1], t[2]].map(|i| base.checked_add(i));
            match shifted {
                [Some(a), Some(b), Some(c)] => triangles.push([a, b, c]),
                _ => return Err("more than 2^32 vertices".to_string()),
            }
        }
    }
    Ok((vertices, triangles))
}

/// Reduce OBJ text to `v x y z [w]` and `f i j k ...` lines (position indices only, as written, relative ones
/// included), validating numbers and indices. Errors name the one-based line.
fn sanitize(text: &str) -> Result<String, String> {
    // Positive indices may refer to vertices defined later in the file (tobj resolves them once the file is read).
    let total = text
        .lines()
        .filter(|l| without_comment(l).split_whitespace().next() == Some("v"))
        .count();
    let mut defined = 0usize;
    let mut out = String::with_capacity(text.len());
    // A file cut short ends inside its last line (no newline after it).
    let last = text
        .lines()
        .enumerate()
        .last()
        .filter(|_| !text.ends_with('\n'))
        .map(|(i, _)| i + 1);
    for (number, raw) in text.lines().enumerate() {
        let number = number + 1;
        let line = without_comment(raw);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let values: Vec<&str> = words.collect();
                out.push_str(
                    &vertex_line(&values)
                        .map_err(|m| format!("line {number}: {m}: '{}'", raw.trim()))?,
                );
                defined += 1;
            }
            Some("f") => {
                let corners: Vec<&str> = words.collect();
                if corners.len() < 3 && Some(number) == last {
                    // The file ends inside a face: cut short, with the rest of its faces missing (a complete
                    // line with too few corners is a point or a segment, ignored below).
                    return Err(format!(
                        "line {number}: the last face has {} corner(s), a face needs 3: the file looks truncated",
                        corners.len()
                    ));
                }
                if corners.len() < 3 {
                    continue; // A point or a line has no surface; tobj would ignore it too.
                }
                out.push('f');
                for corner in corners {
                    let index = face_index(corner, defined, total)
                        .map_err(|m| format!("line {number}: {m}"))?;
                    out.push(' ');
                    out.push_str(&index.to_string());
                }
                out.push('\n');
            }
            _ => {}
        }
    }
    Ok(out)
}

/// Validate the numbers of a `v` line and return it without vertex colours: `x y z`, or `x y z w` (homogeneous).
fn vertex_line(values: &[&str]) -> Result<String, String> {
    let parse = |s: &str| {
        s.parse::<f32>()
            .map_err(|_| format!("'{s}' is not a number"))
    };
    if values.len() < 3 {
        return Err("a vertex needs three coordinates".to_string());
    }
    for value in &values[..3] {
        parse(value)?; // NaN is a number here: Mesh::from_raw reports non-finite vertices with their index.
    }
    let mut line = format!("v {} {} {}", values[0], values[1], values[2]);
    if values.len() == 4 {
        let w = parse(values[3])?;
        if w == 0.0 || !w.is_finite() {
            return Err(format!("homogeneous weight w = {w} cannot be divided by"));
        }
        line.push(' ');
        line.push_str(values[3]);
    }
    // Any other extra values (r g b colours) are dropped.
    line.push('\n');
    Ok(line)
}

/// `line` up to its `#` comment.
fn without_comment(line: &str) -> &str {
    line.split('#').next().unwrap_or("")
}

/// The position index of a face corner (`v`, `v/vt`, `v//vn` or `v/vt/vn`), checked against the `defined` vertices
/// so far (relative indices) or the `total` in the file (absolute indices).
fn face_index(corner: &str, defined: usize, total: usize) -> Result<i64, String> {
    let position = corner.split('/').next().unwrap_or("");
    let index: i64 = position
        .parse()
        .map_err(|_| format!("cannot read the vertex index of face corner '{corner}'"))?;
    let ok = match index {
        0 => {
            return Err(format!(
                "face corner '{corner}' uses vertex index 0 (OBJ indices start at 1)"
            ))
        }
        i if i > 0 => i.unsigned_abs() <= total as u64,
        i => i.unsigned_abs() <= defined as u64,
    };
    if ok {
        Ok(index)
    } else if index > 0 {
        Err(format!(
            "face refers to vertex {index}, but the file defines only {total} vertices"
        ))
    } else {
        Err(format!("face refers to relative vertex {index}, but only {defined} vertices are defined before it"))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn sanitize_keeps_positions_and_faces_only() {
        let text =
            "mtllib a.mtl\no one\nv 0 0 0 1 0 0 # red\nv 1 0 0\nv 0 1 0 2\nvt 0.5\nvn 0 0 1\n\
                    usemtl red\ng two\nf 1/1/1 2//1 3/1\nl 1 2 3\nf 1 2\n";
        let clean = sanitize(text).unwrap();
        assert_eq!(clean, "v 0 0 0\nv 1 0 0\nv 0 1 0 2\nf 1 2 3\n");
    }

    #[test]
    fn out_of_range_indices_name_the_line() {
        let v = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        let err = sanitize(&format!("{v}f 1 2 99\n")).unwrap_err();
        assert!(err.contains("line 4") && err.contains("99"), "{err}");
        let err = sanitize(&format!("{v}f -4 1 2\n")).unwrap_err();
        assert!(err.contains("line 4") && err.contains("-4"), "{err}");
        let err = sanitize(&format!("{v}f 0 1 2\n")).unwrap_err();
        assert!(err.contains("index 0"), "{err}");
        let err = sanitize(&format!("{v}f 1 x 2\n")).unwrap_err();
        assert!(err.contains("'x'"), "{err}");
        // Relative indices count only the vertices defined before the face.
        assert!(sanitize(&format!("v 0 0 0\nf -1 -2 -3\n{v}")).is_err());
        // Absolute forward references are accepted (tobj resolves them at the end of the file).
        assert!(sanitize(&format!("f 1 2 3\n{v}")).is_ok());
    }

    #[test]
    fn bad_vertex_lines_name_the_line() {
        let err = sanitize("v 1 2\n").unwrap_err();
        assert!(err.contains("line 1") && err.contains("three"), "{err}");
        let err = sanitize("# c\nv 1 y 2\n").unwrap_err();
        assert!(err.contains("line 2") && err.contains("'y'"), "{err}");
        assert!(sanitize("v 1 2 3 0\n").is_err());
    }

    #[test]
    fn texture_and_normal_indices_out_of_range_do_not_panic() {
        // tobj 4.0.5 alone overflows on these in debug builds; texture/normal parts are not needed and are dropped.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.obj");
        std::fs::write(
            &path,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/-5/-9 2/7/1 3/1/8\n",
        )
        .unwrap();
        let (v, t) = read(&path).unwrap();
        assert_eq!((v.len(), t), (3, vec![[0, 1, 2]]));
    }

    #[test]
    fn broken_material_file_is_ignored() {
        // tobj 4.0.5 panics on `Kd 1 1` when it parses the material file itself.
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("m.mtl"), "newmtl red\nKd 1 1\n").unwrap();
        let path = dir.path().join("t.obj");
        std::fs::write(
            &path,
            "mtllib m.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        )
        .unwrap();
        assert_eq!(read(&path).unwrap().1, vec![[0, 1, 2]]);
    }

    #[test]
    fn groups_share_the_global_vertex_list() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.obj");
        std::fs::write(
            &path,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\ng a\nf 1 2 3\ng b\nf 2 4 3\n",
        )
        .unwrap();
        let (v, t) = read(&path).unwrap();
        assert_eq!(
            v.len(),
            4,
            "shared vertices must not be duplicated per group"
        );
        assert_eq!(t, vec![[0, 1, 2], [1, 3, 2]]);
    }

    #[test]
    fn merge_offsets_indices_per_model() {
        let model = |positions: Vec<f32>, indices: Vec<u32>| {
            let mesh = tobj::Mesh {
                positions,
                indices,
                ..Default::default()
            };
            tobj::Model::new(mesh, "m".to_string())
        };
        let tri = vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let (v, t) =
            merge(&[model(tri.clone(), vec![0, 1, 2]), model(tri, vec![2, 1, 0])]).unwrap();
        assert_eq!(v.len(), 6);
        assert_eq!(t, vec![[0, 1, 2], [5, 4, 3]]);
        assert!(merge(&[model(vec![0.0; 3], vec![0, 0, 1])]).is_err());
    }
}
