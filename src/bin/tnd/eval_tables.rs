//! The markdown tables `tnd eval` prints beside its JSON: the paper's Table I and II rows per method, the model /
//! baseline ratios with their bootstrap intervals, and the rows per contact-size bin and per object.

use std::fmt::Write as _;

use tactile_derender::metrics::breakdown::GroupSummary;
use tactile_derender::metrics::evaluate::{EvalReport, MethodSummary};
use tactile_derender::metrics::MeanStd;

fn cell(m: &MeanStd, scale: f64, digits: usize) -> String {
    if m.n == 0 {
        format!("– (excl. {})", m.excluded)
    } else if m.excluded > 0 {
        format!(
            "{:.digits$} ± {:.digits$} (excl. {})",
            m.mean * scale,
            m.std * scale,
            m.excluded
        )
    } else {
        format!("{:.digits$} ± {:.digits$}", m.mean * scale, m.std * scale)
    }
}

/// A mean ± std cell followed by the median (position errors: a few ambiguous pairs can dominate the mean).
fn median_cell(m: &MeanStd) -> String {
    if m.n == 0 {
        cell(m, 1.0, 3)
    } else {
        format!("{} (median {:.3})", cell(m, 1.0, 3), m.median)
    }
}

fn row(name: &str, s: &MethodSummary) -> String {
    format!(
        "| {name} | {} | {} | {} | {} | {} | {} | {} | {} / {} / {} |\n",
        cell(&s.l1_mm, 1.0, 3),
        cell(&s.l1_union_mm, 1.0, 3),
        cell(&s.psnr_db, 1.0, 2),
        cell(&s.ssim, 1.0, 4),
        median_cell(&s.position_mm),
        cell(&s.theta_rad, 180.0 / std::f64::consts::PI, 2),
        cell(&s.chamfer_m2, 1e6, 3),
        s.no_contact,
        s.theta_excluded_symmetry,
        s.position_axis_excluded,
    )
}

/// How often the truth lies inside each method's posterior regions (empty when no method has a posterior).
fn coverage_table(r: &EvalReport) -> String {
    use tactile_derender::metrics::coverage::WRONG_MM;
    let rows = [
        (r.generator.clone(), Some(&r.model)),
        (
            format!("{} (multi-sample)", r.generator),
            r.model_multi.as_ref(),
        ),
        (
            format!("{} + imprint proposals (checked)", r.generator),
            r.model_combined.as_ref(),
        ),
        (
            "threshold baseline + signature check".into(),
            r.baseline_checked.as_ref(),
        ),
    ];
    let mut s = String::new();
    for (name, m) in rows {
        if let Some(c) = m.and_then(|m| m.coverage) {
            let _ = writeln!(
                s,
                "| {name} | {} |",
                crate::posterior_cmd::coverage_cells(&c)
            );
        }
    }
    if s.is_empty() {
        return s;
    }
    format!(
        "Pose posterior: the truth inside its 50 / 90 / 95 % regions (a calibrated posterior: about 50 / 90 / 95 %); \
         confidently wrong: > {WRONG_MM} mm off, outside the 95 % region.\n\n| method | pairs | inside 50 % | inside 90 % | \
         inside 95 % | confidently wrong |\n| --- | --- | --- | --- | --- | --- |\n{s}\n"
    )
}

/// Table I and II rows of one split as markdown.
pub fn markdown_table(split: &str, r: &EvalReport) -> String {
    let failed = if r.failed.is_empty() {
        String::new()
    } else {
        format!(", {} failed", r.failed.len())
    };
    let mut s = format!("## {split} ({} pairs{failed})\n\n", r.pairs);
    s.push_str("| method | L1 [mm] | L1 on masks [mm] | PSNR [dB] | SSIM | position [mm] | θ [deg] | Chamfer [mm²] | no contact / θ excl. / axis excl. |\n");
    s.push_str("| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    s.push_str(&row(&r.generator, &r.model));
    if let Some(m) = &r.model_multi {
        s.push_str(&row(&format!("{} (multi-sample)", r.generator), m));
    }
    if let Some(m) = &r.model_combined {
        s.push_str(&row(
            &format!("{} + imprint proposals (checked)", r.generator),
            m,
        ));
    }
    s.push_str(&row("threshold baseline", &r.baseline));
    if let Some(b) = &r.baseline_checked {
        s.push_str(&row("threshold baseline + signature check", b));
    }
    s.push('\n');
    s.push_str(&coverage_table(r));
    let ratio = |m: &MethodSummary| m.position_mm.mean / r.baseline.position_mm.mean;
    for (what, m, ci) in [
        ("model", Some(&r.model), r.position_ratio_ci95),
        (
            "multi-sample",
            r.model_multi.as_ref(),
            r.position_ratio_multi_ci95,
        ),
        (
            "model + imprint proposals",
            r.model_combined.as_ref(),
            r.position_ratio_combined_ci95,
        ),
    ] {
        if let (Some(m), Some(ci)) = (m, ci) {
            let _ = writeln!(
                s,
                "Mean position error, {what} / threshold baseline: {:.2} (95 % paired bootstrap interval {}, {} \
                 resamples of these pairs).\n",
                ratio(m),
                interval_text(ci),
                tactile_derender::metrics::breakdown::BOOTSTRAP_RESAMPLES,
            );
        }
    }
    // The ratios above credit the model with the signature check it runs; the baseline with the same check shows
    // what the model's samples add (a model of noise scores near 1 there however good the ratios above look).
    if let Some(b) = r
        .baseline_checked
        .as_ref()
        .filter(|b| b.position_mm.mean > 0.0)
    {
        s.push_str(&fair_table(r, b));
    }
    s
}

/// Each method's mean position error against the threshold baseline alone and against the baseline with the same
/// signature check: what the pipeline gains over the paper's baseline, and what the model's samples add to the check.
fn fair_table(r: &EvalReport, checked: &MethodSummary) -> String {
    let mut s = String::from(
        "| mean position error ratio | / threshold baseline | / (baseline + signature check) |\n| --- | --- | --- |\n",
    );
    let base = r.baseline.position_mm.mean;
    let rows = [
        (
            "pipeline: samples + imprint proposals, checked",
            r.model_combined.as_ref(),
        ),
        ("samples only, checked", Some(&r.model)),
        ("multi-sample", r.model_multi.as_ref()),
    ];
    for (what, m) in rows {
        if let Some(m) = m {
            let _ = writeln!(
                s,
                "| {what} | {:.2} | {:.2} |",
                m.position_mm.mean / base,
                m.position_mm.mean / checked.position_mm.mean
            );
        }
    }
    s.push_str(
        "\nUnder 1 in the last column, the model's samples add to what the signature check finds from the imprint \
         alone; over 1, the check alone does better.\n\n",
    );
    s
}

/// `[lo, hi]` as `lo–hi`.
fn interval_text([lo, hi]: [f64; 2]) -> String {
    format!("{lo:.2}–{hi:.2}")
}

/// A ratio with its interval, when there is one.
fn ratio_cell(ratio: f64, ci: Option<[f64; 2]>) -> String {
    match ci {
        Some(ci) => format!("{ratio:.2} [{}]", interval_text(ci)),
        None => format!("{ratio:.2}"),
    }
}

/// Position error per contact-size bin and per object, model against baseline, as markdown.
pub fn breakdown_tables(r: &EvalReport) -> String {
    type Cell = fn(&GroupSummary) -> Option<String>;
    // (header, cell): a column is shown when the report has its method.
    let columns: [(&str, bool, Cell); 8] = [
        ("model position [mm]", true, |g| {
            Some(median_cell(&g.model.position_mm))
        }),
        ("multi-sample position [mm]", r.model_multi.is_some(), |g| {
            g.model_multi.as_ref().map(|m| median_cell(&m.position_mm))
        }),
        (
            "model + imprint proposals [mm]",
            r.model_combined.is_some(),
            |g| {
                g.model_combined
                    .as_ref()
                    .map(|m| median_cell(&m.position_mm))
            },
        ),
        ("baseline position [mm]", true, |g| {
            Some(median_cell(&g.baseline.position_mm))
        }),
        ("baseline + check [mm]", r.baseline_checked.is_some(), |g| {
            g.baseline_checked
                .as_ref()
                .map(|b| median_cell(&b.position_mm))
        }),
        ("model / baseline [95 % interval]", true, |g| {
            Some(ratio_cell(g.position_ratio, g.position_ratio_ci95))
        }),
        (
            "multi-sample / baseline [95 % interval]",
            r.model_multi.is_some(),
            |g| {
                g.position_ratio_multi
                    .map(|x| ratio_cell(x, g.position_ratio_multi_ci95))
            },
        ),
        (
            "model + imprint proposals / baseline [95 % interval]",
            r.model_combined.is_some(),
            |g| {
                g.position_ratio_combined
                    .map(|x| ratio_cell(x, g.position_ratio_combined_ci95))
            },
        ),
    ];
    let shown: Vec<_> = columns.iter().filter(|(_, on, _)| *on).collect();
    let mut s = String::new();
    for (title, groups) in [
        ("contact size", &r.breakdown.contact_size),
        ("object", &r.breakdown.object),
    ] {
        let _ = write!(s, "| {title} | pairs |");
        for (header, _, _) in &shown {
            let _ = write!(s, " {header} |");
        }
        let _ = writeln!(s, "\n|{}", " --- |".repeat(2 + shown.len()));
        for g in groups {
            let _ = write!(s, "| {} | {} |", g.label, g.pairs);
            for (_, _, cell) in &shown {
                let _ = write!(s, " {} |", cell(g).unwrap_or_else(|| "–".into()));
            }
            s.push('\n');
        }
        s.push('\n');
    }
    s
}
