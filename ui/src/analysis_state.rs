//! Saved settings of the analysis tabs (dataset inspector, de-rendering runs; paper V.A, IV.B), part of
//! [`crate::state::State`]. Paths, filters, sampler, sample count and seed only: datasets, models, textures and
//! samples are caches outside the state.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use tactile_derender::dataset::SplitName;
use tactile_derender::model::{SamplerConfig, SamplerKind};

/// The dataset inspector's settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DatasetSettings {
    /// The dataset directory (`tnd dataset gen` / `import`); `None`: nothing open.
    pub path: Option<PathBuf>,
    /// The split shown in the grid.
    pub split: SplitName,
    /// Show only this object's pairs (`None`: all objects).
    pub object: Option<String>,
    /// The selected pair's index within `split`.
    pub selected: Option<usize>,
    /// Side of one thumbnail in the grid, points.
    pub thumb_size: f32,
}

impl Default for DatasetSettings {
    fn default() -> Self {
        Self {
            path: None,
            split: SplitName::Train,
            object: None,
            selected: None,
            thumb_size: 56.0,
        }
    }
}

/// What is de-rendered.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DerenderInput {
    /// The imprint Y of the current simulated scene (its X0 is the ground truth).
    Scene,
    /// A dataset pair (its X0 is the ground truth).
    DatasetPair {
        dir: PathBuf,
        split: SplitName,
        index: usize,
    },
    /// An imported measurement: an `.npy` imprint in metres (no ground truth).
    Measurement { path: PathBuf },
}

/// Settings of a de-rendering run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DerenderSettings {
    /// The sampler: the core's [`SamplerConfig`], the same settings and defaults as `tnd sample/eval/pose`
    /// (stored flat in the session: `sampler`, `steps` — older sessions' `ddim_steps` is read too — `eta`,
    /// `spacing`).
    #[serde(flatten)]
    pub sampler: SamplerConfig,
    /// Number of samples drawn for the imprint (the paper's uncertainty analysis uses 50).
    pub samples: usize,
    /// Seed of the sampler's noise.
    pub seed: u64,
    /// The input imprint.
    pub input: DerenderInput,
}

impl Default for DerenderSettings {
    fn default() -> Self {
        Self {
            sampler: SamplerConfig::default(),
            samples: 8,
            seed: 0,
            input: DerenderInput::Scene,
        }
    }
}

impl DerenderSettings {
    /// The core's sampler for these settings.
    pub fn sampler_kind(&self) -> SamplerKind {
        self.sampler.sampler_kind()
    }

    /// Check the numbers (sessions may carry anything).
    pub fn validate(&self) -> Result<(), String> {
        self.sampler.validate(None)?;
        if !(1..=256).contains(&self.samples) {
            return Err(format!(
                "number of samples must be 1..=256, got {}",
                self.samples
            ));
        }
        Ok(())
    }
}
