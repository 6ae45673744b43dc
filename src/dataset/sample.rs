//! **Random contacts** for synthetic pairs (paper V.A): the object's SE(2) pose relative to the sensor, the press
//! depth, and the rejection rule for draws with too little contact.
//!
//! The sensor sits at world `x = y = 0`, yaw 0, pressing its membrane apex `press` below the object's top
//! ([`Simulator::pressing_pose`]). The object's origin (its top point, for the library's objects) is placed uniformly
//! in the camera's view at the height of the apex, shrunk about the view's centre by `offset_fraction`, with `θ`
//! uniform in `[0, 2π)` and the press uniform in `press_range`. A draw is rejected and the pose and press redrawn
//! (the object stays) while fewer than `min_contact_fraction` of the pixels are in contact.
//!
//! Each attempt draws, from the pair's stream after its object: `u, v` (position in the view box), `θ`, `press`, and
//! the signature's noise seed — so the pair seed reproduces the pair exactly.

use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::shard::Record;
use super::split::{pair_stream, ObjectDraw, PlannedPair};
use super::{DatasetError, GenConfig};
use crate::sensor::{Scene, Se2};
use crate::sim::{signature, PreparedObject, Simulator};

/// The part of the world plane under the sensor where object positions are drawn: a box in world x/y, metres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OffsetBox {
    /// World x range, metres.
    pub x: [f64; 2],
    /// World y range, metres.
    pub y: [f64; 2],
}

impl OffsetBox {
    /// The camera's view at the apex height (the rays through the image's outer pixel edges), shrunk about its
    /// centre by `fraction`, in the world frame of a sensor at `x = y = 0`, yaw 0.
    pub fn new(sim: &Simulator, fraction: f64) -> Self {
        let k = sim.intrinsics();
        let t_sensor_camera = sim.t_sensor_camera();
        let origin = t_sensor_camera.translation;
        let apex_z = sim.apex_height();
        let corners = [
            (-0.5, -0.5),
            (k.width as f64 - 0.5, -0.5),
            (-0.5, k.height as f64 - 0.5),
            (k.width as f64 - 0.5, k.height as f64 - 0.5),
        ];
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for (u, v) in corners {
            let dir = t_sensor_camera.transform_vector3(k.ray_dir(u, v));
            let t = if dir.z.abs() > 1e-12 {
                (apex_z - origin.z) / dir.z
            } else {
                0.0
            };
            let p_sensor = origin + dir * t;
            lo = lo.min(p_sensor);
            hi = hi.max(p_sensor);
        }
        // World = sensor rotated by pi about x at yaw 0: x_w = x_s, y_w = -y_s.
        let shrink = |a: f64, b: f64| {
            let (c, h) = (0.5 * (a + b), 0.5 * (b - a) * fraction);
            [c - h, c + h]
        };
        let x = shrink(lo.x, hi.x);
        let ys = shrink(lo.y, hi.y);
        Self {
            x,
            y: [-ys[1], -ys[0]],
        }
    }
}

/// Draws contacts for planned pairs.
pub struct Sampler<'a> {
    /// The sensor; with an inflation or sensor variation, one per level ([`GenConfig::inflation`],
    /// [`GenConfig::sensor_variation`]).
    pub sims: &'a [Simulator],
    pub objects: &'a [PreparedObject],
    pub names: &'a [String],
    /// How pairs draw their object (the same draw the plan used).
    pub draw: &'a ObjectDraw,
    pub config: &'a GenConfig,
    /// Where object positions are drawn, per simulator.
    pub offsets: Vec<OffsetBox>,
    pub min_pixels: usize,
    /// Per simulator, its depth camera's pass where it has one ([`super::camera_pass`]; empty: every camera ideal).
    pub cameras: &'a [Option<super::camera_pass::CameraPass>],
}

impl<'a> Sampler<'a> {
    /// `sims`: the sensor, or one per inflation level of `config.inflation` (at least one).
    pub fn new(
        sims: &'a [Simulator],
        objects: &'a [PreparedObject],
        names: &'a [String],
        draw: &'a ObjectDraw,
        config: &'a GenConfig,
    ) -> Self {
        let (w, h) = sims
            .first()
            .map_or((1, 1), |s| s.config().camera.resolution);
        Self {
            sims,
            objects,
            names,
            draw,
            config,
            offsets: sims
                .iter()
                .map(|s| OffsetBox::new(s, config.offset_fraction))
                .collect(),
            min_pixels: config.min_contact_pixels(w, h),
            cameras: &[],
        }
    }

    /// The same, each simulator's pair seen through its depth camera's pass where it has one (`cameras[k]` for
    /// `sims[k]`).
    pub fn with_cameras(mut self, cameras: &'a [Option<super::camera_pass::CameraPass>]) -> Self {
        self.cameras = cameras;
        self
    }

    /// Simulate the planned pair, redrawing pose and press until the contact is large enough: the record and the
    /// number of draws it took (1 = the first draw was accepted).
    pub fn sample(&self, plan: &PlannedPair) -> Result<(Record, usize), DatasetError> {
        let (mut rng, object_index) = pair_stream(plan.seed, self.draw);
        let object = self
            .objects
            .get(object_index)
            .ok_or_else(|| DatasetError::Config("the object set is empty".into()))?;
        let level = match (&self.config.inflation, &self.config.sensor_variation) {
            (Some(v), _) => v.level(plan.seed),
            (None, Some(v)) => v.level(plan.seed),
            (None, None) => 0,
        }
        .min(self.sims.len().saturating_sub(1));
        let (sim, b) = match (self.sims.get(level), self.offsets.get(level)) {
            (Some(s), Some(b)) => (s, b),
            _ => {
                return Err(DatasetError::Config(
                    "no simulator for the pair's sensor".into(),
                ))
            }
        };
        let sim_cfg = sim.config();
        let spacing = sim.intrinsics().pixel_size_in(&sim_cfg.camera.native);
        for attempt in 1..=self.config.max_attempts {
            let d = draw_contact(&mut rng, sim, b, object, self.config.press_range);
            if d.contact_pixels < self.min_pixels {
                continue;
            }
            let sig = match self.cameras.get(level).and_then(Option::as_ref) {
                Some(camera) => {
                    let scene = Scene {
                        object: d.pose,
                        sensor: d.sensor,
                    };
                    let m = camera.measure(object, &scene, d.noise_seed);
                    signature::Signature {
                        signature: m.signature,
                        reference: m.reference,
                        imprint: m.imprint,
                    }
                }
                None => signature::synthesize(
                    &d.depth,
                    sim.nominal_depth(),
                    &d.mask,
                    &sim_cfg.signature,
                    spacing,
                    d.noise_seed,
                ),
            };
            let record = Record {
                index: plan.index,
                seed: plan.seed,
                object: object_index,
                split: plan.split,
                pose: d.pose,
                sensor: d.sensor,
                press: d.press,
                contact_pixels: d.contact_pixels,
                imprint: sig.imprint,
                target: d.target,
                signature: sig.signature,
                reference: sig.reference,
                mask: d.mask,
            };
            return Ok((record, attempt));
        }
        Err(DatasetError::NoContact {
            index: plan.index,
            object: self.names.get(object_index).cloned().unwrap_or_default(),
            min_pixels: self.min_pixels,
            attempts: self.config.max_attempts,
        })
    }

    /// Whether object `object_index` makes a contact of at least the minimum size in any of `max_attempts` draws of
    /// position, θ and press (the pairs' distribution, on the first simulator, from a stream seeded with `seed`).
    /// Objects that cannot (a 2 mm screw, a needle tip at the top) are left out of a dataset's object draw up front,
    /// instead of failing the run at the first pair that draws them.
    pub fn can_contact(&self, object_index: usize, seed: u64) -> bool {
        let (Some(object), Some(sim), Some(b)) = (
            self.objects.get(object_index),
            self.sims.first(),
            self.offsets.first(),
        ) else {
            return false;
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..self.config.max_attempts).any(|_| {
            draw_contact(&mut rng, sim, b, object, self.config.press_range).contact_pixels
                >= self.min_pixels
        })
    }
}

/// One draw of a contact: the object's pose, the press and the signature's noise seed, rendered.
struct Contact {
    pose: Se2,
    sensor: crate::sensor::SensorPose,
    press: f64,
    noise_seed: u64,
    depth: crate::image::Image,
    mask: crate::image::Image,
    target: crate::image::Image,
    contact_pixels: usize,
}

/// Draw `u, v` (position in `b`), `θ`, press and noise seed from `rng`, in that order, and render the contact.
fn draw_contact(
    rng: &mut ChaCha8Rng,
    sim: &Simulator,
    b: &OffsetBox,
    object: &PreparedObject,
    [p0, p1]: [f64; 2],
) -> Contact {
    let u: f64 = rng.random();
    let v: f64 = rng.random();
    let theta = rng.random::<f64>() * std::f64::consts::TAU;
    let press = p0 + (p1 - p0) * rng.random::<f64>();
    let noise_seed: u64 = rng.random();
    let pose = Se2::new(
        b.x[0] + (b.x[1] - b.x[0]) * u,
        b.y[0] + (b.y[1] - b.y[0]) * v,
        theta,
    );
    let sensor = sim.pressing_pose(object, 0.0, 0.0, 0.0, press);
    let scene = Scene {
        object: pose,
        sensor,
    };
    let depth = sim.render_depth(object, &scene);
    let (mask, target) = sim.contact(&depth);
    let contact_pixels = mask.count_nonzero();
    Contact {
        pose,
        sensor,
        press,
        noise_seed,
        depth,
        mask,
        target,
        contact_pixels,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::sensor::SensorPose;
    use crate::sim::SimConfig;

    #[test]
    fn offset_box_at_full_fraction_projects_onto_the_image_edges() {
        let sim = Simulator::new(SimConfig::default()).unwrap();
        let k = *sim.intrinsics();
        let sensor = SensorPose::default(); // x = y = 0, yaw 0, looking down
        let t_camera_world = sim.t_world_camera(&sensor).inverse();
        // The apex plane in the world: sensor z = apex height, i.e. world z = position.z - apex height.
        let z = sensor.position[2] - sim.apex_height();
        let b = OffsetBox::new(&sim, 1.0);
        let project = |x: f64, y: f64| {
            k.project(t_camera_world.transform_point3(DVec3::new(x, y, z)))
                .unwrap()
        };
        let (w, h) = (k.width as f64, k.height as f64);
        let corners = [
            (b.x[0], b.y[0]),
            (b.x[1], b.y[0]),
            (b.x[0], b.y[1]),
            (b.x[1], b.y[1]),
        ];
        for (x, y) in corners {
            let (u, v, _) = project(x, y);
            let on_edge = |p: f64, n: f64| (p + 0.5).abs() < 1e-6 || (p - (n - 0.5)).abs() < 1e-6;
            assert!(
                on_edge(u, w) && on_edge(v, h),
                "corner ({x}, {y}) -> ({u}, {v})"
            );
        }
        // Shrinking keeps the centre and scales the extent.
        let s = OffsetBox::new(&sim, 0.4);
        for (a, c) in [(s.x, b.x), (s.y, b.y)] {
            assert!(((a[0] + a[1]) - (c[0] + c[1])).abs() < 1e-12);
            assert!(((a[1] - a[0]) - 0.4 * (c[1] - c[0])).abs() < 1e-12);
        }
    }
}
