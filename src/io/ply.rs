//! Writing PLY files, the format Open3D, trimesh, MeshLab and CloudCompare users open first: point clouds
//! (reconstructed contact, free-space evidence) and triangle meshes (the object at an estimated pose), in metres,
//! as binary little-endian (compact, the default) or ASCII (readable). Reading PLY meshes is
//! [`crate::mesh::ply`]'s; the tests read these files back with it, and CI with trimesh.

use std::fmt::Write as _;
use std::path::Path;

use glam::DVec3;

use super::write_atomic;

/// PLY body encoding.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum PlyEncoding {
    /// `binary_little_endian 1.0` (float32 coordinates).
    #[default]
    Binary,
    /// `ascii 1.0` (shortest round-trip decimals of the float32 coordinates).
    Ascii,
}

fn header(encoding: PlyEncoding, comment: &str, vertices: usize, faces: Option<usize>) -> String {
    let format = match encoding {
        PlyEncoding::Binary => "binary_little_endian",
        PlyEncoding::Ascii => "ascii",
    };
    let mut h = format!("ply\nformat {format} 1.0\n");
    for line in comment.lines() {
        let _ = writeln!(h, "comment {line}");
    }
    let _ = writeln!(
        h,
        "element vertex {vertices}\nproperty float x\nproperty float y\nproperty float z"
    );
    if let Some(f) = faces {
        let _ = writeln!(
            h,
            "element face {f}\nproperty list uchar int vertex_indices"
        );
    }
    h.push_str("end_header\n");
    h
}

fn body(encoding: PlyEncoding, vertices: &[[f32; 3]], faces: &[[u32; 3]], out: &mut Vec<u8>) {
    match encoding {
        PlyEncoding::Binary => {
            for v in vertices {
                for c in v {
                    out.extend_from_slice(&c.to_le_bytes());
                }
            }
            for f in faces {
                out.push(3);
                for &i in f {
                    // Indices of a mesh we hold fit an int (the loaders bound vertex counts far below 2^31).
                    out.extend_from_slice(&(i as i32).to_le_bytes());
                }
            }
        }
        PlyEncoding::Ascii => {
            let mut s = String::new();
            for [x, y, z] in vertices {
                let _ = writeln!(s, "{x} {y} {z}");
            }
            for [a, b, c] in faces {
                let _ = writeln!(s, "3 {a} {b} {c}");
            }
            out.extend_from_slice(s.as_bytes());
        }
    }
}

/// Write `points` (metres) as a PLY point cloud at `path` (atomically); `comment` says what they are and in which
/// frame.
pub fn write_points(
    path: &Path,
    points: &[DVec3],
    comment: &str,
    encoding: PlyEncoding,
) -> std::io::Result<()> {
    let vertices: Vec<[f32; 3]> = points
        .iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let mut out = header(encoding, comment, vertices.len(), None).into_bytes();
    body(encoding, &vertices, &[], &mut out);
    write_atomic(path, &out)
}

/// Write a triangle mesh (vertices in the frame the comment names, metres) as PLY at `path` (atomically);
/// [`crate::mesh::ply::write_mesh`] writes a [`crate::mesh::Mesh`] at a pose.
pub fn write_triangles(
    path: &Path,
    vertices: &[[f32; 3]],
    faces: &[[u32; 3]],
    comment: &str,
    encoding: PlyEncoding,
) -> std::io::Result<()> {
    let mut out = header(encoding, comment, vertices.len(), Some(faces.len())).into_bytes();
    body(encoding, vertices, faces, &mut out);
    write_atomic(path, &out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_clouds_have_the_declared_count_and_values() {
        let dir = tempfile::tempdir().unwrap();
        let pts = [DVec3::new(0.1, 0.2, 0.3), DVec3::new(-1.5, 0.0, 2.25)];
        let p = dir.path().join("pts.ply");
        write_points(&p, &pts, "two points", PlyEncoding::Ascii).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(
            text.contains("element vertex 2\n") && text.ends_with("0.1 0.2 0.3\n-1.5 0 2.25\n"),
            "{text}"
        );
        write_points(&p, &pts, "two points", PlyEncoding::Binary).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        let body: Vec<f32> = bytes[end..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(body, vec![0.1, 0.2, 0.3, -1.5, 0.0, 2.25]);
    }
}
