//! Paper V.A, **synthetic tactile signature**: the depth the sensor would measure with the object pressed in (S), the
//! reference measured with nothing pressed (R), and the imprint Y = R − S (positive where the membrane is pushed in).
//! Both S and R carry independent Gaussian measurement noise (σ = 1.38 mm by default), seeded and reproducible.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::shadows::tactile_signature;
use crate::image::Image;

/// Parameters of the synthetic signature.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SignatureConfig {
    /// Width of the tactile-shadow cloak in **native sensor pixels** (the PMD's 224 x 171 grid), so that the cloak
    /// covers the same part of the membrane at every model resolution (default 21).
    pub shadow_px: f64,
    /// Standard deviation of the Gaussian depth noise on S and on R, metres (default 0.00138; 0 disables noise).
    pub noise_std: f64,
}

impl Default for SignatureConfig {
    fn default() -> Self {
        Self {
            shadow_px: 21.0,
            noise_std: 1.38e-3,
        }
    }
}

impl SignatureConfig {
    pub fn validate(&self) -> Result<(), crate::error::InvalidSetting> {
        use crate::error::InvalidSetting;
        if !(self.shadow_px.is_finite() && self.shadow_px >= 0.0) {
            return Err(InvalidSetting::new(
                "signature.shadow_px",
                format!("shadow_px must be >= 0 pixels, got {}", self.shadow_px),
            ));
        }
        if !(self.noise_std.is_finite() && self.noise_std >= 0.0) {
            return Err(InvalidSetting::new(
                "signature.noise_std",
                format!("noise_std must be >= 0 metres, got {}", self.noise_std),
            ));
        }
        Ok(())
    }
}

/// The three images of a synthetic measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct Signature {
    /// S: measured depth with the object pressed in, metres (0 where the membrane is not seen).
    pub signature: Image,
    /// R: reference depth of the undeformed membrane, metres.
    pub reference: Image,
    /// Y = R − S, metres.
    pub imprint: Image,
}

/// The imprint Y = R − S where both depths are measured (> 0); 0 where the reference R is missing (the membrane
/// not seen, or a pixel that never returns); and where R is measured but the frame S has no return there (a
/// time-of-flight camera's dropouts, steep or dark surfaces), Y filled in from the measured pixels around it
/// ([`fill_gaps`]), so that a contact reaches the model without holes. Simulated signatures, imported pairs and
/// recordings all use this rule; what is measured is S's own non-zero pixels.
pub fn imprint(reference: &Image, signature: &Image) -> Image {
    let mut y = reference.zip_map(
        signature,
        |r, s| if r > 0.0 && s > 0.0 { r - s } else { 0.0 },
    );
    let gaps: Vec<usize> = (0..y.data.len())
        .filter(|&i| reference.data[i] > 0.0 && !crate::image::is_measured_depth(signature.data[i]))
        .collect();
    if !gaps.is_empty() {
        let known: Vec<bool> = reference
            .data
            .iter()
            .zip(&signature.data)
            .map(|(&r, &s)| r > 0.0 && s > 0.0)
            .collect();
        fill_gaps(&mut y, known, gaps);
    }
    y
}

/// Fill the pixels `gaps` of `y` from the pixels `known` (row-major flags) ring by ring: each pass gives every gap
/// pixel with a known 8-neighbour the mean of those neighbours, then counts it known. Gaps no known pixel reaches
/// keep their value. Each pass looks only at the gaps beside the pixels the last one filled, so the whole fill
/// costs a few visits per pixel however far the gaps reach.
pub fn fill_gaps(y: &mut Image, mut known: Vec<bool>, gaps: Vec<usize>) {
    let (w, h) = (y.width, y.height);
    let mut is_gap = vec![false; w * h];
    for &i in &gaps {
        is_gap[i] = true;
    }
    let neighbours = move |i: usize| {
        let (u, v) = (i % w, i / w);
        (v.saturating_sub(1)..(v + 2).min(h))
            .flat_map(move |vv| (u.saturating_sub(1)..(u + 2).min(w)).map(move |uu| vv * w + uu))
    };
    // The first ring: gaps beside a known pixel.
    let mut front: Vec<usize> = gaps
        .into_iter()
        .filter(|&i| neighbours(i).any(|j| known[j]))
        .collect();
    let mut queued = vec![false; w * h];
    for &i in &front {
        queued[i] = true;
    }
    let mut filled = Vec::new();
    while !front.is_empty() {
        filled.clear();
        for &i in &front {
            let (mut sum, mut n) = (0.0f32, 0u32);
            for j in neighbours(i) {
                if known[j] {
                    sum += y.data[j];
                    n += 1;
                }
            }
            if n > 0 {
                filled.push((i, sum / n as f32));
            }
        }
        let mut next = Vec::new();
        for &(i, value) in &filled {
            y.data[i] = value;
            known[i] = true;
            is_gap[i] = false;
        }
        for &(i, _) in &filled {
            for j in neighbours(i) {
                if is_gap[j] && !queued[j] {
                    queued[j] = true;
                    next.push(j);
                }
            }
        }
        front = next;
    }
}

/// Build S, R and Y from the object depth D, the nominal elastomer depth E and the contact mask M. `spacing` is the
/// size of one image pixel in native sensor pixels (see [`crate::sensor::Intrinsics::pixel_size_in`]).
pub fn synthesize(
    depth: &Image,
    nominal: &Image,
    mask: &Image,
    config: &SignatureConfig,
    spacing: (f64, f64),
    seed: u64,
) -> Signature {
    let mut signature = if config.shadow_px > 0.0 {
        tactile_signature(depth, nominal, mask, config.shadow_px, spacing)
    } else {
        tactile_signature(depth, nominal, mask, f64::MIN_POSITIVE, spacing)
    };
    let mut reference = nominal.clone();
    if config.noise_std > 0.0 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // noise_std was validated finite and positive, so Normal::new cannot fail; fall back to no noise regardless.
        if let Ok(normal) = Normal::new(0.0f64, config.noise_std) {
            for img in [&mut signature, &mut reference] {
                for px in img.data.iter_mut() {
                    let n = normal.sample(&mut rng);
                    if *px > 0.0 {
                        *px = (f64::from(*px) + n) as f32;
                    }
                }
            }
        }
    }
    let imprint = imprint(&reference, &signature);
    Signature {
        signature,
        reference,
        imprint,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_has_the_configured_standard_deviation() {
        let (w, h) = (256, 256);
        let e = Image::filled(w, h, 0.09);
        let zero = Image::filled(w, h, 0.0);
        let s = synthesize(
            &zero,
            &e,
            &zero,
            &SignatureConfig::default(),
            (1.0, 1.0),
            42,
        );
        for img in [&s.signature, &s.reference] {
            let n = img.data.len() as f64;
            let mean = img.data.iter().map(|&x| f64::from(x) - 0.09).sum::<f64>() / n;
            let var = img
                .data
                .iter()
                .map(|&x| (f64::from(x) - 0.09 - mean).powi(2))
                .sum::<f64>()
                / (n - 1.0);
            let std = var.sqrt();
            assert!((std - 1.38e-3).abs() < 0.05 * 1.38e-3, "std {std}");
            assert!(mean.abs() < 1e-4);
        }
        // Same seed, same noise; another seed, other noise.
        let again = synthesize(
            &zero,
            &e,
            &zero,
            &SignatureConfig::default(),
            (1.0, 1.0),
            42,
        );
        assert_eq!(again, s);
        let other = synthesize(
            &zero,
            &e,
            &zero,
            &SignatureConfig::default(),
            (1.0, 1.0),
            43,
        );
        assert_ne!(other.signature, s.signature);
    }

    #[test]
    fn frame_dropouts_are_filled_from_their_neighbours_and_unseen_pixels_stay_zero() {
        // A 5 x 3 membrane at 90 mm pressed in by a plane tilted along u (imprint 1..5 mm by column); the reference
        // does not see column 4 (never returns), the frame has no return at (2, 1) and at the whole column 1.
        let r = Image::from_vec(
            5,
            3,
            (0..15)
                .map(|i| if i % 5 == 4 { 0.0 } else { 0.09 })
                .collect(),
        )
        .unwrap();
        let mut s = Image::from_vec(
            5,
            3,
            (0..15).map(|i| 0.09 - 0.001 * (1 + i % 5) as f32).collect(),
        )
        .unwrap();
        for v in 0..3 {
            *s.get_mut(1, v) = 0.0;
        }
        *s.get_mut(2, 1) = f32::NAN;
        let y = imprint(&r, &s);
        for v in 0..3 {
            assert_eq!(y.get(4, v), 0.0, "not seen by the reference");
            assert!((y.get(0, v) - 0.001).abs() < 1e-6 && (y.get(3, v) - 0.004).abs() < 1e-6);
            // Column 1 lies between columns 0 (1 mm) and 2 (3 mm): filled between them, never 0.
            assert!(
                y.get(1, v) > 0.0015 && y.get(1, v) < 0.0026,
                "{}",
                y.get(1, v)
            );
        }
        // (2, 1): the mean of its measured neighbours (columns 2 and 3, 3 and 4 mm).
        assert!(
            y.get(2, 1) > 0.002 && y.get(2, 1) < 0.004,
            "{}",
            y.get(2, 1)
        );
        // Nothing missing, nothing filled: Y = R − S exactly.
        let full = Image::filled(5, 3, 0.085);
        let plain = imprint(&Image::filled(5, 3, 0.09), &full);
        assert!(plain.data.iter().all(|&v| (v - 0.005).abs() < 1e-7));
    }
}
