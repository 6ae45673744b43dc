//! glTF 2.0 reader (`.gltf` with external or embedded buffers, and binary `.glb`) through the `gltf` crate: the
//! format of scanned-object libraries and web viewers. Object geometry for the simulator (paper IV.A, input of
//! step 1).
//!
//! Every triangle primitive of every mesh reachable from the default scene (or from all scenes when none is marked
//! default, or every mesh when there are no scenes) is placed by its node's world transform and merged into one
//! triangle soup. glTF positions are metres by specification, and its up axis is +Y: the soup is turned into this
//! project's +Z-up frame the way Blender imports glTF, (x, y, z) → (x, −z, y), so that a model exported from
//! Blender or a scanner app stands on the table as it was modelled.

use std::path::Path;

use base64::Engine;
use glam::{Mat4, Vec3};
use gltf::mesh::Mode;

use super::MeshError;

/// Read a `.gltf` or `.glb` file: raw vertex positions (file units, metres by the glTF specification) and triangles.
pub fn read(path: &Path) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), MeshError> {
    let bytes = crate::io::input::read_capped(path, crate::io::input::MAX_MESH_BYTES).map_err(
        |source| MeshError::Io {
            path: path.to_path_buf(),
            source,
        },
    )?;
    let dir = path.parent().unwrap_or(Path::new("."));
    decode(&bytes, Some(dir)).map_err(|e| MeshError::Parse {
        path: path.to_path_buf(),
        format: "glTF",
        message: e.into(),
    })
}

/// Decode glTF or GLB bytes; external buffers are looked up in `dir` (refused when `None`).
pub fn decode(
    bytes: &[u8],
    dir: Option<&Path>,
) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("glTF", || {
        // gltf-json 1.4.1's validation indexes some references before checking them (a POSITION accessor index out of
        // range panics; found by tests/fuzz_loaders.rs): a panic inside the crate becomes an error naming the file.
        std::panic::catch_unwind(|| decode_unguarded(bytes, dir)).unwrap_or_else(|_| {
            Err(
            "the file's JSON refers to objects it does not define (the glTF library stopped on it)"
                .into(),
        )
        })
    })
}

fn decode_unguarded(
    bytes: &[u8],
    dir: Option<&Path>,
) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), String> {
    // Geometry behind a required extension (Draco or meshopt compression, quantised positions) is not plain
    // accessors; validation would only report the accessors' missing data, one message per accessor.
    if let Ok(raw) = gltf::Gltf::from_slice_without_validation(bytes) {
        let required: Vec<&str> = raw.extensions_required().collect();
        if !required.is_empty() {
            return Err(format!(
                "the file requires the glTF extension{} {}, which this reader does not support; export it without \
                 ({})",
                if required.len() > 1 { "s" } else { "" },
                required.join(", "),
                export_advice(&required)
            ));
        }
    }
    if let Some(version) = gltf_1_version(bytes) {
        return Err(format!(
            "glTF {version} file; only glTF 2.0 is read (convert it, e.g. with the Khronos glTF 1.0 → 2.0 converter \
             or by importing and exporting it in Blender)"
        ));
    }
    let doc = gltf::Gltf::from_slice(bytes).map_err(|e| e.to_string())?;
    let mut buffers = Vec::new();
    for buffer in doc.buffers() {
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => doc
                .blob
                .clone()
                .ok_or("a buffer refers to the GLB binary chunk, but the file has none")?,
            gltf::buffer::Source::Uri(uri) => load_uri(uri, dir)?,
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "buffer {} holds {} bytes but declares {}",
                buffer.index(),
                data.len(),
                buffer.length()
            ));
        }
        buffers.push(data);
    }
    let mut out = Soup::default();
    let scenes: Vec<gltf::Scene> = match doc.default_scene() {
        Some(s) => vec![s],
        None => doc.scenes().collect(),
    };
    // glTF's +Y up becomes +Z up: a quarter turn about +X, (x, y, z) → (x, −z, y).
    let z_up = Mat4::from_rotation_x(std::f32::consts::FRAC_PI_2);
    if scenes.is_empty() {
        for mesh in doc.meshes() {
            out.add_mesh(&mesh, z_up, &buffers)?;
        }
    } else {
        for scene in scenes {
            for node in scene.nodes() {
                out.add_node(&node, z_up, &buffers, 0)?;
            }
        }
    }
    if out.triangles.is_empty() {
        return Err("no triangle primitives in the file's scenes".into());
    }
    Ok((out.vertices, out.triangles))
}

/// The bytes of a buffer URI: a base64 `data:` URI or a file next to the glTF.
/// How to export a file without the `required` extensions.
fn export_advice(required: &[&str]) -> &'static str {
    if required.contains(&"KHR_mesh_quantization") {
        "e.g. gltfpack -noq, or Blender without quantised positions"
    } else if required.contains(&"EXT_meshopt_compression") {
        "e.g. gltfpack without -c"
    } else {
        "e.g. from Blender with mesh compression off"
    }
}

/// The `asset.version` of a glTF 1.x JSON file (whose layout the 2.0 parser rejects with an unhelpful message).
fn gltf_1_version(bytes: &[u8]) -> Option<String> {
    let json: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    let version = json.get("asset")?.get("version")?;
    let text = version
        .as_str()
        .map(str::to_string)
        .or_else(|| version.as_f64().map(|v| format!("{v:.1}")))?;
    text.starts_with('1').then_some(text)
}

fn load_uri(uri: &str, dir: Option<&Path>) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest
            .split_once(";base64,")
            .ok_or("a data URI buffer is not base64-encoded")?;
        return base64::engine::general_purpose::STANDARD
            .decode(payload)
            .map_err(|e| format!("a data URI buffer is not valid base64: {e}"));
    }
    let dir = dir.ok_or_else(|| format!("external buffer '{uri}' cannot be resolved here"))?;
    if uri.contains("..") || Path::new(uri).is_absolute() {
        return Err(format!(
            "external buffer '{uri}' must be a relative path inside the model's folder"
        ));
    }
    let path = dir.join(uri.replace("%20", " "));
    crate::io::input::read_capped(&path, crate::io::input::MAX_MESH_BYTES)
        .map_err(|e| format!("external buffer {}: {e}", path.display()))
}

/// The merged triangle soup.
#[derive(Default)]
struct Soup {
    vertices: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

impl Soup {
    fn add_node(
        &mut self,
        node: &gltf::Node,
        parent: Mat4,
        buffers: &[Vec<u8>],
        depth: usize,
    ) -> Result<(), String> {
        // Validation rejects cycles; the depth bound also keeps a pathological deep hierarchy off the stack.
        if depth > 256 {
            return Err("the node hierarchy is deeper than 256 levels".into());
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            self.add_mesh(&mesh, world, buffers)?;
        }
        for child in node.children() {
            self.add_node(&child, world, buffers, depth + 1)?;
        }
        Ok(())
    }

    fn add_mesh(
        &mut self,
        mesh: &gltf::Mesh,
        world: Mat4,
        buffers: &[Vec<u8>],
    ) -> Result<(), String> {
        for prim in mesh.primitives() {
            let mode = prim.mode();
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                continue;
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
            let Some(positions) = reader.read_positions() else {
                continue;
            };
            let base = self.vertices.len();
            self.vertices
                .extend(positions.map(|p| world.transform_point3(Vec3::from_array(p))));
            let count = self.vertices.len() - base;
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..count as u32).collect(),
            };
            if let Some(&bad) = indices.iter().find(|&&i| i as usize >= count) {
                return Err(format!(
                    "mesh {} uses vertex {bad} of a primitive with {count} vertices",
                    mesh.index()
                ));
            }
            let b = base as u32;
            let n = indices.len();
            match mode {
                Mode::Triangles => self.triangles.extend(
                    indices
                        .chunks_exact(3)
                        .map(|t| [b + t[0], b + t[1], b + t[2]]),
                ),
                Mode::TriangleStrip => self.triangles.extend((2..n).map(|k| {
                    let (i, j) = if k % 2 == 0 {
                        (k - 2, k - 1)
                    } else {
                        (k - 1, k - 2)
                    };
                    [b + indices[i], b + indices[j], b + indices[k]]
                })),
                _ => self
                    .triangles
                    .extend((2..n).map(|k| [b + indices[0], b + indices[k - 1], b + indices[k]])),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A one-triangle glTF with an embedded buffer (3 f32 positions, then 3 u16 indices), its node translated.
    fn triangle_gltf(buffer: &[u8], declared: usize) -> String {
        let data = base64::engine::general_purpose::STANDARD.encode(buffer);
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
            "nodes":[{{"mesh":0,"translation":[0.0,0.0,0.5]}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
            "buffers":[{{"byteLength":{declared},"uri":"data:application/octet-stream;base64,{data}"}}],
            "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":6}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
                         {{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}}]}}"#
        )
    }

    fn triangle_buffer() -> Vec<u8> {
        let mut b = Vec::new();
        for x in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for i in [0u16, 1, 2] {
            b.extend_from_slice(&i.to_le_bytes());
        }
        b
    }

    #[test]
    fn embedded_buffer_and_node_transform() {
        let (v, t) = decode(triangle_gltf(&triangle_buffer(), 42).as_bytes(), None).unwrap();
        assert_eq!(t, vec![[0, 1, 2]]);
        // glTF (x, y, z) is (x, −z, y) here: the node's +Z translation points to −Y, glTF's up (+Y) is +Z.
        let close = |a: Vec3, b: Vec3| (a - b).length() < 1e-6;
        assert!(close(v[1], Vec3::new(1.0, -0.5, 0.0)), "{:?}", v[1]);
        assert!(close(v[2], Vec3::new(0.0, -0.5, 1.0)), "{:?}", v[2]);
    }

    #[test]
    fn gltf_1_and_quantised_files_get_their_own_advice() {
        let v1 = br#"{"asset":{"version":"1.0"},"scene":"defaultScene","scenes":{"defaultScene":{"nodes":[]}}}"#;
        let err = decode(v1, None).unwrap_err();
        assert!(
            err.message
                .starts_with("glTF 1.0 file; only glTF 2.0 is read"),
            "{err}"
        );
        let quantised = triangle_gltf(&triangle_buffer(), 42).replacen(
            r#"{"asset""#,
            r#"{"extensionsUsed":["KHR_mesh_quantization"],"extensionsRequired":["KHR_mesh_quantization"],"asset""#,
            1,
        );
        let err = decode(quantised.as_bytes(), None).unwrap_err();
        assert!(err.message.contains("gltfpack -noq"), "{err}");
    }

    #[test]
    fn short_buffers_and_garbage_are_errors() {
        let short = triangle_buffer()[..30].to_vec();
        assert!(decode(triangle_gltf(&short, 42).as_bytes(), None).is_err());
        assert!(decode(b"glTF\x02\x00\x00\x00garbage", None).is_err());
        assert!(decode(b"{not json", None).is_err());
        // A POSITION accessor that does not exist (gltf-json panics on it in validation): an error.
        let dangling =
            triangle_gltf(&triangle_buffer(), 42).replace(r#""POSITION":0"#, r#""POSITION":7"#);
        assert!(decode(dangling.as_bytes(), None).is_err());
    }

    #[test]
    fn a_required_extension_is_named() {
        // A Draco-compressed file: its accessors have no buffer views; the error names the extension once.
        let draco = triangle_gltf(&triangle_buffer(), 42).replacen(
            r#"{"asset""#,
            r#"{"extensionsUsed":["KHR_draco_mesh_compression"],"extensionsRequired":["KHR_draco_mesh_compression"],"asset""#,
            1,
        );
        let err = decode(draco.as_bytes(), None).unwrap_err();
        assert!(
            err.message
                .contains("requires the glTF extension KHR_draco_mesh_compression"),
            "{err}"
        );
        // Used but not required: read as usual.
        let used = triangle_gltf(&triangle_buffer(), 42).replacen(
            r#"{"asset""#,
            r#"{"extensionsUsed":["KHR_materials_unlit"],"asset""#,
            1,
        );
        assert!(decode(used.as_bytes(), None).is_ok());
    }
}
