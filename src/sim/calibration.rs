//! **Inflation calibration** of the elastomer model (paper IV.A: the membrane is a parametric dome whose inflation
//! height is the free parameter to match a real sensor). With the sensor held where it is, the inflation height is
//! swept over a range; each value is scored by the simulated contact area and, when a measured imprint is available,
//! by the intersection-over-union between the simulated contact mask M and the measured imprint's thresholded region
//! `{Y > threshold}`. The object depth D does not depend on the membrane, so it is rendered once per sweep.

use serde::{Deserialize, Serialize};

use super::{PreparedObject, SimConfig, SimError, Simulator};
use crate::image::Image;
use crate::sensor::{Intrinsics, Scene};

/// Errors of an inflation sweep; each says what to change.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    #[error(
        "inflation sweep {lo} .. {hi} m in {steps} steps: need 0 < lo <= hi and at least 1 step"
    )]
    BadRange { lo: f64, hi: f64, steps: usize },
    #[error(
        "inflation calibration needs the parametric membrane; the elastomer is the mesh file {0}"
    )]
    MeshElastomer(String),
    #[error(
        "measured imprint is {measured_w}x{measured_h} but the simulation renders {sim_w}x{sim_h}; \
         set the sensor resolution to the imprint's size"
    )]
    SizeMismatch {
        measured_w: usize,
        measured_h: usize,
        sim_w: usize,
        sim_h: usize,
    },
    #[error("inflation sweep cancelled")]
    Cancelled,
    #[error(transparent)]
    Sim(#[from] SimError),
}

/// A measured imprint Y (metres) and the threshold (metres) above which a pixel counts as "in contact".
#[derive(Clone, Copy, Debug)]
pub struct MeasuredImprint<'a> {
    pub imprint: &'a Image,
    pub threshold: f64,
}

/// One inflation value of a sweep.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SweepPoint {
    /// Inflation height of the membrane, metres.
    pub inflation: f64,
    /// Number of contact pixels in M.
    pub contact_pixels: usize,
    /// Contact area, m²: the sum over contact pixels of the pixel's footprint `D² / (fx fy)` on a plane facing the
    /// camera at the pixel's depth.
    pub contact_area_m2: f64,
    /// IoU of M with the measured imprint's thresholded region (`None` without a measurement, or when both are
    /// empty).
    pub iou: Option<f64>,
}

/// `steps` inflation values evenly spaced over `[lo, hi]` metres (just `lo` when `steps == 1`).
pub fn inflation_values(lo: f64, hi: f64, steps: usize) -> Result<Vec<f64>, CalibrationError> {
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= lo && steps >= 1) {
        return Err(CalibrationError::BadRange { lo, hi, steps });
    }
    if steps == 1 {
        return Ok(vec![lo]);
    }
    Ok((0..steps)
        .map(|i| lo + (hi - lo) * i as f64 / (steps - 1) as f64)
        .collect())
}

/// Contact area in m² of an in-contact depth image X0 (zeros outside contact): see [`SweepPoint::contact_area_m2`].
pub fn contact_area(target: &Image, intrinsics: &Intrinsics) -> f64 {
    target
        .data
        .iter()
        .filter(|&&d| d > 0.0 && d.is_finite())
        .map(|&d| f64::from(d).powi(2) / (intrinsics.fx * intrinsics.fy))
        .sum()
}

/// The region `{imprint > threshold}` as a 0/1 mask.
pub fn threshold_region(imprint: &Image, threshold: f64) -> Image {
    Image {
        width: imprint.width,
        height: imprint.height,
        data: imprint
            .data
            .iter()
            .map(|&y| if f64::from(y) > threshold { 1.0 } else { 0.0 })
            .collect(),
    }
}

/// Intersection over union of the non-zero pixels of two same-sized masks; `None` when both are empty or the sizes
/// differ.
pub fn iou(a: &Image, b: &Image) -> Option<f64> {
    if (a.width, a.height) != (b.width, b.height) {
        return None;
    }
    let (mut inter, mut union) = (0usize, 0usize);
    for (&x, &y) in a.data.iter().zip(&b.data) {
        let (x, y) = (x != 0.0, y != 0.0);
        inter += usize::from(x && y);
        union += usize::from(x || y);
    }
    (union > 0).then(|| inter as f64 / union as f64)
}

/// Sweep the membrane's inflation over `inflations` (metres) for `object` at `scene` (the sensor pose is held fixed),
/// starting from `base`. `progress(done, total)` is called after each value; returning `false` cancels.
pub fn sweep_inflation(
    base: &SimConfig,
    object: &PreparedObject,
    scene: &Scene,
    inflations: &[f64],
    measured: Option<MeasuredImprint<'_>>,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<Vec<SweepPoint>, CalibrationError> {
    if let Some(path) = &base.elastomer.mesh_file {
        return Err(CalibrationError::MeshElastomer(path.display().to_string()));
    }
    let first = Simulator::new(base.clone())?;
    let depth = first.render_depth(object, scene);
    let region = match measured {
        Some(m) => {
            if (m.imprint.width, m.imprint.height) != (depth.width, depth.height) {
                return Err(CalibrationError::SizeMismatch {
                    measured_w: m.imprint.width,
                    measured_h: m.imprint.height,
                    sim_w: depth.width,
                    sim_h: depth.height,
                });
            }
            Some(threshold_region(m.imprint, m.threshold))
        }
        None => None,
    };
    let mut points = Vec::with_capacity(inflations.len());
    for (i, &inflation) in inflations.iter().enumerate() {
        let mut config = base.clone();
        config.elastomer.inflation = inflation;
        let sim = Simulator::new(config)?;
        let (mask, target) = sim.contact(&depth);
        points.push(SweepPoint {
            inflation,
            contact_pixels: mask.count_nonzero(),
            contact_area_m2: contact_area(&target, sim.intrinsics()),
            iou: region.as_ref().and_then(|r| iou(&mask, r)),
        });
        if !progress(i + 1, inflations.len()) {
            return Err(CalibrationError::Cancelled);
        }
    }
    Ok(points)
}

/// The sweep point to pick: the highest IoU when the sweep has IoUs, otherwise `None` (contact area alone does not
/// define a best value).
pub fn best_by_iou(points: &[SweepPoint]) -> Option<SweepPoint> {
    points
        .iter()
        .filter(|p| p.iou.is_some())
        .max_by(|a, b| {
            a.iou
                .partial_cmp(&b.iou)
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .copied()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::shapes::extrude_z;
    use crate::sensor::{Se2, SensorPose};
    use glam::Vec2;

    /// A 100 x 100 x 20 mm slab under the sensor, whose base is fixed so that the default 30 mm dome presses 3 mm.
    fn slab_scene() -> (PreparedObject, Scene) {
        let square = [
            Vec2::new(-0.05, -0.05),
            Vec2::new(0.05, -0.05),
            Vec2::new(0.05, 0.05),
            Vec2::new(-0.05, 0.05),
        ];
        let object = PreparedObject::new(extrude_z(&square, 0.02).unwrap()).unwrap();
        let sensor = SensorPose::pressing(0.0, 0.0, 0.0, [0.0, 0.0], 0.030, 0.02, 0.003);
        let scene = Scene {
            object: Se2::default(),
            sensor,
        };
        (object, scene)
    }

    #[test]
    fn iou_of_hand_made_masks() {
        let a = Image::from_vec(4, 1, vec![1.0, 1.0, 0.0, 0.0]).unwrap();
        let b = Image::from_vec(4, 1, vec![0.0, 1.0, 1.0, 0.0]).unwrap();
        assert_eq!(iou(&a, &b), Some(1.0 / 3.0));
        assert_eq!(iou(&a, &a), Some(1.0));
        let empty = Image::filled(4, 1, 0.0);
        assert_eq!(iou(&empty, &empty), None);
        assert_eq!(iou(&a, &Image::filled(2, 2, 1.0)), None);
        let region = threshold_region(
            &Image::from_vec(3, 1, vec![0.001, 0.003, -0.01]).unwrap(),
            0.002,
        );
        assert_eq!(region.data, vec![0.0, 1.0, 0.0]);
    }

    #[test]
    fn slab_contact_matches_the_ellipse_cut_from_the_dome() {
        // The slab's top is a plane z0 = 27 mm above the (fixed) membrane base. A half-ellipsoid with semi-axes
        // a = 60, b = 40 mm and height h cuts it in an ellipse of area pi a b (1 - z0^2 / h^2), zero for h <= z0.
        let (object, scene) = slab_scene();
        let inflations = [0.020, 0.026, 0.028, 0.030, 0.033];
        let mut calls = 0;
        let points = sweep_inflation(
            &SimConfig::default(),
            &object,
            &scene,
            &inflations,
            None,
            &mut |done, total| {
                calls += 1;
                assert!(done <= total);
                true
            },
        )
        .unwrap();
        assert_eq!(calls, inflations.len());
        assert_eq!(points[0].contact_pixels, 0);
        assert_eq!(points[1].contact_pixels, 0);
        let (a, b, z0) = (0.06, 0.04, 0.027);
        for p in &points[2..] {
            let exact = std::f64::consts::PI * a * b * (1.0 - (z0 / p.inflation).powi(2));
            let rel = (p.contact_area_m2 - exact).abs() / exact;
            assert!(
                rel < 0.03,
                "h = {}: area {} vs {exact} ({rel})",
                p.inflation,
                p.contact_area_m2
            );
        }
        assert!(points
            .windows(2)
            .all(|w| w[0].contact_pixels <= w[1].contact_pixels));
    }

    #[test]
    fn iou_peaks_at_the_inflation_that_made_the_measurement() {
        let (object, scene) = slab_scene();
        let mut truth = SimConfig::default();
        truth.elastomer.inflation = 0.031;
        truth.signature.noise_std = 0.0;
        truth.signature.shadow_px = 0.0;
        let sim = Simulator::new(truth.clone()).unwrap();
        let measured = sim.simulate(&object, &scene, 0).imprint;
        let inflations = inflation_values(0.028, 0.034, 7).unwrap();
        let points = sweep_inflation(
            &truth,
            &object,
            &scene,
            &inflations,
            Some(MeasuredImprint {
                imprint: &measured,
                threshold: 1e-5,
            }),
            &mut |_, _| true,
        )
        .unwrap();
        let best = best_by_iou(&points).unwrap();
        assert!((best.inflation - 0.031).abs() < 1e-9, "{points:?}");
        assert!(best.iou.unwrap() > 0.95, "{best:?}");
    }

    #[test]
    fn bad_input_is_reported_and_cancel_stops() {
        assert!(matches!(
            inflation_values(0.03, 0.02, 5),
            Err(CalibrationError::BadRange { .. })
        ));
        assert!(inflation_values(f64::NAN, 0.02, 5).is_err());
        let (object, scene) = slab_scene();
        let wrong = Image::filled(8, 8, 0.0);
        let err = sweep_inflation(
            &SimConfig::default(),
            &object,
            &scene,
            &[0.03],
            Some(MeasuredImprint {
                imprint: &wrong,
                threshold: 0.001,
            }),
            &mut |_, _| true,
        )
        .unwrap_err();
        assert!(err.to_string().contains("8x8"), "{err}");
        let err = sweep_inflation(
            &SimConfig::default(),
            &object,
            &scene,
            &[0.03, 0.031],
            None,
            &mut |_, _| false,
        )
        .unwrap_err();
        assert!(matches!(err, CalibrationError::Cancelled));
    }
}
