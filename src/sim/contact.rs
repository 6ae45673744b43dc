//! Paper IV.A steps 2–4: **depth projection to 3D**, **signed distance** of the projected points to the elastomer, and
//! the **contact mask** M (points inside the membrane) with the **in-contact depth** X0 = M ⊙ D.

use glam::{DAffine3, Vec3};
use rayon::prelude::*;

use crate::image::Image;
use crate::mesh::SignedDistance;
use crate::sensor::Intrinsics;

/// Back-project every valid pixel of a depth image to the frame of `t_frame_camera`: `(pixel index, point)`.
/// Pixels with depth 0 or non-finite are skipped.
pub fn back_project(
    depth: &Image,
    intrinsics: &Intrinsics,
    t_frame_camera: &DAffine3,
) -> Vec<(usize, glam::DVec3)> {
    depth
        .data
        .iter()
        .enumerate()
        .filter(|(_, &d)| d > 0.0 && d.is_finite())
        .map(|(i, &d)| {
            let (u, v) = ((i % depth.width) as f64, (i / depth.width) as f64);
            let p_cam = intrinsics.back_project(u, v, f64::from(d));
            (i, t_frame_camera.transform_point3(p_cam))
        })
        .collect()
}

/// The membrane prepared for contact queries in the sensor frame.
pub struct ElastomerSdf {
    sdf: SignedDistance,
    aabb: (Vec3, Vec3),
}

impl ElastomerSdf {
    pub fn new(sdf: SignedDistance, aabb: (Vec3, Vec3)) -> Self {
        Self { sdf, aabb }
    }

    /// Signed distance (metres, negative inside) of a sensor-frame point to the membrane; points outside the
    /// membrane's bounding box return a positive lower bound without the exact query.
    pub fn distance(&self, p_sensor: Vec3) -> f32 {
        let (lo, hi) = self.aabb;
        let outside = (lo - p_sensor).max(p_sensor - hi).max(Vec3::ZERO);
        if outside != Vec3::ZERO {
            return outside.length();
        }
        self.sdf.distance(p_sensor)
    }
}

/// Contact mask M (1 where the back-projected object point is inside the membrane) and in-contact depth X0 = M ⊙ D.
pub fn contact(
    depth: &Image,
    intrinsics: &Intrinsics,
    t_sensor_camera: &DAffine3,
    elastomer: &ElastomerSdf,
) -> (Image, Image) {
    let points = back_project(depth, intrinsics, t_sensor_camera);
    let inside: Vec<usize> = points
        .par_iter()
        .filter(|(_, p)| elastomer.distance(p.as_vec3()) < 0.0)
        .map(|(i, _)| *i)
        .collect();
    let mut mask = Image::filled(depth.width, depth.height, 0.0);
    let mut target = mask.clone();
    for i in inside {
        mask.data[i] = 1.0;
        target.data[i] = depth.data[i];
    }
    (mask, target)
}
