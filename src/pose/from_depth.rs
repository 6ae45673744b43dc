//! **Pose from in-contact depth** (paper IV.C): an in-contact depth image X̂0 is back-projected into contact points,
//! the undeformed membrane gives free-space points, and the object is registered to both ([`register_depth`]).
//!
//! The **multi-sample estimate**: the diffusion model draws many plausible X̂0 for one signature (the paper's 50 for
//! the uncertainty KDE). Where the imprint says little, single samples paint familiar contact shapes in different
//! places; their per-pixel agreement ([`contact_probability`]) separates what the imprint supports from what one
//! sample invented. [`consensus_depth`] keeps the pixels that at least half of the samples mark as contact, at the
//! median of their depths, and is registered like a single sample.
//!
//! [`anchor_to_signature`] removes a common depth offset between a generated X̂0 and the measured signature
//! (membrane inflation drift) before registration.

use glam::DAffine3;

use super::{register, Hypothesis, InitStrategy, PoseError, RegistrationProblem, SdfRegistration};
use crate::image::Image;
use crate::recon::{back_project, free_space_points, FreeSpaceConfig};
use crate::sensor::Intrinsics;

/// What the sensor saw besides the contact: its camera and the undeformed membrane.
#[derive(Clone, Copy, Debug)]
pub struct SensorView<'a> {
    pub intrinsics: &'a Intrinsics,
    /// E: depth of the undeformed membrane, metres (0 where not seen): free-space evidence.
    pub membrane: &'a Image,
    /// `t_world_camera` of the sensor camera.
    pub t_world_camera: &'a DAffine3,
}

/// Register the object to an in-contact depth image `x0` (metres, 0 = no contact): every hypothesis, best first;
/// `None` when `x0` has no contact pixel.
pub fn register_depth(
    registration: &SdfRegistration,
    x0: &Image,
    view: &SensorView<'_>,
    free_space: &FreeSpaceConfig,
    strategy: &InitStrategy,
    seed: u64,
) -> Result<Option<Vec<Hypothesis>>, PoseError> {
    if (x0.width, x0.height) != (view.membrane.width, view.membrane.height) {
        return Err(PoseError::Config(format!(
            "the in-contact depth is {}x{} pixels, the sensor's membrane image {}x{}",
            x0.width, x0.height, view.membrane.width, view.membrane.height
        )));
    }
    let surface = back_project(x0, view.intrinsics, view.t_world_camera).p_world;
    if surface.is_empty() {
        return Ok(None);
    }
    let free = free_space_points(
        x0,
        view.membrane,
        view.intrinsics,
        view.t_world_camera,
        free_space,
        seed,
    );
    let problem = RegistrationProblem {
        surface: &surface,
        free: &free,
    };
    register(registration, &problem, strategy).map(Some)
}

/// The largest depth shift [`anchor_to_signature`] applies, metres: a bubble's inflation drifts by a few
/// millimetres; a larger disagreement is a wrong contact, not an offset.
pub const MAX_ANCHOR_SHIFT_M: f64 = 0.005;

/// Pixels of a generated contact count for [`anchor_to_signature`] only where the imprint is at least this deep,
/// metres (1.5 σ of the sensor noise, σ = 1.38 mm): there the sensor itself says contact. Where a sample painted
/// contact the imprint does not support, the signature is the membrane or its shadow, not the contact depth.
pub const ANCHOR_MIN_IMPRINT_M: f32 = 0.002;

/// Fewer such pixels than this and [`anchor_to_signature`] leaves the estimate as it is.
pub const ANCHOR_MIN_PIXELS: usize = 100;

/// Offsets smaller than this (metres) are left alone by [`anchor_to_signature`]: within the model's own depth error,
/// not a drift.
pub const ANCHOR_MIN_SHIFT_M: f64 = 0.001;

/// **Depth anchoring.** On a true contact the signature S *is* the in-contact depth (plus sensor noise), so a
/// generated X̂0 whose contact depths sit off S by a common offset — the model learnt the nominal membrane, and the
/// real bubble's inflation has drifted, so every contact depth is off by the drift — is shifted by the median of
/// `S − X̂0` over its contact pixels where S is valid and the imprint Y is at least [`ANCHOR_MIN_IMPRINT_M`] deep
/// (clamped to ±[`MAX_ANCHOR_SHIFT_M`]; no shift with fewer than [`ANCHOR_MIN_PIXELS`] such pixels or a median
/// under [`ANCHOR_MIN_SHIFT_M`]). The registration, an SE(2) fit with no height freedom, otherwise trades that
/// offset for a lateral error. Returns the shifted image and the shift (metres).
pub fn anchor_to_signature(
    x0: &Image,
    signature: &Image,
    imprint: &Image,
) -> Result<(Image, f64), PoseError> {
    for (what, other) in [("signature", signature), ("imprint", imprint)] {
        if (x0.width, x0.height) != (other.width, other.height) {
            return Err(PoseError::Config(format!(
                "the in-contact depth is {}x{} pixels, the {what} {}x{}",
                x0.width, x0.height, other.width, other.height
            )));
        }
    }
    let mut diffs: Vec<f32> = x0
        .data
        .iter()
        .zip(&signature.data)
        .zip(&imprint.data)
        .filter(|&((&d, &s), &y)| {
            d > 0.0 && s.is_finite() && s > 0.0 && y.is_finite() && y >= ANCHOR_MIN_IMPRINT_M
        })
        .map(|((&d, &s), _)| s - d)
        .collect();
    if diffs.len() < ANCHOR_MIN_PIXELS {
        return Ok((x0.clone(), 0.0));
    }
    diffs.sort_by(f32::total_cmp);
    let mid = diffs.len() / 2;
    let median = if diffs.len() % 2 == 1 {
        f64::from(diffs[mid])
    } else {
        0.5 * (f64::from(diffs[mid - 1]) + f64::from(diffs[mid]))
    };
    if median.abs() < ANCHOR_MIN_SHIFT_M {
        return Ok((x0.clone(), 0.0));
    }
    let shift = median.clamp(-MAX_ANCHOR_SHIFT_M, MAX_ANCHOR_SHIFT_M);
    Ok((shift_contact(x0, shift), shift))
}

/// `x0` with every contact depth moved by `shift` metres (kept positive: still contact); background stays 0.
pub fn shift_contact(x0: &Image, shift: f64) -> Image {
    let mut out = x0.clone();
    for d in out.data.iter_mut().filter(|d| **d > 0.0) {
        *d = (f64::from(*d) + shift).max(f64::from(f32::MIN_POSITIVE)) as f32;
    }
    out
}

/// Check that `samples` is non-empty, same-sized and finite.
fn check_samples(samples: &[Image]) -> Result<(usize, usize), PoseError> {
    let first = samples.first().ok_or_else(|| {
        PoseError::Config("the multi-sample estimate needs at least one sample".into())
    })?;
    let size = (first.width, first.height);
    for (i, s) in samples.iter().enumerate() {
        if (s.width, s.height) != size || s.data.len() != size.0 * size.1 {
            return Err(PoseError::Config(format!(
                "sample {i} is {}x{}, sample 0 is {}x{}",
                s.width, s.height, size.0, size.1
            )));
        }
        if let Some(index) = s.data.iter().position(|v| !v.is_finite()) {
            return Err(PoseError::NonFinite {
                what: "an in-contact depth sample",
                index,
            });
        }
    }
    Ok(size)
}

/// Per-pixel contact probability: the fraction of `samples` with contact (depth > 0) at each pixel, in [0, 1].
pub fn contact_probability(samples: &[Image]) -> Result<Image, PoseError> {
    let (w, h) = check_samples(samples)?;
    let n = samples.len() as f32;
    let data = (0..w * h)
        .map(|i| samples.iter().filter(|s| s.data[i] > 0.0).count() as f32 / n)
        .collect();
    Image::from_vec(w, h, data).ok_or_else(|| PoseError::Config("internal: image size".into()))
}

/// The consensus in-contact depth of `samples`: pixels that at least `min_probability` of the samples mark as
/// contact, at the median of those samples' depths there (the lower middle value for an even count); 0 elsewhere.
pub fn consensus_depth(samples: &[Image], min_probability: f64) -> Result<Image, PoseError> {
    if !(min_probability.is_finite() && min_probability > 0.0 && min_probability <= 1.0) {
        return Err(PoseError::Config(format!(
            "the consensus contact probability {min_probability} must be in (0, 1]"
        )));
    }
    let (w, h) = check_samples(samples)?;
    let need = (min_probability * samples.len() as f64).ceil().max(1.0) as usize;
    let mut depths = Vec::with_capacity(samples.len());
    let data = (0..w * h)
        .map(|i| {
            depths.clear();
            depths.extend(samples.iter().map(|s| s.data[i]).filter(|&d| d > 0.0));
            if depths.len() < need {
                return 0.0;
            }
            depths.sort_by(f32::total_cmp);
            depths[(depths.len() - 1) / 2]
        })
        .collect();
    Image::from_vec(w, h, data).ok_or_else(|| PoseError::Config("internal: image size".into()))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn img(data: &[f32]) -> Image {
        Image::from_vec(data.len(), 1, data.to_vec()).unwrap()
    }

    #[test]
    fn anchoring_moves_contact_depths_by_the_median_offset_to_the_signature() {
        // Contact pixels at 0.080 m; the signature reads 2 mm deeper on them, except two rim pixels in the
        // shadow (+9 mm) and an invalid reading; a painted contact pixel without imprint (+20 mm) does not count;
        // the last pixel is background.
        let n = ANCHOR_MIN_PIXELS + 6;
        let mut x0 = vec![0.080f32; n];
        x0[n - 1] = 0.0;
        let mut s = vec![0.082f32; n];
        (s[0], s[1], s[2], s[n - 2], s[n - 1]) = (0.089, 0.089, f32::NAN, 0.100, 0.09);
        let mut y = vec![0.004f32; n];
        (y[n - 2], y[n - 1]) = (0.0005, 0.0);
        let (x0, s, y) = (img(&x0), img(&s), img(&y));
        let (out, shift) = anchor_to_signature(&x0, &s, &y).unwrap();
        // Counted: pixels 0, 1 (+9 mm) and 3..n - 2 (+2 mm): median 2 mm.
        assert!((shift - 0.002).abs() < 1e-6, "{shift}");
        for &d in &out.data[..n - 1] {
            assert!((d - 0.082).abs() < 1e-6, "{d}");
        }
        assert_eq!(out.data[n - 1], 0.0, "background stays no-contact");
        // A disagreement beyond a drift is clamped.
        let far = img(&vec![0.090; n]);
        let (_, shift) = anchor_to_signature(&x0, &far, &y).unwrap();
        assert_eq!(shift, MAX_ANCHOR_SHIFT_M);
        // An offset within the model's own depth error (0.5 mm) is left alone.
        let near = img(&vec![0.0805; n]);
        let (same, shift) = anchor_to_signature(&x0, &near, &y).unwrap();
        assert_eq!((same.data, shift), (x0.data.clone(), 0.0));
        // Too few pixels where the imprint says contact: no shift.
        let mut shallow = vec![0.001f32; n];
        shallow[..ANCHOR_MIN_PIXELS - 1].fill(0.004);
        let (same, shift) = anchor_to_signature(&x0, &far, &img(&shallow)).unwrap();
        assert_eq!((same.data, shift), (x0.data.clone(), 0.0));
        assert!(anchor_to_signature(&x0, &img(&[0.08]), &y).is_err());
        assert!(anchor_to_signature(&x0, &s, &img(&[0.08])).is_err());
    }

    #[test]
    fn probability_and_consensus_follow_the_majority() {
        let samples = [
            img(&[0.08, 0.0, 0.081, 0.0]),
            img(&[0.082, 0.0, 0.0, 0.0]),
            img(&[0.081, 0.09, 0.083, 0.0]),
        ];
        let p = contact_probability(&samples).unwrap();
        assert_eq!(p.data, vec![1.0, 1.0 / 3.0, 2.0 / 3.0, 0.0]);
        let c = consensus_depth(&samples, 0.5).unwrap();
        // Pixel 0: median of 0.080, 0.081, 0.082; pixel 1: one vote of three; pixel 2: lower middle of two.
        assert_eq!(c.data, vec![0.081, 0.0, 0.081, 0.0]);
        let all = consensus_depth(&samples, 1.0).unwrap();
        assert_eq!(all.data, vec![0.081, 0.0, 0.0, 0.0]);
        // One sample: the consensus is the sample.
        assert_eq!(consensus_depth(&samples[..1], 0.5).unwrap(), samples[0]);
    }

    #[test]
    fn bad_samples_are_errors() {
        assert!(contact_probability(&[]).is_err());
        assert!(consensus_depth(&[img(&[0.1]), img(&[0.1, 0.2])], 0.5).is_err());
        assert!(consensus_depth(&[img(&[f32::NAN])], 0.5).is_err());
        assert!(consensus_depth(&[img(&[0.1])], 0.0).is_err());
    }
}
