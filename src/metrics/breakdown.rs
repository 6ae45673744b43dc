//! The evaluation **broken down by where it fails**: the paper's Table I/II rows per contact-size bin and per
//! object, with the model's mean position error as a ratio of the threshold baseline's.
//!
//! Contact size is the number of in-contact pixels of the true X0 at the dataset's resolution (64 x 64 = 4 096
//! pixels by default). Real objects make smaller, less regular contacts than the paper's families, so a model can
//! beat the baseline on large contacts and lose on small ones; the bins show it.

use std::collections::BTreeMap;

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
}

impl GroupSummary {
    /// Summarise `records` under `label`.
    pub fn of(label: String, records: &[&PairRecord]) -> Self {
        let model = MethodSummary::of(records.iter().map(|r| &r.model));
        let baseline = MethodSummary::of(records.iter().map(|r| &r.baseline));
        let multi: Vec<&MethodResult> = records
            .iter()
            .filter_map(|r| r.model_multi.as_ref())
            .collect();
        let model_multi = (!multi.is_empty()).then(|| MethodSummary::of(multi.iter().copied()));
        let checked: Vec<&MethodResult> = records
            .iter()
            .filter_map(|r| r.baseline_checked.as_ref())
            .collect();
        let baseline_checked =
            (!checked.is_empty()).then(|| MethodSummary::of(checked.iter().copied()));
        let ratio = |m: &MethodSummary| m.position_mm.mean / baseline.position_mm.mean;
        Self {
            label,
            pairs: records.len(),
            position_ratio: ratio(&model),
            position_ratio_multi: model_multi.as_ref().map(ratio),
            model,
            model_multi,
            baseline,
            baseline_checked,
        }
    }
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
        }
    }

    fn record(object: &str, contact_pixels: usize, model: f64, baseline: f64) -> PairRecord {
        PairRecord {
            name: String::new(),
            object: object.into(),
            truth: Se2::default(),
            contact_pixels,
            model: result(model),
            model_multi: None,
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
    }
}
