//! PLY reader (ASCII and binary, either endianness) through the `ply-rs-bw` crate: the format scanners and Open3D /
//! trimesh users write first. Object geometry for the simulator (paper IV.A, input of step 1).
//!
//! Vertices come from the `vertex` element's `x`, `y`, `z` (any numeric type); faces from the `face` element's
//! `vertex_indices` (or `vertex_index`) list, polygons fanned into triangles. A point cloud (no faces) is refused
//! with a message saying so: the simulator needs a surface.

use std::path::Path;

use glam::Vec3;
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};

use super::{Mesh, MeshError};

/// Read a PLY file: raw vertex positions in file units and triangle indices.
pub fn read(path: &Path) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), MeshError> {
    let bytes = crate::io::input::read_capped(path, crate::io::input::MAX_MESH_BYTES).map_err(
        |source| MeshError::Io {
            path: path.to_path_buf(),
            source,
        },
    )?;
    decode(&bytes).map_err(|e| MeshError::Parse {
        path: path.to_path_buf(),
        format: "PLY",
        message: e.into(),
    })
}

/// Decode PLY bytes.
pub fn decode(bytes: &[u8]) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("PLY", || {
        let parser = Parser::<DefaultElement>::new();
        let mut reader = bytes;
        // The parser's error is a multi-line dump (the input line, a parser state); its first line says the problem.
        let ply = parser.read_ply(&mut reader).map_err(|e| {
            let text = e.to_string();
            text.lines()
                .map(str::trim)
                .find(|l| !l.is_empty())
                .unwrap_or("not a PLY file")
                .to_string()
        })?;
        let vertex_elements = ply
            .payload
            .get("vertex")
            .ok_or("no 'vertex' element in the header")?;
        let mut vertices = Vec::with_capacity(vertex_elements.len());
        for (i, v) in vertex_elements.iter().enumerate() {
            let coord = |name: &str| {
                v.get(name)
                    .and_then(scalar)
                    .ok_or_else(|| format!("vertex {i} has no numeric '{name}' property"))
            };
            vertices.push(Vec3::new(
                coord("x")? as f32,
                coord("y")? as f32,
                coord("z")? as f32,
            ));
        }
        let faces = ply.payload.get("face").map(Vec::as_slice).unwrap_or(&[]);
        if faces.is_empty() {
            return Err(format!(
                "{} vertices but no faces: a point cloud, not a surface mesh",
                vertices.len()
            ));
        }
        let mut triangles = Vec::with_capacity(faces.len());
        for (f, face) in faces.iter().enumerate() {
            let list = face
                .get("vertex_indices")
                .or_else(|| face.get("vertex_index"))
                .ok_or_else(|| format!("face {f} has no 'vertex_indices' list"))?;
            let indices = index_list(list)
                .ok_or_else(|| format!("face {f}: 'vertex_indices' is not a list of integers"))?;
            if indices.len() < 3 {
                return Err(format!(
                    "face {f} has {} vertices (at least 3 needed)",
                    indices.len()
                ));
            }
            if let Some(&bad) = indices
                .iter()
                .find(|&&i| i < 0 || i >= vertices.len() as i64)
            {
                return Err(format!(
                    "face {f} uses vertex {bad}, but the file has {} vertices",
                    vertices.len()
                ));
            }
            for k in 1..indices.len() - 1 {
                triangles.push([indices[0] as u32, indices[k] as u32, indices[k + 1] as u32]);
            }
        }
        Ok((vertices, triangles))
    })
}

/// A scalar property as f64.
fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v.into(),
        Property::UChar(v) => v.into(),
        Property::Short(v) => v.into(),
        Property::UShort(v) => v.into(),
        Property::Int(v) => v.into(),
        Property::UInt(v) => v.into(),
        Property::Float(v) => v.into(),
        Property::Double(v) => v,
        _ => return None,
    })
}

/// An integer list property as i64.
fn index_list(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListShort(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x.into()).collect(),
        _ => return None,
    })
}

/// Write `mesh` with every vertex mapped by `transform` (e.g. `t_world_object`) as a PLY triangle mesh at `path`
/// (atomically), for Open3D, trimesh and MeshLab.
pub fn write_mesh(
    path: &Path,
    mesh: &Mesh,
    transform: &glam::DAffine3,
    comment: &str,
    encoding: crate::io::ply::PlyEncoding,
) -> std::io::Result<()> {
    let vertices: Vec<[f32; 3]> = mesh
        .vertices()
        .iter()
        .map(|v| {
            let p = transform.transform_point3(v.as_dvec3());
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .collect();
    crate::io::ply::write_triangles(path, &vertices, mesh.triangles(), comment, encoding)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    const ASCII_QUAD_PYRAMID: &str =
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n\
        property float z\nelement face 5\nproperty list uchar int vertex_indices\nend_header\n\
        0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 0.5 1\n4 3 2 1 0\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n";

    #[test]
    fn ascii_polygons_are_fanned() {
        let (v, t) = decode(ASCII_QUAD_PYRAMID.as_bytes()).unwrap();
        assert_eq!(v.len(), 5);
        assert_eq!(v[4], Vec3::new(0.5, 0.5, 1.0));
        assert_eq!(t.len(), 6);
        assert_eq!(t[0], [3, 2, 1]);
        assert_eq!(t[1], [3, 1, 0]);
    }

    #[test]
    fn binary_little_endian_doubles_and_uint_indices() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
            property double z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n"
            .to_vec();
        for x in [0.0f64, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.02, 0.0] {
            b.extend_from_slice(&x.to_le_bytes());
        }
        b.push(3);
        for i in [0u32, 1, 2] {
            b.extend_from_slice(&i.to_le_bytes());
        }
        let (v, t) = decode(&b).unwrap();
        assert_eq!(v[2], Vec3::new(0.0, 0.02, 0.0));
        assert_eq!(t, vec![[0, 1, 2]]);
        // Truncated payload: an error, not a panic.
        assert!(decode(&b[..b.len() - 3]).is_err());
    }

    #[test]
    fn point_clouds_and_bad_indices_are_refused_with_a_reason() {
        let cloud = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
            end_header\n0 0 0\n";
        assert!(decode(cloud.as_bytes())
            .unwrap_err()
            .message
            .contains("point cloud"));
        let bad = ASCII_QUAD_PYRAMID.replace("3 3 0 4\n", "3 3 0 9\n");
        assert!(decode(bad.as_bytes())
            .unwrap_err()
            .message
            .contains("vertex 9"));
        // A header claiming 2^62 vertices is an error, not an allocation.
        let huge = "ply\nformat binary_little_endian 1.0\nelement vertex 4611686018427387904\nproperty float x\n\
            property float y\nproperty float z\nend_header\n";
        assert!(decode(huge.as_bytes()).is_err());
    }

    #[test]
    fn meshes_read_back_through_the_ply_loader_in_both_encodings() {
        let dir = tempfile::tempdir().unwrap();
        let cube = Mesh::from_raw(
            vec![
                glam::Vec3::new(0.0, 0.0, 0.0),
                glam::Vec3::new(0.01, 0.0, 0.0),
                glam::Vec3::new(0.0, 0.02, 0.0),
                glam::Vec3::new(0.0, 0.0, 0.03),
            ],
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            "tetrahedron",
        )
        .unwrap();
        let t = glam::DAffine3::from_translation(glam::DVec3::new(1.0, -2.0, 0.5));
        for enc in [
            crate::io::ply::PlyEncoding::Binary,
            crate::io::ply::PlyEncoding::Ascii,
        ] {
            let p = dir.path().join(format!("tet_{enc:?}.ply"));
            write_mesh(&p, &cube, &t, "a tetrahedron\nworld frame, metres", enc).unwrap();
            let back = crate::mesh::load(&p, &crate::mesh::LoadOptions::default()).unwrap();
            assert_eq!(back.triangles(), cube.triangles());
            for (a, b) in back.vertices().iter().zip(cube.vertices()) {
                let want = t.transform_point3(b.as_dvec3()).as_vec3();
                assert!((*a - want).length() < 1e-6, "{a} vs {want}");
            }
        }
    }
}
