//! Training pairs from the dataset stage (paper V.A → IV.B): an adapter from [`crate::dataset::Dataset`]'s
//! shuffled pairs to the trainer's [`TrainingData`]. The train split is used for training (of one dataset, or of
//! several read as one). The logged validation
//! loss comes from a fixed batch of a separate validation dataset when one is given ([`DatasetTraining::with_validation`]:
//! pairs that no test split holds, so that stopping and tuning decisions never look at test pairs); otherwise from
//! the (first) dataset's `unseen_poses` split (or `train` when that is empty), which only monitors. Also the per-pixel loss weights
//! that stress the contact boundary ([`contact_boundary_weights`]).

use crate::dataset::reader::epoch_order;
use crate::dataset::{Dataset, SplitName};

use super::train::{TrainBatch, TrainingData};
use super::ModelError;

/// Batches of the train split of one dataset, or of several read as one (their train splits concatenated, one
/// shuffle over all of them: a sensor's recordings imported one by one), in the `(seed, epoch)` order.
pub struct DatasetTraining<'a> {
    datasets: Vec<&'a Dataset>,
    /// A separate validation dataset, if any.
    validation: Option<&'a Dataset>,
    /// The open epoch and its order of (dataset, index within its train split).
    cursor: Option<(u64, Vec<(usize, usize)>)>,
}

impl<'a> DatasetTraining<'a> {
    pub fn new(dataset: &'a Dataset) -> Self {
        Self::concatenated(vec![dataset])
    }

    /// Train on the train splits of every dataset in `datasets` (same image size; checked by the caller). One
    /// dataset visits its pairs in the order [`Dataset::batches`] would.
    pub fn concatenated(datasets: Vec<&'a Dataset>) -> Self {
        Self {
            datasets,
            validation: None,
            cursor: None,
        }
    }

    /// Take the validation loss from `validation` instead: a fixed draw of [`Self::VALIDATION_PAIRS`] pairs (or
    /// fewer) from its first non-empty split.
    pub fn with_validation(mut self, validation: &'a Dataset) -> Self {
        self.validation = Some(validation);
        self
    }

    /// Pairs in the validation batch of a separate validation dataset.
    pub const VALIDATION_PAIRS: usize = 128;

    /// The epoch's order over the concatenated train splits.
    fn order(&self, seed: u64, epoch: u64) -> Vec<(usize, usize)> {
        let mut owner = Vec::with_capacity(self.len());
        for (k, d) in self.datasets.iter().enumerate() {
            owner.extend((0..d.len(SplitName::Train)).map(|i| (k, i)));
        }
        epoch_order(owner.len(), seed, epoch)
            .into_iter()
            .map(|g| owner[g])
            .collect()
    }
}

fn convert(b: crate::dataset::Batch) -> TrainBatch {
    TrainBatch {
        n: b.n,
        width: b.width,
        height: b.height,
        imprint: b.imprint,
        target: b.target,
    }
}

impl TrainingData for DatasetTraining<'_> {
    fn len(&self) -> usize {
        self.datasets.iter().map(|d| d.len(SplitName::Train)).sum()
    }

    fn batch(
        &mut self,
        epoch: u64,
        index: usize,
        batch: usize,
        seed: u64,
    ) -> Result<TrainBatch, ModelError> {
        if !matches!(&self.cursor, Some((e, _)) if *e == epoch) {
            self.cursor = Some((epoch, self.order(seed, epoch)));
        }
        let Some((_, order)) = self.cursor.as_ref() else {
            return Err(ModelError::Data("internal: no open epoch".into()));
        };
        let batch = batch.max(1);
        let picked = order
            .get(index.saturating_mul(batch)..)
            .filter(|rest| !rest.is_empty())
            .ok_or_else(|| ModelError::Data(format!("epoch {epoch} has no batch {index}")))?;
        let picked = &picked[..batch.min(picked.len())];
        let Some(first) = self.datasets.first() else {
            return Err(ModelError::Data("no training dataset".into()));
        };
        let (width, height) = first.resolution();
        let mut imprint = Vec::with_capacity(picked.len() * width * height);
        let mut target = Vec::with_capacity(picked.len() * width * height);
        for &(k, i) in picked {
            self.datasets[k]
                .read_training(SplitName::Train, i, &mut imprint, &mut target)
                .map_err(ModelError::Dataset)?;
        }
        Ok(TrainBatch {
            n: picked.len(),
            width,
            height,
            imprint,
            target,
        })
    }

    fn validation(&mut self, batch: usize) -> Result<Option<TrainBatch>, ModelError> {
        if let Some(val) = self.validation {
            let Some(split) = SplitName::ALL.into_iter().find(|&s| val.len(s) > 0) else {
                return Ok(None);
            };
            return val
                .batches(split, batch.max(Self::VALIDATION_PAIRS), 0, 0)
                .next()
                .transpose()
                .map(|b| b.map(convert))
                .map_err(ModelError::Dataset);
        }
        let Some(first) = self.datasets.first() else {
            return Ok(None);
        };
        let split = if first.len(SplitName::UnseenPoses) > 0 {
            SplitName::UnseenPoses
        } else {
            SplitName::Train
        };
        first
            .batches(split, batch, 0, 0)
            .next()
            .transpose()
            .map(|b| b.map(convert))
            .map_err(ModelError::Dataset)
    }
}

/// Per-pixel loss weights that stress the contact boundary, for `n` in-contact depth targets of `height × width`
/// (metres, 0 = no contact; row-major, image after image). A pixel is on the boundary when its
/// `(2·radius_px + 1)²` window (clipped at the image edge) holds both a contact and a no-contact pixel; it weighs
/// `1 + boundary_weight`, every other pixel 1, and each image's weights are then scaled to a mean of 1, so the loss
/// keeps its scale and an image without contact (or all contact) weighs every pixel 1. The same definition as
/// `train_torch.py --boundary-weight` (max pooling over the mask and its complement).
pub fn contact_boundary_weights(
    target_m: &[f32],
    n: usize,
    height: usize,
    width: usize,
    radius_px: usize,
    boundary_weight: f32,
) -> Vec<f32> {
    let mut out = vec![1.0f32; target_m.len()];
    let r = radius_px as isize;
    let (h, w) = (height as isize, width as isize);
    for (image, weights) in target_m
        .chunks_exact(height * width)
        .zip(out.chunks_exact_mut(height * width))
        .take(n)
    {
        let contact = |y: isize, x: isize| image[(y * w + x) as usize] > 0.0;
        let mut sum = 0.0f64;
        for y in 0..h {
            for x in 0..w {
                let (mut some_contact, mut some_free) = (false, false);
                for yy in (y - r).max(0)..=(y + r).min(h - 1) {
                    for xx in (x - r).max(0)..=(x + r).min(w - 1) {
                        if contact(yy, xx) {
                            some_contact = true;
                        } else {
                            some_free = true;
                        }
                    }
                }
                let weight = if some_contact && some_free {
                    1.0 + boundary_weight
                } else {
                    1.0
                };
                weights[(y * w + x) as usize] = weight;
                sum += f64::from(weight);
            }
        }
        let mean = (sum / (height * width) as f64) as f32;
        weights.iter_mut().for_each(|v| *v /= mean);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::contact_boundary_weights;

    #[test]
    fn the_boundary_is_the_ring_either_side_of_the_contact_edge() {
        // 8 x 8 image, contact in the 4 x 4 square rows/cols 2..=5; radius 1: the boundary is every pixel within one
        // (Chebyshev) step of an edge between contact and no contact, i.e. the 6 x 6 square 1..=6 minus the 2 x 2
        // core 3..=4: 32 pixels. Weight 3 there, 1 elsewhere; mean = (32·3 + 32·1) / 64 = 2.
        let mut t = vec![0.0f32; 64];
        for y in 2..=5 {
            for x in 2..=5 {
                t[y * 8 + x] = 0.04;
            }
        }
        // Second image: no contact at all; third: all contact.
        t.extend(std::iter::repeat_n(0.0, 64));
        t.extend(std::iter::repeat_n(0.05, 64));
        let w = contact_boundary_weights(&t, 3, 8, 8, 1, 2.0);
        for y in 0..8 {
            for x in 0..8 {
                let ring = (1..=6).contains(&y)
                    && (1..=6).contains(&x)
                    && !((3..=4).contains(&y) && (3..=4).contains(&x));
                let want = if ring { 1.5 } else { 0.5 };
                assert_eq!(w[y * 8 + x], want, "({y}, {x})");
            }
        }
        assert!(w[64..].iter().all(|&v| v == 1.0));
        // Weight 0: every pixel 1, whatever the mask.
        assert!(contact_boundary_weights(&t, 3, 8, 8, 2, 0.0)
            .iter()
            .all(|&v| v == 1.0));
    }
}
