//! Live timings of the workbench (shown in the status bar, printed by `--timings`): the update latency from a changed
//! parameter to the image showing it, the simulator's own time, the UI build time and the frame interval.

use std::collections::VecDeque;

/// The last samples of one timing, milliseconds.
#[derive(Clone, Debug, Default)]
pub struct Samples {
    values: VecDeque<f64>,
}

/// Samples kept per timing.
const KEEP: usize = 240;

impl Samples {
    pub fn push(&mut self, ms: f64) {
        if self.values.len() == KEEP {
            self.values.pop_front();
        }
        self.values.push_back(ms);
    }

    pub fn len(&self) -> usize {
        self.values.len()
    }

    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The `q` quantile (0..1, nearest rank) of the kept samples; 0 when empty.
    pub fn quantile(&self, q: f64) -> f64 {
        let mut v: Vec<f64> = self.values.iter().copied().collect();
        if v.is_empty() {
            return 0.0;
        }
        v.sort_by(f64::total_cmp);
        let i = ((q.clamp(0.0, 1.0) * (v.len() - 1) as f64).round()) as usize;
        v[i]
    }

    pub fn median(&self) -> f64 {
        self.quantile(0.5)
    }
}

/// All live timings, milliseconds.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// From a parameter change to the arrival of the simulation showing it (queue + simulate + geometry).
    pub update: Samples,
    /// The simulator alone (render, contact, signature).
    pub simulate: Samples,
    /// CPU time to build one frame's UI.
    pub ui: Samples,
    /// Interval between consecutive frames while frames are being produced (gaps over 250 ms are idle time).
    pub frame: Samples,
}

impl Timings {
    /// One JSON line: median and p90 of each timing, and sample counts.
    pub fn summary_json(&self) -> String {
        let one = |s: &Samples| serde_json::json!({"median_ms": s.median(), "p90_ms": s.quantile(0.9), "n": s.len()});
        serde_json::json!({
            "update": one(&self.update),
            "simulate": one(&self.simulate),
            "ui": one(&self.ui),
            "frame_interval": one(&self.frame),
        })
        .to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_known_samples() {
        let mut s = Samples::default();
        assert_eq!(s.median(), 0.0);
        for v in [5.0, 1.0, 3.0, 2.0, 4.0] {
            s.push(v);
        }
        assert_eq!(
            (s.median(), s.quantile(0.0), s.quantile(1.0)),
            (3.0, 1.0, 5.0)
        );
        for _ in 0..KEEP {
            s.push(10.0);
        }
        assert_eq!((s.len(), s.quantile(0.0)), (KEEP, 10.0));
    }
}
