//! Saved settings of the analysis tabs (dataset inspector, de-rendering runs; paper V.A, IV.B), part of
//! [`crate::state::State`]. Paths, filters, sampler, sample count and seed only: datasets, models, textures and
//! samples are caches outside the state.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use tactile_derender::dataset::SplitName;
use tactile_derender::pipeline::DerenderConfig;

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
    /// Frame `frame` of the recording open in the Recording tab.
    RecordingFrame { path: PathBuf, frame: usize },
}

/// Settings of a de-rendering run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DerenderSettings {
    /// Samples, sampler and seed: the core's [`DerenderConfig`], the same settings and defaults as `tnd sample` and
    /// `tnd pose` (stored flat in the session: `samples`, `seed`, `sampler`, `steps` — older sessions'
    /// `ddim_steps` is read too — `eta`, `spacing`).
    #[serde(flatten)]
    pub config: DerenderConfig,
    /// The input imprint.
    pub input: DerenderInput,
}

impl Default for DerenderSettings {
    fn default() -> Self {
        Self {
            config: DerenderConfig::default(),
            input: DerenderInput::Scene,
        }
    }
}
