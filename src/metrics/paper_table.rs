//! The **paper's table layout** (Tables I and II): one row per training configuration or method, the test splits
//! side by side as column groups, depth as L1 [mm], PSNR [dB] and SSIM, pose as position [mm], θ [rad] and Chamfer
//! [m²] — the paper's units, beside `tnd eval`'s own tables (θ in degrees, Chamfer in mm², medians, exclusions).
//!
//! Built from [`MethodSummary`] rows, which `tnd eval --json` writes one split at a time, so several evaluation
//! runs (one per trained model) can be set side by side without evaluating again. Comparability: the paper's
//! figures are on real sensor data and its PSNR uses another range; see docs/evaluation.md.

use std::fmt::Write as _;

use super::evaluate::MethodSummary;
use super::summary::MeanStd;

/// One cell group of the tables: a row label (training configuration or method) on one split.
#[derive(Clone, Debug)]
pub struct PaperEntry {
    /// Row label, e.g. the model file or "threshold baseline".
    pub label: String,
    /// Split name (column group), e.g. `unseen_poses`.
    pub split: String,
    pub summary: MethodSummary,
}

/// Both tables as markdown: rows in the order their labels first appear in `entries`, column groups in the order
/// their splits first appear; a label without a split shows "–" there. A repeated (label, split) keeps the first.
pub fn paper_tables(entries: &[PaperEntry]) -> String {
    let mut labels: Vec<&str> = Vec::new();
    let mut splits: Vec<&str> = Vec::new();
    for e in entries {
        if !labels.contains(&e.label.as_str()) {
            labels.push(&e.label);
        }
        if !splits.contains(&e.split.as_str()) {
            splits.push(&e.split);
        }
    }
    let find = |label: &str, split: &str| {
        entries
            .iter()
            .find(|e| e.label == label && e.split == split)
            .map(|e| &e.summary)
    };
    let mut s = String::new();
    type Cells = fn(&MethodSummary) -> [String; 3];
    let tables: [(&str, [&str; 3], Cells); 2] = [
        ("Table I (depth)", ["L1 [mm]", "PSNR [dB]", "SSIM"], |m| {
            [
                mean_std(&m.l1_mm, Digits::Fixed(2)),
                mean_std(&m.psnr_db, Digits::Fixed(2)),
                mean_std(&m.ssim, Digits::Fixed(3)),
            ]
        }),
        (
            "Table II (pose)",
            ["position [mm]", "θ [rad]", "Chamfer [m²]"],
            |m| {
                [
                    mean_std(&m.position_mm, Digits::Fixed(2)),
                    mean_std(&m.theta_rad, Digits::Fixed(3)),
                    mean_std(&m.chamfer_m2, Digits::Sci(2)),
                ]
            },
        ),
    ];
    for (title, columns, cells) in tables {
        let _ = writeln!(s, "### {title}\n");
        s.push_str("| configuration |");
        for split in &splits {
            for c in columns {
                let _ = write!(s, " {split}: {c} |");
            }
        }
        s.push_str("\n| --- |");
        s.push_str(&" --- |".repeat(3 * splits.len()));
        s.push('\n');
        for label in &labels {
            let _ = write!(s, "| {label} |");
            for split in &splits {
                match find(label, split) {
                    Some(m) => {
                        for c in cells(m) {
                            let _ = write!(s, " {c} |");
                        }
                    }
                    None => s.push_str(&" – |".repeat(3)),
                }
            }
            s.push('\n');
        }
        s.push('\n');
    }
    s
}

/// How a cell's numbers are written.
#[derive(Clone, Copy)]
enum Digits {
    /// Fixed point with this many decimals.
    Fixed(usize),
    /// Scientific with this many decimals (Chamfer distances in m²).
    Sci(usize),
}

/// `mean ± std` of `m` in `digits`, "–" without values.
fn mean_std(m: &MeanStd, digits: Digits) -> String {
    if m.n == 0 {
        return "–".into();
    }
    let f = |v: f64| match digits {
        Digits::Fixed(d) => format!("{v:.d$}"),
        Digits::Sci(d) => format!("{v:.d$e}"),
    };
    format!("{} ± {}", f(m.mean), f(m.std))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn ms(values: &[f64]) -> MeanStd {
        MeanStd::of(values.iter().map(|&v| Some(v)))
    }

    fn summary(l1: f64, theta: f64, chamfer: f64) -> MethodSummary {
        MethodSummary {
            l1_mm: ms(&[l1 - 1.0, l1 + 1.0]),
            l1_union_mm: ms(&[l1]),
            psnr_db: ms(&[20.0]),
            ssim: ms(&[0.9, 0.8]),
            position_mm: ms(&[0.5, 1.5]),
            theta_rad: ms(&[theta]),
            chamfer_m2: ms(&[chamfer]),
            no_contact: 0,
            theta_excluded_symmetry: 0,
            position_axis_excluded: 0,
            coverage: None,
        }
    }

    #[test]
    fn rows_per_configuration_splits_side_by_side_in_the_papers_units() {
        let e = |label: &str, split: &str, m| PaperEntry {
            label: label.into(),
            split: split.into(),
            summary: m,
        };
        let entries = [
            e("sim", "unseen_poses", summary(2.0, 0.0175, 3.4e-6)),
            e("sim", "unseen_objects", summary(3.0, 0.02, 5.0e-6)),
            e(
                "threshold baseline",
                "unseen_poses",
                summary(11.0, 0.04, 2.0e-5),
            ),
            e("sim + real", "unseen_objects", summary(1.0, 0.01, 1.0e-6)),
            // A repeated (label, split) keeps the first.
            e("sim", "unseen_poses", summary(99.0, 9.0, 9.0)),
        ];
        let md = paper_tables(&entries);
        let lines: Vec<&str> = md.lines().collect();
        let header = lines.iter().find(|l| l.contains("L1 [mm]")).unwrap();
        assert_eq!(
            *header,
            "| configuration | unseen_poses: L1 [mm] | unseen_poses: PSNR [dB] | unseen_poses: SSIM | \
             unseen_objects: L1 [mm] | unseen_objects: PSNR [dB] | unseen_objects: SSIM |"
        );
        // Mean ± population std: L1 {1, 3} → 2.00 ± 1.00; SSIM {0.9, 0.8} → 0.850 ± 0.050.
        assert!(lines.contains(
            &"| sim | 2.00 ± 1.00 | 20.00 ± 0.00 | 0.850 ± 0.050 | 3.00 ± 1.00 | 20.00 ± 0.00 | 0.850 ± 0.050 |"
        ));
        // θ stays in radians (0.0175 rad, not 1.00°), Chamfer in m² (3.4e-6, not 3.4 mm²).
        assert!(lines.contains(
            &"| sim | 1.00 ± 0.50 | 0.018 ± 0.000 | 3.40e-6 ± 0.00e0 | 1.00 ± 0.50 | 0.020 ± 0.000 | 5.00e-6 ± 0.00e0 |"
        ));
        // Rows in first-appearance order, a missing split as dashes, the repeated entry ignored.
        let pose_rows: Vec<&&str> = lines
            .iter()
            .skip_while(|l| !l.contains("Table II"))
            .filter(|l| {
                l.starts_with("| ") && !l.starts_with("| configuration") && !l.starts_with("| ---")
            })
            .collect();
        assert_eq!(pose_rows.len(), 3);
        assert!(pose_rows[1]
            .starts_with("| threshold baseline | 1.00 ± 0.50 | 0.040 ± 0.000 | 2.00e-5"));
        assert!(pose_rows[1].ends_with("| – | – | – |"));
        assert!(pose_rows[2].starts_with("| sim + real | – | – | – | 1.00 ± 0.50 | 0.010"));
        assert!(!md.contains("99.00"));
    }

    #[test]
    fn no_values_is_a_dash() {
        let mut m = summary(1.0, 0.1, 1e-6);
        m.theta_rad = MeanStd::of(std::iter::once(None));
        let md = paper_tables(&[PaperEntry {
            label: "sphere only".into(),
            split: "unseen_objects".into(),
            summary: m,
        }]);
        assert!(md.contains("| sphere only | 1.00 ± 0.50 | – | 1.00e-6 ± 0.00e0 |"));
    }
}
