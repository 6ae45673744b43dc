//! The SE(2) fit figure (paper Fig. "SE(2) fits"): a top view in millimetres, world frame, of the object's outline at
//! the true pose, at the single-sample and multi-sample estimates and at the threshold baseline's, with the
//! back-projected contact points the estimate was fitted to, and the pose posterior: each mode's 90 % position ellipse
//! and the outline at the top mode's 90 % θ extremes. SVG and PNG through [`crate::io::figure`].

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::outline::{placed_mm, Outline};
use crate::io::figure::{draw_axes, draw_legend, err, font, swatch, Draw};
use crate::sensor::Se2;

/// What the fit figure shows.
pub struct FitFigure<'a> {
    /// Object name, for the title.
    pub object: &'a str,
    /// Top-view outline in the object frame, metres ([`super::outline::outline`]).
    pub outline: &'a [Outline],
    /// Contact points `(x, y)`, world frame, metres.
    pub contacts: &'a [[f64; 2]],
    pub truth: Option<Se2>,
    pub single: Option<Se2>,
    pub multi: Option<Se2>,
    pub baseline: Option<Se2>,
    /// The registered samples' positions `(x, y)`, world frame, metres.
    pub samples: &'a [[f64; 2]],
    /// The pose posterior: each mode's 90 % position ellipse, and the outline at the top mode's 90 % θ extremes.
    pub posterior: Option<&'a super::posterior::PosePosterior>,
    /// The object's symmetry: the posterior's far θ is uniform over its period.
    pub symmetry: crate::objects::Symmetry,
}

/// An outline placed in the world: loops of (x, y) millimetres.
type Outlines = Vec<Vec<[f64; 2]>>;

/// The probability of the posterior's position ellipses and θ range in the fit figure.
pub const ELLIPSE_P: f64 = 0.9;

/// The fit figure's chart: world x and y in millimetres.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Each posterior mode's position ellipse as a closed polygon in millimetres, with the mode's weight.
type Ellipses = Vec<(Vec<(f64, f64)>, f64)>;

/// The colour of the posterior (its ellipses and θ range).
const POSTERIOR_RGB: RGBColor = RGBColor(0, 170, 190);

impl Draw for FitFigure<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        s: f64,
    ) -> Result<(), crate::io::figure::DrawError> {
        let poses = [
            (self.truth, RGBColor(120, 120, 120), "true pose"),
            (self.baseline, RED, "threshold baseline"),
            (self.single, BLUE, "single-sample estimate"),
            (self.multi, RGBColor(0, 150, 60), "multi-sample estimate"),
        ];
        let placed: Vec<_> = poses
            .iter()
            .filter_map(|(p, c, l)| p.map(|p| (placed_mm(self.outline, &p), *c, *l)))
            .collect();
        let contacts = millimetres(self.contacts);
        let samples = millimetres(self.samples);
        let ellipses = self.ellipses_mm();
        let theta_range = self.theta_range();
        let all = placed
            .iter()
            .flat_map(|(loops, _, _)| loops.iter().flatten().map(|p| (p[0], p[1])))
            .chain(
                theta_range
                    .iter()
                    .flat_map(|(_, sides)| sides.iter().flatten().flatten().map(|p| (p[0], p[1]))),
            )
            .chain(contacts.iter().copied())
            .chain(samples.iter().copied())
            .chain(ellipses.iter().flat_map(|(e, _)| e.iter().copied()));
        let stroke = (2.0 * s).round().max(1.0) as u32;
        let mut chart = fit_chart(root, self.object, bounds(all), s)?;
        draw_axes(&mut chart, "x, world frame [mm]", "y [mm]", s)?;
        draw_points(&mut chart, &contacts, &samples, s, stroke)?;
        draw_ellipses(&mut chart, &ellipses, s, stroke)?;
        if let Some((half, sides)) = &theta_range {
            draw_theta_range(&mut chart, *half, sides, stroke)?;
        }
        draw_outlines(&mut chart, placed, stroke)?;
        draw_legend(&mut chart, s)?;
        Ok(())
    }
}

impl FitFigure<'_> {
    /// The posterior modes' [`ELLIPSE_P`] position ellipses, closed, in millimetres (none without a posterior).
    fn ellipses_mm(&self) -> Ellipses {
        self.posterior
            .map(|p| {
                p.modes
                    .iter()
                    .map(|m| {
                        let mut e: Vec<(f64, f64)> = m
                            .ellipse_xy(ELLIPSE_P, 64)
                            .iter()
                            .map(|[x, y]| (x * 1e3, y * 1e3))
                            .collect();
                        e.extend(e.first().copied());
                        (e, m.weight)
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    /// θ uncertainty: the half-width of the top mode's central [`ELLIPSE_P`] θ interval (its core, tail and far
    /// component; [`super::posterior::PosteriorMode::half_widths`]),
    /// with the outline placed at both extremes; `None` without a posterior or with no finite, positive range.
    fn theta_range(&self) -> Option<(f64, [Outlines; 2])> {
        self.posterior.and_then(|p| p.top()).and_then(|top| {
            let half = top.half_widths(ELLIPSE_P, &self.symmetry)[2];
            (half.is_finite() && half > 0.0).then(|| {
                let at = |sign: f64| {
                    let mean = top.pose();
                    placed_mm(
                        self.outline,
                        &Se2::new(mean.x, mean.y, mean.theta + sign * half),
                    )
                };
                (half, [at(-1.0), at(1.0)])
            })
        })
    }
}

/// Points `(x, y)` in metres as millimetres.
fn millimetres(points: &[[f64; 2]]) -> Vec<(f64, f64)> {
    points.iter().map(|[x, y]| (x * 1e3, y * 1e3)).collect()
}

/// The bounding box `(x0, x1, y0, y1)` of `points`, or ±10 (mm) on both axes when there are none.
fn bounds(points: impl Iterator<Item = (f64, f64)>) -> (f64, f64, f64, f64) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y) in points {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (-10.0, 10.0, -10.0, 10.0);
    }
    (x0, x1, y0, y1)
}

/// The chart of the figure of `object` over the box `(x0, x1, y0, y1)`, millimetres, at scale `s`: equal scales
/// on both axes (the narrower range widened to the plot's aspect), the drawing in the left 60 % of the width so
/// that the legend (top right) covers none of it.
fn fit_chart<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    object: &str,
    (x0, x1, y0, y1): (f64, f64, f64, f64),
    s: f64,
) -> Result<Chart<'a, DB>, crate::io::figure::DrawError> {
    let (w, h) = root.dim_in_pixel();
    let aspect = f64::from(w.max(1)) / f64::from(h.max(1));
    let cy = (y0 + y1) / 2.0;
    let half_h = ((y1 - y0) / 2.0).max((x1 - x0) / 0.6 / 2.0 / aspect) * 1.1 + 1.0;
    let half_w = half_h * aspect;
    let cx = x0 - 0.05 * (x1 - x0) - 1.0 + half_w;
    ChartBuilder::on(root)
        .caption(format!("SE(2) fits: {object}"), font(18.0, s))
        .margin((12.0 * s) as i32)
        .x_label_area_size((46.0 * s) as i32)
        .y_label_area_size((60.0 * s) as i32)
        .build_cartesian_2d(cx - half_w..cx + half_w, cy - half_h..cy + half_h)
        .map_err(err)
}

/// The contact points (dots) and, if any, the registered samples' positions (crosses), millimetres.
fn draw_points<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    contacts: &[(f64, f64)],
    samples: &[(f64, f64)],
    s: f64,
    stroke: u32,
) -> Result<(), crate::io::figure::DrawError> {
    let dot = (2.0 * s).max(1.0) as i32;
    chart
        .draw_series(
            contacts
                .iter()
                .map(|&p| Circle::new(p, dot, RGBColor(30, 30, 30).filled())),
        )
        .map_err(err)?
        .label(format!("contact points ({})", contacts.len()))
        .legend(move |(x, y)| Circle::new((x + 10, y), dot + 1, RGBColor(30, 30, 30).filled()));
    if !samples.is_empty() {
        let colour = RGBColor(160, 60, 200);
        chart
            .draw_series(
                samples
                    .iter()
                    .map(move |&p| Cross::new(p, dot + 2, colour.stroke_width(stroke))),
            )
            .map_err(err)?
            .label(format!("registered samples ({})", samples.len()))
            .legend(move |(x, y)| Cross::new((x + 10, y), dot + 2, colour.stroke_width(stroke)));
    }
    Ok(())
}

/// The posterior modes' position ellipses, heavier modes bolder; one legend entry for all.
fn draw_ellipses<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    ellipses: &Ellipses,
    s: f64,
    stroke: u32,
) -> Result<(), crate::io::figure::DrawError> {
    if ellipses.is_empty() {
        return Ok(());
    }
    let colour = POSTERIOR_RGB;
    let n = ellipses.len();
    for (k, (e, weight)) in ellipses.iter().enumerate() {
        // Heavier modes drawn bolder.
        let width = ((1.0 + 3.0 * weight) * s).round().max(1.0) as u32;
        let series = chart
            .draw_series(std::iter::once(PathElement::new(
                e.clone(),
                colour.stroke_width(width),
            )))
            .map_err(err)?;
        if k == 0 {
            series
                .label(format!(
                    "posterior: {:.0} % region of {n} mode{} (top weight {:.2})",
                    ELLIPSE_P * 100.0,
                    if n == 1 { "" } else { "s" },
                    weight
                ))
                .legend(swatch(colour, stroke));
        }
    }
    Ok(())
}

/// The outline at both extremes of the top mode's θ range (half-width `half`, radians), thin and faded.
fn draw_theta_range<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    half: f64,
    sides: &[Outlines; 2],
    stroke: u32,
) -> Result<(), crate::io::figure::DrawError> {
    let colour = POSTERIOR_RGB;
    let style = colour.mix(0.6).stroke_width(stroke.div_ceil(2));
    for (k, loops) in sides.iter().enumerate() {
        let series = chart
            .draw_series(loops.iter().flat_map(|l| {
                l.windows(2).map(move |w| {
                    PathElement::new(vec![(w[0][0], w[0][1]), (w[1][0], w[1][1])], style)
                })
            }))
            .map_err(err)?;
        if k == 0 {
            series
                .label(format!(
                    "{:.0} % θ range of the top mode (±{:.1}°)",
                    ELLIPSE_P * 100.0,
                    half.to_degrees()
                ))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], style));
        }
    }
    Ok(())
}

/// The object's outline at each pose of `placed` (outline, colour, label), one legend entry each.
fn draw_outlines<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    placed: Vec<(Outlines, RGBColor, &str)>,
    stroke: u32,
) -> Result<(), crate::io::figure::DrawError> {
    // Each outline edge on its own: a thick polyline's mitred joins shoot far out of the plot at the sharp
    // turns of a real mesh's outline (the bitmap backend has no miter limit).
    for (loops, colour, label) in placed {
        let style = colour.stroke_width(stroke);
        let series = chart
            .draw_series(loops.iter().flat_map(|l| {
                l.windows(2).map(move |w| {
                    PathElement::new(vec![(w[0][0], w[0][1]), (w[1][0], w[1][1])], style)
                })
            }))
            .map_err(err)?;
        series.label(label).legend(swatch(colour, stroke));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::figure::{write_figure, FigureConfig, FigureError};

    #[test]
    fn the_fit_figure_is_written_as_svg_and_png_at_the_chosen_size() {
        let dir = tempfile::tempdir().unwrap();
        let outline = vec![vec![
            [-0.01, -0.005],
            [0.01, -0.005],
            [0.01, 0.005],
            [-0.01, 0.005],
            [-0.01, -0.005],
        ]];
        let cov = [[1e-6, 0.0, 0.0], [0.0, 4e-6, 0.0], [0.0, 0.0, 1e-3]];
        let posterior = crate::pose::posterior::PosePosterior {
            modes: vec![crate::pose::posterior::PosteriorMode {
                weight: 1.0,
                mean: [0.0012, 0.0001, 0.21],
                cov,
                nats: 0.0,
                hessian: cov,
                tails: Default::default(),
            }],
            contact_px: 100,
            predicted_contact_px: None,
            noise: None,
            distinct_nats: Vec::new(),
        };
        let fig = FitFigure {
            object: "box",
            outline: &outline,
            contacts: &[[0.0, 0.0], [0.004, 0.001]],
            truth: Some(Se2::new(0.001, 0.0, 0.2)),
            single: Some(Se2::new(0.0012, 0.0001, 0.21)),
            multi: None,
            baseline: Some(Se2::new(0.002, 0.0, 0.3)),
            samples: &[[0.0011, 0.0], [0.0013, 0.0002]],
            posterior: Some(&posterior),
            symmetry: Default::default(),
        };
        let size = FigureConfig {
            width_px: 900,
            height_px: 600,
        };
        let [svg, png] = write_figure(dir.path(), "fit", &size, &fig).unwrap();
        let text = std::fs::read_to_string(svg).unwrap();
        let theta_label = format!(
            "90 % θ range of the top mode (±{:.1}°)",
            (1.644_853_6 * posterior.modes[0].cov[2][2].sqrt()).to_degrees()
        );
        for want in [
            "SE(2) fits: box",
            "x, world frame [mm]",
            "contact points (2)",
            "threshold baseline",
            "registered samples (2)",
            "posterior: 90 % region of 1 mode",
            // The θ range: ±1.645 σθ of the mode's θ variance (a Gaussian's 90 % central interval; below).
            theta_label.as_str(),
        ] {
            assert!(text.contains(want), "no '{want}' in the SVG");
        }
        assert!(
            !text.contains("multi-sample"),
            "no multi-sample estimate was given"
        );
        let img = image::open(png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (900, 600));
        // Text was rasterised with the bundled font: the title row holds dark pixels.
        let dark = (0..900)
            .filter(|&x| (0..40).any(|y| img.get_pixel(x, y).0[0] < 100))
            .count();
        assert!(dark > 20, "{dark}");
        let err = write_figure(
            dir.path(),
            "tiny",
            &FigureConfig {
                width_px: 10,
                height_px: 10,
            },
            &fig,
        );
        assert!(matches!(err, Err(FigureError::Size(10, 10))));
    }
}
