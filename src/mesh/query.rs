//! Geometric queries on a [`Mesh`]: ray casting (paper IV.A step 1, object depth rendering) and signed distance
//! (step 3, distance of back-projected points to the elastomer; also the object SDF used for registration).
//!
//! Ray casting uses our own BVH ([`super::bvh`], built once per mesh, about 3x faster than parry's for primary rays);
//! signed distance uses parry3d's `TriMesh`: a maintained, well-tested geometry crate whose closest-point queries
//! and pseudo-normals we would otherwise re-implement. Signs come from parry's angle-weighted pseudo-normals on closed meshes (exact for watertight, consistently
//! oriented meshes) and from the generalised winding number on open meshes (robust to holes: a point is inside where
//! the surface wraps it at least halfway).

use glam::Vec3;
use parry3d::query::PointQuery;
use parry3d::shape::{TriMesh, TriMeshFlags};

use super::{Mesh, MeshError};

/// A mesh prepared for ray casting (BVH built once; see [`super::bvh`] for why it is our own).
pub struct RayCaster {
    bvh: super::bvh::Bvh,
}

impl RayCaster {
    /// Build the BVH of `mesh` (in whatever frame its vertices are: rays must be given in the same frame).
    pub fn new(mesh: &Mesh) -> Result<Self, MeshError> {
        Ok(Self {
            bvh: super::bvh::Bvh::new(mesh),
        })
    }

    /// First hit of the ray `origin + t * dir` with `0 <= t <= max_t`, as the ray parameter `t` (in units of `|dir|`);
    /// `None` on a miss.
    #[inline]
    pub fn cast(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<f32> {
        self.bvh.cast(origin, dir, max_t)
    }

    /// Axis-aligned bounds of the mesh.
    pub fn aabb(&self) -> (Vec3, Vec3) {
        self.bvh.aabb()
    }
}

/// How the inside/outside sign is decided.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SignMethod {
    /// Angle-weighted pseudo-normals at the closest feature (closed meshes).
    PseudoNormal,
    /// Generalised winding number |w| >= 0.5 (open, multi-shell or non-manifold meshes; Barill et al.'s fast
    /// hierarchical approximation, [`super::FastWinding`]).
    WindingNumber,
}

/// Exact signed distance to a mesh: closest-point distance, negative inside.
pub struct SignedDistance {
    trimesh: TriMesh,
    method: SignMethod,
    /// The winding-number tree ([`SignMethod::WindingNumber`] only).
    winding: Option<super::FastWinding>,
}

impl SignedDistance {
    /// Prepare `mesh` for signed-distance queries. Vertices are welded (1 µm) first so that pseudo-normals see the
    /// topology; closed meshes use pseudo-normals, open ones the winding number.
    pub fn new(mesh: &Mesh) -> Result<Self, MeshError> {
        let welded = mesh.welded(1e-6);
        let report = welded.report();
        let method = if report.closed && welded.shell_count() == 1 {
            SignMethod::PseudoNormal
        } else {
            SignMethod::WindingNumber
        };
        // Inward-facing closed meshes would invert the sign: flip them.
        let welded = if report.closed && report.volume_m3 < 0.0 {
            welded.flipped()
        } else {
            welded
        };
        let flags = match method {
            SignMethod::PseudoNormal => TriMeshFlags::ORIENTED,
            SignMethod::WindingNumber => TriMeshFlags::empty(),
        };
        let trimesh = TriMesh::with_flags(
            welded.vertices().to_vec(),
            welded.triangles().to_vec(),
            flags,
        )
        .map_err(|e| MeshError::Invalid {
            context: "signed distance".into(),
            message: e.to_string(),
        })?;
        let winding =
            (method == SignMethod::WindingNumber).then(|| super::FastWinding::new(&welded));
        Ok(Self {
            trimesh,
            method,
            winding,
        })
    }

    /// The sign method chosen for this mesh.
    pub fn method(&self) -> SignMethod {
        self.method
    }

    /// Signed distance (metres) from `p` to the surface: negative inside, positive outside.
    pub fn distance(&self, p: Vec3) -> f32 {
        let proj = self.trimesh.project_local_point(p, false);
        let d = (p - proj.point).length();
        let inside = match self.method {
            SignMethod::PseudoNormal => proj.is_inside,
            SignMethod::WindingNumber => self.winding_number(p).abs() >= 0.5,
        };
        if inside {
            -d
        } else {
            d
        }
    }

    /// Generalised winding number of the surface around `p` (1 inside a closed outward mesh, 0 outside; exact sum
    /// for closed meshes, the fast hierarchical approximation for the others).
    pub fn winding_number(&self, p: Vec3) -> f32 {
        let p = p.as_dvec3();
        match &self.winding {
            Some(w) => w.winding_number(p) as f32,
            None => {
                let v = self.trimesh.vertices();
                let tris = self
                    .trimesh
                    .indices()
                    .iter()
                    .map(|t| t.map(|i| v[i as usize].as_dvec3()));
                super::winding::winding_number_of(tris, p) as f32
            }
        }
    }

    /// Closest point on the surface to `p`.
    pub fn closest_point(&self, p: Vec3) -> Vec3 {
        self.trimesh.project_local_point(p, false).point
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Closed, outward-oriented axis-aligned box with half extents `h`.
    pub(crate) fn box_mesh(h: Vec3) -> Mesh {
        let v: Vec<Vec3> = (0..8)
            .map(|i| {
                Vec3::new(
                    if i & 1 == 0 { -h.x } else { h.x },
                    if i & 2 == 0 { -h.y } else { h.y },
                    if i & 4 == 0 { -h.z } else { h.z },
                )
            })
            .collect();
        let quads = [
            [0, 2, 3, 1], // z-
            [4, 5, 7, 6], // z+
            [0, 1, 5, 4], // y-
            [2, 6, 7, 3], // y+
            [0, 4, 6, 2], // x-
            [1, 3, 7, 5], // x+
        ];
        let t = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Mesh::from_raw(v, t, "box").unwrap()
    }

    fn box_sdf(p: Vec3, h: Vec3) -> f32 {
        let q = p.abs() - h;
        q.max(Vec3::ZERO).length() + q.max_element().min(0.0)
    }

    #[test]
    fn box_signed_distance_is_exact() {
        let h = Vec3::new(0.02, 0.01, 0.03);
        let mesh = box_mesh(h);
        let report = mesh.report();
        assert!(report.closed);
        assert!((report.volume_m3 / (8.0 * 0.02 * 0.01 * 0.03) - 1.0).abs() < 1e-6);
        let sdf = SignedDistance::new(&mesh).unwrap();
        assert_eq!(sdf.method(), SignMethod::PseudoNormal);
        let mut state = 12345u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) as f32 / (1u64 << 31) as f32) * 2.0 - 1.0
        };
        for _ in 0..2000 {
            let p = Vec3::new(rnd() * 0.05, rnd() * 0.05, rnd() * 0.05);
            let (got, want) = (sdf.distance(p), box_sdf(p, h));
            // A box is represented exactly: only f32 rounding remains.
            assert!((got - want).abs() < 1e-6, "p={p} got={got} want={want}");
        }
        // Flipped (inward) winding is detected and corrected.
        let flipped = SignedDistance::new(&mesh.flipped()).unwrap();
        assert!(flipped.distance(Vec3::ZERO) < 0.0);
    }

    #[test]
    fn sphere_signed_distance_matches_analytic_within_tessellation_error() {
        // An icosphere (4 subdivisions, 5120 faces) inscribed in a sphere of radius r: the surface lies between the
        // sphere and the inscribed radius r cos(a), a = the largest angular radius of a face (< 0.06 rad here; an edge spans about 0.07 rad), so
        // the mesh SDF equals |p - c| - r up to r (1 - cos a) < 2e-3 r, plus f32 rounding.
        let r = 0.02f64;
        let mesh = crate::objects::shapes::sphere(r, 4).unwrap();
        let c = Vec3::new(0.0, 0.0, r as f32);
        let sdf = SignedDistance::new(&mesh).unwrap();
        let tolerance = (r * (1.0 - 0.06f64.cos())) as f32 + 1e-6;
        let mut state = 99u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) as f32 / (1u64 << 31) as f32) * 2.0 - 1.0
        };
        let mut worst = 0.0f32;
        for _ in 0..2000 {
            let p = c + Vec3::new(rnd(), rnd(), rnd()) * 0.04;
            let want = (p - c).length() - r as f32;
            let err = sdf.distance(p) - want;
            // The tessellated surface is inside the sphere: the mesh SDF is never below the analytic one.
            assert!(err > -1e-6, "p={p} err={err}");
            worst = worst.max(err);
        }
        assert!(worst < tolerance, "worst {worst} vs bound {tolerance}");
        assert!(worst > 0.0, "a tessellated sphere cannot be exact");
    }

    #[test]
    fn open_mesh_uses_winding_number() {
        // A box without its top face: points well inside are still inside, points outside are outside.
        let mesh = box_mesh(Vec3::splat(0.01));
        let tris: Vec<[u32; 3]> = mesh.triangles()[..2]
            .iter()
            .chain(&mesh.triangles()[4..])
            .copied()
            .collect();
        let open = Mesh::from_raw(mesh.vertices().to_vec(), tris, "open box").unwrap();
        assert!(!open.report().closed);
        let sdf = SignedDistance::new(&open).unwrap();
        assert_eq!(sdf.method(), SignMethod::WindingNumber);
        assert!(sdf.distance(Vec3::new(0.0, 0.0, -0.005)) < 0.0);
        assert!(sdf.distance(Vec3::new(0.0, 0.0, -0.02)) > 0.0);
        assert!(sdf.distance(Vec3::new(0.03, 0.0, 0.0)) > 0.0);
        assert!((sdf.winding_number(Vec3::new(0.0, 0.0, -0.009)) - 1.0).abs() < 0.2);
    }

    #[test]
    fn ray_hits_box_face_at_analytic_distance() {
        let mesh = box_mesh(Vec3::splat(0.01));
        let rc = RayCaster::new(&mesh).unwrap();
        let t = rc
            .cast(
                Vec3::new(0.003, -0.002, 0.1),
                Vec3::new(0.0, 0.0, -1.0),
                1.0,
            )
            .unwrap();
        assert!((t - 0.09).abs() < 1e-6);
        assert!(rc
            .cast(Vec3::new(0.05, 0.0, 0.1), Vec3::new(0.0, 0.0, -1.0), 1.0)
            .is_none());
    }
}
