//! **Sensor variation** in synthetic data: a model trained on one exact membrane leans on it, and a real sensor is
//! never exactly that membrane. With a variation, pairs are simulated by `levels` sensors spread over calibrated
//! ranges of inflation, camera distance, footprint, tactile-shadow width and noise (a Latin hypercube: each setting's
//! range cut into `levels` strata, each stratum used by one level, the pairing shuffled by a fixed hash), and pair `i`
//! uses the level a hash of its seed picks — so the pair's own random stream is unchanged.

use serde::{Deserialize, Serialize};

use super::split::mix64;
use super::DatasetError;
use crate::sim::SimConfig;

/// Ranges of the sensor settings that vary from pair to pair (`None`: the sensor's own value for every pair).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorVariation {
    /// Inflation height of the membrane apex, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inflation: Option<[f64; 2]>,
    /// Camera distance behind the membrane base, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_offset: Option<[f64; 2]>,
    /// Scale of the footprint (both axes), relative to the sensor's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub footprint_scale: Option<[f64; 2]>,
    /// Tactile-shadow width, native pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shadow_px: Option<[f64; 2]>,
    /// Depth noise standard deviation, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_std: Option<[f64; 2]>,
    /// Strength of the depth camera's artefacts ([`crate::sim::DepthCameraConfig`]): 0 an ideal camera, 1 the
    /// sensor's own `depth_camera` (the time-of-flight preset where the sensor's is ideal), between and beyond
    /// scaled — missing returns, the edge band, the fixed pattern and the noise's growth with depth; flying pixels on
    /// above 0. Each level has its own fixed pattern.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_artefacts: Option<[f64; 2]>,
    /// Number of sensors (2..=64; each is one prepared membrane).
    pub levels: usize,
}

impl SensorVariation {
    fn ranges(&self) -> [(&'static str, Option<[f64; 2]>); 6] {
        [
            ("inflation", self.inflation),
            ("camera offset", self.camera_offset),
            ("footprint scale", self.footprint_scale),
            ("shadow width", self.shadow_px),
            ("noise", self.noise_std),
            ("camera artefacts", self.camera_artefacts),
        ]
    }

    /// Check the ranges against the sensor `base`, with a message saying what to change.
    pub fn validate(&self, base: &SimConfig) -> Result<(), DatasetError> {
        let bad = |m: String| Err(DatasetError::Config(m));
        if !(2..=64).contains(&self.levels) {
            return bad(format!(
                "sensor variation: {} levels; need 2..=64",
                self.levels
            ));
        }
        if self.ranges().iter().all(|(_, r)| r.is_none()) {
            return bad("sensor variation: no setting varies".into());
        }
        for (i, (name, r)) in self.ranges().into_iter().enumerate() {
            if let Some([lo, hi]) = r {
                // Inflation, camera offset and footprint scale must stay positive; shadow and noise may be 0.
                let floor_ok = if i < 3 { lo > 0.0 } else { lo >= 0.0 };
                if !(lo.is_finite() && hi.is_finite() && floor_ok && hi >= lo) {
                    return bad(format!(
                        "sensor variation: {name} range [{lo}, {hi}] must satisfy {} min <= max",
                        if i < 3 { "0 <" } else { "0 <=" }
                    ));
                }
            }
        }
        let membrane = self.inflation.is_some() || self.footprint_scale.is_some();
        if membrane && base.elastomer.mesh_file.is_some() {
            return bad(
                "sensor variation: inflation and footprint ranges need the parametric membrane; the elastomer is a \
                 mesh file"
                    .into(),
            );
        }
        Ok(())
    }

    /// Where level `k` sits in the `j`-th setting's range: the centre of one of `levels` strata, each stratum used by
    /// one level (a fixed shuffle per setting), as a fraction of the range.
    fn fraction(&self, j: usize, k: usize) -> f64 {
        let n = self.levels.max(2);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&l| mix64(0x5E75_0A11 ^ ((j as u64) << 32) ^ l as u64));
        let stratum = order.iter().position(|&l| l == k % n).unwrap_or(0);
        (stratum as f64 + 0.5) / n as f64
    }

    /// The sensor of level `k`: `base` with each varied setting at its point of the range.
    pub fn sensor(&self, base: &SimConfig, k: usize) -> SimConfig {
        let mut c = base.clone();
        let at = |j: usize, [lo, hi]: [f64; 2]| lo + (hi - lo) * self.fraction(j, k);
        if let Some(r) = self.inflation {
            c.elastomer.inflation = at(0, r);
        }
        if let Some(r) = self.camera_offset {
            c.mount.position[2] = -at(1, r);
        }
        if let Some(r) = self.footprint_scale {
            let s = at(2, r);
            c.elastomer.footprint_x *= s;
            c.elastomer.footprint_y *= s;
        }
        if let Some(r) = self.shadow_px {
            c.signature.shadow_px = at(3, r);
        }
        if let Some(r) = self.noise_std {
            c.signature.noise_std = at(4, r);
        }
        if let Some(r) = self.camera_artefacts {
            let full = if base.depth_camera.is_ideal() {
                crate::sim::DepthCameraConfig::time_of_flight()
            } else {
                base.depth_camera.clone()
            };
            c.depth_camera = full.scaled(at(5, r), full.fixed_pattern_seed.wrapping_add(k as u64));
        }
        c
    }

    /// Every level's sensor.
    pub fn sensors(&self, base: &SimConfig) -> Vec<SimConfig> {
        (0..self.levels.max(2))
            .map(|k| self.sensor(base, k))
            .collect()
    }

    /// The level pair `pair_seed` uses (independent of the ChaCha stream the pair draws its contact from).
    pub fn level(&self, pair_seed: u64) -> usize {
        (mix64(pair_seed ^ 0x2C4E_6A8B_0D1F_3579) % self.levels.max(2) as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use std::collections::BTreeSet;

    #[test]
    fn levels_cover_every_stratum_of_every_range_once() {
        let v = SensorVariation {
            inflation: Some([0.027, 0.033]),
            camera_offset: Some([0.057, 0.063]),
            footprint_scale: None,
            shadow_px: Some([15.0, 30.0]),
            noise_std: Some([0.001, 0.0025]),
            camera_artefacts: Some([0.0, 1.6]),
            levels: 8,
        };
        let base = SimConfig::default();
        v.validate(&base).unwrap();
        let sensors = v.sensors(&base);
        assert_eq!(sensors.len(), 8);
        let strata = |get: &dyn Fn(&SimConfig) -> f64, [lo, hi]: [f64; 2]| {
            let mut s: Vec<usize> = sensors
                .iter()
                .map(|c| ((get(c) - lo) / (hi - lo) * 8.0).floor() as usize)
                .collect();
            s.sort_unstable();
            s
        };
        let all: Vec<usize> = (0..8).collect();
        assert_eq!(strata(&|c| c.elastomer.inflation, [0.027, 0.033]), all);
        assert_eq!(strata(&|c| -c.mount.position[2], [0.057, 0.063]), all);
        assert_eq!(strata(&|c| c.signature.shadow_px, [15.0, 30.0]), all);
        assert_eq!(strata(&|c| c.signature.noise_std, [0.001, 0.0025]), all);
        // The camera's strength scales the time-of-flight preset (the default sensor's camera is ideal); each level
        // has its own fixed pattern.
        let tof = crate::sim::DepthCameraConfig::time_of_flight();
        assert_eq!(
            strata(&|c| c.depth_camera.dropout / tof.dropout, [0.0, 1.6]),
            all
        );
        for c in &sensors {
            let k = c.depth_camera.dropout / tof.dropout;
            assert!((c.depth_camera.fixed_pattern_m - k * tof.fixed_pattern_m).abs() < 1e-12);
            assert!((c.depth_camera.noise_exponent - k * tof.noise_exponent).abs() < 1e-9);
            assert_eq!(c.depth_camera.flying_jump_m, tof.flying_jump_m);
        }
        let patterns: BTreeSet<u64> = sensors
            .iter()
            .map(|c| c.depth_camera.fixed_pattern_seed)
            .collect();
        assert_eq!(patterns.len(), 8);
        // Not the same order in every setting (the levels are not a diagonal of the hypercube).
        let first: Vec<f64> = sensors.iter().map(|c| c.elastomer.inflation).collect();
        let shadow: Vec<f64> = sensors.iter().map(|c| c.signature.shadow_px).collect();
        let rank = |x: &[f64]| {
            let mut r: Vec<usize> = (0..x.len()).collect();
            r.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
            r
        };
        assert_ne!(rank(&first), rank(&shadow));
        assert!(sensors.iter().all(|c| c.elastomer.footprint_x == 0.12));
        // Every level is used by some pair; bad ranges are refused.
        let mut used = [false; 8];
        for s in 0..200u64 {
            used[v.level(s)] = true;
        }
        assert!(used.iter().all(|&u| u));
        let bad = SensorVariation {
            noise_std: Some([0.002, 0.001]),
            ..v
        };
        assert!(bad
            .validate(&base)
            .unwrap_err()
            .to_string()
            .contains("noise"));
        let mut mesh = base.clone();
        mesh.elastomer.mesh_file = Some("bubble.obj".into());
        assert!(v
            .validate(&mesh)
            .unwrap_err()
            .to_string()
            .contains("mesh file"));
    }

    #[test]
    fn every_pair_is_simulated_by_one_of_the_levels_sensors() {
        // Independent truth: the simulator's own membrane for each level's sensor. Without noise, a pair's
        // reference R is exactly the nominal depth E of the sensor that made it.
        let dir = tempfile::tempdir().unwrap();
        let mut base = SimConfig::default();
        base.signature.noise_std = 0.0;
        let v = SensorVariation {
            inflation: Some([0.027, 0.033]),
            camera_offset: Some([0.056, 0.064]),
            footprint_scale: None,
            shadow_px: Some([15.0, 30.0]),
            noise_std: None,
            camera_artefacts: None,
            levels: 4,
        };
        let config = crate::dataset::GenConfig {
            pairs: 40,
            seed: 9,
            sensor_variation: Some(v),
            ..Default::default()
        };
        let set = crate::objects::ObjectSet::builtin();
        crate::dataset::generate(dir.path(), &base, &set, &config, &|_| {}).unwrap();
        let nominal: Vec<crate::image::Image> = v
            .sensors(&base)
            .into_iter()
            .map(|c| {
                crate::sim::Simulator::new(c)
                    .unwrap()
                    .nominal_depth()
                    .clone()
            })
            .collect();
        let ds = crate::dataset::Dataset::open(dir.path()).unwrap();
        let mut used = [0usize; 4];
        for split in crate::dataset::SplitName::ALL {
            for i in 0..ds.len(split) {
                let r = ds.pair(split, i).unwrap().reference;
                let k = nominal
                    .iter()
                    .position(|e| *e == r)
                    .expect("a level's membrane");
                used[k] += 1;
            }
        }
        assert_eq!(used.iter().sum::<usize>(), 40);
        assert!(used.iter().filter(|&&n| n > 0).count() >= 3, "{used:?}");
    }
}
