//! The uncertainty figure (paper V.D, Fig. "uncertainty"): one panel per pose-error variable (position in mm, θ in
//! degrees) with the KDE of the samples' errors, the samples as a rug, and the threshold baseline's, the single-sample
//! estimate's (the pose reported) and the multi-sample estimate's errors as vertical lines; axes, units and a legend. SVG and PNG through
//! [`crate::io::figure`].

use plotters::coord::Shift;
use plotters::prelude::*;

use super::UncertaintyReport;
use crate::io::figure::{draw_axes, draw_legend, err, font, swatch, Draw};

/// The KDE figure of one report.
pub struct KdeFigure<'a> {
    pub report: &'a UncertaintyReport,
}

struct Panel<'a> {
    title: &'a str,
    axis: &'a str,
    curve: &'a [(f64, f64)],
    samples: Vec<f64>,
    baseline: Option<f64>,
    estimate: Option<f64>,
    multi: Option<f64>,
    /// Draw a histogram of the samples under the KDE (θ: a KDE alone hides how the samples split).
    histogram: bool,
}

impl Draw for KdeFigure<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        scale: f64,
    ) -> Result<(), String> {
        let r = self.report;
        let truth = if r.reference_is_truth {
            "true pose"
        } else {
            "estimate"
        };
        let mut panels = vec![Panel {
            title: "position error",
            axis: "position error against the reference [mm]",
            curve: &r.position_kde,
            samples: r.samples.iter().map(|s| s.position_mm).collect(),
            baseline: r.baseline.map(|b| b.position_mm),
            estimate: r.estimate.map(|e| e.position_mm),
            multi: r.multi_sample.map(|m| m.position_mm),
            histogram: false,
        }];
        let theta: Vec<f64> = r.samples.iter().filter_map(|s| s.theta_deg).collect();
        if !theta.is_empty() {
            panels.push(Panel {
                title: "θ error",
                axis: "θ error against the reference [deg]",
                curve: &r.theta_kde,
                samples: theta,
                baseline: r.baseline.and_then(|b| b.theta_deg),
                estimate: r.estimate.and_then(|e| e.theta_deg),
                multi: r.multi_sample.and_then(|m| m.theta_deg),
                histogram: true,
            });
        }
        let areas = root.split_evenly((1, panels.len()));
        for (area, p) in areas.iter().zip(&panels) {
            panel(area, p, truth, scale)?;
        }
        Ok(())
    }
}

fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &Panel<'_>,
    reference: &str,
    s: f64,
) -> Result<(), String> {
    let xs = p
        .curve
        .iter()
        .map(|c| c.0)
        .chain(p.samples.iter().copied())
        .chain(p.baseline)
        .chain(p.estimate)
        .chain(p.multi)
        .filter(|v| v.is_finite());
    let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    let (lo, hi) = if lo.is_finite() && hi > lo {
        let pad = 0.05 * (hi - lo);
        (lo - pad, hi + pad)
    } else if lo.is_finite() {
        (lo - 0.5, lo + 0.5)
    } else {
        (0.0, 1.0)
    };
    // The samples' θ errors (already wrapped to the symmetry period) as a histogram in density units, under the KDE:
    // how many samples fall each side, without the KDE's smoothing. Bars (from, to, density).
    let bars: Vec<(f64, f64, f64)> = if p.histogram && !p.samples.is_empty() {
        let bins = 12usize;
        let lo_v = p.samples.iter().copied().fold(f64::INFINITY, f64::min);
        let hi_v = p.samples.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let width = ((hi_v - lo_v) / bins as f64).max(0.5);
        let n = p.samples.len() as f64;
        let mut counts = vec![0usize; bins + 1];
        for &v in &p.samples {
            counts[(((v - lo_v) / width) as usize).min(bins)] += 1;
        }
        counts
            .iter()
            .enumerate()
            .filter(|(_, &c)| c > 0)
            .map(|(k, &c)| {
                let x0 = lo_v + k as f64 * width;
                (x0, x0 + width, c as f64 / (n * width))
            })
            .collect()
    } else {
        Vec::new()
    };
    let top = p
        .curve
        .iter()
        .map(|c| c.1)
        .chain(bars.iter().map(|b| b.2))
        .fold(0.0, f64::max);
    // Headroom above the curve for the legend (top right), so that it covers none of the data.
    let top = if top > 0.0 { top * 1.7 } else { 1.0 };
    let stroke = (2.0 * s).round().max(1.0) as u32;
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("{} (reference: {reference})", p.title),
            font(18.0, s),
        )
        .margin((12.0 * s) as i32)
        .x_label_area_size((46.0 * s) as i32)
        .y_label_area_size((64.0 * s) as i32)
        .build_cartesian_2d(lo..hi, 0.0..top)
        .map_err(err)?;
    draw_axes(&mut chart, p.axis, "density", s)?;
    if !p.curve.is_empty() {
        chart
            .draw_series(LineSeries::new(
                p.curve.iter().copied(),
                BLUE.stroke_width(stroke),
            ))
            .map_err(err)?
            .label(format!("KDE of {} samples", p.samples.len()))
            .legend(swatch(BLUE, stroke));
    }
    if !bars.is_empty() {
        let fill = RGBColor(150, 170, 230).mix(0.5).filled();
        let width = bars[0].1 - bars[0].0;
        chart
            .draw_series(
                bars.iter()
                    .map(|&(x0, x1, d)| Rectangle::new([(x0, 0.0), (x1, d)], fill)),
            )
            .map_err(err)?
            .label(format!("histogram, {width:.1}° bins"))
            .legend(move |(x, y)| Rectangle::new([(x + 4, y - 5), (x + 16, y + 5)], fill));
    }
    let rug = top * 0.05;
    chart
        .draw_series(p.samples.iter().map(|&v| {
            PathElement::new(
                [(v, 0.0), (v, rug)],
                RGBColor(90, 90, 90).stroke_width(stroke),
            )
        }))
        .map_err(err)?
        .label("samples")
        .legend(move |(x, y)| {
            PathElement::new(
                [(x + 10, y - 6), (x + 10, y + 6)],
                RGBColor(90, 90, 90).stroke_width(stroke),
            )
        });
    for (value, colour, label) in [
        (p.baseline, RED, "threshold baseline"),
        (p.estimate, RGBColor(230, 140, 0), "single-sample estimate"),
        (p.multi, RGBColor(0, 150, 60), "multi-sample estimate"),
    ] {
        if let Some(v) = value {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    [(v, 0.0), (v, top)],
                    colour.stroke_width(stroke),
                )))
                .map_err(err)?
                .label(label)
                .legend(swatch(colour, stroke));
        }
    }
    draw_legend(&mut chart, s)?;
    Ok(())
}
