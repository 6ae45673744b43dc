//! **Pose from in-contact depth** (paper IV.C): an in-contact depth image X̂0 is back-projected into contact points,
//! the undeformed membrane gives free-space points, and the object is registered to both ([`register_depth`]).
//!
//! The **multi-sample estimate**: the diffusion model draws many plausible X̂0 for one signature (the paper's 50 for
//! the uncertainty KDE). Where the imprint says little, single samples paint familiar contact shapes in different
//! places; their per-pixel agreement ([`contact_probability`]) separates what the imprint supports from what one
//! sample invented. [`consensus_depth`] keeps the pixels that at least half of the samples mark as contact, at the
//! median of their depths, and is registered like a single sample.

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
