//! Publication figures: drawn once with plotters onto both an SVG (vector, text as text) and a high-resolution PNG
//! (rasterised with the bundled DejaVu Sans, so a figure looks the same on every machine), written atomically side by
//! side. The figures themselves live with their stage ([`crate::uncertainty::figure`] for the KDE plots,
//! [`crate::pose::figure`] for the SE(2) fit view).

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use super::write_atomic;

/// The font every figure uses (registered with plotters once).
pub const FONT: &str = "DejaVu Sans";
static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-subset.ttf");
static REGISTER: Once = Once::new();

/// Size of an exported figure.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FigureConfig {
    /// Width of the PNG, pixels (the SVG has the same width in its own units).
    pub width_px: u32,
    /// Height of the PNG, pixels.
    pub height_px: u32,
}

impl Default for FigureConfig {
    /// 2400 x 1000 px: 8 x 3.3 inches at 300 dpi.
    fn default() -> Self {
        Self {
            width_px: 2400,
            height_px: 1000,
        }
    }
}

impl FigureConfig {
    /// Text and line sizes scale with the figure: 1 at 800 px wide.
    pub fn scale(&self) -> f64 {
        f64::from(self.width_px) / 800.0
    }
}

/// Errors drawing or writing a figure.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    #[error("{}: cannot draw the figure: {source}", path.display())]
    Draw {
        path: PathBuf,
        #[source]
        source: DrawError,
    },
    #[error("{}: cannot write: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("figure size {0}x{1} px is outside 64..=20000")]
    Size(u32, u32),
}

/// A figure that can draw itself on any plotters backend.
pub trait Draw {
    /// Draw onto `root`; `scale` (1 at 800 px wide) sizes text and lines.
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        scale: f64,
    ) -> Result<(), DrawError>;
}

/// A figure that could not be drawn: plotters' error as text (its error type is generic over the backend, so it is
/// not kept as a source).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct DrawError(pub String);

/// A plotters error as a [`DrawError`].
pub fn err<E: std::fmt::Display>(e: E) -> DrawError {
    DrawError(e.to_string())
}

/// A font of `size` (at scale 1) in the figures' typeface.
pub fn font(size: f64, scale: f64) -> FontDesc<'static> {
    (FONT, size * scale).into_font()
}

/// The figures' axes over metric ranges: labels with units, a light grid.
pub fn draw_axes<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    x_desc: &str,
    y_desc: &str,
    scale: f64,
) -> Result<(), DrawError> {
    // As many tick labels as fit side by side without touching (a label such as "-2.5" is ~3 em wide).
    let (w, h) = chart.plotting_area().dim_in_pixel();
    let fit = |px: u32, per: f64| ((f64::from(px) / (per * scale)) as usize).clamp(2, 12);
    chart
        .configure_mesh()
        .x_labels(fit(w, 45.0))
        .y_labels(fit(h, 30.0))
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(font(13.0, scale))
        .axis_desc_style(font(15.0, scale))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(210, 210, 210))
        .draw()
        .map_err(err)
}

/// The figures' legend: upper right, over a light background.
pub fn draw_legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    scale: f64,
) -> Result<(), DrawError> {
    draw_legend_at(chart, scale, SeriesLabelPosition::UpperRight)
}

/// [`draw_legend`] at `position`.
pub fn draw_legend_at<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    scale: f64,
    position: SeriesLabelPosition,
) -> Result<(), DrawError> {
    chart
        .configure_series_labels()
        .label_font(font(13.0, scale))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .position(position)
        .draw()
        .map_err(err)
}

/// A legend entry's swatch: a short line in `colour`.
pub fn swatch(colour: RGBColor, stroke: u32) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(stroke))
}

/// Draw `figure` onto `<stem>.svg` and `<stem>.png` in `dir` at `config`'s size; returns both paths.
pub fn write_figure(
    dir: &Path,
    stem: &str,
    config: &FigureConfig,
    figure: &impl Draw,
) -> Result<[PathBuf; 2], FigureError> {
    let (w, h) = (config.width_px, config.height_px);
    if !((64..=20_000).contains(&w) && (64..=20_000).contains(&h)) {
        return Err(FigureError::Size(w, h));
    }
    REGISTER.call_once(|| {
        // The bundled font is valid (the tests draw with it); a failure would only mean plain fallback text.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES);
    });
    let svg_path = dir.join(format!("{stem}.svg"));
    let png_path = dir.join(format!("{stem}.png"));
    let fail = |path: &Path, source: DrawError| FigureError::Draw {
        path: path.to_path_buf(),
        source,
    };
    let scale = config.scale();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&svg_path, err(e)))?;
        figure.draw(&root, scale).map_err(|m| fail(&svg_path, m))?;
        root.present().map_err(|e| fail(&svg_path, err(e)))?;
    }
    let mut rgb = vec![255u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&png_path, err(e)))?;
        figure.draw(&root, scale).map_err(|m| fail(&png_path, m))?;
        root.present().map_err(|e| fail(&png_path, err(e)))?;
    }
    let img = image::RgbImage::from_raw(w, h, rgb)
        .ok_or_else(|| fail(&png_path, DrawError("image buffer size".into())))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| fail(&png_path, err(e)))?;
    std::fs::create_dir_all(dir).map_err(|source| FigureError::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    for (path, bytes) in [(&svg_path, svg.as_bytes()), (&png_path, png.as_slice())] {
        write_atomic(path, bytes).map_err(|source| FigureError::Write {
            path: path.clone(),
            source,
        })?;
    }
    Ok([svg_path, png_path])
}

/// A grid of depth images with a title and a colour bar each (metres shown in mm; JET colour map as the previews),
/// e.g. an imprint with the mean, spread and samples of its de-rendering.
pub struct ImageGrid<'a> {
    pub title: String,
    /// The images with their titles, ranges and units ([`super::preview::PanelStyle`]; `scale` is ignored).
    pub panels: Vec<(&'a crate::image::Image, super::preview::PanelStyle)>,
    /// Panels per row.
    pub columns: usize,
}

impl Draw for ImageGrid<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        s: f64,
    ) -> Result<(), DrawError> {
        let area = root.titled(&self.title, font(20.0, s)).map_err(err)?;
        let columns = self.columns.clamp(1, self.panels.len().max(1));
        let rows = self.panels.len().div_ceil(columns).max(1);
        let cells = area.split_evenly((rows, columns));
        for (cell, (image, style)) in cells.iter().zip(&self.panels) {
            grid_panel(cell, image, style, s)?;
        }
        Ok(())
    }
}

fn grid_panel<DB: DrawingBackend>(
    cell: &DrawingArea<DB, Shift>,
    image: &crate::image::Image,
    style: &super::preview::PanelStyle,
    s: f64,
) -> Result<(), DrawError> {
    let inner = cell
        .margin(
            (6.0 * s) as i32,
            (6.0 * s) as i32,
            (6.0 * s) as i32,
            (6.0 * s) as i32,
        )
        .titled(&style.title, font(13.0, s))
        .map_err(err)?;
    let (w, _) = inner.dim_in_pixel();
    let bar_w = ((70.0 * s) as u32).min(w / 3);
    let (picture, bar) = inner.split_horizontally(w - bar_w);
    let range = super::preview::display_range(image, style);
    // The image, nearest-neighbour upscaled to the largest size that keeps its aspect.
    let (pw, ph) = picture.dim_in_pixel();
    let k =
        (f64::from(pw) / image.width.max(1) as f64).min(f64::from(ph) / image.height.max(1) as f64);
    let (sw, sh) = (
        ((image.width as f64 * k) as u32).max(1),
        ((image.height as f64 * k) as u32).max(1),
    );
    let colours = super::preview::colorize(image, range, style.zero_is_missing);
    let scaled = image::imageops::resize(&colours, sw, sh, image::imageops::FilterType::Nearest);
    let element =
        BitMapElement::<(i32, i32)>::with_owned_buffer((0, 0), (sw, sh), scaled.into_raw())
            .ok_or_else(|| DrawError("image buffer size".into()))?;
    picture.draw(&element).map_err(err)?;
    let bar = bar.shrink((0, 0), (bar_w, sh));
    // The colour bar with its axis.
    let (lo, hi) = if style.millimetres {
        (f64::from(range.0) * 1e3, f64::from(range.1) * 1e3)
    } else {
        (f64::from(range.0), f64::from(range.1))
    };
    let hi = if hi > lo { hi } else { lo + 1.0 };
    let mut chart = ChartBuilder::on(&bar)
        .margin_right((4.0 * s) as i32)
        .y_label_area_size((44.0 * s) as i32)
        .build_cartesian_2d(0.0..1.0, lo..hi)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .disable_x_axis()
        .disable_y_mesh()
        .y_desc(if style.millimetres { "mm" } else { "" })
        .y_labels(5)
        .label_style(font(11.0, s))
        .axis_desc_style(font(12.0, s))
        .draw()
        .map_err(err)?;
    let steps = 64;
    chart
        .draw_series((0..steps).map(|i| {
            let t = i as f64 / steps as f64;
            let [r, g, b] = super::preview::jet((t + 0.5 / steps as f64) as f32);
            Rectangle::new(
                [
                    (0.0, lo + (hi - lo) * t),
                    (1.0, lo + (hi - lo) * (t + 1.0 / steps as f64)),
                ],
                RGBColor(r, g, b).filled(),
            )
        }))
        .map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;
    use crate::io::preview::PanelStyle;

    #[test]
    fn image_grids_embed_each_image_once_with_titles_and_colour_bars() {
        let dir = tempfile::tempdir().unwrap();
        let ramp =
            Image::from_vec(8, 4, (0..32).map(|i| 0.07 + i as f32 * 1e-3).collect()).unwrap();
        let holes = Image::from_vec(
            8,
            4,
            (0..32)
                .map(|i| if i % 3 == 0 { 0.0 } else { 0.08 })
                .collect(),
        )
        .unwrap();
        let style = |title: &str| PanelStyle {
            title: title.into(),
            zero_is_missing: true,
            ..PanelStyle::default()
        };
        let grid = ImageGrid {
            title: "two images".into(),
            panels: vec![(&ramp, style("ramp")), (&holes, style("with holes"))],
            columns: 2,
        };
        let size = FigureConfig {
            width_px: 1000,
            height_px: 400,
        };
        let [svg, png] = write_figure(dir.path(), "grid", &size, &grid).unwrap();
        let text = std::fs::read_to_string(svg).unwrap();
        for want in ["two images", "ramp", "with holes", "mm"] {
            assert!(text.contains(want), "no '{want}' in the SVG");
        }
        // One embedded PNG per image, not a rectangle per pixel.
        assert_eq!(text.matches("<image").count(), 2);
        assert!(text.len() < 200_000, "{} bytes", text.len());
        let img = image::open(png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (1000, 400));
    }
}
