//! **Users' own meshes** for the object library (paper V.A objects): what a mesh file holds ([`check`]: shells,
//! holes, non-manifold edges, volume, extent, a unit guess) and a folder of meshes turned into an object set
//! ([`import_dir`]: `objects.json` with units, scale-to-fit, closedness and a symmetry guess the user can edit).
//!
//! Real meshes (scans, CAD exports, convex decompositions) are often open, non-manifold or made of several shells;
//! nothing here refuses them — the simulator ray-casts any triangle soup and registration signs its distance with
//! the winding number — but the report says what was found so surprises are visible.

use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};
use parry3d::query::PointQuery;
use parry3d::shape::TriMesh;
use serde::{Deserialize, Serialize};

use super::{ObjectEntry, ObjectError, ObjectManifest, RotationSymmetry, Split, Symmetry};
use crate::mesh::{self, LoadOptions, Mesh, Units};

/// Largest extents, metres, that a pressed object plausibly has; outside, the units are probably wrong.
pub const PLAUSIBLE_EXTENT_M: [f64; 2] = [0.003, 0.5];

/// Whether a largest extent of `m` metres is plausible for a pressed object ([`PLAUSIBLE_EXTENT_M`]).
pub(crate) fn plausible_extent(m: f64) -> bool {
    (PLAUSIBLE_EXTENT_M[0]..=PLAUSIBLE_EXTENT_M[1]).contains(&m)
}

/// What [`check`] found in a mesh file (after its units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeshCheck {
    pub path: PathBuf,
    pub units: Units,
    pub vertices: usize,
    pub triangles: usize,
    /// Connected pieces (after welding vertices closer than a millionth of the extent).
    pub shells: usize,
    /// Edges used by one triangle only (the rims of holes).
    pub boundary_edges: usize,
    /// Edges used by more than two triangles, or twice in the same direction.
    pub non_manifold_edges: usize,
    /// Watertight and consistently oriented.
    pub closed: bool,
    /// Enclosed volume, m³ (negative: inward-facing); `None` for an open mesh, which encloses nothing.
    pub volume_m3: Option<f64>,
    /// Bounding-box size, metres.
    pub extent_m: [f64; 3],
    /// A likely unit when the extent is implausible in the given one (e.g. a millimetre file read as metres).
    pub likely_units: Option<Units>,
    /// Plain-language findings.
    pub notes: Vec<String>,
}

/// Load `path` with `options` and report what it holds.
pub fn check(path: &Path, options: &LoadOptions) -> Result<MeshCheck, ObjectError> {
    Ok(check_mesh(path, &load(path, options)?, options))
}

fn load(path: &Path, options: &LoadOptions) -> Result<Mesh, ObjectError> {
    mesh::load(path, options).map_err(ObjectError::MeshFile)
}

/// What `mesh`, read from `path` with `options`, holds.
fn check_mesh(path: &Path, mesh: &Mesh, options: &LoadOptions) -> MeshCheck {
    let (lo, hi) = mesh.aabb();
    let size = (hi - lo).as_dvec3();
    let largest = size.max_element();
    let welded = mesh.welded_for_topology();
    let report = welded.report();
    let shells = welded.shell_count();
    let likely_units = if options.fit_to_size.is_none() {
        likely_units(largest, options.units)
    } else {
        None
    };
    let mut notes: Vec<String> = size_note(largest, options.units, options.fit_to_size)
        .into_iter()
        .collect();
    if shells > 1 {
        notes.push(format!(
            "{shells} separate shells (e.g. a convex decomposition or an assembly)"
        ));
    }
    if report.boundary_edges > 0 {
        notes.push(format!(
            "open: {} boundary edges (holes)",
            report.boundary_edges
        ));
    }
    if report.bad_edges > 0 {
        notes.push(format!(
            "{} non-manifold or inconsistently oriented edges",
            report.bad_edges
        ));
    }
    if report.closed && report.volume_m3 < 0.0 {
        notes.push("faces point inwards (negative volume)".into());
    }
    MeshCheck {
        path: path.to_path_buf(),
        units: options.units,
        vertices: mesh.vertices().len(),
        triangles: mesh.triangles().len(),
        shells,
        boundary_edges: report.boundary_edges,
        non_manifold_edges: report.bad_edges,
        closed: report.closed,
        volume_m3: report.closed.then_some(report.volume_m3),
        extent_m: size.to_array(),
        likely_units,
        notes,
    }
}

/// What to tell a user whose object's largest extent is `largest_m` metres (read in `units`, scaled to `fit_size`
/// metres if given) when that is implausible for a pressed object: the unit that makes it plausible, or, when none
/// does, that it needs scaling.
pub fn size_note(largest_m: f64, units: Units, fit_size: Option<f64>) -> Option<String> {
    if fit_size.is_some() || plausible_extent(largest_m) {
        return None;
    }
    let read = match units {
        Units::Scale(s) => format!("read at scale {s}"),
        u => format!("in {u}"),
    };
    Some(match likely_units(largest_m, units) {
        Some(u) => format!(
            "largest extent {} {read} is implausible for a pressed object; the file is probably in \
             {u} (--units {u} gives {:.1} mm)",
            length(largest_m),
            largest_m / units.to_metres() * u.to_metres() * 1e3
        ),
        None => format!(
            "largest extent {} {read} is implausible for a pressed object ({:.0} mm to {:.1} m), \
             and no unit makes it plausible; scale it with --fit-size (e.g. --fit-size 0.05 for 50 mm)",
            length(largest_m),
            PLAUSIBLE_EXTENT_M[0] * 1e3,
            PLAUSIBLE_EXTENT_M[1]
        ),
    })
}

/// The unit under which a largest extent of `largest_m` metres (read with `units`) becomes plausible, if the given
/// one is not. Millimetres win whenever they make it 5 mm or more: CAD and slicer files (STL above all) are in
/// millimetres and centimetre files are rare, so a file 13 units across is a 13 mm screw, not a 130 mm object wider
/// than the sensor (a 3-unit file stays a 30 mm object: at 3 mm it would barely touch the membrane). Otherwise the
/// plausible unit that brings the object closest (in ratio) to a typical 50 mm.
pub fn likely_units(largest_m: f64, units: Units) -> Option<Units> {
    if plausible_extent(largest_m) {
        return None;
    }
    let in_file_units = largest_m / units.to_metres();
    let candidates: Vec<Units> = [Units::Mm, Units::Cm, Units::M]
        .into_iter()
        .filter(|u| *u != units && plausible_extent(in_file_units * u.to_metres()))
        .collect();
    if candidates.contains(&Units::Mm) && in_file_units * Units::Mm.to_metres() >= 0.005 {
        return Some(Units::Mm);
    }
    candidates.into_iter().min_by(|a, b| {
        let off = |u: &Units| (in_file_units * u.to_metres() / 0.05).ln().abs();
        off(a).total_cmp(&off(b))
    })
}

/// A length for a message: millimetres below a metre (three significant decimals), else metres.
pub(crate) fn length(m: f64) -> String {
    if m.abs() < 1.0 {
        format!("{:.3} mm", m * 1e3)
    } else {
        format!("{m:.2} m")
    }
}

/// Guess the rotational symmetry of a resting mesh about the vertical axis through its surface centroid:
/// continuous when seven irregular angles all map it onto itself, else the largest n ≤ [`MAX_GUESSED_FOLD`] for which
/// every rotation by a multiple of 2π/n does (the first alone would let a 33-fold guess pass on a 30-tooth gear: the
/// two angles are 0.4 mm apart at its rim). "Onto itself": 99 % of 1 000 surface samples, rotated, lie within 1 % of
/// the extent of the surface. That counts a gear's teeth (the mean distance, used before, did not: the flat faces
/// that any rotation keeps in place outweighed them) and forgives a small keyway. A guess for the user to check.
pub fn guess_symmetry(mesh: &Mesh) -> Symmetry {
    let centre = mesh.surface_centroid();
    let tolerance = 0.01 * mesh.largest_extent().max(1e-9);
    let Ok(trimesh) = TriMesh::new(mesh.vertices().to_vec(), mesh.triangles().to_vec()) else {
        return Symmetry::default();
    };
    let samples = mesh::sample_surface(mesh, 1000, 7);
    // At most 1 % of the samples may land off the surface (a keyway, a can's pull tab, a scan's spike: features the
    // sensor rarely touches); counting stops at the first sample over that, so that the many angles that fail cost
    // a few queries each.
    let allowed_off = samples.len() / 100;
    let fits = |angle: f64| {
        let q = DQuat::from_rotation_z(angle);
        samples
            .iter()
            .filter(|&&p| {
                let r = centre + q * DVec3::new(p.x - centre.x, p.y - centre.y, p.z - centre.z);
                f64::from(trimesh.distance_to_local_point(r.as_vec3(), true)) >= tolerance
            })
            .take(allowed_off + 1)
            .count()
            <= allowed_off
    };
    let rotation = if [0.37, 1.1, 1.9, 2.6, 3.3, 4.4, 5.5]
        .iter()
        .all(|&a| fits(a))
    {
        RotationSymmetry::Continuous
    } else if let Some(n) = (2..=MAX_GUESSED_FOLD)
        .rev()
        .find(|&n| (1..n).all(|k| fits(std::f64::consts::TAU * f64::from(k) / f64::from(n))))
    {
        RotationSymmetry::NFold(n)
    } else {
        RotationSymmetry::None
    };
    Symmetry {
        rotation,
        translation_axis: None,
    }
}

/// The largest n-fold symmetry [`guess_symmetry`] looks for (a 64-tooth gear; finer ones read as continuous).
pub const MAX_GUESSED_FOLD: u32 = 64;

/// What lies below a folder that [`import_dir`] does not read (it reads only the files directly in it): mesh files
/// in subfolders (a URDF package keeps them in `meshes/visual`, `meshes/collision`) and formats it cannot read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NotImported {
    /// Mesh files in subfolders (up to three levels down).
    pub in_subfolders: usize,
    /// The subfolder holding the most of them.
    pub busiest_subfolder: Option<PathBuf>,
    /// COLLADA (`.dae`) files, anywhere in those levels.
    pub collada: usize,
}

/// Look below `dir` for what [`import_dir`] leaves out, to tell the user (errors reading subfolders are ignored:
/// this is a hint, not the import).
pub fn not_imported(dir: &Path) -> NotImported {
    fn walk(dir: &Path, depth: usize, top: bool, out: &mut NotImported, best: &mut usize) {
        let Ok(read) = std::fs::read_dir(dir) else {
            return;
        };
        let mut here = 0;
        for path in read.flatten().map(|e| e.path()) {
            if path.is_dir() {
                if depth < 3 {
                    walk(&path, depth + 1, false, out, best);
                }
            } else if path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("dae"))
            {
                out.collada += 1;
            } else if !top && mesh::is_mesh_file(&path) {
                here += 1;
            }
        }
        out.in_subfolders += here;
        if here > *best {
            *best = here;
            out.busiest_subfolder = Some(dir.to_path_buf());
        }
    }
    let mut out = NotImported::default();
    walk(dir, 0, true, &mut out, &mut 0);
    out
}

/// Options of [`import_dir`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ImportOptions {
    /// Units of the files; `None`: metres, unless the extent is implausible and another unit makes it plausible.
    pub units: Option<Units>,
    /// Scale every mesh so its largest extent is this many metres (overrides the units).
    pub fit_m: Option<f64>,
    /// Split of every imported object (default seen).
    pub split: Split,
}

/// One imported file.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImportedMesh {
    pub entry: ObjectEntry,
    pub check: MeshCheck,
}

/// What [`import_dir`] made of a folder: the manifest, each imported mesh with its check, and the files that could
/// not be read with their errors.
pub type Imported = (
    ObjectManifest,
    Vec<ImportedMesh>,
    Vec<(PathBuf, ObjectError)>,
);

/// Turn every mesh file ([`mesh::MESH_EXTENSIONS`]) directly in `dir` into an object entry (name from the file stem,
/// `scale_to_m` from the units or the fit, symmetry guessed) and return them with their checks; files that cannot be
/// read are returned as errors beside the others, so one bad file does not stop the import.
pub fn import_dir(dir: &Path, options: &ImportOptions) -> Result<Imported, ObjectError> {
    let read = std::fs::read_dir(dir).map_err(|source| ObjectError::ReadDir {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut files: Vec<PathBuf> = read
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file() && mesh::is_mesh_file(p))
        .collect();
    files.sort();
    let mut imported = Vec::new();
    let mut failed = Vec::new();
    let mut names = std::collections::HashSet::new();
    for path in files {
        match import_file(&path, dir, options, &mut names) {
            Ok(m) => imported.push(m),
            Err(e) => failed.push((path, e)),
        }
    }
    let manifest = ObjectManifest {
        version: super::MANIFEST_VERSION,
        objects: imported.iter().map(|m| m.entry.clone()).collect(),
    };
    Ok((manifest, imported, failed))
}

fn import_file(
    path: &Path,
    dir: &Path,
    options: &ImportOptions,
    names: &mut std::collections::HashSet<String>,
) -> Result<ImportedMesh, ObjectError> {
    // The file is read once, in file units; each scale is applied to that mesh as `mesh::load` would.
    let raw = load(path, &LoadOptions::default())?;
    let scaled = |units: Units| {
        let options = LoadOptions {
            units,
            fit_to_size: None,
        };
        raw.clone()
            .apply_units(&options, &path.display().to_string())
            .map(|m| (m, options))
            .map_err(ObjectError::MeshFile)
    };
    let given = options.units.unwrap_or(Units::M);
    let (mesh, read_as) = scaled(given)?;
    let first = check_mesh(path, &mesh, &read_as);
    let largest = first.extent_m.iter().copied().fold(0.0, f64::max);
    let scale_to_m = match (options.fit_m, options.units, first.likely_units) {
        (Some(fit), _, _) => fit / (largest / given.to_metres()).max(1e-12),
        (None, None, Some(likely)) => likely.to_metres(),
        (None, _, _) => given.to_metres(),
    };
    let (mesh, read_as) = scaled(Units::Scale(scale_to_m))?;
    let mut check = check_mesh(path, &mesh, &read_as);
    let final_largest = check.extent_m.iter().copied().fold(0.0, f64::max);
    if options.fit_m.is_none() && !plausible_extent(final_largest) {
        // Not written into the set: a 0.06 mm finger or a 700 m engine only fails later, in the simulator.
        let read = options.units.unwrap_or(Units::M);
        let note = size_note(final_largest, read, None).unwrap_or_default();
        let advice = if options.units.is_some() {
            "not imported (without --units each file's size picks its unit; or add it to objects.json with its scale_to_m)"
        } else {
            "not imported"
        };
        return Err(ObjectError::ImplausibleSize {
            path: path.to_path_buf(),
            message: format!("{note}; {advice}"),
        });
    }
    if let (None, None, Some(likely)) = (options.fit_m, options.units, first.likely_units) {
        check.notes.insert(
            0,
            format!(
                "units guessed from its size: {likely} (largest extent {:.1} mm; --units, or scale_to_m in \
                 objects.json, to change)",
                final_largest * 1e3
            ),
        );
    }
    let mesh = mesh.rest_on_table();
    let stem: String = path
        .file_stem()
        .map(|s| s.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let mut name = if stem.is_empty() {
        "object".to_string()
    } else {
        stem
    };
    let base = name.clone();
    let mut k = 1;
    while !names.insert(name.clone()) {
        k += 1;
        name = format!("{base}_{k}");
    }
    let relative = path.strip_prefix(dir).unwrap_or(path);
    Ok(ImportedMesh {
        entry: ObjectEntry {
            name,
            family: None,
            mesh: relative.display().to_string(),
            scale_to_m,
            rotation: None,
            split: options.split,
            symmetry: guess_symmetry(&mesh),
            dimensions: Default::default(),
            weight: 1.0,
        },
        check,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::objects::shapes;

    #[test]
    fn units_guess_names_the_plausible_unit() {
        assert_eq!(likely_units(50.0, Units::M), Some(Units::Mm));
        assert_eq!(likely_units(0.05, Units::M), None);
        assert_eq!(likely_units(0.00005, Units::Mm), Some(Units::M));
        // 3–50 units across is plausible in millimetres and in centimetres: millimetres, the CAD convention (a
        // 13 mm screw, a 6.35 mm nut; not a 130 mm part wider than the sensor).
        assert_eq!(likely_units(13.0, Units::M), Some(Units::Mm));
        assert_eq!(likely_units(6.35, Units::M), Some(Units::Mm));
        // Under 5 units centimetres (a 3 mm part would barely touch the membrane; 1.2 mm is implausible).
        assert_eq!(likely_units(3.0, Units::M), Some(Units::Cm));
        assert_eq!(likely_units(1.2, Units::M), Some(Units::Cm));
        // A metres file read as millimetres.
        assert_eq!(likely_units(0.000057, Units::Mm), Some(Units::M));
    }

    #[test]
    fn size_notes_name_the_unit_or_the_scaling() {
        assert_eq!(size_note(0.05, Units::M, None), None);
        assert_eq!(size_note(50.0, Units::M, Some(0.05)), None);
        let mm = size_note(50.0, Units::M, None).unwrap();
        assert!(
            mm.contains("probably in mm") && mm.contains("50.0 mm"),
            "{mm}"
        );
        // 743 m read as metres is still 0.74 m in mm: no unit helps, scaling does.
        let big = size_note(743.0, Units::M, None).unwrap();
        assert!(
            big.contains("no unit") && big.contains("--fit-size"),
            "{big}"
        );
        // Tiny sizes are written in millimetres, not as 0.0000 m.
        let tiny = size_note(0.000057, Units::Mm, None).unwrap();
        assert!(tiny.starts_with("largest extent 0.057 mm in mm"), "{tiny}");
        let scaled = size_note(743.0, Units::Scale(1.0), None).unwrap();
        assert!(scaled.contains("read at scale 1 "), "{scaled}");
    }

    #[test]
    fn symmetry_guesses_match_the_built_in_shapes() {
        let cross = shapes::cross(0.012, 0.05, 0.02).unwrap();
        assert_eq!(guess_symmetry(&cross).rotation, RotationSymmetry::NFold(4));
        let sphere = shapes::sphere(0.02, 3).unwrap();
        assert_eq!(
            guess_symmetry(&sphere).rotation,
            RotationSymmetry::Continuous
        );
        let lying = shapes::cylinder_lying(0.01, 0.05, 32).unwrap();
        assert_eq!(guess_symmetry(&lying).rotation, RotationSymmetry::NFold(2));
        let tri = [
            glam::Vec2::new(0.0, 0.0),
            glam::Vec2::new(0.03, 0.0),
            glam::Vec2::new(0.005, 0.02),
        ];
        let wedge = shapes::extrude_z(&tri, 0.01).unwrap();
        assert_eq!(guess_symmetry(&wedge).rotation, RotationSymmetry::None);
    }

    /// A gear: a 42 mm disc, 8 mm thick, with `teeth` teeth 2.5 mm deep (square waves in the radius).
    fn gear(teeth: u32) -> Mesh {
        let outline: Vec<glam::Vec2> = (0..teeth * 8)
            .map(|k| {
                let phi = std::f32::consts::TAU * k as f32 / (teeth * 8) as f32;
                let r = if (k % 8) < 4 { 0.021 } else { 0.0185 };
                glam::Vec2::new(r * phi.cos(), r * phi.sin())
            })
            .collect();
        shapes::extrude_z(&outline, 0.008).unwrap()
    }

    #[test]
    fn symmetry_guess_counts_the_teeth_of_a_gear() {
        // The teeth are 6 % of the extent deep but a small share of the surface: the discs' faces, which every
        // rotation keeps in place, made the old mean-distance test call such gears continuous.
        for teeth in [5, 12, 30] {
            assert_eq!(
                guess_symmetry(&gear(teeth)).rotation,
                RotationSymmetry::NFold(teeth),
                "{teeth} teeth"
            );
        }
        // One 4 mm lug (3 % of the surface) on a 64-sided disc breaks every rotation.
        let circle: Vec<glam::Vec2> = (0..64)
            .map(|k| {
                let phi = std::f32::consts::TAU * k as f32 / 64.0;
                0.02 * glam::Vec2::new(phi.cos(), phi.sin())
            })
            .collect();
        let disc = shapes::extrude_z(&circle, 0.008).unwrap();
        let square = [
            glam::Vec2::new(-0.002, -0.002),
            glam::Vec2::new(0.002, -0.002),
            glam::Vec2::new(0.002, 0.002),
            glam::Vec2::new(-0.002, 0.002),
        ];
        let lug = shapes::extrude_z(&square, 0.006).unwrap().transformed(
            &glam::Affine3A::from_translation(glam::Vec3::new(0.021, 0.0, 0.0)),
        );
        assert_eq!(
            guess_symmetry(&Mesh::merged(&[disc.clone(), lug])).rotation,
            RotationSymmetry::None
        );
        assert_eq!(guess_symmetry(&disc).rotation, RotationSymmetry::Continuous);
    }

    #[test]
    fn check_counts_shells_and_holes_and_import_reads_a_folder() {
        let dir = tempfile::tempdir().unwrap();
        let a = shapes::sphere(0.01, 2).unwrap();
        let b = a.transformed(&glam::Affine3A::from_translation(glam::Vec3::new(
            0.05, 0.0, 0.0,
        )));
        let two = Mesh::merged(&[a.clone(), b]);
        // Millimetre coordinates: a 70 mm pair of spheres written as numbers in millimetres.
        let mm = two.transformed(&glam::Affine3A::from_scale(glam::Vec3::splat(1000.0)));
        std::fs::write(dir.path().join("Two Spheres.obj"), mm.to_obj_string()).unwrap();
        let mut holed = a.clone();
        holed = Mesh::from_raw(
            holed.vertices().to_vec(),
            holed.triangles()[3..].to_vec(),
            "holed",
        )
        .unwrap();
        std::fs::write(dir.path().join("holed.obj"), holed.to_obj_string()).unwrap();
        std::fs::write(dir.path().join("broken.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();

        let c = check(&dir.path().join("Two Spheres.obj"), &LoadOptions::default()).unwrap();
        assert_eq!(c.shells, 2);
        assert!(c.closed);
        assert_eq!(c.likely_units, Some(Units::Mm));
        let h = check(&dir.path().join("holed.obj"), &LoadOptions::default()).unwrap();
        assert!(!h.closed && h.boundary_edges > 0, "{h:?}");

        let (manifest, imported, failed) =
            import_dir(dir.path(), &ImportOptions::default()).unwrap();
        assert_eq!(failed.len(), 1, "{failed:?}");
        assert_eq!(imported.len(), 2);
        let two = manifest
            .objects
            .iter()
            .find(|e| e.name == "two_spheres")
            .unwrap();
        assert!((two.scale_to_m - 0.001).abs() < 1e-12);
        // The guess is said, not only applied.
        let two_check = &imported
            .iter()
            .find(|m| m.entry.name == "two_spheres")
            .unwrap()
            .check;
        assert!(
            two_check.notes[0]
                .starts_with("units guessed from its size: mm (largest extent 70.0 mm"),
            "{:?}",
            two_check.notes
        );
        // Given units that make a file implausible (the 20 mm holed sphere, in metres, read as millimetres) leave
        // that file out with the unit that fits, and keep the others.
        let (_, imported, failed) = import_dir(
            dir.path(),
            &ImportOptions {
                units: Some(Units::Mm),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(
            imported
                .iter()
                .map(|m| m.entry.name.as_str())
                .collect::<Vec<_>>(),
            ["two_spheres"]
        );
        let (path, e) = failed
            .iter()
            .find(|(p, _)| p.ends_with("holed.obj"))
            .unwrap();
        let e = e.to_string();
        assert!(
            e.starts_with(&path.display().to_string())
                && e.contains("0.020 mm in mm is implausible")
                && e.contains("probably in m ")
                && e.contains("not imported"),
            "{e}"
        );
        let fit = import_dir(
            dir.path(),
            &ImportOptions {
                fit_m: Some(0.05),
                ..Default::default()
            },
        )
        .unwrap();
        let c = &fit
            .1
            .iter()
            .find(|m| m.entry.name == "two_spheres")
            .unwrap()
            .check;
        assert!((c.extent_m[0] - 0.05).abs() < 1e-6, "{:?}", c.extent_m);
    }

    #[test]
    fn not_imported_finds_meshes_in_subfolders_and_collada_files() {
        let dir = tempfile::tempdir().unwrap();
        let visual = dir.path().join("meshes/visual");
        let collision = dir.path().join("meshes/collision");
        std::fs::create_dir_all(&visual).unwrap();
        std::fs::create_dir_all(&collision).unwrap();
        for f in ["a.STL", "b.stl", "c.obj"] {
            std::fs::write(collision.join(f), "").unwrap();
        }
        std::fs::write(visual.join("a.dae"), "").unwrap();
        std::fs::write(visual.join("a.png"), "").unwrap();
        std::fs::write(dir.path().join("top.obj"), "").unwrap();
        let n = not_imported(dir.path());
        assert_eq!(n.in_subfolders, 3);
        assert_eq!(n.busiest_subfolder.as_deref(), Some(collision.as_path()));
        assert_eq!(n.collada, 1);
        assert_eq!(not_imported(&collision).in_subfolders, 0);
    }
}
