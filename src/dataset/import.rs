//! **Import of real sensor pairs** (paper V.A, the real dataset used for fine-tuning and evaluation) into the dataset
//! format, so that real and synthetic data share one reader.
//!
//! The source directory holds a pair table, `pairs.csv` or `pairs.json`, whose rows name the object (an entry of
//! the object set), its pose relative to the sensor axis `x, y` (metres) and `theta` (radians), and image files
//! relative to the directory:
//!
//! | column | required | meaning |
//! | --- | --- | --- |
//! | `object`, `x`, `y`, `theta` | yes | object name and pose |
//! | `target` | yes | in-contact depth X0 (0 outside the contact) |
//! | `signature` or `imprint` | one of them | measured depth S with the object pressed in, or the imprint Y = R − S |
//! | `reference` | unless `reference.npy`/`.npz`/`.png` is in the directory | the sensor's reference frame R |
//! | `press` | no | press depth, metres (NaN = unknown otherwise) |
//! | `split` | no | `train`, `unseen_poses`, `unseen_objects` (default: the automatic 9:1 rule of [`super::split`]) |
//!
//! `pairs.json` is a list of objects with the same keys (numbers as JSON numbers). Images are `.npy`, `.npz` (its only
//! array, or `file.npz:name`) scaled by `npy_scale` metres per unit, or 16-bit grayscale PNG scaled by `png_scale`
//! (default millimetres); 0 means no measurement. Frames at the native or cropped size are cropped and resampled
//! ([`super::resample`]) — S and R as depths, then Y = R − S at the model resolution, as the simulator does.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::gen::{refuse_foreign_dir, remove_all_stale_temp_files};
use super::manifest::{
    DatasetKind, DatasetManifest, ImportInfo, ObjectSetInfo, SplitCounts, FORMAT_NAME,
    FORMAT_VERSION, MANIFEST_FILE, OBJECTS_DIR,
};
use super::shard::SHARDS_DIR;
use super::shard::{self, Record};
use super::split;
use super::{DatasetError, SplitName};
use crate::image::Image;
use crate::io::depth_file;
use crate::objects::ObjectSet;
use crate::sensor::resample;
use crate::sensor::{Se2, SensorPose};
use crate::sim::{PreparedObject, SimConfig, Simulator};

/// Pairs per shard chunk of an imported dataset.
pub const IMPORT_SHARD_PAIRS: usize = 1000;

/// Units and split options of an import.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ImportConfig {
    /// Metres per unit of `.npy`/`.npz` arrays (default 1: metres).
    pub npy_scale: f64,
    /// Metres per unit of 16-bit PNG images (default 0.001: millimetres).
    pub png_scale: f64,
    /// Split for rows without a `split` column; `None` = automatic (unseen objects, seen objects 9:1).
    pub split: Option<SplitName>,
    /// Seed of the automatic 9:1 split.
    pub seed: u64,
}

impl Default for ImportConfig {
    fn default() -> Self {
        Self {
            npy_scale: 1.0,
            png_scale: 0.001,
            split: None,
            seed: 0,
        }
    }
}

/// What an import did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImportReport {
    pub pairs: usize,
    pub counts: SplitCounts,
    pub out: PathBuf,
}

/// One row of the pair table, as strings.
type Row = BTreeMap<String, String>;

/// Import `from` (see the module docs) into a new dataset at `out`.
pub fn import(
    from: &Path,
    out: &Path,
    sim_config: &SimConfig,
    set: &ObjectSet,
    config: &ImportConfig,
) -> Result<ImportReport, DatasetError> {
    for (name, v) in [
        ("npy_scale", config.npy_scale),
        ("png_scale", config.png_scale),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(DatasetError::Config(format!(
                "{name} = {v} must be a positive number of metres per unit"
            )));
        }
    }
    let (table, rows) = read_table(from)?;
    if rows.is_empty() {
        return Err(DatasetError::Import {
            path: table,
            message: "the pair table has no rows".into(),
        });
    }
    refuse_unless_interrupted_import(out)?;
    let sim = Simulator::new(sim_config.clone())?;
    let mut reader = RowReader {
        from,
        table: &table,
        set,
        sim: &sim,
        config,
        global_reference: find_global_reference(from),
        tops: BTreeMap::new(),
    };
    let mut explicit_splits = Vec::with_capacity(rows.len());
    let mut records = Vec::with_capacity(rows.len());
    let mut sizes = Vec::new();
    for (i, row) in rows.iter().enumerate() {
        let (record, split, size) = reader.read(i, row)?;
        explicit_splits.push(split);
        sizes.push(size);
        records.push(record);
    }
    let table_name = table
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    write_real_dataset(
        out,
        RealSource {
            from: &from.display().to_string(),
            table: &table_name,
            sizes,
        },
        sim_config,
        set,
        config.seed,
        records,
        explicit_splits,
    )
}

/// Where the pairs of a real dataset came from (recorded in its manifest).
pub(crate) struct RealSource<'a> {
    /// The imported directory or recording.
    pub from: &'a str,
    /// The pair table's file name, or the recording's depth topic.
    pub table: &'a str,
    /// Source frame sizes `[w, h]`.
    pub sizes: Vec<[usize; 2]>,
}

/// Assign splits (explicit, else the automatic 9:1 rule with `seed`) and write `records` as a real dataset at `out`.
pub(crate) fn write_real_dataset(
    out: &Path,
    source: RealSource<'_>,
    sim_config: &SimConfig,
    set: &ObjectSet,
    seed: u64,
    mut records: Vec<Record>,
    explicit_splits: Vec<Option<SplitName>>,
) -> Result<ImportReport, DatasetError> {
    let (w, h) = sim_config.camera.resolution;
    let objects: Vec<usize> = records.iter().map(|r| r.object).collect();
    let mut sizes = source.sizes;
    let object_splits: Vec<_> = set.entries().iter().map(|e| e.split).collect();
    let auto = split::assign(seed, &objects, &object_splits, 10);
    let mut counts = SplitCounts::default();
    for (r, (explicit, auto)) in records
        .iter_mut()
        .zip(explicit_splits.into_iter().zip(auto))
    {
        r.split = explicit.unwrap_or(auto);
        counts.add(r.split, 1);
    }

    set.export(&out.join(OBJECTS_DIR))?;
    let mut shards = Vec::new();
    for (chunk, block) in records.chunks(IMPORT_SHARD_PAIRS).enumerate() {
        for split in SplitName::ALL {
            let mine: Vec<&Record> = block.iter().filter(|r| r.split == split).collect();
            if !mine.is_empty() {
                shards.push(shard::write(out, split, chunk, &mine, w, h)?);
            }
        }
    }
    sizes.sort_unstable();
    sizes.dedup();
    let manifest = DatasetManifest {
        format: FORMAT_NAME.into(),
        version: FORMAT_VERSION,
        kind: DatasetKind::Real,
        resolution: [w, h],
        sim: sim_config.clone(),
        generation: None,
        import: Some(ImportInfo {
            from: source.from.to_string(),
            table: source.table.to_string(),
            source_resolution: sizes,
        }),
        object_set: ObjectSetInfo {
            source: set.spec(),
            dir: OBJECTS_DIR.into(),
            manifest: set.exported_manifest(),
        },
        counts,
        arrays: DatasetManifest::array_table(),
        shards,
    };
    let path = out.join(MANIFEST_FILE);
    manifest.validate(&path)?;
    manifest.save(&path)?;
    Ok(ImportReport {
        pairs: records.len(),
        counts,
        out: out.to_path_buf(),
    })
}

/// Reads the rows of a pair table into records (split not yet assigned).
struct RowReader<'a> {
    from: &'a Path,
    table: &'a Path,
    set: &'a ObjectSet,
    sim: &'a Simulator,
    config: &'a ImportConfig,
    global_reference: Option<PathBuf>,
    /// Object name -> height of its top, metres (for the sensor pose of pairs with a press depth).
    tops: BTreeMap<String, f64>,
}

impl RowReader<'_> {
    /// Row `i` (0-based): its record, its explicit split (column or `--split`), and the source frame size.
    fn read(
        &mut self,
        i: usize,
        row: &Row,
    ) -> Result<(Record, Option<SplitName>, [usize; 2]), DatasetError> {
        let (w, h) = self.sim.config().camera.resolution;
        let at = |message: String| DatasetError::Import {
            path: self.table.to_path_buf(),
            message: format!("row {}: {message}", i + 1),
        };
        let name = field(row, "object").map_err(at)?;
        let object = self
            .set
            .entries()
            .iter()
            .position(|e| e.name == name)
            .ok_or_else(|| {
                at(format!(
                    "object '{name}' is not in the object set {}",
                    self.set.spec()
                ))
            })?;
        let num = |key: &str| -> Result<f64, DatasetError> {
            let s = field(row, key).map_err(at)?;
            let v: f64 = s
                .parse()
                .map_err(|_| at(format!("{key} '{s}' is not a number")))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(at(format!("{key} is not finite")))
            }
        };
        let pose = Se2::new(num("x")?, num("y")?, num("theta")?);
        let press = match row.get("press").filter(|s| !s.trim().is_empty()) {
            Some(_) => num("press")?,
            None => f64::NAN,
        };
        let explicit_split = match row.get("split").filter(|s| !s.trim().is_empty()) {
            Some(s) => Some(s.parse::<SplitName>().map_err(|e| at(e.into()))?),
            None => self.config.split,
        };
        let load = |key: &str| -> Result<Option<Image>, DatasetError> {
            row.get(key)
                .map(|s| s.trim())
                .filter(|s| !s.is_empty())
                .map(|rel| load_image(self.from, rel, self.config))
                .transpose()
        };
        let reference = match (load("reference")?, &self.global_reference) {
            (Some(r), _) => r,
            (None, Some(p)) => load_image(self.from, &p.to_string_lossy(), self.config)?,
            (None, None) => {
                return Err(at(
                    "no reference column and no reference.npy/.npz/.png in the directory".into(),
                ))
            }
        };
        let size = |img: &Image| (img.width, img.height);
        let target = load("target")?.ok_or_else(|| at("missing target".into()))?;
        let signature = match (load("signature")?, load("imprint")?) {
            (Some(s), _) => s,
            (None, Some(y)) if size(&y) == size(&reference) => {
                reference.zip_map(&y, |r, y| if r > 0.0 { r - y } else { 0.0 })
            }
            (None, Some(y)) => {
                return Err(at(format!(
                    "imprint is {:?} but the reference is {:?}",
                    size(&y),
                    size(&reference)
                )))
            }
            (None, None) => return Err(at("give a signature or an imprint".into())),
        };
        if size(&signature) != size(&reference) || size(&target) != size(&reference) {
            return Err(at(format!(
                "target {:?}, signature {:?} and reference {:?} must have the same size",
                size(&target),
                size(&signature),
                size(&reference)
            )));
        }
        let size = [reference.width, reference.height];
        let to_model = |img: &Image, what: &str| {
            resample::to_model(&self.sim.config().camera, img)
                .map_err(|m| at(format!("{what}: {m}")))
        };
        let s = to_model(&signature, "signature")?;
        let r = to_model(&reference, "reference")?;
        let target = to_model(&target, "target")?;
        let imprint = crate::sim::signature::imprint(&r, &s);
        let mask = Image {
            width: w,
            height: h,
            data: target
                .data
                .iter()
                .map(|&x| if x > 0.0 { 1.0 } else { 0.0 })
                .collect(),
        };
        let sensor = if press.is_finite() {
            let top = match self.tops.get(name) {
                Some(&t) => t,
                None => {
                    let t = PreparedObject::new(self.set.mesh(name)?)?.top_z;
                    self.tops.insert(name.to_string(), t);
                    t
                }
            };
            SensorPose::pressing(
                0.0,
                0.0,
                0.0,
                [0.0, 0.0],
                self.sim.apex_height(),
                top,
                press,
            )
        } else {
            SensorPose {
                position: [0.0, 0.0, f64::NAN],
                yaw: 0.0,
                tilt: [0.0, 0.0],
            }
        };
        let record = Record {
            index: i,
            seed: 0,
            object,
            split: SplitName::Train,
            pose,
            sensor,
            press,
            contact_pixels: mask.count_nonzero(),
            imprint,
            target,
            signature: s,
            reference: r,
            mask,
        };
        Ok((record, explicit_split, size))
    }
}

/// Import writes every shard before `manifest.json`, so a directory holding only `shards/`, `objects/` and temporary
/// files is an interrupted import of ours and is overwritten (the same command resumes by starting over); anything
/// else must be missing or empty.
pub(crate) fn refuse_unless_interrupted_import(out: &Path) -> Result<(), DatasetError> {
    let Ok(entries) = std::fs::read_dir(out) else {
        return refuse_foreign_dir(out);
    };
    let ours = entries.flatten().all(|e| {
        let name = e.file_name().to_string_lossy().into_owned();
        name == SHARDS_DIR
            || name == OBJECTS_DIR
            || (name.starts_with('.') && name.contains(".tmp."))
    });
    if ours && !out.join(MANIFEST_FILE).exists() {
        remove_all_stale_temp_files(out)
    } else {
        refuse_foreign_dir(out)
    }
}

fn field<'a>(row: &'a Row, key: &str) -> Result<&'a str, String> {
    row.get(key)
        .map(|s| s.trim())
        .filter(|s| !s.is_empty())
        .ok_or_else(|| format!("missing '{key}'"))
}

/// `pairs.csv` or `pairs.json` in `from`, parsed into rows of strings.
fn read_table(from: &Path) -> Result<(PathBuf, Vec<Row>), DatasetError> {
    let csv = from.join("pairs.csv");
    let json = from.join("pairs.json");
    if csv.is_file() {
        let text = std::fs::read_to_string(&csv).map_err(|e| DatasetError::io(&csv, e))?;
        let rows = parse_csv(&text).map_err(|e| DatasetError::Import {
            path: csv.clone(),
            message: e.into(),
        })?;
        Ok((csv, rows))
    } else if json.is_file() {
        let text = std::fs::read_to_string(&json).map_err(|e| DatasetError::io(&json, e))?;
        let bad = |message: String| DatasetError::Import {
            path: json.clone(),
            message,
        };
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
        let list = value
            .as_array()
            .ok_or_else(|| bad("expected a list of pair objects".into()))?;
        let rows = list
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let obj = v
                    .as_object()
                    .ok_or_else(|| bad(format!("entry {} is not an object", i + 1)))?;
                Ok(obj
                    .iter()
                    .map(|(k, v)| {
                        let s = match v {
                            serde_json::Value::String(s) => s.clone(),
                            other => other.to_string(),
                        };
                        (k.clone(), s)
                    })
                    .collect())
            })
            .collect::<Result<Vec<Row>, DatasetError>>()?;
        Ok((json, rows))
    } else {
        Err(DatasetError::Import {
            path: from.to_path_buf(),
            message: "no pairs.csv or pairs.json in the directory".into(),
        })
    }
}

/// `pairs.csv` text: a header line and comma-separated rows (no quoting; `#` starts a comment line), as rows of
/// trimmed strings keyed by the lower-case header.
pub fn parse_csv(text: &str) -> Result<Vec<BTreeMap<String, String>>, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("CSV", || {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
        let (_, header) = lines.next().ok_or("empty CSV")?;
        let keys: Vec<String> = header
            .split(',')
            .map(|k| k.trim().to_ascii_lowercase())
            .collect();
        lines
            .map(|(n, line)| {
                if line.contains('"') {
                    return Err(format!("line {}: quoted fields are not supported", n + 1));
                }
                let values: Vec<&str> = line.split(',').collect();
                if values.len() != keys.len() {
                    return Err(format!(
                        "line {}: {} fields, the header has {}",
                        n + 1,
                        values.len(),
                        keys.len()
                    ));
                }
                Ok(keys
                    .iter()
                    .cloned()
                    .zip(values.iter().map(|v| v.trim().to_string()))
                    .collect())
            })
            .collect()
    })
}

/// `reference.npy`, `reference.npz` or `reference.png` in `from`, relative.
fn find_global_reference(from: &Path) -> Option<PathBuf> {
    ["reference.npy", "reference.npz", "reference.png"]
        .iter()
        .map(PathBuf::from)
        .find(|p| from.join(p).is_file())
}

/// Load one image in metres; `rel` is relative to `from` (`file.npz:name` picks an array of an npz).
pub(crate) fn load_image(
    from: &Path,
    rel: &str,
    config: &ImportConfig,
) -> Result<Image, DatasetError> {
    depth_file::read(from, rel, config.npy_scale, config.png_scale).map_err(|e| {
        DatasetError::Import {
            path: e.path,
            message: e.message,
        }
    })
}
