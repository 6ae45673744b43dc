//! Parameters of synthetic **dataset generation** (paper V.A: random contacts of the object library against the
//! simulated Soft Bubble). The sensor itself is described by [`crate::sim::SimConfig`]; this is everything else.

use serde::{Deserialize, Serialize};

use super::DatasetError;

/// How pairs are drawn, split and sharded. Together with the `SimConfig` and the object set it determines the dataset
/// byte for byte.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct GenConfig {
    /// Number of pairs to generate (default 24 000, the paper's pre-training set).
    pub pairs: usize,
    /// Global seed; pair `i` uses the seed [`super::split::pair_seed`]`(seed, i)` (default 0).
    pub seed: u64,
    /// Press depth of the membrane apex below the object's top, drawn uniformly in `[min, max]`, metres
    /// (default 0.003..0.015).
    pub press_range: [f64; 2],
    /// Where the object's top point may lie: uniformly in the camera's view at the height of the membrane apex,
    /// shrunk about its centre by this factor (0..1], so the contact stays inside the image (default 0.4).
    pub offset_fraction: f64,
    /// Rejection rule: a draw is kept only if at least this fraction of the image's pixels are in contact
    /// (default 0.01, i.e. 41 pixels at 64 x 64); otherwise pose and press are redrawn (the object is kept).
    pub min_contact_fraction: f64,
    /// Draws per pair before generation stops with an error naming the object (default 200).
    pub max_attempts: usize,
    /// Pairs per chunk: chunk `k` holds pairs `k * shard_pairs ..`, written as one shard per split it contains
    /// (default 1000; about 80 MB per chunk at 64 x 64).
    pub shard_pairs: usize,
    /// One pair in every `holdout_every` of each seen object goes to `unseen_poses` (default 10: the paper's 9:1).
    pub holdout_every: usize,
    /// Elastomer inflation drawn per pair (`None`, the default: every pair uses the sensor's inflation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inflation: Option<InflationVariation>,
    /// The whole sensor varied per pair (inflation, camera distance, footprint, shadow, noise; `None`, the default:
    /// every pair uses the sensor as it is). Not together with `inflation`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_variation: Option<super::sensor_variation::SensorVariation>,
    /// Render every pair at the camera's native resolution and bring it to the model's as an import brings a
    /// recording's frames ([`super::camera_pass`]), even with an ideal camera (a sensor with a depth camera always
    /// is). Such inputs are several times quieter than model-resolution pairs, as imported frames are (default
    /// false).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub native_frames: bool,
}

/// Per-pair variation of the membrane's inflation height, as a real Soft Bubble's drifts with its air pressure and
/// temperature: pair `i` uses one of `levels` evenly spaced heights in `range`, chosen by a hash of its seed (so the
/// pair's own random stream, and a dataset without variation, stay as they are).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct InflationVariation {
    /// Lowest and highest inflation height, metres.
    pub range: [f64; 2],
    /// Number of heights (>= 2; each is one prepared membrane).
    pub levels: usize,
}

impl InflationVariation {
    /// The inflation heights, metres.
    pub fn heights(&self) -> Vec<f64> {
        let [lo, hi] = self.range;
        let n = self.levels.max(2);
        (0..n)
            .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
            .collect()
    }

    /// The level pair `pair_seed` uses.
    pub fn level(&self, pair_seed: u64) -> usize {
        // SplitMix64 finaliser of the seed: independent of the ChaCha stream the pair draws its contact from.
        let mut z = pair_seed ^ 0x1F0E_5A7C_9D3B_2468;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z % self.levels.max(2) as u64) as usize
    }
}

impl Default for GenConfig {
    fn default() -> Self {
        Self {
            pairs: 24_000,
            seed: 0,
            press_range: [0.003, 0.015],
            offset_fraction: 0.4,
            min_contact_fraction: 0.01,
            max_attempts: 200,
            shard_pairs: 1000,
            holdout_every: 10,
            inflation: None,
            sensor_variation: None,
            native_frames: false,
        }
    }
}

impl GenConfig {
    /// Check the parameters, with a message saying what to change.
    pub fn validate(&self) -> Result<(), DatasetError> {
        let bad = |m: String| Err(DatasetError::Config(m));
        let [lo, hi] = self.press_range;
        if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi >= lo) {
            return bad(format!(
                "press range [{lo}, {hi}] must satisfy 0 <= min <= max (metres)"
            ));
        }
        if !(self.offset_fraction.is_finite()
            && self.offset_fraction >= 0.0
            && self.offset_fraction <= 1.0)
        {
            return bad(format!(
                "offset fraction {} must be in [0, 1]",
                self.offset_fraction
            ));
        }
        if !(self.min_contact_fraction.is_finite()
            && self.min_contact_fraction >= 0.0
            && self.min_contact_fraction < 1.0)
        {
            return bad(format!(
                "minimum contact fraction {} must be in [0, 1)",
                self.min_contact_fraction
            ));
        }
        if self.max_attempts == 0 || self.shard_pairs == 0 || self.holdout_every < 2 {
            return bad(format!(
                "max_attempts ({}), shard_pairs ({}) must be >= 1 and holdout_every ({}) >= 2",
                self.max_attempts, self.shard_pairs, self.holdout_every
            ));
        }
        if self.pairs == 0 {
            return bad("the number of pairs must be at least 1".into());
        }
        if self.inflation.is_some() && self.sensor_variation.is_some() {
            return bad(
                "an inflation variation and a sensor variation together: give the inflation range in the sensor \
                 variation"
                    .into(),
            );
        }
        if let Some(v) = &self.inflation {
            let [lo, hi] = v.range;
            if !(lo.is_finite()
                && hi.is_finite()
                && lo > 0.0
                && hi >= lo
                && v.levels >= 2
                && v.levels <= 64)
            {
                return bad(format!(
                    "inflation range [{lo}, {hi}] in {} levels: need 0 < min <= max (metres) and 2..=64 levels",
                    v.levels
                ));
            }
        }
        Ok(())
    }

    /// Minimum number of contact pixels of the rejection rule for a `width x height` image (at least 1).
    pub fn min_contact_pixels(&self, width: usize, height: usize) -> usize {
        ((self.min_contact_fraction * (width * height) as f64).ceil() as usize).max(1)
    }

    /// Number of chunks.
    pub fn chunks(&self) -> usize {
        self.pairs.div_ceil(self.shard_pairs)
    }
}
