//! STL reader (ASCII and binary) and binary writer: object geometry for the simulator (paper IV.A, input of step 1).
//!
//! STL stores each triangle's three corners separately, so [`read`] returns three new vertices per facet (no
//! welding; use [`Mesh::welded`] to recover topology). Binary files are recognised by their size (80-byte header,
//! `u32` triangle count, 50 bytes per triangle), never by the `solid` prefix, which many binary exporters also write
//! into the header.

use std::path::Path;

use glam::Vec3;

use super::{Mesh, MeshError};

const HEADER_LEN: usize = 80;
const PREFIX_LEN: usize = HEADER_LEN + 4;
const RECORD_LEN: usize = 50;

/// What went wrong while decoding STL bytes; turned into a [`MeshError`] naming the file in [`read`].
#[derive(Debug, PartialEq)]
enum Problem {
    /// No triangles at all (empty file, `solid`/`endsolid` only, or a binary count of zero).
    Empty,
    Malformed(String),
}

/// Read an ASCII or binary STL file: raw vertex positions in file units (three per facet) and triangle indices.
pub fn read(path: &Path) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), MeshError> {
    let bytes = crate::io::input::read_capped(path, crate::io::input::MAX_MESH_BYTES).map_err(
        |source| MeshError::Io {
            path: path.to_path_buf(),
            source,
        },
    )?;
    let problem = |p: Problem| match p {
        Problem::Empty => MeshError::Empty {
            context: path.display().to_string(),
        },
        Problem::Malformed(message) => MeshError::Parse {
            path: path.to_path_buf(),
            format: "STL",
            message,
        },
    };
    let vertices = decode(&bytes).map_err(problem)?;
    let triangles = soup_indices(vertices.len()).map_err(problem)?;
    Ok((vertices, triangles))
}

/// Write `mesh` as a binary STL (metres, facet normals from the winding), atomically.
pub fn write_binary(path: &Path, mesh: &Mesh) -> Result<(), MeshError> {
    let bytes = encode_binary(mesh).map_err(|message| MeshError::Invalid {
        context: path.display().to_string(),
        message,
    })?;
    crate::io::write_atomic(path, &bytes).map_err(|source| MeshError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Binary STL bytes of `mesh`. The header does not start with `solid`, so naive readers do not take it for ASCII.
fn encode_binary(mesh: &Mesh) -> Result<Vec<u8>, String> {
    let count = u32::try_from(mesh.triangles().len()).map_err(|_| {
        format!(
            "{} triangles do not fit in a binary STL",
            mesh.triangles().len()
        )
    })?;
    let mut bytes = Vec::with_capacity(PREFIX_LEN + RECORD_LEN * mesh.triangles().len());
    let mut header = b"binary STL written by tactile-derender, units: metres".to_vec();
    header.resize(HEADER_LEN, b' ');
    bytes.extend_from_slice(&header);
    bytes.extend_from_slice(&count.to_le_bytes());
    for i in 0..mesh.triangles().len() {
        let [a, b, c] = mesh.triangle(i);
        let normal = (b - a).cross(c - a).normalize_or_zero();
        for v in [normal, a, b, c] {
            for x in v.to_array() {
                bytes.extend_from_slice(&x.to_le_bytes());
            }
        }
        bytes.extend_from_slice(&0u16.to_le_bytes());
    }
    Ok(bytes)
}

/// Decode STL bytes into a triangle soup (three consecutive vertices per triangle).
fn decode(bytes: &[u8]) -> Result<Vec<Vec3>, Problem> {
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(Problem::Empty);
    }
    // Declared triangle count of a binary STL and the file length it implies.
    let declared = bytes.get(HEADER_LEN..PREFIX_LEN).map(|c| {
        let n = u64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
        (n, PREFIX_LEN as u64 + RECORD_LEN as u64 * n)
    });
    if let Some((n, len)) = declared {
        if len == bytes.len() as u64 {
            return non_empty(decode_binary(bytes, n));
        }
    }
    let textual = bytes
        .iter()
        .all(|b| b.is_ascii_graphic() || b.is_ascii_whitespace());
    let ascii = match decode_ascii(bytes) {
        Ok(vertices) if textual || !vertices.is_empty() => return non_empty(vertices),
        // A binary file whose header starts with "solid" and has no line break reads as a nameless empty solid.
        Ok(_) => "no ASCII facets in a file with binary data".to_string(),
        Err(ascii) => ascii,
    };
    let starts_with_solid = {
        let start = bytes
            .iter()
            .position(|b| !b.is_ascii_whitespace())
            .unwrap_or(0);
        bytes
            .get(start..start + 5)
            .is_some_and(|w| w.eq_ignore_ascii_case(b"solid"))
    };
    let message = match declared {
        _ if textual => ascii,
        Some((n, len)) => {
            let binary = format!(
                "header declares {n} triangles ({len} bytes) but the file has {} bytes",
                bytes.len()
            );
            if starts_with_solid {
                // The ASCII reader's complaint quotes the binary bytes it met; name what was read instead.
                format!("truncated or corrupt binary STL (its header starts with 'solid', but it holds binary data): {binary}")
            } else {
                format!("truncated or corrupt binary STL: {binary}")
            }
        }
        None => format!(
            "{ascii} (and at {} bytes the file is too short for binary STL)",
            bytes.len()
        ),
    };
    Err(Problem::Malformed(message))
}

fn non_empty(vertices: Vec<Vec3>) -> Result<Vec<Vec3>, Problem> {
    if vertices.is_empty() {
        Err(Problem::Empty)
    } else {
        Ok(vertices)
    }
}

/// Triangle indices `[3i, 3i+1, 3i+2]` of a soup of `vertex_count` vertices.
fn soup_indices(vertex_count: usize) -> Result<Vec<[u32; 3]>, Problem> {
    let count = u32::try_from(vertex_count).map_err(|_| {
        Problem::Malformed(format!(
            "{vertex_count} vertices exceed the 2^32 index limit"
        ))
    })?;
    Ok((0..count / 3)
        .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
        .collect())
}

/// Decode a binary STL whose size has been checked against its declared `count`. Facet normals are ignored.
fn decode_binary(bytes: &[u8], count: u64) -> Vec<Vec3> {
    let records = bytes.get(PREFIX_LEN..).unwrap_or(&[]);
    let f32_at = |r: &[u8], at: usize| f32::from_le_bytes([r[at], r[at + 1], r[at + 2], r[at + 3]]);
    let mut vertices = Vec::with_capacity(3 * count as usize);
    for record in records.chunks_exact(RECORD_LEN) {
        for corner in 0..3 {
            let at = 12 + 12 * corner;
            vertices.push(Vec3::new(
                f32_at(record, at),
                f32_at(record, at + 4),
                f32_at(record, at + 8),
            ));
        }
    }
    vertices
}

/// Decode ASCII STL: `solid`, then per facet `facet normal nx ny nz / outer loop / vertex x y z (x3) / endloop /
/// endfacet`, then `endsolid`. Keywords are case-insensitive and may be separated by any whitespace, line breaks
/// included. Facets with more than three vertices are fan-triangulated. Errors name the one-based line.
fn decode_ascii(bytes: &[u8]) -> Result<Vec<Vec3>, String> {
    const KEYWORDS: [&str; 7] = [
        "facet", "outer", "loop", "vertex", "endloop", "endfacet", "endsolid",
    ];
    let text = String::from_utf8_lossy(bytes);
    let mut tokens = text
        .lines()
        .enumerate()
        .flat_map(|(i, line)| line.split_whitespace().map(move |t| (i + 1, t)))
        .peekable();
    let is = |token: &str, keyword: &str| token.eq_ignore_ascii_case(keyword);
    let mut vertices = Vec::new();
    // Line where the open facet started, and its corners.
    let mut facet: Option<(usize, Vec<Vec3>)> = None;
    while let Some((line, token)) = tokens.next() {
        if is(token, "solid") || is(token, "endsolid") {
            // The solid's name runs to the end of the line.
            while tokens.next_if(|&(l, _)| l == line).is_some() {}
        } else if is(token, "facet") {
            if let Some((start, _)) = facet {
                return Err(format!("line {line}: 'facet' before the 'endfacet' of the facet opened on line {start}"));
            }
            // The normal is recomputed from the winding downstream; skip it (exporters write e.g. "-nan" here).
            if tokens.next_if(|(_, t)| is(t, "normal")).is_some() {
                for _ in 0..3 {
                    tokens.next_if(|(_, t)| !KEYWORDS.iter().any(|k| is(t, k)));
                }
            }
            facet = Some((line, Vec::new()));
        } else if is(token, "outer") || is(token, "loop") || is(token, "endloop") {
            if facet.is_none() {
                return Err(format!("line {line}: '{token}' outside a facet"));
            }
        } else if is(token, "vertex") {
            let Some((_, corners)) = facet.as_mut() else {
                return Err(format!("line {line}: 'vertex' outside a facet"));
            };
            let mut xyz = [0.0f32; 3];
            for x in &mut xyz {
                let value = tokens.next_if(|&(l, _)| l == line).map(|(_, t)| t);
                *x = value.and_then(|t| t.parse().ok()).ok_or_else(|| {
                    let found = value.map_or("end of line".to_string(), |t| format!("'{t}'"));
                    format!(
                        "line {line}: malformed vertex, expected 'vertex x y z' but found {found}"
                    )
                })?;
            }
            corners.push(Vec3::from_array(xyz));
        } else if is(token, "endfacet") {
            let Some((start, corners)) = facet.take() else {
                return Err(format!("line {line}: 'endfacet' without 'facet'"));
            };
            if corners.len() < 3 {
                return Err(format!(
                    "line {line}: the facet opened on line {start} has {} vertices, needs 3",
                    corners.len()
                ));
            }
            for k in 1..corners.len() - 1 {
                vertices.extend_from_slice(&[corners[0], corners[k], corners[k + 1]]);
            }
        } else {
            return Err(format!("line {line}: unexpected '{token}' (expected facet, outer loop, vertex, endloop, endfacet or endsolid)"));
        }
    }
    match facet {
        Some((start, _)) => Err(format!(
            "the facet opened on line {start} is never closed (truncated file?)"
        )),
        None => Ok(vertices),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    const FACET: &str = "facet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  vertex 0 1 0\n endloop\nendfacet\n";

    #[test]
    fn ascii_is_case_and_whitespace_tolerant() {
        let text = format!("solid my part\n{FACET}\tFACET NORMAL -nan -nan -nan OUTER\nLOOP VERTEX 0 0 1 vertex 1 0 1\r\n\
                            Vertex 0 1 1e0 EndLoop ENDFACET endsolid my part\n");
        let v = decode(text.as_bytes()).unwrap();
        assert_eq!(v.len(), 6);
        assert_eq!(v[5], Vec3::new(0.0, 1.0, 1.0));
    }

    #[test]
    fn ascii_quad_facet_is_fan_triangulated() {
        let text = FACET.replace("  vertex 0 1 0\n", "  vertex 1 1 0\n  vertex 0 1 0\n");
        assert_eq!(decode(text.as_bytes()).unwrap().len(), 6);
    }

    #[test]
    fn ascii_errors_name_the_line() {
        let bad = format!(
            "solid x\n{}",
            FACET.replace("vertex 1 0 0", "vertex 1 zero 0")
        );
        let err = decode_ascii(bad.as_bytes()).unwrap_err();
        assert!(err.contains("line 5") && err.contains("'zero'"), "{err}");
        let short = format!("solid x\n{}", FACET.replace("vertex 1 0 0", "vertex 1 0"));
        assert!(decode_ascii(short.as_bytes())
            .unwrap_err()
            .contains("line 5"));
        let two = format!("solid x\n{}", FACET.replace("  vertex 0 1 0\n", ""));
        assert!(decode_ascii(two.as_bytes())
            .unwrap_err()
            .contains("2 vertices"));
        let open = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n";
        assert!(decode_ascii(open.as_bytes())
            .unwrap_err()
            .contains("line 2"));
    }

    #[test]
    fn empty_inputs() {
        assert_eq!(decode(b""), Err(Problem::Empty));
        assert_eq!(decode(b" \n\t"), Err(Problem::Empty));
        assert_eq!(decode(b"solid x\nendsolid x\n"), Err(Problem::Empty));
        let mut zero = b"solid but binary".to_vec();
        zero.resize(PREFIX_LEN, 0);
        assert_eq!(decode(&zero), Err(Problem::Empty));
    }

    fn binary(header: &[u8], triangles: &[[f32; 9]]) -> Vec<u8> {
        let mut bytes = header.to_vec();
        bytes.resize(HEADER_LEN, b' ');
        bytes.extend_from_slice(&(triangles.len() as u32).to_le_bytes());
        for t in triangles {
            bytes.extend_from_slice(&[0u8; 12]);
            t.iter()
                .for_each(|x| bytes.extend_from_slice(&x.to_le_bytes()));
            bytes.extend_from_slice(&[0u8; 2]);
        }
        bytes
    }

    #[test]
    fn binary_with_solid_header_is_detected_by_size() {
        let tri = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let bytes = binary(b"solid exported by some CAD tool", &[tri, tri]);
        let v = decode(&bytes).unwrap();
        assert_eq!(v.len(), 6);
        assert_eq!(v[1], Vec3::X);
    }

    #[test]
    fn truncated_binary_is_reported() {
        let tri = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let bytes = binary(b"binary", &[tri, tri]);
        let Err(Problem::Malformed(err)) = decode(&bytes[..bytes.len() - 7]) else {
            panic!("truncated binary accepted")
        };
        assert!(err.contains("declares 2 triangles"), "{err}");
        let bytes = binary(b"solid", &[tri, tri]);
        let Err(Problem::Malformed(err)) = decode(&bytes[..bytes.len() - 7]) else {
            panic!("truncated binary accepted")
        };
        // A binary file whose header starts with "solid": one readable line, not the ASCII reader's quote of
        // binary bytes.
        assert!(
            err.contains("binary STL") && err.contains("declares 2 triangles"),
            "{err}"
        );
        assert!(
            !err.chars().any(char::is_control) && err.len() < 200,
            "{err}"
        );
        assert!(matches!(decode(b"not an stl"), Err(Problem::Malformed(_))));
    }

    #[test]
    fn soup_indices_are_consecutive() {
        assert_eq!(soup_indices(6).unwrap(), vec![[0, 1, 2], [3, 4, 5]]);
    }
}
