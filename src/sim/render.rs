//! Paper IV.A step 1, **object depth rendering**: the z-depth image D of the object seen by the sensor camera, by CPU
//! ray casting against the object's BVH (parallel over image rows), and the elastomer's nominal depth E (the undeformed
//! membrane seen from inside).

use glam::{DAffine3, Vec3};
use rayon::prelude::*;

use crate::image::Image;
use crate::mesh::RayCaster;
use crate::sensor::Intrinsics;

/// Rays longer than this (metres) are treated as misses.
pub const MAX_RANGE_M: f32 = 10.0;

/// Render the z-depth image of the mesh behind `caster` (vertices in its own frame, e.g. the object frame) seen by a
/// pinhole camera at `t_mesh_camera`. Misses are 0.
pub fn render_depth(
    caster: &RayCaster,
    intrinsics: &Intrinsics,
    t_mesh_camera: &DAffine3,
) -> Image {
    render_depth_where(caster, intrinsics, t_mesh_camera, |_, _| true)
}

/// [`render_depth`] at the pixels `(u, v)` where `cast(u, v)`; the others are 0 (no ray cast).
pub fn render_depth_where(
    caster: &RayCaster,
    intrinsics: &Intrinsics,
    t_mesh_camera: &DAffine3,
    cast: impl Fn(usize, usize) -> bool + Sync,
) -> Image {
    let (w, h) = (intrinsics.width, intrinsics.height);
    let mut image = Image::filled(w, h, 0.0);
    let origin = t_mesh_camera.translation.as_vec3();
    let rot = t_mesh_camera.matrix3;
    image
        .data
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(v, row)| {
            for (u, px) in row.iter_mut().enumerate() {
                if !cast(u, v) {
                    continue;
                }
                // Rigid motion keeps |dir|, and dir has unit camera z, so the ray parameter is the z-depth.
                let dir = (rot * intrinsics.ray_dir(u as f64, v as f64)).as_vec3();
                if let Some(t) = caster.cast(origin, dir, MAX_RANGE_M) {
                    *px = t;
                }
            }
        });
    image
}

/// The depth of the **far** side of a closed mesh along each camera ray: the membrane's inner surface seen by a camera
/// placed behind its base (the ray enters through the base and leaves through the dome). Cast from beyond the mesh
/// back towards the camera and keep the first hit. Misses are 0.
pub fn render_far_depth(
    caster: &RayCaster,
    intrinsics: &Intrinsics,
    t_mesh_camera: &DAffine3,
) -> Image {
    let (w, h) = (intrinsics.width, intrinsics.height);
    let origin = t_mesh_camera.translation;
    let rot = t_mesh_camera.matrix3;
    let (lo, hi) = caster.aabb();
    // Farther than any corner of the mesh from the camera: |dir| >= 1, so t_far in ray units is beyond the mesh.
    let t_far = (0..8)
        .map(|i| {
            let c = Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            (c.as_dvec3() - origin).length()
        })
        .fold(0.0, f64::max)
        * 1.01
        + 1e-3;
    let mut image = Image::filled(w, h, 0.0);
    image
        .data
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(v, row)| {
            for (u, px) in row.iter_mut().enumerate() {
                let dir = rot * intrinsics.ray_dir(u as f64, v as f64);
                let start = origin + dir * t_far;
                if let Some(s) = caster.cast(start.as_vec3(), (-dir).as_vec3(), t_far as f32) {
                    let depth = t_far - f64::from(s);
                    if depth > 0.0 {
                        *px = depth as f32;
                    }
                }
            }
        });
    image
}
