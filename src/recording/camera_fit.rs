//! The **depth camera's artefacts fitted to a recording's no-contact frames** ([`crate::sim::DepthCameraConfig`]):
//! what frames of a membrane touching nothing show of the camera, so that a calibrated sensor file makes simulated
//! frames (`tnd recording simulate --sensor`) that miss returns and grow noisy the way the user's camera does.
//!
//! - the **edge band without returns**: per image row and column, how many pixels from each edge never return in
//!   any frame; the median over them;
//! - **random dropouts**: of the pixels inside the band that return in some frame, the share of (pixel, frame) without
//!   a return;
//! - **noise growing with depth**: each pixel's spread over the frames against its mean depth, a least-squares line
//!   in log-log (σ ∝ d^e); the reference depth is where that line meets the overall noise `signature.noise_std`;
//! - the **fixed pattern**: the mean frame's residual against the fitted membrane less its 5 x 5 local mean (the
//!   membrane model's error is smooth, a fixed pattern is not), beyond what the noise of the mean leaves.
//!
//! Flying pixels need depth jumps, which a membrane without contact does not have: they are not fitted.

use crate::image::Image;
use crate::sim::DepthCameraConfig;

/// What the no-contact frames show of the camera (lengths in metres).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CameraFit {
    /// The fitted artefacts (flying pixels left at 0).
    pub camera: DepthCameraConfig,
    /// Pixels that never returned in any no-contact frame, of all.
    pub never_returned_px: usize,
    pub pixels: usize,
}

/// Least frames the per-pixel spreads need.
const MIN_FRAMES: usize = 3;

/// Fit the camera (module docs) to no-contact frames `frames` (native resolution, metres, 0 where no return), whose
/// mean is `mean` and membrane `fitted`, with overall noise `noise_std` (metres). `None` with fewer than
/// [`MIN_FRAMES`] frames.
pub fn fit_camera(
    frames: &[&Image],
    mean: &Image,
    fitted: &Image,
    noise_std: f64,
) -> Option<CameraFit> {
    let n = frames.len();
    let first = frames.first()?;
    if n < MIN_FRAMES {
        return None;
    }
    let (w, h) = (first.width, first.height);
    let returns: Vec<usize> = (0..w * h)
        .map(|i| frames.iter().filter(|f| f.data[i] > 0.0).count())
        .collect();
    let never = |u: usize, v: usize| returns[v * w + u] == 0;
    // Edge band: leading never-returning pixels from each edge, per row and column.
    let mut runs = Vec::with_capacity(2 * (w + h));
    for v in 0..h {
        runs.push((0..w).take_while(|&u| never(u, v)).count());
        runs.push((0..w).rev().take_while(|&u| never(u, v)).count());
    }
    for u in 0..w {
        runs.push((0..h).take_while(|&v| never(u, v)).count());
        runs.push((0..h).rev().take_while(|&v| never(u, v)).count());
    }
    runs.sort_unstable();
    let band = runs[runs.len() / 2];
    let inside = |i: usize| {
        let (u, v) = (i % w, i / w);
        u >= band && v >= band && u + band < w && v + band < h
    };
    // Dropouts among the pixels inside the band that do return.
    let (mut missed, mut chances) = (0usize, 0usize);
    for (i, &r) in returns.iter().enumerate() {
        if r > 0 && inside(i) {
            missed += n - r;
            chances += n;
        }
    }
    let dropout = if chances > 0 {
        missed as f64 / chances as f64
    } else {
        0.0
    };
    // Noise against depth: per pixel, the spread over the frames that returned.
    let mut points = Vec::new();
    for (i, &r) in returns.iter().enumerate() {
        if r < MIN_FRAMES || mean.data[i] <= 0.0 {
            continue;
        }
        let m = f64::from(mean.data[i]);
        let var = frames
            .iter()
            .map(|f| f.data[i])
            .filter(|&d| d > 0.0)
            .map(|d| (f64::from(d) - m).powi(2))
            .sum::<f64>()
            / (r - 1) as f64;
        if var > 0.0 {
            points.push((m.ln(), 0.5 * var.ln()));
        }
    }
    let (exponent, reference) = power_law(&points, noise_std);
    // Fixed pattern: the residual's part that is not smooth, beyond the mean frame's own noise.
    let residual = mean.zip_map(fitted, |m, f| if m > 0.0 && f > 0.0 { m - f } else { 0.0 });
    let smooth = super::process::box_means(&residual, 2);
    let rough: Vec<f64> = (0..w * h)
        .filter(|&i| mean.data[i] > 0.0 && fitted.data[i] > 0.0)
        .map(|i| f64::from(residual.data[i]) - smooth[i])
        .collect();
    let rough_rms = if rough.is_empty() {
        0.0
    } else {
        (rough.iter().map(|r| r * r).sum::<f64>() / rough.len() as f64).sqrt()
    };
    // Taking a 5 x 5 mean off leaves 24/25 of a per-pixel pattern's variance, and of the mean frame's noise
    // (σ² / frames): the pattern is what is left of the first beyond the second.
    let floor = noise_std / (n as f64).sqrt();
    let fixed = (rough_rms * rough_rms * 25.0 / 24.0 - floor * floor)
        .max(0.0)
        .sqrt();
    // Under a fifth of the mean frame's noise, a fixed pattern is within what the frames can tell.
    let fixed_pattern_m = if fixed > 0.2 * floor.max(1e-6) {
        fixed.min(0.01)
    } else {
        0.0
    };
    Some(CameraFit {
        camera: DepthCameraConfig {
            noise_exponent: exponent,
            noise_reference_m: reference,
            dropout: dropout.min(0.9),
            edge_missing_px: (band as f64).min(40.0),
            flying_jump_m: 0.0,
            fixed_pattern_m,
            fixed_pattern_seed: 0,
        },
        never_returned_px: returns.iter().filter(|&&r| r == 0).count(),
        pixels: w * h,
    })
}

/// Least-squares line through (ln d, ln σ): the exponent (clamped to 0..=4; 0 with too little spread of depth) and
/// the depth at which the line gives `noise_std` (metres; 0.08 when the exponent is 0).
fn power_law(points: &[(f64, f64)], noise_std: f64) -> (f64, f64) {
    let n = points.len() as f64;
    let default = (0.0, DepthCameraConfig::default().noise_reference_m);
    if points.len() < 10 || noise_std <= 0.0 {
        return default;
    }
    let (sx, sy) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), &(x, y)| (a + x, b + y));
    let (mx, my) = (sx / n, sy / n);
    let (sxx, sxy) = points.iter().fold((0.0, 0.0), |(a, b), &(x, y)| {
        (a + (x - mx).powi(2), b + (x - mx) * (y - my))
    });
    // Depths within 2 % of each other say nothing about a power law.
    if sxx / n < 0.02f64.powi(2) {
        return default;
    }
    let e = (sxy / sxx).clamp(0.0, 4.0);
    if e < 0.25 {
        return default;
    }
    // ln σ = my + e (ln d − mx) = ln noise_std  ⇒  ln d = mx + (ln noise_std − my) / e.
    let reference = (mx + (noise_std.ln() - my) / e).exp();
    (e, reference.clamp(1e-3, 1.0))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_camera_that_made_the_frames_is_found_again() {
        // A membrane whose depth runs from 60 to 100 mm across the image, seen by a camera with noise ∝ d², 3 %
        // dropouts, a 3-pixel edge band and a 0.4 mm fixed pattern; 40 frames.
        let (w, h) = (120, 90);
        let membrane = Image::from_vec(
            w,
            h,
            (0..w * h)
                .map(|i| 0.06 + 0.04 * (i % w) as f32 / (w - 1) as f32)
                .collect(),
        )
        .unwrap();
        let truth = DepthCameraConfig {
            noise_exponent: 2.0,
            noise_reference_m: 0.08,
            dropout: 0.03,
            edge_missing_px: 3.0,
            fixed_pattern_m: 4e-4,
            ..DepthCameraConfig::default()
        };
        // Each frame: the signature's 1 mm noise (as the simulator adds it), then the camera's artefacts, whose
        // noise tops it up to σ(d) = 1 mm · (d / 80 mm)² where that is more.
        let base = 1e-3;
        let frames: Vec<Image> = (0..40u64)
            .map(|k| {
                use rand::SeedableRng;
                use rand_distr::Distribution;
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(100 + k);
                let normal = rand_distr::Normal::new(0.0, base).unwrap();
                let noisy = Image {
                    data: membrane
                        .data
                        .iter()
                        .map(|&d| (f64::from(d) + normal.sample(&mut rng)) as f32)
                        .collect(),
                    ..membrane.clone()
                };
                truth.apply(&noisy, base, k)
            })
            .collect();
        let refs: Vec<&Image> = frames.iter().collect();
        let mean = crate::recording::calibrate::mean_image(&refs);
        let fit = fit_camera(&refs, &mean, &membrane, base).unwrap();
        let c = &fit.camera;
        assert_eq!(c.edge_missing_px, 3.0, "{c:?}");
        assert!((c.dropout - 0.03).abs() < 0.005, "{c:?}");
        assert!((c.fixed_pattern_m - 4e-4).abs() < 1e-4, "{c:?}");
        // Above 80 mm the frames' noise follows the power law; below it stays at the signature's σ — the fitted
        // exponent lies between 0 and 2, clearly above 0.
        assert!(c.noise_exponent > 0.5 && c.noise_exponent <= 2.2, "{c:?}");
        assert!(fit.never_returned_px >= 2 * 3 * (w + h) - 36);
    }

    #[test]
    fn a_camera_without_artefacts_fits_none() {
        let membrane = Image::filled(60, 40, 0.08);
        let frames: Vec<Image> = (0..10).map(|_| membrane.clone()).collect();
        let refs: Vec<&Image> = frames.iter().collect();
        let fit = fit_camera(&refs, &membrane, &membrane, 1e-3).unwrap();
        assert_eq!(fit.camera, DepthCameraConfig::default());
        assert!(fit_camera(&refs[..2], &membrane, &membrane, 1e-3).is_none());
    }
}
