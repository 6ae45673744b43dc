//! **Depth metrics** of a generated in-contact depth X̂0 against the true X0 (paper V.C, Table I). Both images are
//! z-depths in metres with 0 off contact.
//!
//! * `l1_mm`: mean over **all** pixels of |X̂0 − X0|, in millimetres.
//! * `l1_union_mm`: the same mean over the union of the two contact masks (pixels where either image is > 0);
//!   `None` when both are empty.
//! * `psnr_db`: 10·log10(L² / MSE), MSE over all pixels in m², L = `data_range_m`; +∞ for identical images
//!   (as scikit-image's `peak_signal_noise_ratio(x0, x0_hat, data_range=L)`).
//! * `ssim`: [`super::ssim::ssim`] with the same L.
//!
//! The data range L is fixed (default 0.1 m, the depth span [0, 100 mm] from the camera to beyond the membrane apex
//! of the default sensor, 90 mm), not taken per image, so that scores are comparable across pairs.

use serde::{Deserialize, Serialize};

use super::ssim::{ssim, SsimConfig};
use super::{check_same_size, MetricsError};
use crate::image::Image;

/// Settings of the depth metrics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DepthMetricsConfig {
    /// Data range L for PSNR and SSIM, metres (default 0.1).
    pub data_range_m: f64,
    /// SSIM window and constants.
    pub ssim: SsimConfig,
}

impl Default for DepthMetricsConfig {
    fn default() -> Self {
        Self {
            data_range_m: 0.1,
            ssim: SsimConfig::default(),
        }
    }
}

/// Depth metrics of one generated image (definitions in the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthMetrics {
    /// Mean absolute error over all pixels, mm.
    pub l1_mm: f64,
    /// Mean absolute error over the union of both contact masks, mm (`None`: both masks empty).
    pub l1_union_mm: Option<f64>,
    /// Peak signal-to-noise ratio, dB (+∞ when identical; `"inf"` in JSON).
    #[serde(with = "super::summary::json_f64")]
    pub psnr_db: f64,
    /// Structural similarity (mean SSIM).
    pub ssim: f64,
}

/// Compute [`DepthMetrics`] of `generated` against `truth`.
pub fn depth_metrics(
    generated: &Image,
    truth: &Image,
    config: &DepthMetricsConfig,
) -> Result<DepthMetrics, MetricsError> {
    check_same_size(generated, truth)?;
    let l = config.data_range_m;
    if !(l.is_finite() && l > 0.0) {
        return Err(MetricsError::DataRange(l));
    }
    let (mut abs_sum, mut sq_sum, mut union_sum, mut union_n) = (0.0, 0.0, 0.0, 0usize);
    for (&g, &t) in generated.data.iter().zip(&truth.data) {
        let e = (f64::from(g) - f64::from(t)).abs();
        abs_sum += e;
        sq_sum += e * e;
        if g > 0.0 || t > 0.0 {
            union_sum += e;
            union_n += 1;
        }
    }
    let n = generated.data.len() as f64;
    let mse = sq_sum / n;
    let psnr_db = if mse > 0.0 {
        10.0 * (l * l / mse).log10()
    } else {
        f64::INFINITY
    };
    Ok(DepthMetrics {
        l1_mm: abs_sum / n * 1e3,
        l1_union_mm: (union_n > 0).then(|| union_sum / union_n as f64 * 1e3),
        psnr_db,
        ssim: ssim(generated, truth, l, &config.ssim)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_l1_and_psnr() {
        let truth = Image::from_vec(
            16,
            16,
            (0..256).map(|i| if i < 64 { 0.08 } else { 0.0 }).collect(),
        )
        .unwrap();
        // Off by 2 mm on the 64 contact pixels, and a 4 mm false positive on 16 more.
        let mut generated = truth.clone();
        for i in 0..64 {
            generated.data[i] += 0.002;
        }
        for i in 64..80 {
            generated.data[i] = 0.004;
        }
        let m = depth_metrics(&generated, &truth, &DepthMetricsConfig::default()).unwrap();
        let l1 = (64.0 * 2.0 + 16.0 * 4.0) / 256.0;
        assert!((m.l1_mm - l1).abs() < 1e-4, "{}", m.l1_mm);
        assert!((m.l1_union_mm.unwrap() - (64.0 * 2.0 + 16.0 * 4.0) / 80.0).abs() < 1e-4);
        let mse: f64 = (64.0 * 4e-6 + 16.0 * 16e-6) / 256.0;
        assert!((m.psnr_db - 10.0 * (0.01 / mse).log10()).abs() < 1e-3);
        let same = depth_metrics(&truth, &truth, &DepthMetricsConfig::default()).unwrap();
        assert_eq!(same.l1_mm, 0.0);
        assert!(same.psnr_db.is_infinite() && (same.ssim - 1.0).abs() < 1e-12);
        // Records round-trip every value they hold, the infinite PSNR of identical images included.
        let text = serde_json::to_string(&same).unwrap();
        assert!(text.contains("\"psnr_db\":\"inf\""), "{text}");
        let back: DepthMetrics = serde_json::from_str(&text).unwrap();
        assert_eq!(back.psnr_db, f64::INFINITY);
        assert_eq!(back, same);
        let other = Image::filled(8, 16, 0.0);
        assert!(depth_metrics(&other, &truth, &DepthMetricsConfig::default()).is_err());
    }
}
