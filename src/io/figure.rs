//! Publication figures: drawn once with plotters onto both an SVG (vector, text as text) and a high-resolution PNG
//! (rasterised with the bundled DejaVu Sans, so a figure looks the same on every machine), written atomically side by
//! side. The figures themselves live with their stage ([`crate::uncertainty::figure`] for the KDE plots,
//! [`crate::pose::figure`] for the SE(2) fit view).

use std::path::{Path, PathBuf};
use std::sync::Once;

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
    #[error("{}: cannot draw the figure: {message}", path.display())]
    Draw { path: PathBuf, message: String },
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
    ) -> Result<(), String>;
}

/// A plotters error as text.
pub fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// A font of `size` (at scale 1) in the figures' typeface.
pub fn font(size: f64, scale: f64) -> FontDesc<'static> {
    (FONT, size * scale).into_font()
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
    let fail = |path: &Path, message: String| FigureError::Draw {
        path: path.to_path_buf(),
        message,
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
        .ok_or_else(|| fail(&png_path, "image buffer size".into()))?;
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
