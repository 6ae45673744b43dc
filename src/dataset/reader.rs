//! The dataset **reader**: [`Dataset::open`] validates `manifest.json` (format, version, counts) and every shard's
//! size; the first access to a shard checks its sha256 and each array's dtype and shape, after which pairs are read
//! by seeking straight into the stored `.npz` members (random access). [`Dataset::batches`] yields shuffled
//! mini-batches of (imprint, target) for training, in metres — normalisation belongs to the model config.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::manifest::{DatasetManifest, ShardEntry, MANIFEST_FILE, PROGRESS_FILE};
use super::npz::{self, Dtype, MemberInfo, NpzIndex};
use super::shard::{self, IMAGE_ARRAYS};
use super::split::mix64;
use super::{DatasetError, Pair, PairMeta, SplitName};
use crate::image::Image;
use crate::objects::ObjectSet;
use crate::sensor::{Se2, SensorPose};
use crate::sim::SimConfig;

/// A mini-batch of pairs: row-major `(n, height, width)` images in metres.
#[derive(Clone, Debug, PartialEq)]
pub struct Batch {
    pub n: usize,
    pub width: usize,
    pub height: usize,
    /// Imprints Y, `n * height * width` values.
    pub imprint: Vec<f32>,
    /// Targets X0, `n * height * width` values.
    pub target: Vec<f32>,
    /// The pairs' positions within the split.
    pub indices: Vec<usize>,
}

/// An opened dataset. Cheap to share between threads (`&Dataset` is `Sync`).
pub struct Dataset {
    dir: PathBuf,
    manifest: DatasetManifest,
    /// Per split: the shards in order and the split index of each shard's first pair.
    splits: [Vec<(usize, usize)>; 3],
    shards: Vec<Mutex<Option<Arc<LoadedShard>>>>,
}

/// A verified shard: where its images are and its metadata.
struct LoadedShard {
    path: PathBuf,
    file: File,
    /// Serialises seek + read where positioned reads are not available.
    #[cfg_attr(unix, allow(dead_code))]
    seek_lock: Mutex<()>,
    images: Vec<MemberInfo>,
    index: Vec<u64>,
    seed: Vec<u64>,
    object: Vec<i32>,
    pose: Vec<f64>,
    press: Vec<f64>,
    sensor: Vec<f64>,
    contact_pixels: Vec<i32>,
}

impl Dataset {
    /// Open and validate `dir` (see the module docs). Shard checksums are verified on first use; call
    /// [`Dataset::verify`] to check every shard now.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let dir = dir.as_ref().to_path_buf();
        let path = dir.join(MANIFEST_FILE);
        if !path.exists() {
            let message = if dir.join(PROGRESS_FILE).exists() {
                "generation has not finished (progress.json but no manifest.json); re-run the same `tnd dataset gen` command".to_string()
            } else {
                format!(
                    "no {MANIFEST_FILE} (make one with `tnd dataset gen` or `tnd dataset import`)"
                )
            };
            return Err(DatasetError::NotADataset { path: dir, message });
        }
        let mut manifest = DatasetManifest::load(&path)?;
        crate::sim::bounds::check_settings(&manifest.sim).map_err(|e| DatasetError::Manifest {
            path: path.clone(),
            message: format!("its sensor cannot exist: {}: {}", e.setting, e.message),
        })?;
        // A membrane mesh stored with the dataset (`tnd dataset gen --elastomer-mesh`) is named relative to it.
        if let Some(mesh) = &manifest.sim.elastomer.mesh_file {
            if mesh.is_relative() && dir.join(mesh).is_file() {
                manifest.sim.elastomer.mesh_file = Some(dir.join(mesh));
            }
        }
        let mut splits: [Vec<(usize, usize)>; 3] = Default::default();
        for (i, s) in manifest.shards.iter().enumerate() {
            let list = &mut splits[s.split.code()];
            let start = list
                .last()
                .map_or(0, |&(j, start)| start + manifest.shards[j].pairs);
            list.push((i, start));
            let shard_path = dir.join(&s.file);
            let len = std::fs::metadata(&shard_path)
                .map_err(|e| DatasetError::io(&shard_path, e))?
                .len();
            if len != s.bytes {
                return Err(DatasetError::Truncated {
                    path: shard_path,
                    found: len,
                    expected: s.bytes,
                });
            }
        }
        let shards = manifest.shards.iter().map(|_| Mutex::new(None)).collect();
        Ok(Self {
            dir,
            manifest,
            splits,
            shards,
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn manifest(&self) -> &DatasetManifest {
        &self.manifest
    }

    pub fn sim_config(&self) -> &SimConfig {
        &self.manifest.sim
    }

    /// `(width, height)` of every image.
    pub fn resolution(&self) -> (usize, usize) {
        (self.manifest.resolution[0], self.manifest.resolution[1])
    }

    /// The object set stored with the dataset (meshes for registration); its names must match the manifest's.
    pub fn object_set(&self) -> Result<ObjectSet, DatasetError> {
        let dir = self.dir.join(&self.manifest.object_set.dir);
        let set = ObjectSet::load_dir(&dir)?;
        let ours: Vec<_> = self
            .manifest
            .object_set
            .manifest
            .objects
            .iter()
            .map(|e| (&e.name, e.split))
            .collect();
        let theirs: Vec<_> = set.entries().iter().map(|e| (&e.name, e.split)).collect();
        if ours != theirs {
            return Err(DatasetError::Manifest {
                path: dir.join(crate::objects::MANIFEST_FILE),
                message: "objects (names or splits) differ from the dataset manifest's object set"
                    .into(),
            });
        }
        Ok(set)
    }

    /// Number of pairs in `split`.
    pub fn len(&self, split: SplitName) -> usize {
        self.manifest.counts.get(split)
    }

    /// True when the dataset holds no pairs at all.
    pub fn is_empty(&self) -> bool {
        self.manifest.counts.total() == 0
    }

    /// Verify every shard (size, sha256, dtypes, shapes) now.
    pub fn verify(&self) -> Result<(), DatasetError> {
        for i in 0..self.shards.len() {
            self.shard(i)?;
        }
        Ok(())
    }

    /// Pair `index` of `split` (0-based within the split, in global index order).
    pub fn pair(&self, split: SplitName, index: usize) -> Result<Pair, DatasetError> {
        let (shard_i, row) = self.locate(split, index)?;
        let shard = self.shard(shard_i)?;
        let mut images = Vec::with_capacity(IMAGE_ARRAYS.len());
        for k in 0..IMAGE_ARRAYS.len() {
            images.push(self.read_image(&shard, k, row)?);
        }
        let object = shard.object[row];
        let object_name = usize::try_from(object)
            .ok()
            .and_then(|o| self.manifest.object_set.manifest.objects.get(o))
            .map(|e| e.name.clone())
            .ok_or_else(|| DatasetError::BadValue {
                path: shard.path.clone(),
                message: format!("pair row {row}: object index {object} is not in the object set"),
            })?;
        let s = &shard.sensor[row * 6..row * 6 + 6];
        let p = &shard.pose[row * 3..row * 3 + 3];
        let meta = PairMeta {
            object: object_name,
            object_pose: Se2::new(p[0], p[1], p[2]),
            sensor: SensorPose {
                position: [s[0], s[1], s[2]],
                yaw: s[3],
                tilt: [s[4], s[5]],
            },
            press: shard.press[row],
            seed: shard.seed[row],
            split,
            index: shard.index[row] as usize,
            split_index: index,
            contact_pixels: usize::try_from(shard.contact_pixels[row]).unwrap_or(0),
        };
        let mut it = images.into_iter();
        let mut next = || {
            it.next()
                .ok_or_else(|| DatasetError::Config("missing image".into()))
        };
        Ok(Pair {
            imprint: next()?,
            target: next()?,
            signature: next()?,
            reference: next()?,
            mask: next()?,
            meta,
        })
    }

    /// Shuffled mini-batches of `split` for one epoch: the order is a permutation drawn from `(seed, epoch)`; the last
    /// batch holds the remainder (fewer than `batch` pairs).
    pub fn batches(&self, split: SplitName, batch: usize, seed: u64, epoch: u64) -> Batches<'_> {
        Batches {
            dataset: self,
            split,
            order: epoch_order(self.len(split), seed, epoch),
            pos: 0,
            batch: batch.max(1),
        }
    }

    /// Imprint and target of one pair (what training needs), appended to `imprint` and `target`.
    pub(crate) fn read_training(
        &self,
        split: SplitName,
        index: usize,
        imprint: &mut Vec<f32>,
        target: &mut Vec<f32>,
    ) -> Result<(), DatasetError> {
        let (shard_i, row) = self.locate(split, index)?;
        let shard = self.shard(shard_i)?;
        imprint.extend_from_slice(&self.read_image(&shard, 0, row)?.data);
        target.extend_from_slice(&self.read_image(&shard, 1, row)?.data);
        Ok(())
    }

    fn locate(&self, split: SplitName, index: usize) -> Result<(usize, usize), DatasetError> {
        let len = self.len(split);
        let list = &self.splits[split.code()];
        if index >= len {
            return Err(DatasetError::IndexOutOfRange { split, index, len });
        }
        let pos = list
            .partition_point(|&(_, start)| start <= index)
            .saturating_sub(1);
        let (shard, start) = list[pos];
        Ok((shard, index - start))
    }

    fn read_image(&self, shard: &LoadedShard, k: usize, row: usize) -> Result<Image, DatasetError> {
        let (w, h) = self.resolution();
        let bytes = w * h * 4;
        let offset = shard.images[k].data_offset + (row * bytes) as u64;
        let raw = shard.read(offset, bytes)?;
        let data = npz::decode_f32(&raw);
        if let Some(bad) = data.iter().position(|x| !x.is_finite()) {
            return Err(DatasetError::BadValue {
                path: shard.path.clone(),
                message: format!(
                    "array '{}' row {row} has a non-finite value at pixel {bad}",
                    IMAGE_ARRAYS[k]
                ),
            });
        }
        Image::from_vec(w, h, data).ok_or_else(|| DatasetError::Config("image size".into()))
    }

    /// The verified shard `i`, loading it on first use.
    fn shard(&self, i: usize) -> Result<Arc<LoadedShard>, DatasetError> {
        let entry = &self.manifest.shards[i];
        let mut slot = self.shards[i]
            .lock()
            .map_err(|_| poisoned(&self.dir.join(&entry.file)))?;
        if let Some(s) = slot.as_ref() {
            return Ok(Arc::clone(s));
        }
        let loaded = Arc::new(load_shard(&self.dir, entry, self.resolution())?);
        *slot = Some(Arc::clone(&loaded));
        Ok(loaded)
    }
}

/// The order in which one epoch visits `len` pairs: a permutation drawn from `(seed, epoch)` (what
/// [`Dataset::batches`] and training over several datasets use).
pub fn epoch_order(len: usize, seed: u64, epoch: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..len).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(mix64(seed) ^ mix64(epoch.wrapping_add(0x4550_4f43)));
    order.shuffle(&mut rng);
    order
}

fn poisoned(path: &Path) -> DatasetError {
    DatasetError::Config(format!("{}: a reader thread panicked", path.display()))
}

impl LoadedShard {
    /// `len` bytes at `offset`: a positioned read on Unix (parallel readers need no lock), seek + read under a lock
    /// elsewhere.
    fn read(&self, offset: u64, len: usize) -> Result<Vec<u8>, DatasetError> {
        let io = |e| DatasetError::io(&self.path, e);
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileExt;
            let mut buf = vec![0u8; len];
            self.file.read_exact_at(&mut buf, offset).map_err(io)?;
            Ok(buf)
        }
        #[cfg(not(unix))]
        {
            let _guard = self.seek_lock.lock().map_err(|_| poisoned(&self.path))?;
            npz::read_at(&mut &self.file, offset, len).map_err(io)
        }
    }
}

/// Verify a shard (size, sha256) and index its arrays (dtype, shape).
fn load_shard(
    dir: &Path,
    entry: &ShardEntry,
    (w, h): (usize, usize),
) -> Result<LoadedShard, DatasetError> {
    shard::verify_file(dir, entry)?;
    let path = dir.join(&entry.file);
    let mut file = File::open(&path).map_err(|e| DatasetError::io(&path, e))?;
    let index = NpzIndex::read(&mut file, &path)?;
    let n = entry.pairs;
    let mut images = Vec::new();
    for name in IMAGE_ARRAYS {
        images.push(npz::check_member(
            &index,
            &path,
            name,
            Dtype::F32,
            &[n, h, w],
        )?);
    }
    let mut read = |name: &str, dtype: Dtype, shape: &[usize]| -> Result<Vec<u8>, DatasetError> {
        let m = npz::check_member(&index, &path, name, dtype, shape)?;
        npz::read_at(&mut file, m.data_offset, m.data_len as usize)
            .map_err(|e| DatasetError::io(&path, e))
    };
    let pair_index = npz::decode_u64(&read("index", Dtype::U64, &[n])?);
    let seed = npz::decode_u64(&read("seed", Dtype::U64, &[n])?);
    let object = npz::decode_i32(&read("object", Dtype::I32, &[n])?);
    let pose = npz::decode_f64(&read("pose", Dtype::F64, &[n, 3])?);
    let press = npz::decode_f64(&read("press", Dtype::F64, &[n])?);
    let sensor = npz::decode_f64(&read("sensor", Dtype::F64, &[n, 6])?);
    let contact_pixels = npz::decode_i32(&read("contact_pixels", Dtype::I32, &[n])?);
    Ok(LoadedShard {
        path,
        file,
        seek_lock: Mutex::new(()),
        images,
        index: pair_index,
        seed,
        object,
        pose,
        press,
        sensor,
        contact_pixels,
    })
}

/// Iterator over the mini-batches of one epoch (see [`Dataset::batches`]).
pub struct Batches<'a> {
    dataset: &'a Dataset,
    split: SplitName,
    order: Vec<usize>,
    pos: usize,
    batch: usize,
}

impl Iterator for Batches<'_> {
    type Item = Result<Batch, DatasetError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.pos >= self.order.len() {
            return None;
        }
        let end = (self.pos + self.batch).min(self.order.len());
        let indices = self.order[self.pos..end].to_vec();
        self.pos = end;
        let (width, height) = self.dataset.resolution();
        let mut imprint = Vec::with_capacity(indices.len() * width * height);
        let mut target = Vec::with_capacity(indices.len() * width * height);
        for &i in &indices {
            if let Err(e) = self
                .dataset
                .read_training(self.split, i, &mut imprint, &mut target)
            {
                self.pos = self.order.len();
                return Some(Err(e));
            }
        }
        Some(Ok(Batch {
            n: indices.len(),
            width,
            height,
            imprint,
            target,
            indices,
        }))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = (self.order.len() - self.pos).div_ceil(self.batch);
        (left, Some(left))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dataset_can_be_shared_between_threads() {
        fn assert_send_sync<T: Send + Sync>() {}
        assert_send_sync::<Dataset>();
        assert_send_sync::<Batch>();
    }
}
