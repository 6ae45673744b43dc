//! The **reliability figure** of `tnd posterior --figures DIR` ([`super::coverage::reliability`]), as forecasters
//! draw it: the share of pairs whose truth lies inside the posterior's region of each level against the level (a
//! calibrated posterior lies on the diagonal; above it is too wide, below it overconfident), one line per contact-size
//! bin; and sharpness: the median σ of the top mode (filled) and the median half-width of its central 68 % interval
//! (open: the spread read as a Gaussian's ±σ, which heavy tails set apart from the standard deviation) against the
//! median error of the estimate, position in mm and θ in degrees, with the lines σ = error and σ = 3 × error (a
//! useful posterior is calibrated *and* near the first).

use plotters::coord::Shift;
use plotters::prelude::*;

use super::coverage::Reliability;
use crate::io::figure::{draw_axes, draw_legend_at, err, font, swatch, Draw, DrawError};

/// The figure: one entry per group of pairs (e.g. "all", "<100 px"), drawn in this order.
pub struct ReliabilityFigure<'a> {
    pub title: &'a str,
    pub groups: &'a [(String, Reliability)],
}

/// Colours of the groups, in order (the first is "all": black).
const COLOURS: [RGBColor; 7] = [
    RGBColor(20, 20, 20),
    RGBColor(230, 140, 0),
    RGBColor(0, 114, 178),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(213, 94, 0),
    RGBColor(86, 180, 233),
];

impl Draw for ReliabilityFigure<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        s: f64,
    ) -> Result<(), DrawError> {
        let root = root
            .margin((8.0 * s) as u32, 0, 0, 0)
            .titled(self.title, font(18.0, s))
            .map_err(err)?;
        let panels = root.split_evenly((1, 3));
        let stroke = (2.0 * s).round().max(1.0) as u32;
        let dot = (3.0 * s).max(2.0) as i32;
        let colour = |k: usize| COLOURS[k % COLOURS.len()];
        let label = |name: &str, r: &Reliability| format!("{name} ({} pairs)", r.pairs);

        // Coverage against level.
        let mut chart = ChartBuilder::on(&panels[0])
            .caption("reliability", font(15.0, s))
            .margin((14.0 * s) as i32)
            .x_label_area_size((40.0 * s) as i32)
            .y_label_area_size((55.0 * s) as i32)
            .build_cartesian_2d(0.0..1.0, 0.0..1.0)
            .map_err(err)?;
        draw_axes(
            &mut chart,
            "region level",
            "share of pairs, truth inside",
            s,
        )?;
        chart
            .draw_series(LineSeries::new(
                [(0.0, 0.0), (1.0, 1.0)],
                RGBColor(150, 150, 150).stroke_width(stroke),
            ))
            .map_err(err)?
            .label("calibrated")
            .legend(swatch(RGBColor(150, 150, 150), stroke));
        for (k, (name, r)) in self.groups.iter().enumerate() {
            let c = colour(k);
            let points: Vec<(f64, f64)> = r
                .levels
                .iter()
                .copied()
                .zip(r.inside.iter().copied())
                .collect();
            chart
                .draw_series(LineSeries::new(points.clone(), c.stroke_width(stroke)))
                .map_err(err)?
                .label(label(name, r))
                .legend(swatch(c, stroke));
            chart
                .draw_series(points.into_iter().map(|p| Circle::new(p, dot, c.filled())))
                .map_err(err)?;
        }
        draw_legend_at(&mut chart, s, SeriesLabelPosition::UpperLeft)?;

        // Sharpness: median σ (filled) and median half-width of the central 68 % interval (open) against median
        // error, position and θ.
        // (median error, median σ, median half-width of the central 68 % interval).
        type Sharp = (f64, f64, Option<f64>);
        type Pick = fn(&Reliability) -> Option<Sharp>;
        let sharpness: [(&str, &str, &str, Pick); 2] = [
            (
                "sharpness: position (top mode)",
                "median position error [mm]",
                "median σ per axis [mm]",
                |r| {
                    Some((
                        r.median_error_position_mm,
                        r.median_sigma_position_mm,
                        r.median_half_width_position_mm,
                    ))
                },
            ),
            (
                "sharpness: θ (top mode)",
                "median θ error [deg]",
                "median σθ [deg]",
                |r| {
                    Some((
                        r.median_error_theta_deg?,
                        r.median_sigma_theta_deg?,
                        r.median_half_width_theta_deg,
                    ))
                },
            ),
        ];
        for (panel, (caption, x_desc, y_desc, pick)) in panels[1..].iter().zip(sharpness) {
            let points: Vec<(usize, Sharp)> = self
                .groups
                .iter()
                .enumerate()
                .filter_map(|(k, (_, r))| pick(r).map(|p| (k, p)))
                .filter(|(_, (x, y, _))| x.is_finite() && y.is_finite())
                .collect();
            let top = points
                .iter()
                .map(|(_, (x, y, _))| x.max(*y))
                .fold(0.0f64, f64::max)
                .max(1e-3)
                * 1.15;
            let mut chart = ChartBuilder::on(panel)
                .caption(caption, font(15.0, s))
                .margin((14.0 * s) as i32)
                .x_label_area_size((40.0 * s) as i32)
                .y_label_area_size((55.0 * s) as i32)
                .build_cartesian_2d(0.0..top, 0.0..top)
                .map_err(err)?;
            draw_axes(&mut chart, x_desc, y_desc, s)?;
            for (factor, shade, text) in [(1.0, 150u8, "σ = error"), (3.0, 200u8, "σ = 3 × error")]
            {
                let grey = RGBColor(shade, shade, shade);
                chart
                    .draw_series(LineSeries::new(
                        [(0.0, 0.0), (top / factor, top)],
                        grey.stroke_width(stroke),
                    ))
                    .map_err(err)?
                    .label(text)
                    .legend(swatch(grey, stroke));
            }
            let black = RGBColor(40, 40, 40);
            for (k, (x, y, half)) in &points {
                let c = colour(*k);
                let sd = chart
                    .draw_series(std::iter::once(Circle::new((*x, *y), dot + 2, c.filled())))
                    .map_err(err)?;
                if *k == 0 {
                    sd.label("standard deviation")
                        .legend(move |(x, y)| Circle::new((x + 6, y), dot + 2, black.filled()));
                }
                if let Some(h) = half.filter(|h| h.is_finite()) {
                    let open = chart
                        .draw_series(std::iter::once(Circle::new(
                            (*x, h.min(top)),
                            dot + 2,
                            c.stroke_width(stroke),
                        )))
                        .map_err(err)?;
                    if *k == 0 {
                        open.label("±: central 68 % interval")
                            .legend(move |(x, y)| {
                                Circle::new((x + 6, y), dot + 2, black.stroke_width(stroke))
                            });
                    }
                }
            }
            draw_legend_at(&mut chart, s, SeriesLabelPosition::LowerRight)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::figure::{write_figure, FigureConfig};

    #[test]
    fn the_figure_draws_every_group_and_skips_a_free_theta() {
        let r = |inside: f64, theta: Option<f64>| Reliability {
            pairs: 10,
            levels: vec![0.5, 0.9],
            inside: vec![inside, 0.9],
            mean_nll: -10.0,
            median_sigma_position_mm: 0.5,
            median_sigma_theta_deg: theta,
            median_core_sigma_theta_deg: theta,
            median_half_width_position_mm: Some(0.3),
            median_half_width_theta_deg: theta,
            median_error_position_mm: 0.4,
            median_error_theta_deg: theta.map(|t| t / 2.0),
        };
        let groups = vec![
            ("all".to_string(), r(0.5, Some(3.0))),
            ("<100 px".to_string(), r(0.7, None)),
        ];
        let dir = tempfile::tempdir().unwrap();
        let [svg, png] = write_figure(
            dir.path(),
            "reliability",
            &FigureConfig::default(),
            &ReliabilityFigure {
                title: "test",
                groups: &groups,
            },
        )
        .unwrap();
        let text = std::fs::read_to_string(svg).unwrap();
        // Both groups in the legend with their pair counts, and the axes say what is plotted.
        assert!(text.contains("all (10 pairs)") && text.contains("&lt;100 px (10 pairs)"));
        assert!(text.contains("region level") && text.contains("median σθ [deg]"));
        assert!(text.contains("central 68 % interval") && text.contains("standard deviation"));
        assert!(image::open(png).unwrap().width() == 2400);
    }
}
