//! **Fast generalised winding numbers** for any triangle soup (Barill, Dickson, Schmidt, Levin and Jacobson 2018,
//! "Fast winding numbers for soups and clouds"): the inside/outside test behind the signed distance of open,
//! multi-shell, non-manifold and self-intersecting meshes — the real meshes users bring (scans with holes, CAD
//! exports, convex decompositions).
//!
//! The generalised winding number `w(p) = Σ Ω_t(p) / 4π` sums the signed solid angles of the triangles seen from
//! `p` (Jacobson et al. 2013): 1 inside a closed outward-facing surface, 0 outside, close to 1 inside a surface with
//! small holes, 2 inside two overlapping shells, −1 inside an inward-facing one. Summing every triangle costs
//! O(triangles) per query; here a bounding-volume tree stores, per node, the area-weighted normal sum `N` and centroid
//! `c` of its triangles, and a node farther from `p` than `β` times its radius contributes its dipole term
//! `N·(c − p) / 4π|c − p|³` instead of its triangles. With the default `β = 2` the approximation error is a few
//! 10⁻² at worst (curved patches seen from their centre of curvature; measured against the exact sum in the tests),
//! far below the ½ threshold that decides the sign. Barill et al. add the next two Taylor terms for 10⁻³; the
//! first of them alone does not help (on curved patches it is of the same order as the one after it), so it is left
//! out. Near the surface the tree is descended down to exact per-triangle solid angles.

use glam::DVec3;

use super::Mesh;

/// Triangles per leaf.
const LEAF_SIZE: usize = 8;

/// Longest triangle edge the tree holds, as a fraction of the mesh's bounding-box diagonal. CAD exports tessellate
/// flat faces into long slivers (a robot jaw: a fifth of its triangles have edges over 5 % of the diagonal); a
/// node holding one is as large as the sliver, so it is never far, and every query sums it exactly. Splitting
/// slivers leaves the winding number unchanged (solid angles add up) and keeps the nodes compact.
const MAX_EDGE_FRACTION: f64 = 1.0 / 64.0;

/// One tree node: bounds of its triangles, their dipole expansion and where they are in [`FastWinding::tris`].
#[derive(Clone, Debug)]
struct Node {
    /// Area-weighted centroid of the node's triangles.
    center: DVec3,
    /// Σ area · unit normal (= Σ ½ (b − a) × (c − a)).
    normal_sum: DVec3,
    /// Largest distance from `center` to a vertex of the node's triangles.
    radius: f64,
    /// Leaf: range into `tris`; inner node: children indices.
    kind: NodeKind,
}

#[derive(Clone, Copy, Debug)]
enum NodeKind {
    Leaf { start: u32, end: u32 },
    Inner { left: u32, right: u32 },
}

/// A triangle soup prepared for fast winding-number queries (any frame; queries in the same frame).
#[derive(Clone, Debug)]
pub struct FastWinding {
    nodes: Vec<Node>,
    tris: Vec<[DVec3; 3]>,
    beta: f64,
}

impl FastWinding {
    /// Accuracy parameter of the far-field test (Barill et al.'s β): larger is more exact and slower.
    pub const DEFAULT_BETA: f64 = 2.0;

    /// Build the tree over the triangles of `mesh` (degenerate triangles contribute nothing and are dropped).
    pub fn new(mesh: &Mesh) -> Self {
        Self::with_beta(mesh, Self::DEFAULT_BETA)
    }

    /// [`Self::new`] with an explicit β (≥ 1).
    pub fn with_beta(mesh: &Mesh, beta: f64) -> Self {
        let tris: Vec<[DVec3; 3]> = (0..mesh.triangles().len())
            .map(|i| mesh.triangle(i).map(|v| v.as_dvec3()))
            .filter(|[a, b, c]| (*b - *a).cross(*c - *a).length_squared() > 0.0)
            .collect();
        let (lo, hi) = mesh.aabb();
        // At most eight times the triangles (or 250 000, 18 MB): a soup of huge triangles is split less finely.
        let cap = (8 * tris.len()).max(250_000);
        let mut max_edge = f64::from((hi - lo).length()) * MAX_EDGE_FRACTION;
        let mut tris = loop {
            match split_long(&tris, max_edge, cap) {
                Some(split) => break split,
                None => max_edge *= 2.0,
            }
        };
        let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF_SIZE + 1);
        if !tris.is_empty() {
            let n = tris.len();
            build(&mut tris, 0, n, &mut nodes);
        }
        Self {
            nodes,
            tris,
            beta: beta.max(1.0),
        }
    }

    /// Number of (non-degenerate) triangles.
    pub fn triangles(&self) -> usize {
        self.tris.len()
    }

    /// Generalised winding number of the surface around `p`.
    pub fn winding_number(&self, p: DVec3) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        let mut total = 0.0;
        let mut stack = [0u32; 64];
        let mut top = 1;
        stack[0] = 0;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            let d = node.center - p;
            let dist2 = d.length_squared();
            let far = self.beta * node.radius;
            if dist2 > far * far {
                // The dipole term of the node's triangles about its centre, r = c − p.
                total +=
                    node.normal_sum.dot(d) / (dist2 * dist2.sqrt()) / (4.0 * std::f64::consts::PI);
                continue;
            }
            match node.kind {
                NodeKind::Leaf { start, end } => {
                    total += self.tris[start as usize..end as usize]
                        .iter()
                        .map(|t| solid_angle(t, p))
                        .sum::<f64>()
                        / (4.0 * std::f64::consts::PI);
                }
                NodeKind::Inner { left, right } => {
                    // The tree is balanced (median splits), so 64 levels hold any mesh that fits in memory.
                    stack[top] = left;
                    stack[top + 1] = right;
                    top += 2;
                }
            }
        }
        total
    }

    /// Whether `p` is inside: |w| ≥ ½ (so inward-facing surfaces and overlapping shells count as solid).
    pub fn inside(&self, p: DVec3) -> bool {
        self.winding_number(p).abs() >= 0.5
    }

    /// The exact winding number (every triangle's solid angle): the reference the tree approximates.
    pub fn exact_winding_number(&self, p: DVec3) -> f64 {
        winding_number_of(self.tris.iter().copied(), p)
    }
}

/// The exact generalised winding number of the triangles `tris` around `p` (O(triangles)).
pub fn winding_number_of(tris: impl IntoIterator<Item = [DVec3; 3]>, p: DVec3) -> f64 {
    tris.into_iter().map(|t| solid_angle(&t, p)).sum::<f64>() / (4.0 * std::f64::consts::PI)
}

/// `tris` with every triangle whose longest edge exceeds `max_edge` halved across that edge's midpoint, recursively
/// (orientation kept, so every solid angle is the sum of its pieces'); `None` when that makes more than `cap`.
fn split_long(tris: &[[DVec3; 3]], max_edge: f64, cap: usize) -> Option<Vec<[DVec3; 3]>> {
    if !max_edge.is_finite() || max_edge <= 0.0 {
        return Some(tris.to_vec());
    }
    let mut out = Vec::with_capacity(tris.len());
    let mut stack: Vec<[DVec3; 3]> = tris.iter().rev().copied().collect();
    while let Some(t) = stack.pop() {
        if out.len() + stack.len() > cap {
            return None;
        }
        // The longest edge (t[i], t[i + 1]).
        let (i, len) = (0..3)
            .map(|i| (i, t[i].distance(t[(i + 1) % 3])))
            .fold((0, 0.0), |best, e| if e.1 > best.1 { e } else { best });
        if len <= max_edge {
            out.push(t);
            continue;
        }
        let (a, b, c) = (t[i], t[(i + 1) % 3], t[(i + 2) % 3]);
        let m = 0.5 * (a + b);
        stack.push([m, b, c]);
        stack.push([a, m, c]);
    }
    Some(out)
}

/// Signed solid angle of triangle `t` seen from `p` (Van Oosterom & Strackee 1983).
fn solid_angle(t: &[DVec3; 3], p: DVec3) -> f64 {
    let (a, b, c) = (t[0] - p, t[1] - p, t[2] - p);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    2.0 * num.atan2(den)
}

/// Build the subtree over `tris[start..end]` (reordered in place); returns its node index.
fn build(tris: &mut [[DVec3; 3]], start: usize, end: usize, nodes: &mut Vec<Node>) -> u32 {
    let slice = &tris[start..end];
    let mut area_sum = 0.0;
    let mut weighted = DVec3::ZERO;
    let mut normal_sum = DVec3::ZERO;
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for [a, b, c] in slice {
        let n = 0.5 * (*b - *a).cross(*c - *a);
        let area = n.length();
        area_sum += area;
        weighted += area * (*a + *b + *c) / 3.0;
        normal_sum += n;
        let centroid = (*a + *b + *c) / 3.0;
        lo = lo.min(centroid);
        hi = hi.max(centroid);
    }
    let center = if area_sum > 0.0 {
        weighted / area_sum
    } else {
        (lo + hi) * 0.5
    };
    let radius = slice
        .iter()
        .flat_map(|t| t.iter())
        .map(|v| v.distance(center))
        .fold(0.0, f64::max);
    let index = nodes.len() as u32;
    nodes.push(Node {
        center,
        normal_sum,
        radius,
        kind: NodeKind::Leaf {
            start: start as u32,
            end: end as u32,
        },
    });
    if end - start > LEAF_SIZE {
        let axis = (hi - lo).max_position();
        let mid = (end - start) / 2;
        let key = |t: &[DVec3; 3]| (t[0][axis] + t[1][axis] + t[2][axis]) / 3.0;
        tris[start..end].select_nth_unstable_by(mid, |x, y| key(x).total_cmp(&key(y)));
        let left = build(tris, start, start + mid, nodes);
        let right = build(tris, start + mid, end, nodes);
        nodes[index as usize].kind = NodeKind::Inner { left, right };
    }
    index
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::objects::shapes::sphere;

    /// A 20 mm sphere centred at the origin (the catalogue's rests on the table).
    fn unit_sphere() -> Mesh {
        sphere(0.02, 3)
            .unwrap()
            .transformed(&glam::Affine3A::from_translation(-glam::Vec3::Z * 0.02))
    }

    #[test]
    fn closed_sphere_is_one_inside_and_zero_outside() {
        let w = FastWinding::new(&unit_sphere());
        assert!(w.triangles() > 500);
        for p in [DVec3::ZERO, DVec3::new(0.01, 0.005, -0.012)] {
            assert!((w.winding_number(p) - 1.0).abs() < 0.05, "{p}");
        }
        for p in [
            DVec3::new(0.05, 0.0, 0.0),
            DVec3::new(0.0, 0.03, 0.021),
            DVec3::splat(1.0),
        ] {
            assert!(w.winding_number(p).abs() < 0.05, "{p}");
        }
    }

    #[test]
    fn tree_matches_the_exact_sum() {
        let w = FastWinding::new(&unit_sphere());
        let mut worst: f64 = 0.0;
        for i in 0..400 {
            // Points on a spiral through and around the sphere, some within a millimetre of the surface.
            let t = i as f64 / 400.0;
            let r = 0.002 + 0.05 * t;
            let p = DVec3::new(
                r * (37.0 * t).cos(),
                r * (23.0 * t).sin(),
                r * (2.0 * t - 1.0),
            );
            worst = worst.max((w.winding_number(p) - w.exact_winding_number(p)).abs());
        }
        assert!(worst < 0.05, "largest deviation {worst}");
    }

    #[test]
    fn holes_inward_faces_and_overlaps() {
        let mesh = unit_sphere();
        // Punch a hole: drop every triangle whose centroid is in the top cap (z > 0.017 of radius 0.02).
        let keep: Vec<[u32; 3]> = mesh
            .triangles()
            .iter()
            .enumerate()
            .filter(|(i, _)| {
                let [a, b, c] = mesh.triangle(*i);
                (a.z + b.z + c.z) / 3.0 < 0.017
            })
            .map(|(_, t)| *t)
            .collect();
        assert!(keep.len() < mesh.triangles().len());
        let holed = Mesh::from_raw(mesh.vertices().to_vec(), keep, "holed sphere").unwrap();
        let w = FastWinding::new(&holed);
        assert!(w.inside(DVec3::ZERO));
        assert!(w.inside(DVec3::new(0.0, 0.0, -0.015)));
        assert!(!w.inside(DVec3::new(0.0, 0.0, 0.03)));
        assert!(!w.inside(DVec3::new(0.025, 0.0, 0.0)));
        // Inward-facing: w = −1 inside, still "inside".
        let w = FastWinding::new(&mesh.flipped());
        assert!((w.winding_number(DVec3::ZERO) + 1.0).abs() < 0.05);
        assert!(w.inside(DVec3::ZERO));
        // Two overlapping shells: 2 in the overlap, 1 in one only.
        let shifted = mesh.transformed(&glam::Affine3A::from_translation(glam::Vec3::X * 0.02));
        let both = Mesh::merged(&[mesh.clone(), shifted]);
        let w = FastWinding::new(&both);
        assert!((w.winding_number(DVec3::new(0.01, 0.0, 0.0)) - 2.0).abs() < 0.05);
        assert!((w.winding_number(DVec3::new(-0.015, 0.0, 0.0)) - 1.0).abs() < 0.05);
        assert!(w.winding_number(DVec3::new(0.05, 0.0, 0.0)).abs() < 0.05);
    }

    #[test]
    fn duplicated_faces_and_a_self_intersecting_fold() {
        // Every face twice (a common export bug): w = 2 inside, 0 outside.
        let mesh = unit_sphere();
        let doubled = Mesh::merged(&[mesh.clone(), mesh.clone()]);
        let w = FastWinding::new(&doubled);
        assert_eq!(doubled.triangles().len(), 2 * mesh.triangles().len());
        // The tree's far-field approximation errs by a few per cent of |w| (the exact sum is 2.000 here).
        let w0 = w.winding_number(DVec3::ZERO);
        assert!((w0 - 2.0).abs() < 0.08, "{w0}");
        assert!(w.inside(DVec3::new(0.0, 0.015, 0.0)));
        assert!(w.winding_number(DVec3::new(0.0, 0.03, 0.0)).abs() < 0.05);
        // One shell whose cap is folded through the opposite side (vertices of the top cap mirrored below the
        // equator): a single self-intersecting surface. Points inside the untouched lower body still have |w| >= 1/2
        // and points far away 0, as the exact solid-angle sum says.
        let folded: Vec<glam::Vec3> = mesh
            .vertices()
            .iter()
            .map(|v| {
                if v.z > 0.015 {
                    glam::Vec3::new(v.x, v.y, -v.z * 0.5)
                } else {
                    *v
                }
            })
            .collect();
        let fold = Mesh::from_raw(folded, mesh.triangles().to_vec(), "folded sphere").unwrap();
        let w = FastWinding::new(&fold);
        for p in [
            DVec3::new(0.0, 0.0, -0.015),
            DVec3::new(0.03, 0.0, 0.0),
            DVec3::new(0.0, 0.0, 0.05),
        ] {
            let exact = winding_number_of(
                (0..fold.triangles().len()).map(|i| fold.triangle(i).map(|v| v.as_dvec3())),
                p,
            );
            assert!(
                (w.winding_number(p) - exact).abs() < 0.05,
                "{p}: {} vs {exact}",
                w.winding_number(p)
            );
        }
        assert!(w.inside(DVec3::new(0.0, 0.0, -0.015)));
        assert!(!w.inside(DVec3::new(0.0, 0.0, 0.05)));
    }

    #[test]
    fn slivers_are_split_without_changing_the_winding_number() {
        // A 60 x 4 x 4 mm bar of 12 triangles: every face a pair of slivers, split down to 1/64 of the diagonal.
        let bar = crate::objects::shapes::extrude_z(
            &[
                (-0.03, -0.002),
                (0.03, -0.002),
                (0.03, 0.002),
                (-0.03, 0.002),
            ]
            .map(|(x, y)| glam::Vec2::new(x, y)),
            0.004,
        )
        .unwrap();
        let w = FastWinding::new(&bar);
        let (lo, hi) = bar.aabb();
        let max_edge = f64::from((hi - lo).length()) * MAX_EDGE_FRACTION;
        assert!(
            w.triangles() > 100 * bar.triangles().len(),
            "{}",
            w.triangles()
        );
        assert!(w
            .tris
            .iter()
            .all(|t| (0..3).all(|i| t[i].distance(t[(i + 1) % 3]) <= max_edge + 1e-15)));
        let original: Vec<[DVec3; 3]> = (0..bar.triangles().len())
            .map(|i| bar.triangle(i).map(|v| v.as_dvec3()))
            .collect();
        for k in 0..200 {
            let t = f64::from(k) / 200.0;
            let p = DVec3::new(
                -0.04 + 0.08 * t,
                0.003 * (7.0 * t).sin(),
                0.002 + 0.004 * (5.0 * t).cos(),
            );
            let split = w.exact_winding_number(p);
            let whole = winding_number_of(original.iter().copied(), p);
            assert!((split - whole).abs() < 1e-9, "{p}: {split} vs {whole}");
            // Inside the bar (|y| < 2 mm, 0 < z < 4 mm, |x| < 30 mm) the tree says so too.
            let inside = p.x.abs() < 0.03 && p.y.abs() < 0.002 && p.z > 0.0 && p.z < 0.004;
            if (p.y.abs() - 0.002).abs() > 2e-4
                && (p.z - 0.002).abs() < 0.0018
                && (p.x.abs() - 0.03).abs() > 2e-4
            {
                assert_eq!(w.inside(p), inside, "{p}");
            }
        }
    }
}
