//! The dataset inspector's caches (paper V.A dataset): the open [`Dataset`], which object each pair shows, a loader
//! thread that decodes only the thumbnails the grid currently shows (latest request wins, so fast scrolling never
//! queues stale work) plus the selected pair, and an LRU cache of thumbnail textures. Nothing here is saved.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

use anyhow::{Context, Result};
use egui::{ColorImage, TextureHandle, TextureOptions};
use tactile_derender::dataset::{split, Dataset, Pair, SplitName};
use tactile_derender::image::Image;
use tactile_derender::io::preview::{self, PanelStyle};

use crate::colormap::to_color_image;
use crate::worker::WorkerMsg;

/// Thumbnail textures kept (two 64 x 64 textures each; about 30 MB at the cap).
pub const THUMB_CACHE: usize = 800;

/// A pair's position: split and index within the split.
pub type PairKey = (SplitName, usize);

/// The grid's filter: split and object name.
type FilterKey = (SplitName, Option<String>);

/// What the dataset loader reports (through [`WorkerMsg::Dataset`]).
pub enum DatasetMsg {
    /// Colourised imprint and target of one pair.
    Thumbnail {
        generation: u64,
        key: PairKey,
        imprint: ColorImage,
        target: ColorImage,
    },
    /// The selected pair, all images.
    Pair { generation: u64, pair: Box<Pair> },
    /// Object index (into the dataset's object list) of every pair of `split`, in split order.
    Objects {
        generation: u64,
        split: SplitName,
        objects: Vec<u16>,
    },
    /// Reading a pair failed.
    Error { generation: u64, message: String },
}

/// Work for the loader thread.
#[derive(Default)]
struct Queue {
    /// Thumbnails still missing from what the grid shows, in display order.
    thumbs: Vec<PairKey>,
    /// The selected pair, if not loaded yet.
    pair: Option<PairKey>,
    /// Splits whose object index must be read pair by pair (imported datasets), with the part read so far.
    scan: Vec<(SplitName, Vec<u16>)>,
    stop: bool,
}

struct Shared {
    queue: Mutex<Queue>,
    wake: Condvar,
}

/// One cached thumbnail.
pub struct Thumb {
    pub imprint: TextureHandle,
    pub target: TextureHandle,
    last_used: u64,
}

/// The selected pair with its textures and colour ranges.
pub struct SelectedPair {
    pub pair: Pair,
    /// Imprint, signature, target and mask with their textures.
    pub shown: Vec<ShownPairImage>,
}

/// One full-size image of the selected pair.
pub struct ShownPairImage {
    pub title: &'static str,
    pub texture: TextureHandle,
    pub range: (f32, f32),
    pub millimetres: bool,
    pub zero_is_missing: bool,
}

impl SelectedPair {
    /// The image shown in card `i` (imprint, signature, target, mask).
    pub fn image(&self, i: usize) -> &Image {
        match i {
            0 => &self.pair.imprint,
            1 => &self.pair.signature,
            2 => &self.pair.target,
            _ => &self.pair.mask,
        }
    }
}

/// An open dataset with its loader thread and caches.
pub struct DatasetBrowser {
    pub dataset: Arc<Dataset>,
    pub dir: PathBuf,
    /// Identifies this browser's messages (a reopened dataset ignores the old loader's).
    pub generation: u64,
    /// Object names, in the dataset's object-set order.
    pub objects: Vec<String>,
    /// Per split (by [`SplitName::code`]): object index of each pair, once known.
    object_of: [Option<Vec<u16>>; 3],
    thumbs: HashMap<PairKey, Thumb>,
    frame: u64,
    shared: Arc<Shared>,
    /// The filtered list shown in the grid and what it was computed from.
    filtered: Option<(FilterKey, Vec<usize>)>,
    pub selected: Option<SelectedPair>,
    /// Thumbnails decoded and uploaded so far (for the timings).
    pub uploaded: usize,
    /// Thumbnails the grid missed in its last frame.
    pub missing: usize,
}

impl Drop for DatasetBrowser {
    fn drop(&mut self) {
        if let Ok(mut q) = self.shared.queue.lock() {
            q.stop = true;
        }
        self.shared.wake.notify_all();
    }
}

impl DatasetBrowser {
    /// Open `dir` and start its loader thread, which reports through `tx` and wakes `ctx`.
    pub fn open(
        dir: &Path,
        generation: u64,
        tx: Sender<WorkerMsg>,
        ctx: egui::Context,
    ) -> Result<Self> {
        let dataset = Arc::new(Dataset::open(dir)?);
        let objects: Vec<String> = dataset
            .manifest()
            .object_set
            .manifest
            .objects
            .iter()
            .map(|e| e.name.clone())
            .collect();
        let planned = planned_objects(&dataset);
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue {
                scan: SplitName::ALL
                    .into_iter()
                    .filter(|s| planned[s.code()].is_none() && dataset.len(*s) > 0)
                    .map(|s| (s, Vec::new()))
                    .collect(),
                ..Queue::default()
            }),
            wake: Condvar::new(),
        });
        let (ds, sh) = (dataset.clone(), shared.clone());
        std::thread::Builder::new()
            .name("tnd-dataset".into())
            .spawn(move || loader(&ds, &sh, generation, &tx, &ctx))
            .context("cannot start the dataset loader thread")?;
        Ok(Self {
            dataset,
            dir: dir.to_path_buf(),
            generation,
            objects,
            object_of: planned,
            thumbs: HashMap::new(),
            frame: 0,
            shared,
            filtered: None,
            selected: None,
            uploaded: 0,
            missing: 0,
        })
    }

    /// True while object names of `split` are still being read (imported datasets).
    pub fn indexing(&self, split: SplitName) -> bool {
        self.object_of[split.code()].is_none() && self.dataset.len(split) > 0
    }

    /// The object name of pair `index` of `split`, once known.
    pub fn object_name(&self, split: SplitName, index: usize) -> Option<&str> {
        let o = *self.object_of[split.code()].as_ref()?.get(index)?;
        self.objects.get(o as usize).map(String::as_str)
    }

    /// Split indices of the pairs passing the filter (all pairs while the object index is unknown).
    pub fn filtered(&mut self, split: SplitName, object: Option<&String>) -> &[usize] {
        let key = (split, object.cloned());
        if self.filtered.as_ref().map(|(k, _)| k) != Some(&key) {
            let n = self.dataset.len(split);
            let list = match (object, &self.object_of[split.code()]) {
                (Some(name), Some(of)) => {
                    let want = self.objects.iter().position(|o| o == name);
                    (0..n)
                        .filter(|&i| want.is_some_and(|w| of.get(i) == Some(&(w as u16))))
                        .collect()
                }
                _ => (0..n).collect(),
            };
            // An unknown object index is recomputed when it arrives (see `handle`).
            self.filtered = Some((key, list));
        }
        self.filtered.as_ref().map_or(&[], |(_, l)| l.as_slice())
    }

    /// Start a new frame of the grid: remember the frame number for the LRU order.
    pub fn begin_frame(&mut self) {
        self.frame += 1;
    }

    /// The cached thumbnail of `key`, marking it used.
    pub fn thumb(&mut self, key: PairKey) -> Option<&Thumb> {
        let frame = self.frame;
        self.thumbs.get_mut(&key).map(|t| {
            t.last_used = frame;
            &*t
        })
    }

    /// Replace the loader's thumbnail queue with what the grid misses now (in display order).
    pub fn request_thumbs(&mut self, missing: Vec<PairKey>) {
        self.missing = missing.len();
        if let Ok(mut q) = self.shared.queue.lock() {
            if q.thumbs != missing {
                q.thumbs = missing;
                self.shared.wake.notify_all();
            }
        }
    }

    /// Ask for the selected pair at full size (the loader does it before any thumbnail).
    pub fn request_pair(&mut self, key: PairKey) {
        if self
            .selected
            .as_ref()
            .is_some_and(|s| (s.pair.meta.split, s.pair.meta.split_index) == key)
        {
            return;
        }
        self.selected = None;
        if let Ok(mut q) = self.shared.queue.lock() {
            q.pair = Some(key);
            self.shared.wake.notify_all();
        }
    }

    /// Number of cached thumbnails.
    pub fn cached(&self) -> usize {
        self.thumbs.len()
    }

    /// Take in a loader message of this browser.
    pub fn handle(&mut self, ctx: &egui::Context, msg: DatasetMsg) -> Option<String> {
        match msg {
            DatasetMsg::Thumbnail {
                key,
                imprint,
                target,
                ..
            } => {
                let name = format!("thumb-{}-{}", key.0, key.1);
                let thumb = Thumb {
                    imprint: ctx.load_texture(
                        format!("{name}-y"),
                        imprint,
                        TextureOptions::NEAREST,
                    ),
                    target: ctx.load_texture(format!("{name}-x0"), target, TextureOptions::NEAREST),
                    last_used: self.frame,
                };
                self.uploaded += 1;
                self.thumbs.insert(key, thumb);
                self.evict();
                None
            }
            DatasetMsg::Pair { pair, .. } => {
                self.selected = Some(select(ctx, *pair));
                None
            }
            DatasetMsg::Objects { split, objects, .. } => {
                self.object_of[split.code()] = Some(objects);
                self.filtered = None;
                None
            }
            DatasetMsg::Error { message, .. } => Some(message),
        }
    }

    fn evict(&mut self) {
        while self.thumbs.len() > THUMB_CACHE {
            let oldest = self
                .thumbs
                .iter()
                .min_by_key(|(_, t)| t.last_used)
                .map(|(k, _)| *k);
            match oldest {
                Some(k) => {
                    self.thumbs.remove(&k);
                }
                None => break,
            }
        }
    }
}

/// Object index of every pair per split for generated datasets, from the generation plan (a pure function of the
/// seed and the object set: [`split::plan`]); `None` for imported datasets or when the plan does not match the counts.
fn planned_objects(ds: &Dataset) -> [Option<Vec<u16>>; 3] {
    let m = ds.manifest();
    let Some(gen) = &m.generation else {
        return Default::default();
    };
    let objects = &m.object_set.manifest.objects;
    let splits: Vec<_> = objects.iter().map(|e| e.split).collect();
    let weights: Vec<f64> = objects.iter().map(|e| e.weight).collect();
    let draw = split::ObjectDraw::new(&weights);
    let plan = split::plan(gen.seed, gen.pairs, &splits, &draw, gen.holdout_every);
    let mut out: [Vec<u16>; 3] = Default::default();
    for p in plan {
        out[p.split.code()].push(p.object as u16);
    }
    let mut result: [Option<Vec<u16>>; 3] = Default::default();
    for s in SplitName::ALL {
        let v = std::mem::take(&mut out[s.code()]);
        if v.len() == ds.len(s) {
            result[s.code()] = Some(v);
        }
    }
    result
}

/// Colourise an image over its own range (depth zeros are missing).
fn thumbnail(img: &Image, zero_is_missing: bool) -> ColorImage {
    let style = PanelStyle {
        zero_is_missing,
        ..Default::default()
    };
    to_color_image(img, preview::display_range(img, &style), zero_is_missing)
}

fn select(ctx: &egui::Context, pair: Pair) -> SelectedPair {
    let specs: [(&'static str, &Image, bool, bool); 4] = [
        ("Y imprint", &pair.imprint, true, false),
        ("S signature", &pair.signature, true, true),
        ("X0 = M·D target", &pair.target, true, true),
        ("M contact mask", &pair.mask, false, false),
    ];
    let shown = specs
        .iter()
        .map(|&(title, img, millimetres, zero_is_missing)| {
            let range = if millimetres {
                let style = PanelStyle {
                    zero_is_missing,
                    ..Default::default()
                };
                preview::display_range(img, &style)
            } else {
                (0.0, 1.0)
            };
            ShownPairImage {
                title,
                texture: ctx.load_texture(
                    format!("pair-{title}"),
                    to_color_image(img, range, zero_is_missing),
                    TextureOptions::NEAREST,
                ),
                range,
                millimetres,
                zero_is_missing,
            }
        })
        .collect();
    SelectedPair { pair, shown }
}

enum Work {
    Pair(PairKey),
    Thumb(PairKey),
    Scan((SplitName, Vec<u16>)),
}

fn next_work(shared: &Shared) -> Option<Work> {
    let mut q = shared.queue.lock().ok()?;
    loop {
        if q.stop {
            return None;
        }
        if let Some(k) = q.pair.take() {
            return Some(Work::Pair(k));
        }
        if !q.thumbs.is_empty() {
            return Some(Work::Thumb(q.thumbs.remove(0)));
        }
        if let Some(s) = q.scan.pop() {
            return Some(Work::Scan(s));
        }
        q = shared
            .wake
            .wait_timeout(q, Duration::from_millis(500))
            .ok()?
            .0;
    }
}

fn loader(
    ds: &Dataset,
    shared: &Shared,
    generation: u64,
    tx: &Sender<WorkerMsg>,
    ctx: &egui::Context,
) {
    while let Some(work) = next_work(shared) {
        let msg = match work {
            Work::Pair((split, index)) => match ds.pair(split, index) {
                Ok(pair) => DatasetMsg::Pair {
                    generation,
                    pair: Box::new(pair),
                },
                Err(e) => DatasetMsg::Error {
                    generation,
                    message: format!("dataset: {e}"),
                },
            },
            Work::Thumb((split, index)) => match ds.pair(split, index) {
                Ok(pair) => DatasetMsg::Thumbnail {
                    generation,
                    key: (split, index),
                    imprint: thumbnail(&pair.imprint, false),
                    target: thumbnail(&pair.target, true),
                },
                Err(e) => DatasetMsg::Error {
                    generation,
                    message: format!("dataset: {e}"),
                },
            },
            Work::Scan(job) => match scan(ds, shared, job, generation) {
                Some(msg) => msg,
                None => continue,
            },
        };
        if tx.send(WorkerMsg::Dataset(msg)).is_err() {
            return;
        }
        ctx.request_repaint();
    }
}

/// Pairs read per scan step before the loader looks at its queue again.
const SCAN_CHUNK: usize = 256;

/// Read the next [`SCAN_CHUNK`] pairs' object names of an imported split; the partial list goes back into the queue
/// (so thumbnails and the selected pair are served in between) until the split is done.
fn scan(
    ds: &Dataset,
    shared: &Shared,
    (split, mut objects): (SplitName, Vec<u16>),
    generation: u64,
) -> Option<DatasetMsg> {
    let names = &ds.manifest().object_set.manifest.objects;
    let end = (objects.len() + SCAN_CHUNK).min(ds.len(split));
    for i in objects.len()..end {
        match ds.pair(split, i) {
            Ok(p) => objects.push(
                names
                    .iter()
                    .position(|n| n.name == p.meta.object)
                    .unwrap_or(0) as u16,
            ),
            Err(e) => {
                return Some(DatasetMsg::Error {
                    generation,
                    message: format!("dataset: {e}"),
                })
            }
        }
    }
    if objects.len() < ds.len(split) {
        if let Ok(mut q) = shared.queue.lock() {
            q.scan.push((split, objects));
        }
        return None;
    }
    Some(DatasetMsg::Objects {
        generation,
        split,
        objects,
    })
}
