//! The uncertainty figure (paper V.D, Fig. "uncertainty"): one panel per pose-error variable (position in mm, θ in
//! degrees) with the KDE of the samples' errors, the samples as a rug, and the threshold baseline's, the single-sample
//! estimate's (the pose reported) and the multi-sample estimate's errors as vertical lines; axes, units and a legend;
//! and a circular histogram of the θ errors (θ is an angle: an error of +170° and one of −170° lie 20° apart, which
//! only a circle shows). SVG and PNG through [`crate::io::figure`].

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::rose::{rose_point, rose_wedges, ROSE_BINS};
use super::UncertaintyReport;
use crate::io::figure::{draw_axes, draw_legend, draw_legend_at, err, font, swatch, Draw};

/// The KDE figure of one report.
pub struct KdeFigure<'a> {
    pub report: &'a UncertaintyReport,
}

/// Colours of the single-sample and the multi-sample estimates' lines.
const ESTIMATE: RGBColor = RGBColor(230, 140, 0);
const MULTI: RGBColor = RGBColor(0, 150, 60);

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
    ) -> Result<(), crate::io::figure::DrawError> {
        let r = self.report;
        let truth = if r.reference_is_truth {
            "true pose"
        } else {
            "estimate"
        };
        // Without the truth, the "errors" are distances from the estimate: say so on the axes.
        let (position_title, position_axis, theta_title, theta_axis) = if r.reference_is_truth {
            (
                "position error",
                "position error [mm]",
                "θ error",
                "θ error [deg]",
            )
        } else {
            (
                "position distance from the estimate",
                "distance from the estimate [mm]",
                "θ distance from the estimate",
                "θ − θ of the estimate [deg]",
            )
        };
        let mut panels = vec![Panel {
            title: position_title,
            axis: position_axis,
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
                title: theta_title,
                axis: theta_axis,
                curve: &r.theta_kde,
                samples: theta,
                baseline: r.baseline.and_then(|b| b.theta_deg),
                estimate: r.estimate.and_then(|e| e.theta_deg),
                multi: r.multi_sample.and_then(|m| m.theta_deg),
                histogram: true,
            });
        }
        let rose = panels.get(1).map(|theta| Rose {
            title: if r.reference_is_truth {
                "θ error, circular"
            } else {
                "θ from the estimate, circular"
            },
            period_deg: r.theta_period_deg.unwrap_or(360.0),
            errors: &theta.samples,
            lines: [
                (theta.baseline, RED, "threshold baseline"),
                (theta.estimate, ESTIMATE, "single-sample estimate"),
                (theta.multi, MULTI, "multi-sample estimate"),
            ],
        });
        // One title names the reference; three panels side by side get text a little smaller than two.
        let count = panels.len() + usize::from(rose.is_some());
        let body = root
            .margin((6.0 * scale) as u32, 0, 0, 0)
            .titled(
                &format!("pose of the registered samples against the {truth}"),
                font(18.0, scale),
            )
            .map_err(err)?;
        let s = if count > 2 { scale * 0.85 } else { scale };
        let areas = body.split_evenly((1, count));
        for (area, p) in areas.iter().zip(&panels) {
            panel(area, p, s)?;
        }
        if let (Some(rose), Some(area)) = (rose, areas.get(panels.len())) {
            rose.draw(area, s)?;
        }
        Ok(())
    }
}

fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &Panel<'_>,
    s: f64,
) -> Result<(), crate::io::figure::DrawError> {
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
        .caption(p.title, font(18.0, s))
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
        (p.estimate, ESTIMATE, "single-sample estimate"),
        (p.multi, MULTI, "multi-sample estimate"),
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

/// A circular histogram of the θ errors ([`super::rose`]), with the estimates' errors as rays.
struct Rose<'a> {
    title: &'static str,
    period_deg: f64,
    errors: &'a [f64],
    lines: [(Option<f64>, RGBColor, &'static str); 3],
}

impl Rose<'_> {
    /// The point at radius `r` in the direction of a θ error of `deg` ([`rose_point`]).
    fn at(&self, deg: f64, r: f64) -> (f64, f64) {
        let [x, y] = rose_point(deg, r, self.period_deg);
        (x, y)
    }

    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        s: f64,
    ) -> Result<(), crate::io::figure::DrawError> {
        let stroke = (2.0 * s).round().max(1.0) as u32;
        let margin = (12.0 * s) as u32;
        let inner = area
            .titled(self.title, font(18.0, s))
            .map_err(err)?
            .margin(margin, margin, margin, margin);
        // Equal units on both axes (a circle on unequal ones is an ellipse): the rose (radius 1, labels out to
        // 1.45) at the top, centred, and room below it for the legend.
        let (w, h) = inner.dim_in_pixel();
        let legend_px = 115.0 * s;
        let side = f64::from(w).min(f64::from(h) - legend_px).max(1.0);
        let unit = side / 2.9;
        let half_w = f64::from(w) / unit / 2.0;
        let mut chart = ChartBuilder::on(&inner)
            .build_cartesian_2d(-half_w..half_w, (1.45 - f64::from(h) / unit)..1.45)
            .map_err(err)?;
        let grey = RGBColor(190, 190, 190).stroke_width(stroke.div_ceil(2));
        for r in [0.5, 1.0] {
            let ring: Vec<(f64, f64)> = (0..=96)
                .map(|k| self.at(self.period_deg * k as f64 / 96.0, r))
                .collect();
            chart
                .draw_series(std::iter::once(PathElement::new(ring, grey)))
                .map_err(err)?;
        }
        let half = self.period_deg / 2.0;
        for deg in [0.0, half / 2.0, half, -half / 2.0] {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    [(0.0, 0.0), self.at(deg, 1.0)],
                    grey,
                )))
                .map_err(err)?;
            let (x, y) = self.at(deg, 1.22);
            // Whole degrees where they are whole (a 4-fold object's quarter period is 22.5°).
            let digits = usize::from(deg.fract() != 0.0);
            let label = if deg == half {
                format!("±{half:.digits$}°")
            } else {
                format!("{deg:+.digits$}°")
            };
            chart
                .draw_series(std::iter::once(Text::new(
                    label,
                    (x, y),
                    TextStyle::from(font(13.0, s)).pos(Pos::new(HPos::Center, VPos::Center)),
                )))
                .map_err(err)?;
        }
        let width = self.period_deg / ROSE_BINS as f64;
        let fill = RGBColor(150, 170, 230).mix(0.7).filled();
        let wedges = rose_wedges(self.errors, self.period_deg)
            .into_iter()
            .map(|w| Polygon::new(w.into_iter().map(|[x, y]| (x, y)).collect::<Vec<_>>(), fill));
        chart
            .draw_series(wedges)
            .map_err(err)?
            .label(format!(
                "{} samples, {width:.0}° wedges (area: share)",
                self.errors.len()
            ))
            .legend(move |(x, y)| Rectangle::new([(x + 4, y - 5), (x + 16, y + 5)], fill));
        for (value, colour, label) in self.lines {
            if let Some(v) = value.filter(|v| v.is_finite()) {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        [(0.0, 0.0), self.at(v, 1.1)],
                        colour.stroke_width(stroke),
                    )))
                    .map_err(err)?
                    .label(label)
                    .legend(swatch(colour, stroke));
            }
        }
        draw_legend_at(&mut chart, s, SeriesLabelPosition::LowerMiddle)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_figure_has_the_rose_only_with_theta_errors() {
        use crate::sensor::Se2;
        let sample = |theta: Option<f64>| super::super::SampleError {
            pose: Se2::default(),
            cost: 0.0,
            position_mm: 1.0,
            theta_deg: theta,
        };
        let svg = |theta: Option<f64>| {
            let mut report = super::super::UncertaintyReport::new(
                Se2::default(),
                true,
                Se2::default(),
                vec![sample(theta.map(|t| t + 3.0)), sample(theta)],
                None,
            );
            report.theta_period_deg = theta.map(|_| 180.0);
            let dir = tempfile::tempdir().unwrap();
            let size = crate::io::figure::FigureConfig {
                width_px: 1200,
                height_px: 500,
            };
            let [svg, _] = crate::io::figure::write_figure(
                dir.path(),
                "u",
                &size,
                &KdeFigure { report: &report },
            )
            .unwrap();
            std::fs::read_to_string(svg).unwrap()
        };
        let with = svg(Some(170.0));
        assert!(with.contains("θ error, circular"), "no rose");
        // The rose's labels name the period: ± 90° at the bottom for a 2-fold object.
        assert!(with.contains("±90°"));
        assert!(!svg(None).contains("circular"));
    }
}
