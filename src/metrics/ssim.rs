//! **SSIM** (Wang et al. 2004) exactly as scikit-image's
//! `structural_similarity(x, y, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=L)`:
//!
//! * local statistics are Gaussian-filtered with σ = 1.5, truncated at 3.5σ (an 11-tap window), with
//!   `scipy.ndimage`'s `reflect` boundary (`d c b a | a b c d | d c b a`), separably along rows then columns;
//! * `μx = G*x`, `μy = G*y`, `σx² = G*(x²) − μx²`, `σy² = G*(y²) − μy²`, `σxy = G*(xy) − μxμy` (population
//!   covariance);
//! * `S = (2μxμy + C1)(2σxy + C2) / ((μx² + μy² + C1)(σx² + σy² + C2))`, `C1 = (0.01 L)²`, `C2 = (0.03 L)²`;
//! * the result is the mean of S after cropping `(win − 1) / 2 = 5` pixels from every border.
//!
//! Computed in f64.

use serde::{Deserialize, Serialize};

use super::{check_same_size, MetricsError};
use crate::image::Image;

/// SSIM parameters (defaults: the Wang 2004 / scikit-image values).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SsimConfig {
    /// Gaussian σ, pixels (default 1.5).
    pub sigma: f64,
    /// Window truncation in σ (scipy's default 4.0 is overridden by scikit-image with 3.5; default 3.5).
    pub truncate: f64,
    /// K1 (default 0.01).
    pub k1: f64,
    /// K2 (default 0.03).
    pub k2: f64,
}

impl Default for SsimConfig {
    fn default() -> Self {
        Self {
            sigma: 1.5,
            truncate: 3.5,
            k1: 0.01,
            k2: 0.03,
        }
    }
}

/// Normalised 1-D Gaussian taps of radius `int(truncate * sigma + 0.5)` (scipy's `_gaussian_kernel1d`).
fn gaussian_taps(sigma: f64, truncate: f64) -> Vec<f64> {
    let radius = (truncate * sigma + 0.5) as i64;
    let w: Vec<f64> = (-radius..=radius)
        .map(|x| (-0.5 * (x * x) as f64 / (sigma * sigma)).exp())
        .collect();
    let sum: f64 = w.iter().sum();
    w.into_iter().map(|x| x / sum).collect()
}

/// scipy `reflect` index for `i` in a length-`n` axis.
fn reflect(mut i: i64, n: i64) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * n;
    i = i.rem_euclid(period);
    if i >= n {
        i = period - 1 - i;
    }
    i as usize
}

/// Separable correlation of a `w x h` row-major image with `taps` along x then y.
fn filter(img: &[f64], w: usize, h: usize, taps: &[f64]) -> Vec<f64> {
    let r = (taps.len() / 2) as i64;
    let mut tmp = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            tmp[y * w + x] = taps
                .iter()
                .enumerate()
                .map(|(k, t)| t * img[y * w + reflect(x as i64 + k as i64 - r, w as i64)])
                .sum();
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            out[y * w + x] = taps
                .iter()
                .enumerate()
                .map(|(k, t)| t * tmp[reflect(y as i64 + k as i64 - r, h as i64) * w + x])
                .sum();
        }
    }
    out
}

/// Mean SSIM of `a` and `b` over data range `data_range` (same units as the images; see the module docs).
pub fn ssim(
    a: &Image,
    b: &Image,
    data_range: f64,
    config: &SsimConfig,
) -> Result<f64, MetricsError> {
    check_same_size(a, b)?;
    if !(data_range.is_finite() && data_range > 0.0) {
        return Err(MetricsError::DataRange(data_range));
    }
    let taps = gaussian_taps(config.sigma, config.truncate);
    let win = taps.len();
    let (w, h) = (a.width, a.height);
    if w < win || h < win {
        return Err(MetricsError::TooSmall { need: win, w, h });
    }
    let x: Vec<f64> = a.data.iter().map(|&v| f64::from(v)).collect();
    let y: Vec<f64> = b.data.iter().map(|&v| f64::from(v)).collect();
    let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
    let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
    let xy: Vec<f64> = x.iter().zip(&y).map(|(p, q)| p * q).collect();
    let [ux, uy, uxx, uyy, uxy] = [&x, &y, &xx, &yy, &xy].map(|i| filter(i, w, h, &taps));
    let c1 = (config.k1 * data_range).powi(2);
    let c2 = (config.k2 * data_range).powi(2);
    let pad = (win - 1) / 2;
    let mut sum = 0.0;
    let mut count = 0usize;
    for row in pad..h - pad {
        for col in pad..w - pad {
            let i = row * w + col;
            let (mx, my) = (ux[i], uy[i]);
            let vx = uxx[i] - mx * mx;
            let vy = uyy[i] - my * my;
            let vxy = uxy[i] - mx * my;
            let s = ((2.0 * mx * my + c1) * (2.0 * vxy + c2))
                / ((mx * mx + my * my + c1) * (vx + vy + c2));
            sum += s;
            count += 1;
        }
    }
    Ok(sum / count as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_images_have_ssim_one_and_taps_match_scipy() {
        let taps = gaussian_taps(1.5, 3.5);
        assert_eq!(taps.len(), 11);
        assert!((taps.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // scipy.ndimage._gaussian_kernel1d(1.5, 0, 5)[5] = 0.26601...
        assert!((taps[5] - 0.266_011_724).abs() < 1e-6, "{}", taps[5]);
        let img =
            Image::from_vec(16, 12, (0..192).map(|i| (i % 7) as f32 * 0.01).collect()).unwrap();
        assert!((ssim(&img, &img, 0.1, &SsimConfig::default()).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(reflect(-1, 5), 0);
        assert_eq!(reflect(-2, 5), 1);
        assert_eq!(reflect(5, 5), 4);
        assert_eq!(reflect(6, 5), 3);
        let small = Image::filled(8, 8, 0.0);
        assert!(matches!(
            ssim(&small, &small, 1.0, &SsimConfig::default()),
            Err(MetricsError::TooSmall { .. })
        ));
    }
}
