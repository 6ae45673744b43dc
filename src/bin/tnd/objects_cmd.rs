//! `tnd objects`: list an object set, export the built-in set, or generate a procedural training set, as meshes
//! plus an `objects.json` manifest.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use clap::{Args, Subcommand};
use tactile_derender::mesh::{LoadOptions, Units};
use tactile_derender::objects::inspect::{self, ImportOptions};
use tactile_derender::objects::procedural::{Kind, ProceduralConfig};
use tactile_derender::objects::{ObjectSet, Split, MANIFEST_FILE};

#[derive(Args, Debug)]
pub struct ObjectsArgs {
    #[command(subcommand)]
    pub command: ObjectsCommand,
}

#[derive(Subcommand, Debug)]
pub enum ObjectsCommand {
    /// Print the objects of a set as JSON lines (name, family, split, symmetry, triangles, closed).
    List {
        /// "builtin" or a directory with objects.json.
        #[arg(long, default_value = "builtin")]
        objects: String,
    },
    /// Write the built-in set to DIR (OBJ meshes in metres + objects.json).
    Export {
        /// Directory to write the meshes and objects.json into (created if missing).
        dir: PathBuf,
        #[command(flatten)]
        force: crate::args::ForceArg,
    },
    /// Report what a mesh file holds: shells, holes, non-manifold edges, volume, extent, and a unit warning when the
    /// size is implausible for a pressed object (e.g. a millimetre file read as metres).
    Check {
        /// The mesh file (OBJ, STL, PLY, glTF/GLB).
        mesh: PathBuf,
        /// Units of the file: m, cm, mm or metres per file unit.
        #[arg(long, default_value = "m")]
        units: Units,
    },
    /// Turn a folder of meshes (.obj, .stl, .ply, .gltf, .glb) into an object set: writes DIR/objects.json with each file's units (or
    /// a scale-to-fit), closedness report and a symmetry guess to check and edit.
    Import {
        /// The folder of mesh files; objects.json is written into it.
        dir: PathBuf,
        /// Units of the files (default: metres, or the plausible unit when a file's size says otherwise).
        #[arg(long)]
        units: Option<Units>,
        /// Scale every mesh so its largest extent is this many metres (e.g. 0.05; also spelled --fit-size, as in
        /// `tnd sim`).
        #[arg(long, alias = "fit-size")]
        fit: Option<f64>,
        /// Split of the imported objects: seen (may be trained on) or unseen (held out).
        #[arg(long, default_value = "seen")]
        split: String,
        /// Replace an existing objects.json.
        #[arg(long)]
        force: bool,
    },
    /// Generate a procedural training set into DIR (OBJ meshes in metres + objects.json): superquadrics, convex
    /// polytopes, blobs, rocks, extrusions with chamfered or filleted rims, lying profiles, unions of primitives,
    /// thin fins, blocks with small bumps, plates with through-holes and swept limbs (knots, rods, bodies with legs),
    /// plus (by default) the built-in catalogue.
    Generate {
        /// Directory to write the meshes and objects.json into (created if missing).
        dir: PathBuf,
        /// Number of procedural objects.
        #[arg(long, value_parser = crate::args::at_most::<100_000>, default_value_t = ProceduralConfig::default().count)]
        count: usize,
        /// Seed: object i depends only on (seed, i).
        #[arg(long, default_value_t = ProceduralConfig::default().seed)]
        seed: u64,
        /// Smallest and largest value of each object's largest extent, metres, as MIN,MAX.
        #[arg(long, value_delimiter = ',', num_args = 2, default_values_t = ProceduralConfig::default().extent_m)]
        extent: Vec<f64>,
        /// Share of a generated dataset's pairs that go to the built-in catalogue's objects (0 leaves them out).
        #[arg(long, default_value_t = 0.25)]
        builtin_share: f64,
        /// Kinds to draw, comma-separated (superquadric, polytope, blob, rock, extrusion, lying_extrusion, union,
        /// fin, bumps, plate, limbs), or `all`, or `v1` (the first nine: reproduces sets made before plates and
        /// limbs, object for object).
        #[arg(long, default_value = "all", value_parser = parse_kinds)]
        kinds: KindList,
        /// Mix in another object set as DIR=SHARE (repeatable): every object of DIR's objects.json (e.g. real
        /// meshes made into a set with `tnd objects import`), weighted so that they make up SHARE of a generated
        /// dataset's pairs. Their splits are kept: import training meshes with `--split seen`, since unseen ones
        /// land in the unseen_objects split and are never trained on.
        #[arg(long, value_name = "DIR=SHARE", value_parser = parse_include)]
        include: Vec<(PathBuf, f64)>,
        #[command(flatten)]
        force: crate::args::ForceArg,
    },
}

pub fn run(a: ObjectsArgs) -> Result<()> {
    match a.command {
        ObjectsCommand::List { objects } => list(&objects),
        ObjectsCommand::Export { dir, force } => export(&dir, force.force),
        ObjectsCommand::Check { mesh, units } => check(&mesh, units),
        ObjectsCommand::Import {
            dir,
            units,
            fit,
            split,
            force,
        } => import(&dir, units, fit, &split, force),
        ObjectsCommand::Generate {
            dir,
            count,
            seed,
            extent,
            builtin_share,
            kinds,
            include,
            force,
        } => generate(
            &dir,
            ProceduralConfig {
                count,
                seed,
                extent_m: [extent[0], extent[1]],
                kinds: kinds.0,
            },
            builtin_share,
            &include,
            force.force,
        ),
    }
}

/// `tnd objects list`: each object of the set `objects` as a JSON line, with its welded mesh's triangles and
/// closedness.
fn list(objects: &str) -> Result<()> {
    let set = ObjectSet::open(objects)?;
    for e in set.entries() {
        // Welded, as `tnd objects check` reports it (an STL stores each triangle's corners apart).
        let report = set.mesh(&e.name)?.welded_for_topology().report();
        let mut v = serde_json::to_value(e)?;
        if let Some(obj) = v.as_object_mut() {
            obj.insert("triangles".into(), report.triangles.into());
            obj.insert("closed".into(), report.closed.into());
        }
        println!("{v}");
    }
    Ok(())
}

/// `tnd objects export`: the built-in set written to `dir`.
fn export(dir: &Path, force: bool) -> Result<()> {
    let _out = crate::outputs::folder("dir", dir, force, &[])?;
    let set = ObjectSet::builtin();
    set.export(dir)?;
    println!(
        "{}",
        serde_json::json!({"exported": set.entries().len(), "dir": crate::path_json(dir)})
    );
    Ok(())
}

/// `tnd objects check`: what the mesh file holds, notes on stderr and the report as JSON.
fn check(mesh: &Path, units: Units) -> Result<()> {
    let c = inspect::check(
        mesh,
        &LoadOptions {
            units,
            fit_to_size: None,
        },
    )?;
    for note in &c.notes {
        eprintln!("{}: {note}", mesh.display());
    }
    println!("{}", serde_json::to_string(&c)?);
    Ok(())
}

/// `tnd objects import`: the folder `dir` of meshes made an object set (its objects.json written and read back),
/// each imported mesh as a JSON line.
fn import(
    dir: &Path,
    units: Option<Units>,
    fit: Option<f64>,
    split: &str,
    force: bool,
) -> Result<()> {
    let split = match split {
        "seen" => Split::Seen,
        "unseen" => Split::Unseen,
        other => bail!("--split must be seen or unseen, got '{other}'"),
    };
    let most = tactile_derender::mesh::MAX_FIT_SIZE_M;
    if let Some(f) = fit.filter(|f| !(f.is_finite() && *f > 0.0 && *f <= most)) {
        bail!("--fit must be a size in metres in (0, {most}], got {f}");
    }
    let _lock = tactile_derender::io::lock::OutputLock::acquire(dir)?;
    let path = dir.join(MANIFEST_FILE);
    if path.exists() && !force {
        bail!(
            "{}: already exists; pass --force to replace it",
            path.display()
        );
    }
    let options = ImportOptions {
        units,
        fit_m: fit,
        split,
    };
    let (manifest, imported, failed) = inspect::import_dir(dir, &options)?;
    for (file, e) in &failed {
        eprintln!(
            "skipped {}: {}",
            file.display(),
            tactile_derender::error::render(e)
        );
    }
    let hint = not_imported_hint(dir);
    if imported.is_empty() {
        let sep = if hint.is_empty() { "" } else { "; " };
        bail!(
            "{}: no readable mesh files (.obj, .stl, .ply, .gltf, .glb){sep}{hint}",
            dir.display()
        );
    }
    if !hint.is_empty() {
        eprintln!("{}: note: {hint}", dir.display());
    }
    for m in &imported {
        for note in &m.check.notes {
            eprintln!("{}: {note}", m.entry.name);
        }
        println!(
            "{}",
            serde_json::json!({"name": m.entry.name, "scale_to_m": m.entry.scale_to_m,
                "symmetry_guess": m.entry.symmetry, "check": m.check})
        );
    }
    let mut json = serde_json::to_string_pretty(&manifest)?;
    json.push('\n');
    tactile_derender::io::write_atomic(&path, json.as_bytes())
        .map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))?;
    // Read back what was written: the same validation `--objects DIR` will do.
    ObjectSet::load_dir(dir)?;
    eprintln!(
        "{}: {} objects ({} skipped); check the symmetry guesses",
        path.display(),
        imported.len(),
        failed.len()
    );
    Ok(())
}

/// What `tnd objects import` left out of `dir` that the user may have meant to import (meshes in subfolders,
/// COLLADA files), as one line of hints joined by "; " (empty when nothing was left out).
fn not_imported_hint(dir: &Path) -> String {
    let below = inspect::not_imported(dir);
    let mut hints = Vec::new();
    if let Some(sub) = &below.busiest_subfolder {
        hints.push(format!(
            "{} mesh file(s) lie in subfolders, which are not searched (import one as its own set, e.g. \
             tnd objects import {})",
            below.in_subfolders,
            sub.display()
        ));
    }
    if below.collada > 0 {
        hints.push(format!(
            "{} COLLADA (.dae) file(s) cannot be read: convert them to .glb, .obj or .stl (e.g. assimp \
             export, or Blender)",
            below.collada
        ));
    }
    hints.join("; ")
}

/// `tnd objects generate`: the procedural set of `config` (with the built-in catalogue at `builtin_share` and the
/// `include`d sets at theirs) exported to `dir`, a warning for each included set's unseen objects.
fn generate(
    dir: &Path,
    config: ProceduralConfig,
    builtin_share: f64,
    include: &[(PathBuf, f64)],
    force: bool,
) -> Result<()> {
    let inputs: Vec<&Path> = include.iter().map(|(p, _)| p.as_path()).collect();
    let _out = crate::outputs::folder("dir", dir, force, &inputs)?;
    let sets = include
        .iter()
        .map(|(path, share)| Ok((ObjectSet::load_dir(path)?, *share)))
        .collect::<Result<Vec<_>>>()?;
    let parts: Vec<(&ObjectSet, f64)> = sets.iter().map(|(set, s)| (set, *s)).collect();
    let set = ObjectSet::procedural_with(&config, builtin_share, &parts)?;
    set.export(dir)?;
    let mut included = Vec::new();
    for (set, share) in &sets {
        let unseen = set.entries_in(Split::Unseen).count();
        if unseen > 0 {
            eprintln!(
                "{}: {unseen} of its {} objects are unseen: they go to the unseen_objects split, never \
                 trained on (re-import with --split seen to train on them)",
                set.spec(),
                set.entries().len()
            );
        }
        included.push(serde_json::json!({
            "dir": set.spec(), "objects": set.entries().len(), "unseen": unseen, "share": share
        }));
    }
    println!(
        "{}",
        serde_json::json!({
            "generated": config.count, "objects": set.entries().len(), "dir": crate::path_json(dir), "included": included
        })
    );
    Ok(())
}

/// One `--include DIR=SHARE` of `tnd objects generate` (split at the last `=`).
fn parse_include(text: &str) -> Result<(PathBuf, f64), String> {
    let (dir, share) = text.rsplit_once('=').ok_or_else(|| {
        format!("'{text}': give the set and its share as DIR=SHARE, e.g. data/train_meshes=0.3")
    })?;
    let share: f64 = share.trim().parse().map_err(|_| {
        format!("'{text}': the share '{share}' is not a number (a fraction of the pairs, e.g. 0.3)")
    })?;
    if share.is_nan() || share <= 0.0 || share >= 1.0 {
        return Err(format!(
            "'{text}': the share {share} must be a fraction of the pairs in (0, 1)"
        ));
    }
    Ok((PathBuf::from(dir), share))
}

/// The `--kinds` list of `tnd objects generate`.
#[derive(Clone, Debug)]
pub struct KindList(Vec<Kind>);

fn parse_kinds(text: &str) -> Result<KindList, String> {
    match text {
        "all" => return Ok(KindList(Kind::ALL.to_vec())),
        "v1" => return Ok(KindList(Kind::V1.to_vec())),
        _ => {}
    }
    let kinds = text
        .split(',')
        .map(|name| {
            Kind::parse(name.trim()).ok_or_else(|| {
                let known: Vec<&str> = Kind::ALL.iter().map(|k| k.as_str()).collect();
                format!(
                    "unknown kind '{name}' (known: {}, all, v1)",
                    known.join(", ")
                )
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    if kinds.is_empty() {
        return Err("list at least one kind".into());
    }
    Ok(KindList(kinds))
}
