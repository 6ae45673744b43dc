//! [`ObjectSet`]: the built-in object catalogue or a directory with an `objects.json` manifest, validated on load,
//! handing out meshes in their resting pose (object library, paper V.A).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use glam::{Affine3A, DQuat};
use rayon::prelude::*;

use super::builtin::{catalogue, ShapeSpec};
use super::{ObjectEntry, ObjectError, ObjectManifest, MANIFEST_VERSION};
use crate::mesh::{self, LoadOptions, Mesh, Units};

/// File name of the manifest inside a set directory.
pub const MANIFEST_FILE: &str = "objects.json";

/// Tolerance on the norm of manifest quaternions and translation axes (quaternions are normalised before use).
const UNIT_NORM_TOLERANCE: f64 = 1e-3;

/// A validated set of objects: the built-in catalogue or a directory holding `objects.json` and mesh files.
#[derive(Clone, Debug)]
pub struct ObjectSet {
    source: Source,
    entries: Vec<ObjectEntry>,
}

#[derive(Clone, Debug)]
enum Source {
    /// Generated in memory; one spec per entry, in the same order.
    Builtin(Vec<ShapeSpec>),
    /// The directory holding `objects.json`; mesh paths are relative to it.
    Dir(PathBuf),
    /// Meshes held in memory (resting pose, metres), one per entry in the same order; e.g. a procedural set before
    /// it is exported.
    Memory { spec: String, meshes: Vec<Mesh> },
}

impl ObjectSet {
    /// The built-in procedural set (28 objects over 7 families, about a quarter unseen). No files are involved.
    pub fn builtin() -> Self {
        let (specs, entries) = catalogue()
            .into_iter()
            .map(|(spec, split)| (spec, spec.entry(split)))
            .unzip();
        Self {
            source: Source::Builtin(specs),
            entries,
        }
    }

    /// A procedural training set ([`super::procedural`]): `config.count` generated objects plus, when
    /// `builtin_share > 0`, the built-in catalogue (with its seen/unseen splits) weighted so that its objects make up
    /// `builtin_share` of the pairs of a dataset generated from the set. Export it with [`ObjectSet::export`].
    pub fn procedural(
        config: &super::procedural::ProceduralConfig,
        builtin_share: f64,
    ) -> Result<Self, ObjectError> {
        Self::procedural_with(config, builtin_share, &[])
    }

    /// [`ObjectSet::procedural`] with more sets mixed in: each `(set, share)` adds every object of `set` (its split,
    /// symmetry and relative weights kept; meshes in their resting pose) weighted so that its objects make up
    /// `share` of the pairs, e.g. real scanned and CAD parts beside the procedural shapes. The shares, the built-in
    /// one included, must leave some of the pairs to the procedural objects; names must not repeat across sets.
    pub fn procedural_with(
        config: &super::procedural::ProceduralConfig,
        builtin_share: f64,
        included: &[(&ObjectSet, f64)],
    ) -> Result<Self, ObjectError> {
        let bad = |message: String| ObjectError::BadShape {
            shape: "procedural",
            message,
        };
        if !(builtin_share.is_finite() && (0.0..1.0).contains(&builtin_share)) {
            return Err(bad(format!(
                "the built-in share {builtin_share} must be in [0, 1)"
            )));
        }
        for (set, share) in included {
            if !(share.is_finite() && *share > 0.0 && *share < 1.0) {
                return Err(bad(format!(
                    "the share {share} of {} must be in (0, 1)",
                    set.spec()
                )));
            }
        }
        let builtin = Self::builtin();
        let mut parts: Vec<(&ObjectSet, f64)> = Vec::new();
        if builtin_share > 0.0 {
            parts.push((&builtin, builtin_share));
        }
        parts.extend(included.iter().copied());
        let procedural_share = 1.0 - parts.iter().map(|(_, s)| s).sum::<f64>();
        if procedural_share <= 0.0 {
            return Err(bad(format!(
                "the shares of the built-in and included sets add up to {} and leave no pairs to the procedural \
                 objects; lower them",
                1.0 - procedural_share
            )));
        }
        let generated = (0..config.count)
            .into_par_iter()
            .map(|i| super::procedural::generate(config, i))
            .collect::<Result<Vec<_>, _>>()?;
        let (mut entries, mut meshes): (Vec<ObjectEntry>, Vec<Mesh>) =
            generated.into_iter().map(|o| (o.entry, o.mesh)).unzip();
        // Procedural objects weigh 1 each, so a set's objects together weigh share / procedural_share of their
        // count (written in the order that keeps the built-in weights of earlier sets bit for bit).
        let count = config.count.max(1) as f64;
        let mut names: HashSet<String> = entries.iter().map(|e| e.name.clone()).collect();
        for (set, share) in &parts {
            let set_weight: f64 = set.entries.iter().map(|e| e.weight).sum();
            if set_weight <= 0.0 {
                return Err(bad(format!(
                    "{} has no object with a positive weight",
                    set.spec()
                )));
            }
            let scale = share / procedural_share * count / set_weight;
            let part_meshes = set
                .entries
                .par_iter()
                .map(|entry| set.mesh(&entry.name))
                .collect::<Result<Vec<_>, _>>()?;
            for (entry, mesh) in set.entries.iter().zip(part_meshes) {
                if !names.insert(entry.name.clone()) {
                    return Err(bad(format!(
                        "object '{}' of {} has the name of an object already in the set; rename it in its \
                         objects.json",
                        entry.name,
                        set.spec()
                    )));
                }
                meshes.push(mesh);
                entries.push(ObjectEntry {
                    weight: entry.weight * scale,
                    ..entry.clone()
                });
            }
        }
        let mut spec = format!(
            "procedural(count={}, seed={}, builtin_share={builtin_share})",
            config.count, config.seed
        );
        for (set, share) in included {
            spec += &format!(" + {}={share}", set.spec());
        }
        Ok(Self {
            source: Source::Memory { spec, meshes },
            entries,
        })
    }

    /// Read and validate `dir/objects.json`: supported version, non-empty unique names, mesh files that exist with a
    /// supported extension, positive finite `scale_to_m`, unit quaternions and valid symmetries. Meshes are not read
    /// until [`ObjectSet::mesh`].
    pub fn load_dir(dir: &Path) -> Result<Self, ObjectError> {
        let path = dir.join(MANIFEST_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| ObjectError::ManifestIo {
            path: path.clone(),
            source,
        })?;
        let manifest: ObjectManifest =
            serde_json::from_str(&text).map_err(|source| ObjectError::ManifestParse {
                path: path.clone(),
                source,
            })?;
        if manifest.version != MANIFEST_VERSION {
            return Err(ObjectError::UnsupportedVersion {
                path,
                version: manifest.version,
            });
        }
        let mut names = HashSet::new();
        for entry in &manifest.objects {
            if !names.insert(entry.name.as_str()) {
                return Err(ObjectError::DuplicateName {
                    path,
                    name: entry.name.clone(),
                });
            }
            validate_entry(dir, &path, entry)?;
        }
        Ok(Self {
            source: Source::Dir(dir.to_path_buf()),
            entries: manifest.objects,
        })
    }

    /// Open a set from a user-facing spec: `"builtin"` (or an empty string) for the built-in set, otherwise the path
    /// of a directory holding `objects.json`.
    pub fn open(spec: &str) -> Result<Self, ObjectError> {
        let spec = spec.trim();
        if spec.is_empty() || spec.eq_ignore_ascii_case("builtin") {
            Ok(Self::builtin())
        } else {
            Self::load_dir(Path::new(spec))
        }
    }

    /// `"builtin"` or the set directory's path, for display and provenance.
    pub fn spec(&self) -> String {
        match &self.source {
            Source::Builtin(_) => "builtin".to_string(),
            Source::Dir(dir) => dir.display().to_string(),
            Source::Memory { spec, .. } => spec.clone(),
        }
    }

    /// The set directory, `None` for the built-in set.
    pub fn dir(&self) -> Option<&Path> {
        match &self.source {
            Source::Builtin(_) | Source::Memory { .. } => None,
            Source::Dir(dir) => Some(dir),
        }
    }

    /// All objects, in manifest order.
    pub fn entries(&self) -> &[ObjectEntry] {
        &self.entries
    }

    /// The objects of one split, in manifest order.
    pub fn entries_in(&self, split: super::Split) -> impl Iterator<Item = &ObjectEntry> {
        self.entries.iter().filter(move |e| e.split == split)
    }

    /// The object called `name`, if any.
    pub fn find(&self, name: &str) -> Option<&ObjectEntry> {
        self.entries.iter().find(|e| e.name == name)
    }

    /// The mesh of object `name` in metres, in its resting pose (lowest point at z = 0, bounding box centred on the z
    /// axis). Built-in objects are generated; directory objects are loaded with `scale_to_m`, rotated by `rotation`
    /// and then rested on the table.
    pub fn mesh(&self, name: &str) -> Result<Mesh, ObjectError> {
        let index = self
            .entries
            .iter()
            .position(|e| e.name == name)
            .ok_or_else(|| self.unknown(name))?;
        let entry = &self.entries[index];
        match &self.source {
            Source::Builtin(specs) => specs.get(index).ok_or_else(|| self.unknown(name))?.build(),
            Source::Memory { meshes, .. } => {
                meshes.get(index).cloned().ok_or_else(|| self.unknown(name))
            }
            Source::Dir(dir) => {
                let options = LoadOptions {
                    units: Units::Scale(entry.scale_to_m),
                    fit_to_size: None,
                };
                let mesh = mesh::load(&dir.join(&entry.mesh), &options).map_err(|source| {
                    ObjectError::Mesh {
                        name: entry.name.clone(),
                        source,
                    }
                })?;
                let (lo, hi) = mesh.aabb();
                let largest = f64::from((hi - lo).max_element());
                if !super::inspect::plausible_extent(largest) {
                    // As `tnd objects import` refuses such a file, and `tnd sim` such a mesh given by path.
                    return Err(ObjectError::BadEntry {
                        path: dir.join(super::MANIFEST_FILE),
                        name: entry.name.clone(),
                        message: format!(
                            "scale_to_m = {} makes it {} across (largest extent), implausible for a pressed \
                             object ({:.0} mm to {} m); scale_to_m is metres per file unit (1 for m, 0.001 for mm)",
                            entry.scale_to_m,
                            super::inspect::length(largest),
                            super::inspect::PLAUSIBLE_EXTENT_M[0] * 1e3,
                            super::inspect::PLAUSIBLE_EXTENT_M[1]
                        ),
                    });
                }
                let mesh = match entry.rotation {
                    Some([x, y, z, w]) => {
                        let q = DQuat::from_xyzw(x, y, z, w).normalize().as_quat();
                        mesh.transformed(&Affine3A::from_quat(q))
                    }
                    None => mesh,
                };
                Ok(mesh.rest_on_table())
            }
        }
    }

    /// The set as a manifest (entries as they are, e.g. for display or saving alongside the original meshes).
    pub fn manifest(&self) -> ObjectManifest {
        ObjectManifest {
            version: MANIFEST_VERSION,
            objects: self.entries.clone(),
        }
    }

    /// The manifest [`Self::export`] writes: the same entries with their exported file names (sanitised, unique),
    /// `scale_to_m = 1` and no rotation. Building it touches no mesh.
    pub fn exported_manifest(&self) -> ObjectManifest {
        let mut used = HashSet::new();
        let objects = self
            .entries
            .iter()
            .map(|entry| ObjectEntry {
                mesh: unique_file_name(&entry.name, &mut used),
                scale_to_m: 1.0,
                rotation: None,
                ..entry.clone()
            })
            .collect();
        ObjectManifest {
            version: MANIFEST_VERSION,
            objects,
        }
    }

    /// Write every mesh as `<name>.obj` in metres, in its resting pose, plus `objects.json` (pretty JSON) into `dir`
    /// (created if needed). Exported entries have `scale_to_m = 1` and no rotation; names with characters unsafe in
    /// file names get a sanitised file name. All meshes are built before anything is written, and each file is
    /// written atomically with the manifest last, so exporting a directory set onto itself is safe.
    pub fn export(&self, dir: &Path) -> Result<(), ObjectError> {
        let manifest = self.exported_manifest();
        // Building and writing the meshes is the whole cost (6 000 procedural objects took ~25 s on one core), and
        // each object is independent: both run in parallel.
        let meshes: Vec<Mesh> = self
            .entries
            .par_iter()
            .map(|entry| self.mesh(&entry.name))
            .collect::<Result<_, _>>()?;
        meshes
            .par_iter()
            .zip(manifest.objects.par_iter())
            .try_for_each(|(mesh, out)| {
                write(&dir.join(&out.mesh), mesh.to_obj_string().as_bytes())
            })?;
        let mut json = serde_json::to_string_pretty(&manifest).map_err(ObjectError::Serialize)?;
        json.push('\n');
        write(&dir.join(MANIFEST_FILE), json.as_bytes())
    }

    fn unknown(&self, name: &str) -> ObjectError {
        let names: Vec<&str> = self.entries.iter().map(|e| e.name.as_str()).collect();
        ObjectError::UnknownObject {
            name: name.to_string(),
            set: self.spec(),
            available: names.join(", "),
        }
    }
}

/// Check one manifest record (the manifest at `path` in `dir`).
fn validate_entry(dir: &Path, path: &Path, entry: &ObjectEntry) -> Result<(), ObjectError> {
    let bad = |message: String| ObjectError::BadEntry {
        path: path.to_path_buf(),
        name: entry.name.clone(),
        message,
    };
    if entry.name.trim().is_empty() {
        return Err(bad(
            "the name is empty; give every object a unique non-empty name".into(),
        ));
    }
    let mesh_path = dir.join(&entry.mesh);
    if !mesh_path.is_file() {
        return Err(ObjectError::MissingMesh {
            path: path.to_path_buf(),
            name: entry.name.clone(),
            mesh: mesh_path,
        });
    }
    if !crate::mesh::is_mesh_file(&mesh_path) {
        return Err(bad(format!(
            "mesh file '{}' is not .obj, .stl, .ply, .gltf or .glb; convert it",
            entry.mesh
        )));
    }
    if !(entry.scale_to_m.is_finite() && entry.scale_to_m > 0.0) {
        return Err(bad(format!(
            "scale_to_m = {} must be positive (metres per file unit: 1 for m, 0.001 for mm)",
            entry.scale_to_m
        )));
    }
    if let Some(q) = entry.rotation {
        let norm = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        if !norm.is_finite() || (norm - 1.0).abs() > UNIT_NORM_TOLERANCE {
            return Err(bad(format!(
                "rotation {q:?} has norm {norm}; give a unit quaternion [x, y, z, w] (identity is [0, 0, 0, 1])"
            )));
        }
    }
    if let super::RotationSymmetry::NFold(0) = entry.symmetry.rotation {
        return Err(bad(
            "symmetry n_fold must be at least 1 (1 means no symmetry)".into(),
        ));
    }
    if let Some([x, y]) = entry.symmetry.translation_axis {
        let norm = x.hypot(y);
        if !norm.is_finite() || (norm - 1.0).abs() > UNIT_NORM_TOLERANCE {
            return Err(bad(format!(
                "translation_axis [{x}, {y}] must be a unit vector in the object's xy plane, e.g. [1, 0]"
            )));
        }
    }
    if !(entry.weight.is_finite() && entry.weight >= 0.0) {
        return Err(bad(format!(
            "weight = {} must be a non-negative number (relative frequency in generated datasets; default 1)",
            entry.weight
        )));
    }
    if let Some((key, value)) = entry.dimensions.iter().find(|(_, v)| !v.is_finite()) {
        return Err(bad(format!(
            "dimension '{key}' = {value} is not a finite number of metres"
        )));
    }
    Ok(())
}

/// `<name>.obj` with characters other than ASCII letters, digits, `-`, `_` and `.` replaced by `_`, made unique
/// (case-insensitively, for case-insensitive file systems) by a numeric suffix.
fn unique_file_name(name: &str, used: &mut HashSet<String>) -> String {
    let stem: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    let stem = if stem.trim_matches('.').is_empty() {
        "object".to_string()
    } else {
        stem
    };
    let mut file = format!("{stem}.obj");
    let mut k = 1;
    while !used.insert(file.to_ascii_lowercase()) {
        k += 1;
        file = format!("{stem}_{k}.obj");
    }
    file
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), ObjectError> {
    crate::io::write_atomic(path, bytes).map_err(|source| ObjectError::Write {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
#[path = "set_tests.rs"]
mod tests;
