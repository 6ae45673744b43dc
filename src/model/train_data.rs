//! Training pairs from the dataset stage (paper V.A → IV.B): an adapter from [`crate::dataset::Dataset`]'s
//! shuffled batches to the trainer's [`TrainingData`]. The train split is used for training. The logged validation
//! loss comes from a fixed batch of a separate validation dataset when one is given ([`DatasetTraining::with_validation`]:
//! pairs that no test split holds, so that stopping and tuning decisions never look at test pairs); otherwise from
//! the `unseen_poses` split (or `train` when that is empty), which only monitors.

use crate::dataset::{Batches, Dataset, SplitName};

use super::train::{TrainBatch, TrainingData};
use super::ModelError;

/// Batches of the train split, read in the dataset's `(seed, epoch)` order.
pub struct DatasetTraining<'a> {
    dataset: &'a Dataset,
    /// A separate validation dataset, if any.
    validation: Option<&'a Dataset>,
    /// The open epoch: (epoch, index of the next batch, iterator).
    cursor: Option<(u64, usize, Batches<'a>)>,
}

impl<'a> DatasetTraining<'a> {
    pub fn new(dataset: &'a Dataset) -> Self {
        Self {
            dataset,
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
        self.dataset.len(SplitName::Train)
    }

    fn batch(
        &mut self,
        epoch: u64,
        index: usize,
        batch: usize,
        seed: u64,
    ) -> Result<TrainBatch, ModelError> {
        let reuse = matches!(&self.cursor, Some((e, i, _)) if *e == epoch && *i == index);
        if !reuse {
            // A new epoch, or a resume in the middle of one: skip to `index`.
            let mut it = self.dataset.batches(SplitName::Train, batch, seed, epoch);
            for _ in 0..index {
                it.next().transpose().map_err(ModelError::Dataset)?;
            }
            self.cursor = Some((epoch, index, it));
        }
        let Some((_, i, it)) = self.cursor.as_mut() else {
            return Err(ModelError::Data("internal: no open epoch".into()));
        };
        let b = it
            .next()
            .transpose()
            .map_err(ModelError::Dataset)?
            .ok_or_else(|| ModelError::Data(format!("epoch {epoch} has no batch {index}")))?;
        *i += 1;
        Ok(convert(b))
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
        let split = if self.dataset.len(SplitName::UnseenPoses) > 0 {
            SplitName::UnseenPoses
        } else {
            SplitName::Train
        };
        self.dataset
            .batches(split, batch, 0, 0)
            .next()
            .transpose()
            .map(|b| b.map(convert))
            .map_err(ModelError::Dataset)
    }
}
