//! The object library: the rigid objects pressed into the Soft Bubble (paper V.A, "objects" of the seen/unseen
//! evaluation), each resting on the table with an SE(2) pose.
//!
//! A set of objects is described by an `objects.json` manifest ([`ObjectManifest`], a list of [`ObjectEntry`]) next to
//! its mesh files, or is the procedurally generated built-in set ([`ObjectSet::builtin`]): cylinders and prisms lying
//! along their object x axis, spheres, upright bullets, crosses and round crosses in several sizes. Every mesh handed
//! out by [`ObjectSet::mesh`] is in metres, in its resting pose, with its lowest point at z = 0 and its bounding box
//! centred on the z axis (the object frame whose SE(2) pose on the table the pose estimator recovers).
//!
//! Files: [`shapes`] (procedural closed meshes), [`procedural`] (thousands of seeded random training objects), [`sweeps`] (holed plates and swept tubes), [`triangulate`] (ear clipping for extruded caps), `builtin.rs` (the
//! built-in catalogue), `set.rs` ([`ObjectSet`]: loading, validation, export).

mod builtin;
pub mod inspect;
pub mod procedural;
mod set;
pub mod shapes;
pub mod sweeps;
pub mod triangulate;

pub use set::{ObjectSet, MANIFEST_FILE};

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::mesh::MeshError;
use crate::sensor::Se2;

/// Version written to and accepted in `objects.json`.
pub const MANIFEST_VERSION: u32 = 1;

/// Everything that can go wrong generating, loading or exporting objects. Each message says what to fix.
#[derive(Debug, thiserror::Error)]
pub enum ObjectError {
    #[error("{shape}: {message}")]
    BadShape {
        shape: &'static str,
        message: String,
    },
    #[error("{context}: cannot triangulate polygon: {message}")]
    BadPolygon { context: String, message: String },
    #[error("{path}: cannot read object manifest: {source} (a set directory must contain {MANIFEST_FILE}; use 'builtin' for the built-in set)")]
    ManifestIo {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: malformed object manifest: {source} (expected {{\"version\": 1, \"objects\": [{{\"name\", \"mesh\", \"scale_to_m\", ...}}]}})")]
    ManifestParse {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{path}: unsupported manifest version {version} (this build reads version {MANIFEST_VERSION})")]
    UnsupportedVersion { path: PathBuf, version: u32 },
    #[error("{path}: object '{name}': {message}")]
    BadEntry {
        path: PathBuf,
        name: String,
        message: String,
    },
    #[error(
        "{path}: object name '{name}' appears more than once; give every object a unique name"
    )]
    DuplicateName { path: PathBuf, name: String },
    #[error("{path}: object '{name}': mesh file {mesh} does not exist (paths are relative to the manifest's directory)")]
    MissingMesh {
        path: PathBuf,
        name: String,
        mesh: PathBuf,
    },
    #[error("unknown object '{name}' in set {set} (available: {available})")]
    UnknownObject {
        name: String,
        set: String,
        available: String,
    },
    /// A mesh file that could not be read or scaled (the mesh error names the file).
    #[error(transparent)]
    MeshFile(MeshError),
    #[error("object '{name}': {source}")]
    Mesh {
        name: String,
        #[source]
        source: MeshError,
    },
    #[error("{path}: cannot write: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: cannot list the directory: {source}")]
    ReadDir {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A mesh whose size, in the units it was read with, no sensor could press.
    #[error("{}: {message}", path.display())]
    ImplausibleSize { path: PathBuf, message: String },
    #[error("cannot serialise the object manifest: {0}")]
    Serialize(#[source] serde_json::Error),
}

/// Shape family of an object (the paper's object classes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Circular cylinder lying on the table, axis along object x.
    Cylinder,
    /// Prism with an isosceles triangular profile, lying along object x with its ridge up.
    TriangularPrism,
    /// Prism with an isosceles trapezoidal profile, lying along object x with its narrow flat face up.
    TrapezoidalPrism,
    /// Upright cylinder with a hemispherical top and a flat bottom.
    Bullet,
    /// Sphere.
    Sphere,
    /// Plus-shaped slab with square arm ends, extruded along z.
    Cross,
    /// Plus-shaped slab whose four arm ends are semicircles, extruded along z.
    RoundCross,
}

impl Family {
    /// All families, in catalogue order.
    pub const ALL: [Family; 7] = [
        Family::Cylinder,
        Family::TriangularPrism,
        Family::TrapezoidalPrism,
        Family::Bullet,
        Family::Sphere,
        Family::Cross,
        Family::RoundCross,
    ];

    /// The serialised (snake_case) name, e.g. `"round_cross"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Family::Cylinder => "cylinder",
            Family::TriangularPrism => "triangular_prism",
            Family::TrapezoidalPrism => "trapezoidal_prism",
            Family::Bullet => "bullet",
            Family::Sphere => "sphere",
            Family::Cross => "cross",
            Family::RoundCross => "round_cross",
        }
    }

    /// Symmetry of the family in its built-in resting pose (symmetric profiles): lying cylinders and prisms are
    /// 2-fold with translation ambiguity along x, spheres and bullets continuous, crosses 4-fold.
    pub fn symmetry(self) -> Symmetry {
        match self {
            Family::Cylinder | Family::TriangularPrism | Family::TrapezoidalPrism => Symmetry {
                rotation: RotationSymmetry::NFold(2),
                translation_axis: Some([1.0, 0.0]),
            },
            Family::Bullet | Family::Sphere => Symmetry {
                rotation: RotationSymmetry::Continuous,
                translation_axis: None,
            },
            Family::Cross | Family::RoundCross => Symmetry {
                rotation: RotationSymmetry::NFold(4),
                translation_axis: None,
            },
        }
    }
}

impl std::fmt::Display for Family {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Which evaluation split an object belongs to: objects seen in training, or held out to test generalisation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Used for training (and seen-object evaluation).
    #[default]
    Seen,
    /// Held out of training; evaluated as an unseen object.
    Unseen,
}

/// Rotational symmetry of a resting object about the table normal (object z axis).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RotationSymmetry {
    /// No symmetry: the orientation theta is compared over the full 2*pi.
    #[default]
    None,
    /// The object maps onto itself when rotated by 2*pi/n about z: theta errors are taken modulo 2*pi/n. `NFold(1)`
    /// is the same as `None`.
    NFold(u32),
    /// Any rotation about z maps the object onto itself: there is no theta error.
    Continuous,
}

impl RotationSymmetry {
    /// The symmetry period in radians (2*pi/n), `None` for continuous symmetry (no theta error).
    pub fn period_rad(self) -> Option<f64> {
        match self {
            RotationSymmetry::None => Some(std::f64::consts::TAU),
            RotationSymmetry::NFold(n) => Some(std::f64::consts::TAU / f64::from(n.max(1))),
            RotationSymmetry::Continuous => None,
        }
    }
}

/// The pose ambiguities of a resting object, used by the pose metrics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Symmetry {
    /// Rotational symmetry about the table normal: decides how the theta error is measured (full circle, modulo
    /// 2*pi/n, or not at all).
    pub rotation: RotationSymmetry,
    /// Unit direction `[x, y]` in the object's xy frame along which the position is ambiguous (the object extends
    /// beyond the sensor, e.g. lying cylinders and prisms: `[1, 0]`). The component of the position error along this
    /// axis is excluded from the position error; `None` means the full 2D position error counts.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub translation_axis: Option<[f64; 2]>,
}

impl Symmetry {
    /// The equivalent of `pose` under the rotation symmetry (a full turn for an object without one) whose θ is
    /// nearest `reference_theta` (radians): the same pose, reported without a jump to another equivalent angle;
    /// `pose` itself where θ is free.
    pub fn nearest_equivalent(&self, pose: Se2, reference_theta: f64) -> Se2 {
        match self.rotation.period_rad() {
            Some(period) if reference_theta.is_finite() && pose.theta.is_finite() => {
                let turns = ((reference_theta - pose.theta) / period).round();
                Se2::new(pose.x, pose.y, pose.theta + turns * period)
            }
            _ => pose,
        }
    }
}

/// One record of an `objects.json` manifest: an object's mesh file, units, resting pose and metadata. Unknown keys
/// are refused: a misspelt `scale_to_mm` would otherwise be ignored and the mesh read in metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectEntry {
    /// Unique name of the object within its set, e.g. `cylinder_r15`.
    pub name: String,
    /// Shape family; optional for user-provided sets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub family: Option<Family>,
    /// Mesh file (`.obj` or `.stl`), relative to the directory holding `objects.json`.
    pub mesh: String,
    /// Metres per file unit (1 for metres, 0.001 for millimetres). Must be positive. Default 1.
    #[serde(default = "one")]
    pub scale_to_m: f64,
    /// Optional unit quaternion `[x, y, z, w]` taking the file's frame to the resting pose; applied after scaling and
    /// before resting the mesh on the table (lowest point at z = 0, bounding box centred on z).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[f64; 4]>,
    /// Evaluation split (default seen).
    #[serde(default)]
    pub split: Split,
    /// Pose ambiguities for the metrics (default: none).
    #[serde(default)]
    pub symmetry: Symmetry,
    /// Named dimensions in metres (e.g. `radius`, `length`), for display and bookkeeping.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub dimensions: BTreeMap<String, f64>,
    /// Relative frequency of the object in generated datasets (default 1: every object equally often). Lets a set
    /// of thousands of procedural objects keep a chosen share for a few hand-picked ones.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub weight: f64,
}

fn one() -> f64 {
    1.0
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

/// The content of an `objects.json` file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectManifest {
    /// Format version; currently [`MANIFEST_VERSION`].
    #[serde(default = "manifest_version")]
    pub version: u32,
    /// The objects of the set.
    pub objects: Vec<ObjectEntry>,
}

fn manifest_version() -> u32 {
    MANIFEST_VERSION
}
