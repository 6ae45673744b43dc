//! PNG plot of the pose-error distributions of the uncertainty analysis (paper V.D, Fig. "uncertainty"): one panel
//! per error variable with the KDE curve (blue), the samples as a rug (grey ticks) and the baseline's error (red
//! line). Drawn with the `image` crate and the 8x8 font of [`crate::io::preview`].

use image::{Rgb, RgbImage};

use crate::io::preview::draw_text;

/// One panel: a variable's KDE curve `(x, density)`, its samples and the baseline's value.
pub struct Panel<'a> {
    /// Title, e.g. "position error [mm]".
    pub title: &'a str,
    /// KDE curve points `(x, density)`, ascending in x (may be empty when no KDE could be fitted).
    pub curve: &'a [(f64, f64)],
    /// The samples' values.
    pub samples: &'a [f64],
    /// The baseline's value, if any.
    pub baseline: Option<f64>,
}

const W: u32 = 320;
const H: u32 = 240;
const LEFT: u32 = 40;
const RIGHT: u32 = 12;
const TOP: u32 = 20;
const BOTTOM: u32 = 36;

fn line(img: &mut RgbImage, (x0, y0): (f64, f64), (x1, y1): (f64, f64), colour: [u8; 3]) {
    let steps = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let (x, y) = (x0 + (x1 - x0) * t, y0 + (y1 - y0) * t);
        if x >= 0.0 && y >= 0.0 && (x as u32) < img.width() && (y as u32) < img.height() {
            img.put_pixel(x as u32, y as u32, Rgb(colour));
        }
    }
}

fn panel(p: &Panel<'_>) -> RgbImage {
    let mut img = RgbImage::from_pixel(W, H, Rgb([255, 255, 255]));
    draw_text(&mut img, 4, 4, p.title, [0, 0, 0]);
    let xs = p
        .curve
        .iter()
        .map(|c| c.0)
        .chain(p.samples.iter().copied())
        .chain(p.baseline)
        .filter(|v| v.is_finite());
    let (mut lo, mut hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        (lo, hi) = (lo - 0.5, hi + 0.5);
    }
    let ymax = p.curve.iter().map(|c| c.1).fold(0.0, f64::max).max(1e-12);
    let (pw, ph) = (f64::from(W - LEFT - RIGHT), f64::from(H - TOP - BOTTOM));
    let px = |x: f64| f64::from(LEFT) + (x - lo) / (hi - lo) * pw;
    let py = |y: f64| f64::from(TOP) + ph - y / ymax * ph;
    // Axes.
    let (x_axis, y_top) = (f64::from(TOP) + ph, f64::from(TOP));
    line(
        &mut img,
        (f64::from(LEFT), x_axis),
        (f64::from(LEFT) + pw, x_axis),
        [0, 0, 0],
    );
    line(
        &mut img,
        (f64::from(LEFT), x_axis),
        (f64::from(LEFT), y_top),
        [0, 0, 0],
    );
    draw_text(
        &mut img,
        LEFT,
        H - BOTTOM + 14,
        &format!("{lo:.2}"),
        [0, 0, 0],
    );
    let hi_label = format!("{hi:.2}");
    draw_text(
        &mut img,
        W - RIGHT - 8 * hi_label.len() as u32,
        H - BOTTOM + 14,
        &hi_label,
        [0, 0, 0],
    );
    draw_text(&mut img, 2, TOP, "pdf", [0, 0, 0]);
    for w in p.curve.windows(2) {
        line(
            &mut img,
            (px(w[0].0), py(w[0].1)),
            (px(w[1].0), py(w[1].1)),
            [20, 60, 200],
        );
    }
    for &s in p.samples {
        line(
            &mut img,
            (px(s), x_axis + 2.0),
            (px(s), x_axis + 9.0),
            [110, 110, 110],
        );
    }
    if let Some(b) = p.baseline {
        line(&mut img, (px(b), x_axis), (px(b), y_top), [210, 30, 30]);
        draw_text(&mut img, W - RIGHT - 8 * 8, TOP, "baseline", [210, 30, 30]);
    }
    img
}

/// Panels side by side.
pub fn plot(panels: &[Panel<'_>]) -> RgbImage {
    let mut out = RgbImage::from_pixel(W * panels.len().max(1) as u32, H, Rgb([255, 255, 255]));
    for (i, p) in panels.iter().enumerate() {
        image::imageops::overlay(&mut out, &panel(p), i64::from(W) * i as i64, 0);
    }
    out
}
