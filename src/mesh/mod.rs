//! Triangle meshes: the object and elastomer geometry of the simulator (paper IV.A, input of step 1).
//!
//! A [`Mesh`] is an indexed triangle soup in metres, validated on construction (finite vertices, indices in range, at
//! least one non-degenerate triangle). Loaders for OBJ ([`obj`]) and STL ([`stl`]) live in their own files and share
//! [`Units`] and [`LoadOptions`]; [`load`] dispatches on the file extension.

pub mod bvh;
pub mod gltf;
pub mod obj;
pub mod ply;
pub mod query;
pub mod sample;
pub mod stl;
pub mod winding;

pub use query::{RayCaster, SignMethod, SignedDistance};
pub use sample::sample_surface;
pub use winding::FastWinding;

use std::path::{Path, PathBuf};

use glam::{Affine3A, Vec3};
use serde::{Deserialize, Serialize};

/// Everything that can go wrong when building or loading a mesh. Each message says what to fix.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("{path}: cannot read mesh file: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: cannot write mesh file: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: malformed {format} file: {message}")]
    Parse {
        path: PathBuf,
        format: &'static str,
        message: String,
    },
    #[error("{path}: unsupported mesh format '{extension}' (use .obj, .stl, .ply, .gltf or .glb)")]
    UnsupportedFormat { path: PathBuf, extension: String },
    #[error("{context}: mesh has no triangles (or no vertices)")]
    Empty { context: String },
    #[error(
        "{context}: vertex {index} is not finite ({value:?}); fix or remove NaN/inf coordinates"
    )]
    NonFinite {
        context: String,
        index: usize,
        value: [f32; 3],
    },
    #[error("{context}: triangle {triangle} uses vertex index {index}, but the mesh has only {count} vertices")]
    IndexOutOfRange {
        context: String,
        triangle: usize,
        index: u32,
        count: usize,
    },
    #[error(
        "{context}: all {count} triangles are degenerate (zero area); the mesh has no surface"
    )]
    AllDegenerate { context: String, count: usize },
    #[error("invalid units '{0}': use m, cm, mm or a positive number (metres per file unit)")]
    BadUnits(String),
    #[error("{context}: {message}")]
    Invalid { context: String, message: String },
}

/// Length unit of a mesh file, as a scale from file units to metres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Units {
    /// File coordinates are metres.
    #[default]
    M,
    /// File coordinates are centimetres.
    Cm,
    /// File coordinates are millimetres.
    Mm,
    /// File coordinates times this number are metres.
    Scale(f64),
}

impl Units {
    /// Metres per file unit.
    pub fn to_metres(self) -> f64 {
        match self {
            Self::M => 1.0,
            Self::Cm => 0.01,
            Self::Mm => 0.001,
            Self::Scale(s) => s,
        }
    }
}

impl std::str::FromStr for Units {
    type Err = MeshError;
    fn from_str(s: &str) -> Result<Self, MeshError> {
        match s.trim().to_ascii_lowercase().as_str() {
            "m" => Ok(Self::M),
            "cm" => Ok(Self::Cm),
            "mm" => Ok(Self::Mm),
            other => match other.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(Self::Scale(v)),
                _ => Err(MeshError::BadUnits(s.to_string())),
            },
        }
    }
}

impl std::fmt::Display for Units {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::M => write!(f, "m"),
            Self::Cm => write!(f, "cm"),
            Self::Mm => write!(f, "mm"),
            Self::Scale(s) => write!(f, "{s}"),
        }
    }
}

/// How a mesh file is turned into metres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LoadOptions {
    /// Unit of the file's coordinates.
    pub units: Units,
    /// If set, the mesh is scaled uniformly (after `units`) so that its largest bounding-box extent equals this many
    /// metres.
    pub fit_to_size: Option<f64>,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            units: Units::M,
            fit_to_size: None,
        }
    }
}

/// File extensions [`load`] reads (lower case).
pub const MESH_EXTENSIONS: [&str; 5] = ["obj", "stl", "ply", "gltf", "glb"];

/// Whether `path` has one of the [`MESH_EXTENSIONS`] (any case).
pub fn is_mesh_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| MESH_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// Load a mesh from an OBJ (every object and group merged), STL, PLY, glTF or GLB file, convert it to metres and
/// validate it.
pub fn load(path: &Path, options: &LoadOptions) -> Result<Mesh, MeshError> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let raw = match extension.as_str() {
        "obj" => obj::read(path)?,
        "stl" => stl::read(path)?,
        "ply" => ply::read(path)?,
        "gltf" | "glb" => gltf::read(path)?,
        _ => {
            return Err(MeshError::UnsupportedFormat {
                path: path.to_path_buf(),
                extension,
            })
        }
    };
    let context = path.display().to_string();
    let mesh = Mesh::from_raw(raw.0, raw.1, &context)?;
    mesh.apply_units(options, &context)
}

/// A validated triangle mesh, in metres. Triangles are counter-clockwise seen from outside (outward normals) when
/// the mesh is closed and consistently oriented.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    vertices: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

/// Largest size, metres, a mesh may be fitted to (`--fit-size`).
pub const MAX_FIT_SIZE_M: f64 = 10.0;

/// Summary of a mesh's topology, reported to users (e.g. `tnd objects`, the workbench).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeshReport {
    pub vertices: usize,
    pub triangles: usize,
    /// Every edge is shared by exactly two triangles with opposite orientation (watertight and consistently oriented).
    pub closed: bool,
    /// Number of edges used by a single triangle.
    pub boundary_edges: usize,
    /// Number of edges used by more than two triangles, or twice in the same direction.
    pub bad_edges: usize,
    /// Enclosed volume in m³ (meaningful when `closed`; negative means inward-facing normals).
    pub volume_m3: f64,
}

impl Mesh {
    /// Build a mesh, validating vertices and indices. Degenerate triangles are dropped (a mesh of only degenerate
    /// triangles is an error). `context` names the source (a file path or a generator) in error messages.
    pub fn from_raw(
        vertices: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
        context: &str,
    ) -> Result<Self, MeshError> {
        if vertices.is_empty() || triangles.is_empty() {
            return Err(MeshError::Empty {
                context: context.to_string(),
            });
        }
        if let Some((index, v)) = vertices.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(MeshError::NonFinite {
                context: context.to_string(),
                index,
                value: v.to_array(),
            });
        }
        let count = vertices.len();
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i as usize >= count) {
                return Err(MeshError::IndexOutOfRange {
                    context: context.to_string(),
                    triangle: t,
                    index,
                    count,
                });
            }
        }
        let total = triangles.len();
        let triangles: Vec<[u32; 3]> = triangles
            .into_iter()
            .filter(|t| !is_degenerate(&vertices, t))
            .collect();
        if triangles.is_empty() {
            return Err(MeshError::AllDegenerate {
                context: context.to_string(),
                count: total,
            });
        }
        Ok(Self {
            vertices,
            triangles,
        })
    }

    /// Vertex positions in metres.
    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    /// Triangle vertex indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The three corners of triangle `i`.
    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[i];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// Axis-aligned bounding box `(min, max)` in metres.
    pub fn aabb(&self) -> (Vec3, Vec3) {
        self.vertices.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), v| (lo.min(*v), hi.max(*v)),
        )
    }

    /// The largest side of the bounding box, metres (the size that units and scale-to-fit are judged by).
    pub fn largest_extent(&self) -> f64 {
        let (lo, hi) = self.aabb();
        f64::from((hi - lo).max_element())
    }

    /// The area-weighted centroid of the surface, metres (on any symmetry axis of the mesh; unlike the bounding
    /// box's centre, which a five-fold star has off its axis). The bounding box's centre for a mesh without area.
    pub fn surface_centroid(&self) -> glam::DVec3 {
        let (mut sum, mut area) = (glam::DVec3::ZERO, 0.0);
        for i in 0..self.triangles.len() {
            let [a, b, c] = self.triangle(i).map(|v| v.as_dvec3());
            let w = 0.5 * (b - a).cross(c - a).length();
            sum += w * (a + b + c) / 3.0;
            area += w;
        }
        if area > 0.0 {
            sum / area
        } else {
            let (lo, hi) = self.aabb();
            (0.5 * (lo + hi)).as_dvec3()
        }
    }

    /// The mesh with every vertex mapped by `t` (e.g. `t_world_object`). Orientation is kept for proper rigid motions
    /// and positive scales; a reflection flips the winding back so normals stay outward.
    pub fn transformed(&self, t: &Affine3A) -> Self {
        let vertices = self
            .vertices
            .iter()
            .map(|v| t.transform_point3(*v))
            .collect();
        let mut triangles = self.triangles.clone();
        if t.matrix3.determinant() < 0.0 {
            for tri in &mut triangles {
                tri.swap(1, 2);
            }
        }
        Self {
            vertices,
            triangles,
        }
    }

    /// Apply file units and the optional fit-to-size.
    pub fn apply_units(self, options: &LoadOptions, context: &str) -> Result<Self, MeshError> {
        let mut scale = options.units.to_metres();
        if let Some(size) = options.fit_to_size {
            let extent = self.largest_extent() * scale;
            if !(size.is_finite() && size > 0.0) || extent <= 0.0 {
                return Err(MeshError::Invalid {
                    context: context.to_string(),
                    message: format!("cannot fit a mesh of extent {extent} m to size {size} m"),
                });
            }
            // Beyond this the vertices (f32) overflow, and no tactile sensor presses such an object.
            if size > MAX_FIT_SIZE_M {
                return Err(MeshError::Invalid {
                    context: context.to_string(),
                    message: format!(
                        "fit size {size:e} m is above {MAX_FIT_SIZE_M} m: sizes are in metres"
                    ),
                });
            }
            scale *= size / extent;
        }
        Ok(self.transformed(&Affine3A::from_scale(Vec3::splat(scale as f32))))
    }

    /// Translate the mesh so that its lowest point is at z = 0 (resting on the table) and its bounding box is centred
    /// on the z axis.
    pub fn rest_on_table(&self) -> Self {
        let (lo, hi) = self.aabb();
        let centre = 0.5 * (lo + hi);
        self.transformed(&Affine3A::from_translation(Vec3::new(
            -centre.x, -centre.y, -lo.z,
        )))
    }

    /// Topology and volume summary.
    pub fn report(&self) -> MeshReport {
        use std::collections::HashMap;
        // Directed edge counts: a closed, consistently oriented mesh uses each directed edge exactly once and its
        // reverse exactly once.
        let mut directed: HashMap<(u32, u32), u32> =
            HashMap::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        let mut boundary_edges = 0;
        let mut bad_edges = 0;
        for (&(a, b), &n) in &directed {
            let reverse = directed.get(&(b, a)).copied().unwrap_or(0);
            if n > 1 || reverse > 1 {
                if a < b || reverse == 0 {
                    bad_edges += 1;
                }
            } else if reverse == 0 {
                boundary_edges += 1;
            }
        }
        let volume_m3 = self
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        MeshReport {
            vertices: self.vertices.len(),
            triangles: self.triangles.len(),
            closed: boundary_edges == 0 && bad_edges == 0,
            boundary_edges,
            bad_edges,
            volume_m3,
        }
    }

    /// [`Self::welded`] at a millionth of the largest extent: the mesh whose topology (shells, closedness) users are
    /// told about, whatever the file format stores (STL keeps every triangle's corners apart).
    pub fn welded_for_topology(&self) -> Self {
        self.welded((self.largest_extent() * 1e-6).max(1e-9) as f32)
    }

    /// Merge vertices closer than `tolerance` metres (e.g. STL files, which store each triangle's corners separately)
    /// so that topology (closedness) can be checked. Triangles that become degenerate are dropped.
    pub fn welded(&self, tolerance: f32) -> Self {
        use std::collections::HashMap;
        let inv = 1.0 / tolerance.max(f32::MIN_POSITIVE);
        let mut map: HashMap<[i64; 3], u32> = HashMap::new();
        let mut vertices = Vec::new();
        let remap: Vec<u32> = self
            .vertices
            .iter()
            .map(|v| {
                let key = [v.x, v.y, v.z].map(|c| (c * inv).round() as i64);
                *map.entry(key).or_insert_with(|| {
                    vertices.push(*v);
                    (vertices.len() - 1) as u32
                })
            })
            .collect();
        let triangles = self
            .triangles
            .iter()
            .map(|t| t.map(|i| remap[i as usize]))
            .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .collect();
        Self {
            vertices,
            triangles,
        }
    }

    /// Connected pieces of the surface (triangles sharing a vertex index; weld first to join coincident corners).
    pub fn shell_count(&self) -> usize {
        let n = self.vertices.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        let mut used = vec![false; n];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| i as usize);
            used[a] = true;
            used[b] = true;
            used[c] = true;
            for (x, y) in [(a, b), (b, c)] {
                let (rx, ry) = (find(&mut parent, x), find(&mut parent, y));
                if rx != ry {
                    parent[rx] = ry;
                }
            }
        }
        (0..n)
            .filter(|&i| used[i] && find(&mut parent, i) == i)
            .count()
    }

    /// The same surface with reversed triangle winding (normals flipped).
    pub fn flipped(&self) -> Self {
        Self {
            vertices: self.vertices.clone(),
            triangles: self.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect(),
        }
    }

    /// Concatenate meshes (no welding).
    pub fn merged(parts: &[Mesh]) -> Self {
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        for p in parts {
            let base = vertices.len() as u32;
            vertices.extend_from_slice(&p.vertices);
            triangles.extend(p.triangles.iter().map(|t| t.map(|i| i + base)));
        }
        Self {
            vertices,
            triangles,
        }
    }

    /// Write the mesh as a Wavefront OBJ text (metres).
    pub fn to_obj_string(&self) -> String {
        use std::fmt::Write;
        let mut s = String::with_capacity(self.vertices.len() * 40 + self.triangles.len() * 24);
        s.push_str(obj::OBJ_MARK);
        s.push('\n');
        for v in &self.vertices {
            let _ = writeln!(s, "v {} {} {}", v.x, v.y, v.z);
        }
        for t in &self.triangles {
            let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        s
    }
}

fn is_degenerate(vertices: &[Vec3], t: &[u32; 3]) -> bool {
    let [a, b, c] = t.map(|i| vertices[i as usize].as_dvec3());
    let n = (b - a).cross(c - a).length();
    let scale = (b - a)
        .length_squared()
        .max((c - a).length_squared())
        .max((c - b).length_squared());
    n.is_nan() || n <= 1e-12 * scale || scale == 0.0
}
