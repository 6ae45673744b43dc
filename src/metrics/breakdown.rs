//! The evaluation **broken down by where it fails**: the paper's Table I/II rows per contact-size bin and per
//! object, with the model's mean position error as a ratio of the threshold baseline's.
//!
//! Contact size is the number of in-contact pixels of the true X0 at the dataset's resolution (64 x 64 = 4 096
//! pixels by default). Real objects make smaller, less regular contacts than the paper's families, so a model can
//! beat the baseline on large contacts and lose on small ones; the bins show it.
//!
//! Mean position errors over a few hundred pairs are dominated by a handful of large misses, so every ratio comes
//! with a 95 % **paired bootstrap interval** ([`ratio_interval`]): how far the ratio could move with another draw of
//! pairs like these.

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::evaluate::{MethodResult, MethodSummary, PairRecord};

/// Contact-size bins, `[lo, hi)` pixels.
pub const CONTACT_BINS: [(usize, usize); 5] = [
    (0, 100),
    (100, 300),
    (300, 700),
    (700, 1500),
    (1500, usize::MAX),
];

/// The rows of one group of pairs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupSummary {
    /// `"<100 px"`, `"100–300 px"`, …, or the object name.
    pub label: String,
    pub pairs: usize,
    pub model: MethodSummary,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_multi: Option<MethodSummary>,
    /// The model with the baseline's proposals, where the check ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_combined: Option<MethodSummary>,
    pub baseline: MethodSummary,
    /// The baseline with the signature check, where it ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline_checked: Option<MethodSummary>,
    /// Model mean position error / baseline mean position error (NaN when either has no pose); below 1 the model
    /// is better.
    pub position_ratio: f64,
    /// The same for the multi-sample estimate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_ratio_multi: Option<f64>,
    /// 95 % paired bootstrap interval of `position_ratio` ([`ratio_interval`]; `None` under 2 pairs with poses).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_ratio_ci95: Option<[f64; 2]>,
    /// The same for `position_ratio_multi`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_ratio_multi_ci95: Option<[f64; 2]>,
    /// Model with the baseline's proposals / baseline, and its interval.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_ratio_combined: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_ratio_combined_ci95: Option<[f64; 2]>,
}

impl GroupSummary {
    /// Summarise `records` under `label`.
    pub fn of(label: String, records: &[&PairRecord]) -> Self {
        let model = MethodSummary::of(records.iter().map(|r| &r.model));
        let baseline = MethodSummary::of(records.iter().map(|r| &r.baseline));
        let optional = |m: &dyn Fn(&PairRecord) -> Option<&MethodResult>| {
            let results: Vec<&MethodResult> = records.iter().filter_map(|r| m(r)).collect();
            (!results.is_empty()).then(|| MethodSummary::of(results.iter().copied()))
        };
        let model_multi = optional(&|r| r.model_multi.as_ref());
        let model_combined = optional(&|r| r.model_combined.as_ref());
        let baseline_checked = optional(&|r| r.baseline_checked.as_ref());
        let ratio = |m: &MethodSummary| m.position_mm.mean / baseline.position_mm.mean;
        let interval = |m: &dyn Fn(&PairRecord) -> Option<&MethodResult>| {
            let pairs: Vec<_> = records
                .iter()
                .map(|r| (m(r).and_then(position), position(&r.baseline)))
                .collect();
            ratio_interval(&pairs)
        };
        Self {
            label,
            pairs: records.len(),
            position_ratio: ratio(&model),
            position_ratio_multi: model_multi.as_ref().map(ratio),
            position_ratio_ci95: interval(&|r| Some(&r.model)),
            position_ratio_multi_ci95: model_multi
                .as_ref()
                .and_then(|_| interval(&|r| r.model_multi.as_ref())),
            position_ratio_combined: model_combined.as_ref().map(ratio),
            position_ratio_combined_ci95: model_combined
                .as_ref()
                .and_then(|_| interval(&|r| r.model_combined.as_ref())),
            model,
            model_multi,
            model_combined,
            baseline,
            baseline_checked,
        }
    }
}

/// A method's position error on a pair, when it has a finite one.
fn position(r: &MethodResult) -> Option<f64> {
    r.pose.map(|p| p.position_mm).filter(|x| x.is_finite())
}

/// Resamples behind [`ratio_interval`].
pub const BOOTSTRAP_RESAMPLES: usize = 2000;

/// 95 % paired bootstrap interval (percentile method) of mean(model position) / mean(baseline position) over
/// `pairs` (each pair's two errors, `None` where that method has no pose): pairs are drawn with replacement, both
/// errors of a pair together, and each resample's ratio is computed as the point estimate is (each mean over the
/// drawn pairs where that method has a pose). The stream is seeded with a constant, so the same records always give
/// the same interval. `None` when fewer than 2 pairs have both errors.
pub fn ratio_interval(pairs: &[(Option<f64>, Option<f64>)]) -> Option<[f64; 2]> {
    let n = pairs.len();
    if pairs
        .iter()
        .filter(|(m, b)| m.is_some() && b.is_some())
        .count()
        < 2
    {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(0x7a11_b007);
    let mut ratios = Vec::with_capacity(BOOTSTRAP_RESAMPLES);
    for _ in 0..BOOTSTRAP_RESAMPLES {
        let (mut sum_m, mut n_m, mut sum_b, mut n_b) = (0.0, 0u32, 0.0, 0u32);
        for _ in 0..n {
            let (m, b) = pairs[rng.random_range(0..n)];
            if let Some(m) = m {
                sum_m += m;
                n_m += 1;
            }
            if let Some(b) = b {
                sum_b += b;
                n_b += 1;
            }
        }
        if n_m > 0 && n_b > 0 && sum_b > 0.0 {
            ratios.push((sum_m / f64::from(n_m)) / (sum_b / f64::from(n_b)));
        }
    }
    if ratios.is_empty() {
        return None;
    }
    ratios.sort_by(f64::total_cmp);
    let at = |q: f64| ratios[(q * (ratios.len() - 1) as f64).round() as usize];
    Some([at(0.025), at(0.975)])
}

/// Rows per contact-size bin (empty bins left out) and per object (sorted by name).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Breakdown {
    pub contact_size: Vec<GroupSummary>,
    pub object: Vec<GroupSummary>,
}

/// Label of a contact-size bin.
pub fn bin_label((lo, hi): (usize, usize)) -> String {
    match (lo, hi) {
        (0, hi) => format!("<{hi} px"),
        (lo, usize::MAX) => format!("≥{lo} px"),
        (lo, hi) => format!("{lo}–{hi} px"),
    }
}

impl Breakdown {
    /// Group `records` by contact size and by object.
    pub fn of(records: &[PairRecord]) -> Self {
        let contact_size = CONTACT_BINS
            .iter()
            .filter_map(|&(lo, hi)| {
                let mine: Vec<&PairRecord> = records
                    .iter()
                    .filter(|r| (lo..hi).contains(&r.contact_pixels))
                    .collect();
                (!mine.is_empty()).then(|| GroupSummary::of(bin_label((lo, hi)), &mine))
            })
            .collect();
        let mut by_object: BTreeMap<&str, Vec<&PairRecord>> = BTreeMap::new();
        for r in records {
            by_object.entry(r.object.as_str()).or_default().push(r);
        }
        let object = by_object
            .into_iter()
            .map(|(name, mine)| GroupSummary::of(name.to_string(), &mine))
            .collect();
        Self {
            contact_size,
            object,
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::metrics::pose::PoseErrors;
    use crate::metrics::DepthMetrics;
    use crate::sensor::Se2;

    fn result(position_mm: f64) -> MethodResult {
        MethodResult {
            depth: DepthMetrics {
                l1_mm: 1.0,
                l1_union_mm: None,
                psnr_db: 20.0,
                ssim: 0.5,
            },
            estimate: Some(Se2::default()),
            pose: Some(PoseErrors {
                position_mm,
                position_axis_excluded: false,
                theta_rad: None,
                chamfer_m2: 0.0,
            }),
            posterior: None,
            truth_region: None,
        }
    }

    fn record(object: &str, contact_pixels: usize, model: f64, baseline: f64) -> PairRecord {
        PairRecord {
            name: String::new(),
            object: object.into(),
            truth: Se2::default(),
            contact_pixels,
            symmetry: Default::default(),
            model: result(model),
            model_multi: None,
            model_combined: None,
            baseline: result(baseline),
            baseline_checked: None,
        }
    }

    #[test]
    fn pairs_land_in_their_bin_and_object_with_the_right_ratio() {
        let records = [
            record("a", 50, 1.0, 2.0),
            record("a", 99, 3.0, 2.0),
            record("b", 100, 1.0, 4.0),
            record("b", 5000, 2.0, 1.0),
        ];
        let b = Breakdown::of(&records);
        let labels: Vec<&str> = b.contact_size.iter().map(|g| g.label.as_str()).collect();
        assert_eq!(labels, ["<100 px", "100–300 px", "≥1500 px"]);
        assert_eq!(b.contact_size[0].pairs, 2);
        assert!((b.contact_size[0].position_ratio - 1.0).abs() < 1e-12);
        assert!((b.contact_size[1].position_ratio - 0.25).abs() < 1e-12);
        assert_eq!(b.object.len(), 2);
        assert_eq!(b.object[1].label, "b");
        assert!((b.object[1].position_ratio - 1.5 / 2.5).abs() < 1e-12);
        // One pair with both poses: no interval.
        assert_eq!(b.contact_size[1].position_ratio_ci95, None);
    }

    #[test]
    fn bootstrap_interval_is_exact_for_proportional_errors_and_holds_the_estimate() {
        // Model errors exactly 0.4x the baseline's on every pair: every resample's ratio is 0.4.
        let errors = [0.1, 0.3, 0.2, 8.0, 1.5, 0.05, 3.0, 0.7];
        let pairs: Vec<_> = errors.iter().map(|&b| (Some(0.4 * b), Some(b))).collect();
        let [lo, hi] = ratio_interval(&pairs).unwrap();
        assert!(
            (lo - 0.4).abs() < 1e-12 && (hi - 0.4).abs() < 1e-12,
            "{lo} {hi}"
        );

        // Unrelated errors: the interval holds the point estimate, is reproducible, and one large miss of the
        // model widens it upwards.
        let records: Vec<PairRecord> = (0..60)
            .map(|i| {
                let b = 1.0 + (i % 7) as f64;
                let m = 0.5 + (i % 5) as f64 * 0.3;
                record("a", 500, m, b)
            })
            .collect();
        let g = GroupSummary::of("all".into(), &records.iter().collect::<Vec<_>>());
        let [lo, hi] = g.position_ratio_ci95.unwrap();
        assert!(
            lo < g.position_ratio && g.position_ratio < hi,
            "{lo} {} {hi}",
            g.position_ratio
        );
        assert!(hi - lo < 0.3, "60 pairs of bounded errors: {lo}..{hi}");
        let again = GroupSummary::of("all".into(), &records.iter().collect::<Vec<_>>());
        assert_eq!(again.position_ratio_ci95, g.position_ratio_ci95);
        let mut tail = records.clone();
        tail[0] = record("a", 500, 200.0, 1.0);
        let t = GroupSummary::of("all".into(), &tail.iter().collect::<Vec<_>>());
        let [tlo, thi] = t.position_ratio_ci95.unwrap();
        assert!(
            thi - tlo > 3.0 * (hi - lo),
            "{tlo}..{thi} against {lo}..{hi}"
        );

        // A pair where the model found no contact leaves the model's mean and keeps the baseline's.
        let pairs = [
            (None, Some(10.0)),
            (Some(1.0), Some(1.0)),
            (Some(1.0), Some(1.0)),
        ];
        let [_, hi] = ratio_interval(&pairs).unwrap();
        assert!(hi <= 1.0 + 1e-12, "{hi}");
        assert_eq!(
            ratio_interval(&[(None, Some(1.0)), (Some(1.0), None)]),
            None
        );
    }
}
