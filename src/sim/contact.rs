//! Paper IV.A steps 2–4: **depth projection to 3D**, **signed distance** of the projected points to the elastomer, and
//! the **contact mask** M (points inside the membrane) with the **in-contact depth** X0 = M ⊙ D.

use glam::{DAffine3, DVec3, Vec3};
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
    /// Certain answers away from the surface for the parametric membrane (see [`DomeBounds`]).
    dome: Option<DomeBounds>,
}

impl ElastomerSdf {
    pub fn new(sdf: SignedDistance, aabb: (Vec3, Vec3)) -> Self {
        Self {
            sdf,
            aabb,
            dome: None,
        }
    }

    /// Answer [`Self::inside`] from `dome` wherever it is certain (the exact query runs only near the surface).
    pub fn with_dome(mut self, dome: Option<DomeBounds>) -> Self {
        self.dome = dome;
        self
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

    /// Whether a sensor-frame point is inside the membrane (the contact test): the same answer as
    /// `distance(p) < 0`, from the dome bounds where they are certain.
    pub fn inside(&self, p_sensor: Vec3) -> bool {
        match self.dome.and_then(|d| d.classify(p_sensor)) {
            Some(inside) => inside,
            None => self.distance(p_sensor) < 0.0,
        }
    }
}

/// Certain inside/outside answers for a convex closed membrane whose vertices lie on a half-ellipsoid (the
/// parametric membrane: semi-axes a, b, h, base at z = 0). In coordinates scaled by the semi-axes the ellipsoid is the
/// unit sphere and the mesh an inscribed convex polyhedron, so a point above the base closer to the centre than the
/// nearest face plane (`inner`) is inside, and a point below the base or beyond the unit sphere is outside; only the
/// thin shell between (about 0.1 % of the radius at the default tessellation) needs the exact signed distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DomeBounds {
    /// Semi-axes (a, b, h), metres.
    axes: DVec3,
    /// Scaled distance from the centre to the nearest dome face plane.
    inner: f64,
}

/// Slack of the certain answers in scaled units (~0.3–0.6 µm at the default membrane), far above float32 rounding of
/// the vertices.
const DOME_SLACK: f64 = 1e-5;

impl DomeBounds {
    /// Bounds for `mesh` as the half-ellipsoid with semi-axes `axes` (metres); `None` when the mesh is not that:
    /// a vertex off the ellipsoid or below the base, an open edge, or a face that is not convex towards the centre.
    pub fn new(mesh: &crate::mesh::Mesh, axes: DVec3) -> Option<Self> {
        if !(axes.min_element() > 0.0 && axes.is_finite()) {
            return None;
        }
        let q: Vec<DVec3> = mesh
            .vertices()
            .iter()
            .map(|v| v.as_dvec3() / axes)
            .collect();
        if q.iter()
            .any(|v| v.length() > 1.0 + DOME_SLACK || v.z < -DOME_SLACK)
        {
            return None;
        }
        let tris = mesh.triangles();
        let planes: Vec<(DVec3, f64)> = tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| q[i as usize]);
                let n = (b - a).cross(c - a).normalize_or_zero();
                (n, n.dot(a))
            })
            .collect();
        // Every edge is shared by exactly two faces and is convex: the third vertex of each face lies on the inner
        // side of the other's plane. With outward faces (the centre (0, 0, 0.25) inside all of them) the closed mesh
        // is then a convex polyhedron: inside it is inside every face plane.
        let centre = DVec3::new(0.0, 0.0, 0.25);
        let mut edges: std::collections::HashMap<(u32, u32), Vec<(usize, u32)>> =
            std::collections::HashMap::new();
        for (f, t) in tris.iter().enumerate() {
            if planes[f].0 == DVec3::ZERO || planes[f].0.dot(centre) >= planes[f].1 {
                return None;
            }
            for k in 0..3 {
                let (i, j) = (t[k], t[(k + 1) % 3]);
                edges
                    .entry((i.min(j), i.max(j)))
                    .or_default()
                    .push((f, t[(k + 2) % 3]));
            }
        }
        for faces in edges.values() {
            let [(f, opposite_f), (g, opposite_g)] = faces.as_slice() else {
                return None;
            };
            let convex = |face: usize, vertex: u32| {
                let (n, d) = planes[face];
                n.dot(q[vertex as usize]) <= d + DOME_SLACK
            };
            if !(convex(*f, *opposite_g) && convex(*g, *opposite_f)) {
                return None;
            }
        }
        let inner = planes
            .iter()
            .filter(|(n, _)| n.z > -0.999_999)
            .map(|&(_, d)| d)
            .fold(f64::INFINITY, f64::min);
        Some(Self { axes, inner })
    }

    /// `Some(inside)` where certain, `None` within the slack of the surface.
    pub fn classify(&self, p_sensor: Vec3) -> Option<bool> {
        let p = p_sensor.as_dvec3();
        let r = (p / self.axes).length();
        let z = p.z / self.axes.z;
        if z < -DOME_SLACK || r > 1.0 + DOME_SLACK {
            Some(false)
        } else if z > DOME_SLACK && r < self.inner - DOME_SLACK {
            Some(true)
        } else {
            None
        }
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
        .filter(|(_, p)| elastomer.inside(p.as_vec3()))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::elastomer::ElastomerConfig;
    use rand::{Rng, SeedableRng};

    /// The certain answers of the dome bounds equal the exact signed distance's sign, on points everywhere around the
    /// membrane and in the thin shell near its surface, for three tessellations and footprints; a mesh that is not
    /// a half-ellipsoid gets no bounds.
    #[test]
    fn dome_bounds_agree_with_the_exact_signed_distance() {
        let configs = [
            ElastomerConfig::default(),
            ElastomerConfig {
                footprint_x: 0.1,
                footprint_y: 0.1,
                inflation: 0.02,
                rings: 6,
                segments: 16,
                ..Default::default()
            },
            ElastomerConfig {
                inflation: 0.045,
                rings: 40,
                segments: 200,
                ..Default::default()
            },
        ];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (c, cfg) in configs.into_iter().enumerate() {
            let mesh = cfg.build().unwrap();
            let axes = DVec3::new(cfg.footprint_x / 2.0, cfg.footprint_y / 2.0, cfg.inflation);
            let dome =
                DomeBounds::new(&mesh, axes).expect("the parametric membrane is a convex dome");
            let exact = ElastomerSdf::new(SignedDistance::new(&mesh).unwrap(), mesh.aabb());
            let (mut certain, mut near, mut inside) = (0usize, 0usize, 0usize);
            for k in 0..40_000 {
                let p = if k % 2 == 0 {
                    // Anywhere around the membrane.
                    DVec3::new(
                        rng.random_range(-1.2..1.2),
                        rng.random_range(-1.2..1.2),
                        rng.random_range(-0.2..1.2),
                    ) * axes
                } else {
                    // In the shell around the surface (dome and base), scaled radius 0.99..1.01.
                    let dir = DVec3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(0.0..1.0f64),
                    )
                    .normalize_or_zero();
                    let r = rng.random_range(0.99..1.01);
                    let z_jitter = if k % 6 == 1 {
                        rng.random_range(-0.002..0.002)
                    } else {
                        0.0
                    };
                    (dir * r + DVec3::new(0.0, 0.0, z_jitter)) * axes
                };
                let want = exact.distance(p.as_vec3()) < 0.0;
                match dome.classify(p.as_vec3()) {
                    Some(got) => {
                        assert_eq!(got, want, "{p:?} with {cfg:?}");
                        certain += 1;
                        inside += usize::from(got);
                    }
                    None => near += 1,
                }
            }
            assert!(
                inside > 1000 && certain - inside > 1000,
                "{inside} of {certain}"
            );
            // Only the shell within the tessellation's gap needs the exact query (the coarse second mesh's gap is
            // wide: 16 segments).
            eprintln!("membrane {c}: {near} of 40 000 points need the exact query");
            if c != 1 {
                assert!(near < 4_000, "{near} of 40 000 uncertain");
            }
        }
        // A box is not a half-ellipsoid.
        let cube = crate::mesh::Mesh::from_raw(
            vec![
                Vec3::new(-0.01, -0.01, 0.0),
                Vec3::new(0.01, -0.01, 0.0),
                Vec3::new(0.01, 0.01, 0.0),
                Vec3::new(-0.01, 0.01, 0.0),
                Vec3::new(-0.01, -0.01, 0.02),
                Vec3::new(0.01, -0.01, 0.02),
                Vec3::new(0.01, 0.01, 0.02),
                Vec3::new(-0.01, 0.01, 0.02),
            ],
            vec![
                [0, 2, 1],
                [0, 3, 2],
                [4, 5, 6],
                [4, 6, 7],
                [0, 1, 5],
                [0, 5, 4],
                [1, 2, 6],
                [1, 6, 5],
                [2, 3, 7],
                [2, 7, 6],
                [3, 0, 4],
                [3, 4, 7],
            ],
            "box",
        )
        .unwrap();
        assert!(DomeBounds::new(&cube, DVec3::new(0.01, 0.01, 0.02)).is_none());
    }
}
