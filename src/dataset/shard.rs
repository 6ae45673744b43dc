//! One **shard**: the pairs of one split within one chunk of pair indices, as an uncompressed `.npz` with fixed array
//! names (see [`ARRAYS`]). Writing is atomic (temp file + rename) and reports the size and sha256 that go into the
//! manifest.

use std::io::Read;
use std::path::Path;

use sha2::{Digest, Sha256};

use super::manifest::ShardEntry;
use super::npz::{self, ArrayData, Dtype};
use super::{DatasetError, SplitName};
use crate::image::Image;
use crate::sensor::{Se2, SensorPose};

/// Directory of the shards inside a dataset.
pub const SHARDS_DIR: &str = "shards";

/// The image arrays, each float32 `(N, H, W)` in metres (mask 0/1), in storage order.
pub const IMAGE_ARRAYS: [&str; 5] = ["imprint", "target", "signature", "reference", "mask"];

/// Every array of a shard: name, dtype, trailing shape after `N` (`0` stands for H and W), meaning.
pub const ARRAYS: [(&str, Dtype, &str); 12] = [
    ("imprint", Dtype::F32, "(N, H, W) imprint Y = R - S, metres"),
    (
        "target",
        Dtype::F32,
        "(N, H, W) in-contact depth X0 = M * D, metres (0 outside the contact)",
    ),
    (
        "signature",
        Dtype::F32,
        "(N, H, W) signature S (depth with the object pressed in), metres",
    ),
    (
        "reference",
        Dtype::F32,
        "(N, H, W) reference R (undeformed membrane depth), metres",
    ),
    ("mask", Dtype::F32, "(N, H, W) contact mask M, 0 or 1"),
    ("index", Dtype::U64, "(N,) global pair index"),
    (
        "seed",
        Dtype::U64,
        "(N,) pair seed (reproduces the pair with the manifest's configuration)",
    ),
    (
        "object",
        Dtype::I32,
        "(N,) index into manifest object_set.manifest.objects",
    ),
    (
        "pose",
        Dtype::F64,
        "(N, 3) object pose x, y (metres), theta (radians) relative to the sensor axis",
    ),
    (
        "press",
        Dtype::F64,
        "(N,) press depth of the membrane apex below the object's top, metres (NaN = unknown)",
    ),
    (
        "sensor",
        Dtype::F64,
        "(N, 6) sensor position x, y, z (metres), yaw, tilt_x, tilt_y (radians)",
    ),
    (
        "contact_pixels",
        Dtype::I32,
        "(N,) number of pixels in contact",
    ),
];

/// One pair ready to be stored.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// Global pair index.
    pub index: usize,
    /// Pair seed.
    pub seed: u64,
    /// Index into the object set's entries.
    pub object: usize,
    pub split: SplitName,
    pub pose: Se2,
    pub sensor: SensorPose,
    /// Press depth, metres (NaN = unknown).
    pub press: f64,
    pub contact_pixels: usize,
    pub imprint: Image,
    pub target: Image,
    pub signature: Image,
    pub reference: Image,
    pub mask: Image,
}

impl Record {
    /// The image called `name` (one of [`IMAGE_ARRAYS`]).
    pub fn image(&self, name: &str) -> &Image {
        match name {
            "imprint" => &self.imprint,
            "target" => &self.target,
            "signature" => &self.signature,
            "reference" => &self.reference,
            _ => &self.mask,
        }
    }
}

/// Relative path of the shard of `split` in chunk `chunk`.
pub fn shard_file(split: SplitName, chunk: usize) -> String {
    format!("{SHARDS_DIR}/{}-{chunk:05}.npz", split.as_str())
}

/// Encode records (all of one resolution) as shard bytes.
pub fn encode(
    records: &[&Record],
    width: usize,
    height: usize,
) -> Result<Vec<u8>, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("dataset shard", || {
        let n = records.len();
        let mut arrays: Vec<ArrayData> = IMAGE_ARRAYS
            .iter()
            .map(|&name| {
                ArrayData::f32(
                    name,
                    vec![n, height, width],
                    records
                        .iter()
                        .flat_map(|r| r.image(name).data.iter().copied()),
                )
            })
            .collect();
        if let Some(r) = records.iter().find(|r| {
            IMAGE_ARRAYS
                .iter()
                .any(|a| (r.image(a).width, r.image(a).height) != (width, height))
        }) {
            return Err(format!("pair {} is not {width}x{height}", r.index));
        }
        arrays.push(ArrayData::u64(
            "index",
            vec![n],
            records.iter().map(|r| r.index as u64),
        ));
        arrays.push(ArrayData::u64(
            "seed",
            vec![n],
            records.iter().map(|r| r.seed),
        ));
        arrays.push(ArrayData::i32(
            "object",
            vec![n],
            records.iter().map(|r| r.object as i32),
        ));
        arrays.push(ArrayData::f64(
            "pose",
            vec![n, 3],
            records
                .iter()
                .flat_map(|r| [r.pose.x, r.pose.y, r.pose.theta]),
        ));
        arrays.push(ArrayData::f64(
            "press",
            vec![n],
            records.iter().map(|r| r.press),
        ));
        arrays.push(ArrayData::f64(
            "sensor",
            vec![n, 6],
            records.iter().flat_map(|r| {
                let p = r.sensor.position;
                [
                    p[0],
                    p[1],
                    p[2],
                    r.sensor.yaw,
                    r.sensor.tilt[0],
                    r.sensor.tilt[1],
                ]
            }),
        ));
        arrays.push(ArrayData::i32(
            "contact_pixels",
            vec![n],
            records.iter().map(|r| r.contact_pixels as i32),
        ));
        npz::encode(&arrays).map_err(String::from)
    })
}

/// Lower-case hex sha256 of bytes.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// Size and sha256 of a file, streaming.
pub fn file_digest(path: &Path) -> Result<(u64, String), DatasetError> {
    let mut f = std::fs::File::open(path).map_err(|e| DatasetError::io(path, e))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0u64;
    loop {
        let n = f.read(&mut buf).map_err(|e| DatasetError::io(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
        total += n as u64;
    }
    Ok((total, hex(&hasher.finalize())))
}

/// Check a shard file against its manifest entry: size first ([`DatasetError::Truncated`]), then sha256
/// ([`DatasetError::Checksum`]).
pub fn verify_file(dir: &Path, entry: &ShardEntry) -> Result<(), DatasetError> {
    let path = dir.join(&entry.file);
    let meta = std::fs::metadata(&path).map_err(|e| DatasetError::io(&path, e))?;
    if meta.len() != entry.bytes {
        return Err(DatasetError::Truncated {
            path,
            found: meta.len(),
            expected: entry.bytes,
        });
    }
    let (_, sha) = file_digest(&path)?;
    if sha != entry.sha256 {
        return Err(DatasetError::Checksum {
            path,
            found: sha,
            expected: entry.sha256.clone(),
        });
    }
    Ok(())
}

/// Encode and atomically write the shard of `split` in `chunk` under `dir`; returns its manifest entry.
pub fn write(
    dir: &Path,
    split: SplitName,
    chunk: usize,
    records: &[&Record],
    width: usize,
    height: usize,
) -> Result<ShardEntry, DatasetError> {
    let file = shard_file(split, chunk);
    let path = dir.join(&file);
    let bytes = encode(records, width, height).map_err(|e| DatasetError::Npz {
        path: path.clone(),
        message: e.into(),
    })?;
    let sha256 = sha256_hex(&bytes);
    crate::io::write_atomic(&path, &bytes).map_err(|e| DatasetError::io(&path, e))?;
    Ok(ShardEntry {
        file,
        split,
        chunk,
        pairs: records.len(),
        first_index: records.first().map_or(0, |r| r.index),
        last_index: records.last().map_or(0, |r| r.index),
        bytes: bytes.len() as u64,
        sha256,
    })
}
