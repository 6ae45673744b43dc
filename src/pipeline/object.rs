//! The object a user names: an entry of an object set (the built-in one or a directory with `objects.json`) or a
//! mesh file of any supported format, loaded in its resting pose with its symmetry. One definition for `tnd`'s
//! `--object/--objects/--units/--fit-size` and the workbench's scene.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::PipelineError;
use crate::mesh::{self, LoadOptions, Mesh, Units};
use crate::objects::inspect::size_note;
use crate::objects::{ObjectSet, Symmetry};

fn default_set() -> String {
    "builtin".into()
}

/// Which object: a name from an object set, or a path to a mesh file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct ObjectSpec {
    /// Object name from the object set, or a path to a mesh file (OBJ, STL, PLY, glTF/GLB).
    #[arg(long)]
    pub object: String,
    /// Object set: "builtin" or a directory with objects.json.
    #[arg(long, default_value_t = default_set())]
    pub objects: String,
    /// Units of a mesh file given by path (m, cm, mm or metres per unit).
    #[arg(long, default_value_t = Units::M)]
    pub units: Units,
    /// Scale a mesh file so that its largest extent is this many metres.
    #[arg(long)]
    pub fit_size: Option<f64>,
}

impl Default for ObjectSpec {
    fn default() -> Self {
        Self {
            object: "cross_w12_s50".into(),
            objects: default_set(),
            units: Units::M,
            fit_size: None,
        }
    }
}

/// An object ready for the pipeline: its name, its mesh in the resting pose (object frame, metres) and symmetry.
#[derive(Clone, Debug)]
pub struct LoadedObject {
    pub name: String,
    pub mesh: Mesh,
    /// From the object set's entry; a mesh file has none (no symmetry assumed).
    pub symmetry: Symmetry,
    /// What the user should know, one line each: a mesh file whose size says its units are wrong (a millimetre
    /// CAD file read as metres becomes a 50-metre object).
    pub warnings: Vec<String>,
}

impl LoadedObject {
    /// Refuse an object whose size says its units are wrong (its first [`Self::warnings`]): `what` of it (`"a
    /// track"`, `"a pose"`) would be meaningless, so the user hears it before any work, not after.
    pub fn check_scale(&self, what: &str) -> Result<(), PipelineError> {
        match self.warnings.first() {
            Some(w) => Err(PipelineError::Scale(format!(
                "{w}; {what} of it would be meaningless"
            ))),
            None => Ok(()),
        }
    }
}

impl ObjectSpec {
    /// The entry `name` of the set `objects`.
    pub fn library(objects: &str, name: &str) -> Self {
        Self {
            object: name.into(),
            objects: objects.into(),
            ..Self::default()
        }
    }

    /// The mesh file at `path` in `units`.
    pub fn file(path: &std::path::Path, units: Units) -> Self {
        Self {
            object: path.display().to_string(),
            units,
            ..Self::default()
        }
    }

    /// Load the object: the set's entry when the set has one of this name, else the mesh file.
    pub fn load(&self) -> Result<LoadedObject, PipelineError> {
        let set = ObjectSet::open(&self.objects)?;
        if let Some(entry) = set.find(&self.object) {
            let symmetry = entry.symmetry;
            if self.fit_size.is_some() || self.units != Units::M {
                return Err(PipelineError::Scale(format!(
                    "{}: an object of the set, sized by it; --units and --fit-size apply to mesh files only",
                    self.object
                )));
            }
            return Ok(LoadedObject {
                name: self.object.clone(),
                mesh: set.mesh(&self.object)?,
                symmetry,
                warnings: Vec::new(),
            });
        }
        let path = PathBuf::from(&self.object);
        if path.extension().is_some() || path.exists() {
            let options = LoadOptions {
                units: self.units,
                fit_to_size: self.fit_size,
            };
            let mesh = mesh::load(&path, &options)?.rest_on_table();
            let mut warnings = Vec::new();
            if let Some(note) = size_note(mesh.largest_extent(), self.units, self.fit_size) {
                warnings.push(format!("{}: {note}", path.display()));
            }
            let name = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| self.object.clone());
            return Ok(LoadedObject {
                name,
                mesh,
                symmetry: Symmetry::default(),
                warnings,
            });
        }
        let known: Vec<&str> = set.entries().iter().map(|e| e.name.as_str()).collect();
        Err(PipelineError::UnknownObject {
            name: self.object.clone(),
            set: self.objects.clone(),
            known: known.join(", "),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn library_entries_carry_their_symmetry_and_files_load_in_their_units() {
        let set = ObjectSet::builtin();
        let entry = &set.entries()[0];
        let loaded = ObjectSpec::library("builtin", &entry.name).load().unwrap();
        assert_eq!(loaded.symmetry, entry.symmetry);
        assert_eq!(loaded.name, entry.name);

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("tri.obj");
        std::fs::write(&path, "v 0 0 0\nv 10 0 0\nv 0 20 0\nf 1 2 3\n").unwrap();
        let loaded = ObjectSpec::file(&path, Units::Mm).load().unwrap();
        assert_eq!(loaded.name, "tri");
        assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
        // The same 20-unit file read as metres is a 20-metre object: the warning names millimetres.
        let as_metres = ObjectSpec::file(&path, Units::M).load().unwrap();
        assert_eq!(as_metres.warnings.len(), 1);
        assert!(
            as_metres.warnings[0].contains("probably in mm"),
            "{:?}",
            as_metres.warnings
        );
        let (lo, hi) = loaded.mesh.aabb();
        assert!(((hi - lo).y - 0.02).abs() < 1e-6, "{:?}", hi - lo);

        let err = ObjectSpec::library("builtin", "no_such_thing")
            .load()
            .unwrap_err();
        assert!(
            err.to_string().contains("unknown object 'no_such_thing'"),
            "{err}"
        );
    }
}
