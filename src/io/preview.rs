//! PNG previews of depth images: JET colour map, a colour bar labelled in millimetres, titles, and side-by-side
//! panels. Display code is the only place where metres become millimetres.

use std::path::Path;

use font8x8::UnicodeFonts;
use image::{Rgb, RgbImage};

use crate::image::Image;

/// Matplotlib's `jet` colour map at `t` in [0, 1] (piecewise linear, clamped).
pub fn jet(t: f32) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let ch = |offset: f32| ((1.5 - (4.0 * t - offset).abs()).clamp(0.0, 1.0) * 255.0).round() as u8;
    [ch(3.0), ch(2.0), ch(1.0)]
}

/// Colour of pixels with no value (0 in a depth image when `zero_is_missing`).
pub const MISSING: [u8; 3] = [40, 40, 40];

/// How to draw one image as a panel.
#[derive(Clone, Debug)]
pub struct PanelStyle {
    /// Title above the panel.
    pub title: String,
    /// Colour range in metres; `None` for the image's own range.
    pub range_m: Option<(f32, f32)>,
    /// Treat exact zeros as "no value" (drawn grey, excluded from the automatic range).
    pub zero_is_missing: bool,
    /// Integer up-scaling factor for small images (nearest neighbour).
    pub scale: u32,
    /// Label the colour bar in millimetres (false: raw values, e.g. masks).
    pub millimetres: bool,
}

impl Default for PanelStyle {
    fn default() -> Self {
        Self {
            title: String::new(),
            range_m: None,
            zero_is_missing: true,
            scale: 4,
            millimetres: true,
        }
    }
}

/// Smallest colour span (metres) for automatic ranges: a flat surface shows as one colour, not as f32 jitter.
pub const MIN_AUTO_SPAN_M: f32 = 1e-3;

/// The colour range used for `image` under `style` (0 to [`MIN_AUTO_SPAN_M`] for an image with nothing to show, e.g.
/// no contact: a bar of 0 to 1 mm, not 0 to 1 000 mm). Automatic ranges span at
/// least [`MIN_AUTO_SPAN_M`] around their centre.
pub fn display_range(image: &Image, style: &PanelStyle) -> (f32, f32) {
    if let Some((lo, hi)) = style.range_m {
        if hi > lo {
            return (lo, hi);
        }
    }
    let (lo, hi) = image
        .range_where(|x| x.is_finite() && !(style.zero_is_missing && x == 0.0))
        .unwrap_or((0.0, MIN_AUTO_SPAN_M));
    if hi - lo >= MIN_AUTO_SPAN_M {
        (lo, hi)
    } else {
        let c = 0.5 * (lo + hi);
        (c - 0.5 * MIN_AUTO_SPAN_M, c + 0.5 * MIN_AUTO_SPAN_M)
    }
}

/// Colour the image with JET over `range` (metres); missing pixels grey.
pub fn colorize(image: &Image, range: (f32, f32), zero_is_missing: bool) -> RgbImage {
    let (lo, hi) = range;
    RgbImage::from_fn(image.width as u32, image.height as u32, |u, v| {
        let x = image.get(u as usize, v as usize);
        if !x.is_finite() || (zero_is_missing && x == 0.0) {
            Rgb(MISSING)
        } else {
            Rgb(jet((x - lo) / (hi - lo)))
        }
    })
}

const BAR_WIDTH: u32 = 12;
const LABEL_WIDTH: u32 = 8 * 7;
const TITLE_HEIGHT: u32 = 14;
const MARGIN: u32 = 4;

/// One panel: title, the up-scaled colourised image, and a colour bar with min/mid/max labels.
pub fn render_panel(image: &Image, style: &PanelStyle) -> RgbImage {
    let (lo, hi) = display_range(image, style);
    let scale = style.scale.max(1);
    let img_w = image.width as u32 * scale;
    let img_h = image.height as u32 * scale;
    let width = MARGIN + img_w + MARGIN + BAR_WIDTH + 2 + LABEL_WIDTH;
    let height = TITLE_HEIGHT + img_h + MARGIN;
    let mut out = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    draw_text(&mut out, MARGIN, 3, &style.title, [0, 0, 0]);
    let colours = colorize(image, (lo, hi), style.zero_is_missing);
    for y in 0..img_h {
        for x in 0..img_w {
            out.put_pixel(
                MARGIN + x,
                TITLE_HEIGHT + y,
                *colours.get_pixel(x / scale, y / scale),
            );
        }
    }
    let bar_x = MARGIN + img_w + MARGIN;
    for y in 0..img_h {
        let t = 1.0 - y as f32 / (img_h.max(2) - 1) as f32;
        for x in 0..BAR_WIDTH {
            out.put_pixel(bar_x + x, TITLE_HEIGHT + y, Rgb(jet(t)));
        }
    }
    let label = |v: f32| {
        if style.millimetres {
            format!("{:.1}mm", v * 1000.0)
        } else {
            format!("{v:.2}")
        }
    };
    let lx = bar_x + BAR_WIDTH + 2;
    draw_text(&mut out, lx, TITLE_HEIGHT, &label(hi), [0, 0, 0]);
    draw_text(
        &mut out,
        lx,
        TITLE_HEIGHT + img_h / 2 - 4,
        &label(0.5 * (lo + hi)),
        [0, 0, 0],
    );
    draw_text(
        &mut out,
        lx,
        TITLE_HEIGHT + img_h.saturating_sub(8),
        &label(lo),
        [0, 0, 0],
    );
    out
}

/// Panels left to right (top aligned), with optional caption lines under them.
pub fn side_by_side(panels: &[RgbImage], caption: &[String]) -> RgbImage {
    let width = panels.iter().map(|p| p.width()).sum::<u32>().max(1);
    let caption_width = caption
        .iter()
        .map(|l| l.chars().count() as u32 * 8 + 2 * MARGIN)
        .max()
        .unwrap_or(0);
    let width = width.max(caption_width);
    let panel_h = panels.iter().map(|p| p.height()).max().unwrap_or(0);
    let height = panel_h + caption.len() as u32 * 10 + MARGIN;
    let mut out = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    let mut x0 = 0;
    for p in panels {
        image::imageops::overlay(&mut out, p, i64::from(x0), 0);
        x0 += p.width();
    }
    for (i, line) in caption.iter().enumerate() {
        draw_text(&mut out, MARGIN, panel_h + i as u32 * 10, line, [0, 0, 0]);
    }
    out
}

/// Draw ASCII text with an 8x8 bitmap font; characters outside the image are clipped.
pub fn draw_text(img: &mut RgbImage, x: u32, y: u32, text: &str, colour: [u8; 3]) {
    for (i, c) in text.chars().enumerate() {
        let Some(glyph) = font8x8::BASIC_FONTS.get(c) else {
            continue;
        };
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8u32 {
                if bits & (1 << col) != 0 {
                    let px = x + i as u32 * 8 + col;
                    let py = y + row as u32;
                    if px < img.width() && py < img.height() {
                        img.put_pixel(px, py, Rgb(colour));
                    }
                }
            }
        }
    }
}

/// The text chunk every PNG tnd writes carries after its header: `Software` = `tactile-derender`, so that a command
/// knows an image it may replace ([`written_by_tnd`]).
const SOFTWARE_KEY: &[u8] = b"Software\0tactile-derender";

/// PNG signature (8 bytes) + IHDR chunk (4 length + 4 type + 13 data + 4 CRC).
const AFTER_IHDR: usize = 33;

/// Encode as PNG (marked as tnd's) and write atomically; the error names the file.
pub fn save_png(path: &Path, img: &RgbImage) -> std::io::Result<()> {
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| std::io::Error::other(format!("{}: PNG encoding failed: {e}", path.display())))?;
    let mut chunk = Vec::with_capacity(12 + SOFTWARE_KEY.len());
    chunk.extend_from_slice(&(SOFTWARE_KEY.len() as u32).to_be_bytes());
    chunk.extend_from_slice(b"tEXt");
    chunk.extend_from_slice(SOFTWARE_KEY);
    chunk.extend_from_slice(&crc32fast::hash(&chunk[4..]).to_be_bytes());
    if bytes.len() > AFTER_IHDR {
        bytes.splice(AFTER_IHDR..AFTER_IHDR, chunk);
    }
    crate::io::write_atomic(path, &bytes)
}

/// Whether `path` is a PNG tnd wrote ([`save_png`]'s text chunk right after the header).
pub fn written_by_tnd(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; AFTER_IHDR + 8 + SOFTWARE_KEY.len()];
    let Ok(()) = std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut head)) else {
        return false;
    };
    head[AFTER_IHDR + 4..].starts_with(b"tEXt") && head[AFTER_IHDR + 8..].starts_with(SOFTWARE_KEY)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_png_tnd_wrote_is_marked_and_still_decodes() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        let img = RgbImage::from_pixel(3, 2, Rgb([10, 20, 30]));
        save_png(&p, &img).unwrap();
        assert!(written_by_tnd(&p));
        let back = image::open(&p).unwrap().to_rgb8();
        assert_eq!(back, img);
        // Another encoder's PNG is not tnd's.
        img.save(dir.path().join("b.png")).unwrap();
        assert!(!written_by_tnd(&dir.path().join("b.png")));
    }

    #[test]
    fn jet_matches_matplotlib_at_key_points() {
        // matplotlib.cm.jet(0.0) = (0, 0, 0.5), jet(0.5) ~ (0.49, 1, 0.48), jet(1.0) = (0.5, 0, 0).
        assert_eq!(jet(0.0), [0, 0, 128]);
        assert_eq!(jet(1.0), [128, 0, 0]);
        let mid = jet(0.5);
        assert_eq!(mid[1], 255);
        assert!((mid[0] as i32 - 128).abs() <= 2 && (mid[2] as i32 - 128).abs() <= 2);
    }

    #[test]
    fn panel_has_expected_size_and_missing_colour() {
        let mut img = Image::filled(4, 3, 0.08);
        *img.get_mut(0, 0) = 0.0;
        let style = PanelStyle {
            scale: 2,
            ..Default::default()
        };
        let p = render_panel(&img, &style);
        assert_eq!(p.height(), TITLE_HEIGHT + 6 + MARGIN);
        assert_eq!(p.get_pixel(MARGIN, TITLE_HEIGHT).0, MISSING);
    }

    #[test]
    fn an_image_with_nothing_to_show_gets_a_millimetre_bar() {
        // No contact: every pixel of the in-contact depth is 0, which the panel treats as missing.
        let style = PanelStyle {
            zero_is_missing: true,
            ..Default::default()
        };
        assert_eq!(
            display_range(&Image::filled(4, 3, 0.0), &style),
            (0.0, MIN_AUTO_SPAN_M)
        );
        // Anything to show sets the range as before.
        let mut img = Image::filled(4, 3, 0.0);
        *img.get_mut(1, 1) = 0.08;
        *img.get_mut(2, 1) = 0.09;
        assert_eq!(display_range(&img, &style), (0.08, 0.09));
    }
}
