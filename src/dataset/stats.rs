//! **Dataset statistics** for `tnd dataset stats`: pairs per split and object, the ranges of the in-contact depth
//! (target X0, over contact pixels), the signature and the imprint, and a histogram of the contact area.

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::Serialize;

use super::manifest::SplitCounts;
use super::{Dataset, DatasetError, SplitName};

/// Number of contact-area histogram bins.
pub const AREA_BINS: usize = 10;

/// Summary of a dataset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Stats {
    pub counts: SplitCounts,
    /// Object name -> pairs per split.
    pub per_object: BTreeMap<String, SplitCounts>,
    /// `[min, max]` of the target X0 over contact pixels, metres.
    pub target_range_m: Option<[f32; 2]>,
    /// `[min, max]` of the signature S over pixels where the membrane is seen, metres.
    pub signature_range_m: Option<[f32; 2]>,
    /// `[min, max]` of the imprint Y over all pixels, metres.
    pub imprint_range_m: Option<[f32; 2]>,
    /// `[min, max]` of the press depth over pairs where it is known, metres.
    pub press_range_m: Option<[f64; 2]>,
    /// Contact area: mean pixels in contact and its fraction of the image.
    pub contact_pixels_mean: f64,
    pub contact_fraction_mean: f64,
    /// Histogram of the contact area as a fraction of the image: `AREA_BINS` equal bins over
    /// `[0, area_hist_max_fraction]`, the top one closed.
    pub area_hist_max_fraction: f64,
    pub area_hist: Vec<usize>,
}

#[derive(Clone, Default)]
struct Acc {
    target: Option<[f32; 2]>,
    signature: Option<[f32; 2]>,
    imprint: Option<[f32; 2]>,
    press: Option<[f64; 2]>,
    contact: Vec<usize>,
    per_object: BTreeMap<String, SplitCounts>,
}

fn widen<T: PartialOrd + Copy>(r: Option<[T; 2]>, lo: T, hi: T) -> Option<[T; 2]> {
    Some(match r {
        None => [lo, hi],
        Some([a, b]) => [if lo < a { lo } else { a }, if hi > b { hi } else { b }],
    })
}

impl Acc {
    fn merge(mut self, o: Acc) -> Acc {
        if let Some(r) = o.target {
            self.target = widen(self.target, r[0], r[1]);
        }
        if let Some(r) = o.signature {
            self.signature = widen(self.signature, r[0], r[1]);
        }
        if let Some(r) = o.imprint {
            self.imprint = widen(self.imprint, r[0], r[1]);
        }
        if let Some(r) = o.press {
            self.press = widen(self.press, r[0], r[1]);
        }
        self.contact.extend(o.contact);
        for (k, v) in o.per_object {
            let e = self.per_object.entry(k).or_default();
            for s in SplitName::ALL {
                e.add(s, v.get(s));
            }
        }
        self
    }
}

/// Read every pair (in parallel) and summarise. `progress(n)` is called as pairs are read.
pub fn compute(ds: &Dataset, progress: &(dyn Fn(usize) + Sync)) -> Result<Stats, DatasetError> {
    let jobs: Vec<(SplitName, usize)> = SplitName::ALL
        .iter()
        .flat_map(|&s| (0..ds.len(s)).map(move |i| (s, i)))
        .collect();
    let acc = jobs
        .par_iter()
        .try_fold(Acc::default, |mut acc, &(split, i)| {
            let pair = ds.pair(split, i)?;
            if let Some((lo, hi)) = pair.target.range_where(|x| x != 0.0) {
                acc.target = widen(acc.target, lo, hi);
            }
            if let Some((lo, hi)) = pair.signature.range_where(|x| x != 0.0) {
                acc.signature = widen(acc.signature, lo, hi);
            }
            if let Some((lo, hi)) = pair.imprint.range_where(|_| true) {
                acc.imprint = widen(acc.imprint, lo, hi);
            }
            if pair.meta.press.is_finite() {
                acc.press = widen(acc.press, pair.meta.press, pair.meta.press);
            }
            acc.contact.push(pair.meta.contact_pixels);
            acc.per_object
                .entry(pair.meta.object)
                .or_default()
                .add(split, 1);
            progress(1);
            Ok::<_, DatasetError>(acc)
        })
        .try_reduce(Acc::default, |a, b| Ok(a.merge(b)))?;
    let (w, h) = ds.resolution();
    let pixels = (w * h) as f64;
    let n = acc.contact.len().max(1) as f64;
    let max_fraction = acc.contact.iter().copied().max().unwrap_or(0) as f64 / pixels;
    let mut hist = vec![0usize; AREA_BINS];
    for &c in &acc.contact {
        let f = c as f64 / pixels;
        let bin = if max_fraction > 0.0 {
            ((f / max_fraction) * AREA_BINS as f64) as usize
        } else {
            0
        };
        hist[bin.min(AREA_BINS - 1)] += 1;
    }
    let mean = acc.contact.iter().sum::<usize>() as f64 / n;
    Ok(Stats {
        counts: ds.manifest().counts,
        per_object: acc.per_object,
        target_range_m: acc.target,
        signature_range_m: acc.signature,
        imprint_range_m: acc.imprint,
        press_range_m: acc.press,
        contact_pixels_mean: mean,
        contact_fraction_mean: mean / pixels,
        area_hist_max_fraction: max_fraction,
        area_hist: hist,
    })
}

/// `[min, max]` of the in-contact depth (target X0 over contact pixels, metres) over at most `limit` pairs of
/// `split`, spread evenly over it; `None` when they hold no contact. Cheap enough to run before a training run.
pub fn target_range_sample(
    ds: &Dataset,
    split: SplitName,
    limit: usize,
) -> Result<Option<[f32; 2]>, DatasetError> {
    let n = ds.len(split);
    let take = n.min(limit.max(1));
    let mut range = None;
    for k in 0..take {
        let pair = ds.pair(split, k * n / take)?;
        if let Some((lo, hi)) = pair.target.range_where(|x| x != 0.0) {
            range = widen(range, lo, hi);
        }
    }
    Ok(range)
}
