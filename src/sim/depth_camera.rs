//! The **depth camera's own artefacts**, beyond the signature's Gaussian noise: what a time-of-flight camera (the
//! Soft Bubble's PMD pico flexx) does to a frame. Applied to a frame at the camera's native resolution (simulated
//! recordings, `tnd recording simulate`), so that every tool can be tried on frames that look like a real sensor's:
//!
//! - **depth-dependent noise**: σ(d) = `signature.noise_std` · (d / `noise_reference_m`)^`noise_exponent` beyond the
//!   reference depth, the signature's σ nearer (a ToF camera's return weakens with distance; exponent 0 keeps the
//!   noise constant);
//! - **missing returns**: a share of pixels at random (`dropout`) and a band at the image's edges
//!   (`edge_missing_px`, where the membrane is seen at a grazing angle and the lens vignettes);
//! - **flying pixels** where depth jumps by more than `flying_jump_m` between neighbours: the pixel lands anywhere
//!   between the two surfaces;
//! - a **fixed-pattern error**: a per-pixel offset with standard deviation `fixed_pattern_m`, the same in every frame
//!   (`fixed_pattern_seed`).
//!
//! Pixels without a return are 0; a recording writes them as its encoding marks them (0 in 16UC1, NaN in 32FC1).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::error::InvalidSetting;
use crate::image::Image;

/// The depth camera's artefacts (module docs). The default is an ideal camera: none of them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DepthCameraConfig {
    /// Exponent of the noise's growth with depth (0: constant noise, the default; 2: a time-of-flight camera).
    pub noise_exponent: f64,
    /// Depth at which the noise is `signature.noise_std`, metres (default 0.08, about the membrane's).
    pub noise_reference_m: f64,
    /// Share of pixels without a return, at random in every frame (0..0.9; default 0).
    pub dropout: f64,
    /// Width of the band at the image's edges without a return, native pixels (default 0).
    pub edge_missing_px: f64,
    /// Depth jump between neighbouring pixels above which the pixel is a flying pixel, metres (0: none, default).
    pub flying_jump_m: f64,
    /// Standard deviation of the per-pixel offset that is the same in every frame, metres (default 0).
    pub fixed_pattern_m: f64,
    /// Seed of the fixed pattern (a camera's own; default 0).
    pub fixed_pattern_seed: u64,
}

impl Default for DepthCameraConfig {
    fn default() -> Self {
        Self {
            noise_exponent: 0.0,
            noise_reference_m: 0.08,
            dropout: 0.0,
            edge_missing_px: 0.0,
            flying_jump_m: 0.0,
            fixed_pattern_m: 0.0,
            fixed_pattern_seed: 0,
        }
    }
}

impl DepthCameraConfig {
    /// A time-of-flight camera's artefacts at a plausible strength (for trying the tools on realistic frames; not
    /// measured on a particular camera): noise growing with the square of depth, 2 % random dropouts, a 2-pixel
    /// edge band without returns, flying pixels at jumps over 5 mm and a 0.3 mm fixed pattern.
    pub fn time_of_flight() -> Self {
        Self {
            noise_exponent: 2.0,
            noise_reference_m: 0.08,
            dropout: 0.02,
            edge_missing_px: 2.0,
            flying_jump_m: 0.005,
            fixed_pattern_m: 3e-4,
            fixed_pattern_seed: 0,
        }
    }

    /// This camera's artefacts at `strength` (0: an ideal camera, 1: this one): missing returns, the edge band, the
    /// fixed pattern and the noise's growth with depth scaled by it, flying pixels kept above 0; the fixed pattern
    /// from `pattern_seed` (another camera of the same kind).
    pub fn scaled(&self, strength: f64, pattern_seed: u64) -> Self {
        let s = strength.max(0.0);
        Self {
            noise_exponent: (self.noise_exponent * s).min(4.0),
            noise_reference_m: self.noise_reference_m,
            dropout: (self.dropout * s).min(0.9),
            edge_missing_px: self.edge_missing_px * s,
            flying_jump_m: if s > 0.0 { self.flying_jump_m } else { 0.0 },
            fixed_pattern_m: (self.fixed_pattern_m * s).min(0.01),
            fixed_pattern_seed: pattern_seed,
        }
    }

    /// A camera that adds nothing to the signature's noise.
    pub fn is_ideal(&self) -> bool {
        self.noise_exponent == 0.0
            && self.dropout == 0.0
            && self.edge_missing_px == 0.0
            && self.flying_jump_m == 0.0
            && self.fixed_pattern_m == 0.0
    }

    /// Every setting within its physical range; the error names the first that is not.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        let check = |name: &'static str, v: f64, ok: bool, range: &str| {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err(InvalidSetting::new(
                    name,
                    format!("{name} must be {range}, got {v}"),
                ))
            }
        };
        let e = self.noise_exponent;
        check(
            "depth_camera.noise_exponent",
            e,
            (0.0..=4.0).contains(&e),
            "in 0..=4",
        )?;
        let r = self.noise_reference_m;
        check(
            "depth_camera.noise_reference_m",
            r,
            r > 0.0 && r <= 1.0,
            "in (0, 1] metres",
        )?;
        let d = self.dropout;
        check(
            "depth_camera.dropout",
            d,
            (0.0..=0.9).contains(&d),
            "in 0..=0.9",
        )?;
        let b = self.edge_missing_px;
        check(
            "depth_camera.edge_missing_px",
            b,
            (0.0..=40.0).contains(&b),
            "in 0..=40 native pixels",
        )?;
        let f = self.flying_jump_m;
        check(
            "depth_camera.flying_jump_m",
            f,
            (0.0..=0.1).contains(&f),
            "in 0..=0.1 metres",
        )?;
        let p = self.fixed_pattern_m;
        check(
            "depth_camera.fixed_pattern_m",
            p,
            (0.0..=0.01).contains(&p),
            "in 0..=0.01 metres",
        )
    }

    /// The frame `depth` (native resolution, metres, 0 where not seen) as this camera measures it, with the
    /// signature's noise `noise_std` (metres) already on it: the extra depth-dependent noise, flying pixels, the
    /// fixed pattern and missing returns (0), from `seed` (the fixed pattern from its own seed).
    pub fn apply(&self, depth: &Image, noise_std: f64, seed: u64) -> Image {
        if self.is_ideal() {
            return depth.clone();
        }
        let (w, h) = (depth.width, depth.height);
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_DE97_CA3E_0000);
        let mut out = depth.clone();
        // Flying pixels: from the frame as rendered, so that a jump is judged between true surfaces.
        if self.flying_jump_m > 0.0 {
            let jump = self.flying_jump_m as f32;
            for v in 0..h {
                for u in 0..w {
                    let d = depth.get(u, v);
                    if d <= 0.0 {
                        continue;
                    }
                    let far = [(1isize, 0isize), (-1, 0), (0, 1), (0, -1)]
                        .iter()
                        .filter_map(|&(du, dv)| {
                            let (uu, vv) = (u as isize + du, v as isize + dv);
                            (uu >= 0 && vv >= 0 && (uu as usize) < w && (vv as usize) < h)
                                .then(|| depth.get(uu as usize, vv as usize))
                        })
                        .filter(|&n| n > 0.0 && n - d > jump)
                        .fold(0.0f32, f32::max);
                    if far > 0.0 {
                        let t: f32 = rng.random();
                        *out.get_mut(u, v) = d + t * (far - d);
                    }
                }
            }
        }
        // Noise that grows with depth: the part beyond the signature's σ.
        if self.noise_exponent > 0.0 && noise_std > 0.0 {
            for d in out.data.iter_mut().filter(|d| **d > 0.0) {
                let sigma =
                    noise_std * (f64::from(*d) / self.noise_reference_m).powf(self.noise_exponent);
                let extra = (sigma * sigma - noise_std * noise_std).max(0.0).sqrt();
                if let Ok(n) = Normal::new(0.0, extra) {
                    *d = (f64::from(*d) + n.sample(&mut rng)) as f32;
                }
            }
        }
        if self.fixed_pattern_m > 0.0 {
            let mut pattern = ChaCha8Rng::seed_from_u64(self.fixed_pattern_seed);
            if let Ok(n) = Normal::new(0.0, self.fixed_pattern_m) {
                for d in out.data.iter_mut() {
                    let offset = n.sample(&mut pattern);
                    if *d > 0.0 {
                        *d = (f64::from(*d) + offset) as f32;
                    }
                }
            }
        }
        let band = self.edge_missing_px;
        for v in 0..h {
            for u in 0..w {
                let edge = (u.min(w - 1 - u).min(v).min(h - 1 - v)) as f64;
                let drop = self.dropout > 0.0 && rng.random::<f64>() < self.dropout;
                if edge < band || drop {
                    *out.get_mut(u, v) = 0.0;
                }
            }
        }
        for d in out.data.iter_mut() {
            if !crate::image::is_measured_depth(*d) {
                *d = 0.0;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn stats(values: impl Iterator<Item = f64>) -> (f64, f64) {
        let v: Vec<f64> = values.collect();
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }

    #[test]
    fn the_ideal_camera_changes_nothing_and_settings_are_bounded() {
        let frame = Image::filled(8, 6, 0.09);
        assert_eq!(DepthCameraConfig::default().apply(&frame, 1e-3, 3), frame);
        assert!(DepthCameraConfig::default().validate().is_ok());
        let bad = DepthCameraConfig {
            dropout: 1.5,
            ..DepthCameraConfig::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("depth_camera.dropout"));
    }

    #[test]
    fn noise_grows_as_the_power_law_and_the_pattern_repeats() {
        // At twice the reference depth with exponent 2 the noise is 4 σ: the extra part is sqrt(15) σ.
        let cam = DepthCameraConfig {
            noise_exponent: 2.0,
            noise_reference_m: 0.05,
            ..DepthCameraConfig::default()
        };
        let frame = Image::filled(200, 200, 0.1);
        let out = cam.apply(&frame, 1e-3, 1);
        let (mean, sd) = stats(out.data.iter().map(|&d| f64::from(d) - 0.1));
        let expected = 15f64.sqrt() * 1e-3;
        assert!(
            (sd - expected).abs() < 0.03 * expected,
            "{sd} vs {expected}"
        );
        assert!(mean.abs() < 1e-4);
        // The fixed pattern is the same in two frames of other seeds; the random part is not.
        let cam = DepthCameraConfig {
            fixed_pattern_m: 5e-4,
            fixed_pattern_seed: 9,
            ..DepthCameraConfig::default()
        };
        let (a, b) = (cam.apply(&frame, 0.0, 1), cam.apply(&frame, 0.0, 2));
        assert_eq!(a, b);
        let (_, sd) = stats(a.data.iter().map(|&d| f64::from(d) - 0.1));
        assert!((sd - 5e-4).abs() < 0.03 * 5e-4, "{sd}");
    }

    #[test]
    fn returns_go_missing_at_random_at_the_edges_and_pixels_fly_at_jumps() {
        let cam = DepthCameraConfig {
            dropout: 0.1,
            edge_missing_px: 3.0,
            ..DepthCameraConfig::default()
        };
        let frame = Image::filled(100, 80, 0.09);
        let out = cam.apply(&frame, 0.0, 4);
        for (u, v) in [(0, 0), (2, 40), (50, 77), (97, 10)] {
            assert_eq!(out.get(u, v), 0.0, "edge ({u}, {v})");
        }
        let inner = (3..77).flat_map(|v| (3..97).map(move |u| (u, v)));
        let (n, zero) = inner.fold((0, 0), |(n, z), (u, v)| {
            (n + 1, z + usize::from(out.get(u, v) == 0.0))
        });
        let share = zero as f64 / n as f64;
        assert!((share - 0.1).abs() < 0.015, "{share}");
        // A 20 mm step: the pixels on the near side of it land between the two surfaces; the far side and the
        // flat parts stay where they were.
        let mut step = Image::filled(10, 4, 0.07);
        for v in 0..4 {
            for u in 5..10 {
                *step.get_mut(u, v) = 0.09;
            }
        }
        let cam = DepthCameraConfig {
            flying_jump_m: 0.005,
            ..DepthCameraConfig::default()
        };
        let out = cam.apply(&step, 0.0, 5);
        for v in 0..4 {
            let d = out.get(4, v);
            assert!((0.07..=0.09).contains(&d), "{d}");
            assert_eq!(out.get(3, v), 0.07);
            assert_eq!(out.get(5, v), 0.09);
        }
        assert!((0..4).any(|v| out.get(4, v) > 0.071), "no pixel flew");
    }
}
