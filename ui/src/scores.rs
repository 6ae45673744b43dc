//! Per-sample depth scores of a de-rendering run against the ground truth X0 (paper V.C, Table I), with the
//! definitions of the evaluation stage (`tactile_derender::metrics::depth`): L1 over all pixels in mm, PSNR with a
//! fixed data range of 0.1 m. SSIM comes from the evaluation module once it is in main (`None` until then).

use anyhow::{anyhow, Result};
use tactile_derender::image::Image;

/// PSNR/SSIM data range L, metres (the evaluation stage's default).
pub const DATA_RANGE_M: f64 = 0.1;

/// Scores of one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthScores {
    /// Mean |X̂0 − X0| over all pixels, mm.
    pub l1_mm: f64,
    /// 10·log10(L² / MSE), dB (+∞ when identical).
    pub psnr_db: f64,
    /// Mean SSIM, when the evaluation module provides it.
    pub ssim: Option<f64>,
}

/// Score `generated` against `truth` (same size, metres).
pub fn depth_scores(generated: &Image, truth: &Image) -> Result<DepthScores> {
    if (generated.width, generated.height) != (truth.width, truth.height) {
        return Err(anyhow!(
            "sample is {}x{} but the ground truth is {}x{}",
            generated.width,
            generated.height,
            truth.width,
            truth.height
        ));
    }
    let (mut abs, mut sq) = (0.0f64, 0.0f64);
    for (&g, &t) in generated.data.iter().zip(&truth.data) {
        let e = (f64::from(g) - f64::from(t)).abs();
        abs += e;
        sq += e * e;
    }
    let n = generated.data.len().max(1) as f64;
    let mse = sq / n;
    Ok(DepthScores {
        l1_mm: abs / n * 1e3,
        psnr_db: if mse > 0.0 {
            10.0 * (DATA_RANGE_M * DATA_RANGE_M / mse).log10()
        } else {
            f64::INFINITY
        },
        ssim: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_l1_and_psnr() {
        // 64 of 256 pixels off by 2 mm.
        let truth = Image::filled(16, 16, 0.08);
        let mut g = truth.clone();
        for v in g.data.iter_mut().take(64) {
            *v += 0.002;
        }
        let s = depth_scores(&g, &truth).unwrap();
        assert!((s.l1_mm - 0.5).abs() < 1e-4, "{}", s.l1_mm);
        let mse = 64.0 * 4e-6 / 256.0;
        assert!((s.psnr_db - 10.0 * (0.01f64 / mse).log10()).abs() < 1e-3);
        assert!(depth_scores(&truth, &truth).unwrap().psnr_db.is_infinite());
        assert!(depth_scores(&Image::filled(8, 16, 0.0), &truth).is_err());
    }
}
