//! **Shadow-width calibration**: the tactile-shadow cloak (paper V.A) is the one part of the sensor model that the
//! no-contact frames cannot show. Contact frames whose object pose is known (a recording's pose topic or pose CSV)
//! can: at each frame's press (given, or estimated as the import does), the simulator's noise-free imprint with a
//! cloak of `w` native pixels is compared with the measured one (mean absolute difference over the image), and the
//! width that explains the frames best is kept — a coarse sweep over 0–48 px in 2 px steps, then 0.5 px steps
//! around its best.

use serde::{Deserialize, Serialize};

use super::import_recording::estimate_press;
use crate::image::Image;
use crate::sensor::{Scene, Se2};
use crate::sim::signature::{synthesize, SignatureConfig};
use crate::sim::{PreparedObject, Simulator};

/// Most contact frames a fit uses (those with the most contact).
pub const MAX_FRAMES: usize = 12;

/// A fitted shadow width.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShadowFit {
    /// The width that explains the frames best, native pixels.
    pub shadow_px: f64,
    /// The width the sensor had.
    pub given_shadow_px: f64,
    /// Mean absolute imprint difference at the fitted and at the given width, metres.
    pub residual_m: f64,
    pub given_residual_m: f64,
    /// Contact frames used.
    pub frames: usize,
}

/// One contact frame: the measured imprint (model resolution), the object's pose, and the press where known.
pub struct ContactFrame<'a> {
    pub imprint: &'a Image,
    pub pose: Se2,
    pub press: Option<f64>,
}

/// Fit the shadow width of `sim` (noise-free; its signature settings give the starting width) to `frames` of
/// `object` (at most [`MAX_FRAMES`], those with the most contact); `None` when no frame has a simulated contact.
pub fn fit_shadow(
    sim: &Simulator,
    object: &PreparedObject,
    frames: &[ContactFrame<'_>],
    max_press: f64,
) -> Option<ShadowFit> {
    let mut order: Vec<usize> = (0..frames.len()).collect();
    let contact = |f: &ContactFrame| f.imprint.data.iter().filter(|&&y| y > 0.003).count();
    order.sort_by_key(|&i| std::cmp::Reverse(contact(&frames[i])));
    // Per frame: the object depth D and contact mask M at its press (they do not depend on the cloak).
    let prepared: Vec<(Image, Image, &Image)> = order
        .iter()
        .take(MAX_FRAMES)
        .filter_map(|&i| {
            let f = &frames[i];
            let press = f
                .press
                .unwrap_or_else(|| estimate_press(sim, object, f.pose, f.imprint, max_press).0);
            let scene = Scene {
                object: f.pose,
                sensor: sim.pressing_pose(object, 0.0, 0.0, 0.0, press),
            };
            let depth = sim.render_depth(object, &scene);
            let (mask, _) = sim.contact(&depth);
            (mask.count_nonzero() > 0).then_some((depth, mask, f.imprint))
        })
        .collect();
    if prepared.is_empty() {
        return None;
    }
    let spacing = sim.intrinsics().pixel_size_in(&sim.config().camera.native);
    let cost = |width: f64| -> f64 {
        let config = SignatureConfig {
            shadow_px: width,
            noise_std: 0.0,
        };
        let mut total = 0.0;
        for (depth, mask, measured) in &prepared {
            let predicted =
                synthesize(depth, sim.nominal_depth(), mask, &config, spacing, 0).imprint;
            let (mut s, mut n) = (0.0f64, 0usize);
            for (&a, &b) in predicted.data.iter().zip(&measured.data) {
                if a.is_finite() && b.is_finite() {
                    s += f64::from((a - b).abs());
                    n += 1;
                }
            }
            total += if n == 0 { 0.0 } else { s / n as f64 };
        }
        total / prepared.len() as f64
    };
    let given = sim.config().signature.shadow_px;
    let given_residual_m = cost(given);
    let mut best = (given, given_residual_m);
    for k in 0..=24 {
        let w = 2.0 * k as f64;
        let c = cost(w);
        if c < best.1 {
            best = (w, c);
        }
    }
    let centre = best.0;
    for k in -4..=4 {
        let w = centre + 0.5 * k as f64;
        if w >= 0.0 {
            let c = cost(w);
            if c < best.1 {
                best = (w, c);
            }
        }
    }
    Some(ShadowFit {
        shadow_px: best.0,
        given_shadow_px: given,
        residual_m: best.1,
        given_residual_m,
        frames: prepared.len(),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::objects::ObjectSet;
    use crate::sim::SimConfig;

    #[test]
    fn the_shadow_width_a_sensor_was_simulated_with_is_found_again() {
        // Independent truth: imprints the simulator made with a 29 px cloak and noise; the fit starts from 21 px.
        let object =
            PreparedObject::new(ObjectSet::builtin().mesh("cylinder_r12").unwrap()).unwrap();
        let mut truth = SimConfig::default();
        truth.signature.shadow_px = 29.0;
        let made = Simulator::new(truth).unwrap();
        let poses = [Se2::new(0.003, -0.002, 0.5), Se2::new(-0.004, 0.001, 1.9)];
        let imprints: Vec<Image> = poses
            .iter()
            .enumerate()
            .map(|(k, &pose)| {
                let scene = Scene {
                    object: pose,
                    sensor: made.pressing_pose(&object, 0.0, 0.0, 0.0, 0.006),
                };
                made.simulate(&object, &scene, k as u64).imprint
            })
            .collect();
        let frames: Vec<ContactFrame> = imprints
            .iter()
            .zip(poses)
            .map(|(imprint, pose)| ContactFrame {
                imprint,
                pose,
                press: None,
            })
            .collect();
        let mut quiet = SimConfig::default();
        quiet.signature.noise_std = 0.0;
        let sim = Simulator::new(quiet).unwrap();
        let fit = fit_shadow(&sim, &object, &frames, 0.03).unwrap();
        assert!((fit.shadow_px - 29.0).abs() <= 2.0, "{fit:?}");
        assert!(fit.residual_m < fit.given_residual_m, "{fit:?}");
        assert_eq!((fit.frames, fit.given_shadow_px), (2, 21.0));
    }
}
