//! **3D reconstruction** (paper IV.C): back-projection of a generated or measured in-contact depth image X0 to a point
//! cloud with the pinhole model, in the camera frame (`p_cam`) and in the world frame (`p_world`), and the
//! **free-space evidence** used by the registration (CHSEL's free semantics): points of the undeformed membrane where
//! there is no contact, and points along every camera ray in front of what the camera sees.
//!
//! Pixels with depth 0 (background), negative or non-finite depth are dropped.

use glam::{DAffine3, DVec3};
use serde::{Deserialize, Serialize};

use crate::image::Image;
use crate::sensor::Intrinsics;

/// A back-projected point cloud: for every kept pixel its index, its camera-frame point and its world-frame point.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Row-major pixel index `v * width + u` of each point.
    pub pixels: Vec<usize>,
    /// Points in the camera frame, metres.
    pub p_cam: Vec<DVec3>,
    /// The same points in the world frame (`t_world_camera * p_cam`), metres.
    pub p_world: Vec<DVec3>,
}

impl PointCloud {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.p_cam.len()
    }

    /// True when no pixel was kept.
    pub fn is_empty(&self) -> bool {
        self.p_cam.is_empty()
    }

    /// Mean of the world-frame points; `None` when empty.
    pub fn centroid_world(&self) -> Option<DVec3> {
        (!self.is_empty())
            .then(|| self.p_world.iter().copied().sum::<DVec3>() / self.p_world.len() as f64)
    }
}

/// Whether a depth value is a valid measurement (finite and positive).
#[inline]
pub fn is_valid_depth(d: f32) -> bool {
    d.is_finite() && d > 0.0
}

/// Back-project every valid pixel of the z-depth image `depth` (metres) through `intrinsics`; world points use
/// `t_world_camera`. Pixel `(u, v)` with depth `d` gives `p_cam = d * ((u - cx) / fx, (v - cy) / fy, 1)`.
///
/// ```
/// use glam::DAffine3;
/// use tactile_derender::image::Image;
/// use tactile_derender::recon::back_project;
/// use tactile_derender::sensor::Intrinsics;
/// let k = Intrinsics { width: 2, height: 1, fx: 100.0, fy: 100.0, cx: 0.0, cy: 0.0 };
/// let depth = Image::from_vec(2, 1, vec![0.0, 0.05]).unwrap();
/// let cloud = back_project(&depth, &k, &DAffine3::from_translation([0.0, 0.0, 1.0].into()));
/// assert_eq!(cloud.pixels, vec![1]);
/// // (f32 depth: 0.05 is stored as 0.050000000745)
/// assert!((cloud.p_cam[0].x - 0.0005).abs() < 1e-9 && (cloud.p_world[0].z - 1.05).abs() < 1e-9);
/// ```
pub fn back_project(
    depth: &Image,
    intrinsics: &Intrinsics,
    t_world_camera: &DAffine3,
) -> PointCloud {
    let mut cloud = PointCloud::default();
    for (i, &d) in depth.data.iter().enumerate() {
        if !is_valid_depth(d) {
            continue;
        }
        let (u, v) = ((i % depth.width) as f64, (i / depth.width) as f64);
        let p_cam = intrinsics.back_project(u, v, f64::from(d));
        cloud.pixels.push(i);
        cloud.p_cam.push(p_cam);
        cloud.p_world.push(t_world_camera.transform_point3(p_cam));
    }
    cloud
}

/// Where free-space points are placed along each camera ray.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FreeSpaceConfig {
    /// Distances in front of the observed surface (towards the camera) at which the ray is known to be empty,
    /// metres (default 0, 2, 5 and 10 mm). On pixels without contact the observed surface is the undeformed
    /// membrane, so offset 0 is the membrane point itself; on contact pixels offset 0 is skipped (that point is on
    /// the object).
    pub offsets_m: Vec<f64>,
    /// Keep at most this many free-space points, to bound the registration cost (default 2000): every point of a
    /// pixel within `band_px` of the contact region first (there the contact's outline is decided), then a seeded
    /// random subset of the others.
    pub max_points: usize,
    /// Width of the band around the contact region whose free-space points are always kept, pixels (Chebyshev
    /// distance; default 3).
    pub band_px: usize,
}

impl Default for FreeSpaceConfig {
    fn default() -> Self {
        Self {
            offsets_m: vec![0.0, 0.002, 0.005, 0.010],
            max_points: 2000,
            band_px: 3,
        }
    }
}

/// Free-space points in the world frame. `contact_depth` is the in-contact depth X0 (0 off contact) and `membrane`
/// the undeformed membrane depth E (0 where the camera does not see it). On a pixel without contact the membrane
/// point and the ray in front of it are empty (the object would otherwise have deformed the membrane there); on a
/// contact pixel the ray in front of the contact point is empty. Subsampled to `config.max_points` with `seed`,
/// keeping the band around the contact first (see [`FreeSpaceConfig`]).
pub fn free_space_points(
    contact_depth: &Image,
    membrane: &Image,
    intrinsics: &Intrinsics,
    t_world_camera: &DAffine3,
    config: &FreeSpaceConfig,
    seed: u64,
) -> Vec<DVec3> {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let near = contact_band(contact_depth, config.band_px);
    let (mut points, mut far) = (Vec::new(), Vec::new());
    for (i, (&x0, &e)) in contact_depth.data.iter().zip(&membrane.data).enumerate() {
        let (u, v) = (
            (i % contact_depth.width) as f64,
            (i / contact_depth.width) as f64,
        );
        let (surface, on_object) = if is_valid_depth(x0) {
            (f64::from(x0), true)
        } else if is_valid_depth(e) {
            (f64::from(e), false)
        } else {
            continue;
        };
        for &offset in &config.offsets_m {
            if on_object && offset <= 0.0 {
                continue;
            }
            let d = surface - offset;
            if d > 0.0 {
                let p_world = t_world_camera.transform_point3(intrinsics.back_project(u, v, d));
                if near[i] {
                    points.push(p_world);
                } else {
                    far.push(p_world);
                }
            }
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    if points.len() > config.max_points {
        points.shuffle(&mut rng);
        points.truncate(config.max_points);
    }
    far.shuffle(&mut rng);
    far.truncate(config.max_points - points.len());
    points.extend(far);
    points
}

/// Pixels within `band` (Chebyshev distance) of a contact pixel, the contact pixels included.
fn contact_band(contact_depth: &Image, band: usize) -> Vec<bool> {
    let (w, h) = (contact_depth.width, contact_depth.height);
    let mut near = vec![false; w * h];
    for (i, &x0) in contact_depth.data.iter().enumerate() {
        if !is_valid_depth(x0) {
            continue;
        }
        let (u, v) = (i % w, i / w);
        for vv in v.saturating_sub(band)..(v + band + 1).min(h) {
            for uu in u.saturating_sub(band)..(u + band + 1).min(w) {
                near[vv * w + uu] = true;
            }
        }
    }
    near
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn back_projection_round_trips_through_the_camera() {
        let k = Intrinsics::pico_flexx()
            .cropped((20, 160), (25, 200))
            .resized(16, 16);
        let mut depth = Image::filled(16, 16, 0.0);
        *depth.get_mut(3, 5) = 0.07;
        *depth.get_mut(10, 12) = f32::NAN;
        *depth.get_mut(11, 12) = -0.01;
        let t =
            DAffine3::from_rotation_z(0.3) * DAffine3::from_translation(DVec3::new(0.1, 0.0, 0.2));
        let cloud = back_project(&depth, &k, &t);
        assert_eq!(cloud.pixels, vec![5 * 16 + 3]);
        let (u, v, d) = k.project(cloud.p_cam[0]).unwrap();
        assert!((u - 3.0).abs() < 1e-9 && (v - 5.0).abs() < 1e-9 && (d - 0.07).abs() < 1e-7);
        let back = t.inverse().transform_point3(cloud.p_world[0]);
        assert!((back - cloud.p_cam[0]).length() < 1e-12);
    }

    #[test]
    fn free_space_lies_in_front_of_the_surface() {
        let k = Intrinsics::pico_flexx()
            .cropped((20, 160), (25, 200))
            .resized(8, 8);
        let membrane = Image::filled(8, 8, 0.08);
        let mut contact = Image::filled(8, 8, 0.0);
        *contact.get_mut(4, 4) = 0.075;
        let cfg = FreeSpaceConfig {
            offsets_m: vec![0.0, 0.002],
            max_points: 10_000,
            band_px: 1,
        };
        let pts = free_space_points(&contact, &membrane, &k, &DAffine3::IDENTITY, &cfg, 0);
        // 63 membrane pixels x 2 offsets + 1 contact pixel x 1 offset.
        assert_eq!(pts.len(), 63 * 2 + 1);
        assert!(pts.iter().all(|p| p.z <= 0.08 + 1e-9));
        assert!(pts.iter().any(|p| (p.z - 0.073).abs() < 1e-7));
        let few = free_space_points(
            &contact,
            &membrane,
            &k,
            &DAffine3::IDENTITY,
            &FreeSpaceConfig {
                max_points: 17,
                ..cfg
            },
            1,
        );
        // The 8 neighbours of the contact pixel (2 points each) and the contact pixel's own point come first.
        assert_eq!(few.len(), 17);
        let centre = k.back_project(4.0, 4.0, 1.0);
        let near = |p: &DVec3| {
            let (u, v, _) = k.project(*p).unwrap();
            (u - 4.0).abs() < 1.5 && (v - 4.0).abs() < 1.5
        };
        assert!(few.iter().all(near), "{centre}");
    }
}
