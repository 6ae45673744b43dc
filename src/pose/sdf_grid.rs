//! A cached **object signed distance** grid (paper IV.C registration; the role of CHSEL's `CachedSDF`): exact signed
//! distances sampled once on a regular grid over the object's bounding box plus a margin, queried with trilinear
//! interpolation and its analytic gradient. Outside the grid the value is extended by the distance to the grid box
//! (see [`SdfGrid::value_grad`]). The grid is sampled a block of 8³ nodes at a time, when a query first reaches the
//! block: registration only visits the object's top near the contact, so a large scan (a 20 cm dragon, 3 million
//! nodes) is not sampled through its whole volume. The values are the same as sampling every node up front.

use std::sync::{Arc, OnceLock};

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::sdf::{ExactSdf, ObjectSdf};
use super::PoseError;

/// How the grid is laid out.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SdfGridConfig {
    /// Distance between grid nodes, metres (default 1 mm).
    pub spacing_m: f64,
    /// Margin added around the object's bounding box on every side, metres (default 10 mm).
    pub padding_m: f64,
    /// Most nodes of a grid (default 8 million, 32 MB if every block were sampled): an object whose grid would need
    /// more at `spacing_m` (a bulky object over ~20 cm: a 30 cm cube, 1.6 mm) gets the finest spacing that fits.
    pub max_nodes: usize,
}

impl Default for SdfGridConfig {
    fn default() -> Self {
        Self {
            spacing_m: 0.001,
            padding_m: 0.010,
            max_nodes: 8_000_000,
        }
    }
}

/// Nodes per block edge: the unit in which the grid is sampled.
const BLOCK: usize = 8;

/// Slack of [`SdfGrid::sign_from_nodes`]'s ball test, metres: node values are stored as f32 and the distance to the
/// surface is projected in f32 (both good to ~10 nm at object sizes).
const BALL_MARGIN_M: f64 = 1e-6;

/// Signed distances on a regular grid (object frame), trilinearly interpolated.
pub struct SdfGrid {
    /// Position of node (0, 0, 0), metres.
    origin: DVec3,
    /// Node spacing, metres.
    spacing: f64,
    /// Nodes along x, y, z.
    dims: [usize; 3],
    /// Blocks along x, y, z.
    block_dims: [usize; 3],
    /// Each block's node values (x fastest within the block, metres), sampled when first needed.
    blocks: Vec<OnceLock<Box<[f32]>>>,
    /// What the nodes sample.
    exact: Arc<ExactSdf>,
}

impl std::fmt::Debug for SdfGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SdfGrid")
            .field("origin", &self.origin)
            .field("spacing", &self.spacing)
            .field("dims", &self.dims)
            .field("sampled_blocks", &self.sampled_blocks())
            .finish_non_exhaustive()
    }
}

impl SdfGrid {
    /// A grid over `exact`'s bounding box grown by `config.padding_m`; its nodes are sampled as queries reach them.
    pub fn build(exact: Arc<ExactSdf>, config: &SdfGridConfig) -> Result<Self, PoseError> {
        let h = config.spacing_m;
        if !(h.is_finite() && h > 0.0 && config.padding_m.is_finite() && config.padding_m >= 0.0) {
            return Err(PoseError::Config(format!(
                "SDF grid spacing {h} m must be positive and padding {} m non-negative",
                config.padding_m
            )));
        }
        let (lo, hi) = exact.aabb();
        let origin = lo - DVec3::splat(config.padding_m);
        let extent = hi + DVec3::splat(config.padding_m) - origin;
        let dims_at = |h: f64| {
            let n = |e: f64| (e / h).ceil() as usize + 1;
            [n(extent.x), n(extent.y), n(extent.z)]
        };
        let total = |d: [usize; 3]| d[0].saturating_mul(d[1]).saturating_mul(d[2]);
        // Too many nodes at the asked spacing (a bulky object over ~20 cm, a file in the wrong units): coarser.
        let mut h = h;
        let mut dims = dims_at(h);
        while total(dims) > config.max_nodes.max(8) {
            h *= (total(dims) as f64 / config.max_nodes.max(8) as f64)
                .cbrt()
                .max(1.01);
            dims = dims_at(h);
        }
        let block_dims = dims.map(|d| d.div_ceil(BLOCK));
        let blocks = (0..block_dims.iter().product())
            .map(|_| OnceLock::new())
            .collect();
        Ok(Self {
            origin,
            spacing: h,
            dims,
            block_dims,
            blocks,
            exact,
        })
    }

    /// Blocks of 8³ nodes sampled so far.
    pub fn sampled_blocks(&self) -> usize {
        self.blocks.iter().filter(|b| b.get().is_some()).count()
    }

    /// The exact signed distances of block (bi, bj, bk) (nodes past the grid's end left 0, never read).
    fn sample_block(&self, bi: usize, bj: usize, bk: usize) -> Box<[f32]> {
        let mut values = vec![0.0f32; BLOCK * BLOCK * BLOCK];
        for dk in 0..BLOCK.min(self.dims[2] - bk * BLOCK) {
            for dj in 0..BLOCK.min(self.dims[1] - bj * BLOCK) {
                for di in 0..BLOCK.min(self.dims[0] - bi * BLOCK) {
                    let (i, j, k) = (bi * BLOCK + di, bj * BLOCK + dj, bk * BLOCK + dk);
                    let p = self.origin + DVec3::new(i as f64, j as f64, k as f64) * self.spacing;
                    values[(dk * BLOCK + dj) * BLOCK + di] = self.exact.value(p) as f32;
                }
            }
        }
        values.into_boxed_slice()
    }

    /// Nodes along x, y, z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// The grid's box, metres (object frame).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let n = DVec3::new(
            (self.dims[0] - 1) as f64,
            (self.dims[1] - 1) as f64,
            (self.dims[2] - 1) as f64,
        );
        (self.origin, self.origin + n * self.spacing)
    }

    #[inline]
    fn node(&self, i: usize, j: usize, k: usize) -> f64 {
        let (b, at) = self.slot(i, j, k);
        let block =
            self.blocks[b].get_or_init(|| self.sample_block(i / BLOCK, j / BLOCK, k / BLOCK));
        f64::from(block[at])
    }

    /// Node (i, j, k) if its block has been sampled (never samples one).
    fn node_if_sampled(&self, i: usize, j: usize, k: usize) -> Option<f64> {
        let (b, at) = self.slot(i, j, k);
        self.blocks[b].get().map(|block| f64::from(block[at]))
    }

    /// Where node (i, j, k) is kept: its block's index and its place within the block (x fastest).
    #[inline]
    fn slot(&self, i: usize, j: usize, k: usize) -> (usize, usize) {
        let b = ((k / BLOCK) * self.block_dims[1] + j / BLOCK) * self.block_dims[0] + i / BLOCK;
        (b, ((k % BLOCK) * BLOCK + j % BLOCK) * BLOCK + i % BLOCK)
    }

    /// Whether `p_obj`, `d` metres from the surface, is inside, settled by a sampled corner of its cell: a node `n`
    /// with signed distance `s` is the centre of a ball of radius |s| that holds no surface, as is `p_obj`'s ball of
    /// radius `d`; when the balls overlap (|p − n| < d + |s|) the two points are joined without crossing the
    /// surface, so they are on the same side. `None` when no sampled corner settles it (then the caller evaluates
    /// the winding number). Exact wherever the solid is bounded by the mesh; across a soup's hole, where the
    /// winding number's ½ draws the boundary through empty space, a point within a cell of that span may take its
    /// neighbour's side.
    pub(crate) fn sign_from_nodes(&self, p_obj: DVec3, d: f64) -> Option<bool> {
        let f = (p_obj - self.origin) / self.spacing;
        if !(f.cmpge(DVec3::ZERO).all() && d.is_finite()) {
            return None;
        }
        let (i, j, k) = (f.x as usize, f.y as usize, f.z as usize);
        if i + 1 >= self.dims[0] || j + 1 >= self.dims[1] || k + 1 >= self.dims[2] {
            return None;
        }
        (0..8usize).find_map(|c| {
            let (a, b, e) = (i + (c & 1), j + ((c >> 1) & 1), k + (c >> 2));
            let s = self.node_if_sampled(a, b, e)?;
            let node = self.origin + DVec3::new(a as f64, b as f64, e as f64) * self.spacing;
            (s.abs() > BALL_MARGIN_M && (p_obj - node).length() + BALL_MARGIN_M < d + s.abs())
                .then_some(s < 0.0)
        })
    }

    /// Trilinear value at a point inside the box (the cost-only path of the solver).
    #[inline]
    fn inside_value(&self, p: DVec3) -> f64 {
        let f = (p - self.origin) / self.spacing;
        let cell = |x: f64, n: usize| {
            let i = (x.floor().max(0.0) as usize).min(n.saturating_sub(2));
            (i, (x - i as f64).clamp(0.0, 1.0))
        };
        let (i, tx) = cell(f.x, self.dims[0]);
        let (j, ty) = cell(f.y, self.dims[1]);
        let (k, tz) = cell(f.z, self.dims[2]);
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let c = |a: usize, b: usize, d: usize| self.node(i + a, j + b, k + d);
        let y0 = lerp(
            lerp(c(0, 0, 0), c(1, 0, 0), tx),
            lerp(c(0, 1, 0), c(1, 1, 0), tx),
            ty,
        );
        let y1 = lerp(
            lerp(c(0, 0, 1), c(1, 0, 1), tx),
            lerp(c(0, 1, 1), c(1, 1, 1), tx),
            ty,
        );
        lerp(y0, y1, tz)
    }

    /// Trilinear value and gradient at a point inside the box.
    #[inline]
    fn inside(&self, p: DVec3) -> (f64, DVec3) {
        let f = (p - self.origin) / self.spacing;
        let cell = |x: f64, n: usize| {
            let i = (x.floor().max(0.0) as usize).min(n.saturating_sub(2));
            (i, (x - i as f64).clamp(0.0, 1.0))
        };
        let (i, tx) = cell(f.x, self.dims[0]);
        let (j, ty) = cell(f.y, self.dims[1]);
        let (k, tz) = cell(f.z, self.dims[2]);
        let c = |a: usize, b: usize, d: usize| self.node(i + a, j + b, k + d);
        let (c000, c100, c010, c110) = (c(0, 0, 0), c(1, 0, 0), c(0, 1, 0), c(1, 1, 0));
        let (c001, c101, c011, c111) = (c(0, 0, 1), c(1, 0, 1), c(0, 1, 1), c(1, 1, 1));
        // Interpolate along x, then y, then z.
        let x00 = c000 + (c100 - c000) * tx;
        let x10 = c010 + (c110 - c010) * tx;
        let x01 = c001 + (c101 - c001) * tx;
        let x11 = c011 + (c111 - c011) * tx;
        let y0 = x00 + (x10 - x00) * ty;
        let y1 = x01 + (x11 - x01) * ty;
        let value = y0 + (y1 - y0) * tz;
        let dx0 = (c100 - c000) + ((c110 - c010) - (c100 - c000)) * ty;
        let dx1 = (c101 - c001) + ((c111 - c011) - (c101 - c001)) * ty;
        let gx = dx0 + (dx1 - dx0) * tz;
        let gy = (x10 - x00) + ((x11 - x01) - (x10 - x00)) * tz;
        let gz = y1 - y0;
        (value, DVec3::new(gx, gy, gz) / self.spacing)
    }
}

impl ObjectSdf for SdfGrid {
    fn value(&self, p_obj: DVec3) -> f64 {
        let (lo, hi) = self.bounds();
        if p_obj.cmpge(lo).all() && p_obj.cmple(hi).all() {
            self.inside_value(p_obj)
        } else {
            self.value_grad(p_obj).0
        }
    }

    /// Inside the box: trilinear interpolation and its exact derivative. Outside: with `q` the nearest point of the
    /// box, the object's closest point is estimated as `c = q - grad(q) * value(q)`, and the value and gradient are
    /// `|p - c|` and `(p - c) / |p - c|` (exact whenever `c` is also the closest surface point of `p`).
    fn value_grad(&self, p_obj: DVec3) -> (f64, DVec3) {
        let (lo, hi) = self.bounds();
        let q = p_obj.clamp(lo, hi);
        if q == p_obj {
            return self.inside(p_obj);
        }
        let (vq, gq) = self.inside(q);
        let c = q - gq.normalize_or_zero() * vq;
        let d = p_obj - c;
        let len = d.length();
        (len, if len > 0.0 { d / len } else { gq })
    }
}

/// The exact signed distance of a grid's object ([`ExactSdf`]), its sign settled by the grid's sampled nodes where
/// they can ([`SdfGrid::sign_from_nodes`]): a soup's winding number is then evaluated only within about a tenth of a
/// cell of the surface. Registration's polish on the exact SDF goes through it; on watertight meshes (signed by
/// pseudo-normals) it is [`ExactSdf`] itself.
pub struct ExactOnGrid<'a>(pub &'a SdfGrid);

impl ObjectSdf for ExactOnGrid<'_> {
    fn value(&self, p_obj: DVec3) -> f64 {
        let grid = self.0;
        grid.exact
            .value_hinted(p_obj, Some(&|p, d| grid.sign_from_nodes(p, d)))
    }

    fn value_grad(&self, p_obj: DVec3) -> (f64, DVec3) {
        let grid = self.0;
        grid.exact
            .value_grad_hinted(p_obj, Some(&|p, d| grid.sign_from_nodes(p, d)))
    }
}

#[cfg(test)]
mod tests {
    use super::super::sdf::tests::{box_mesh, box_sdf};
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Accuracy of the 1 mm grid on a box (exact analytic SDF), over random points within 5 mm of the surface.
    /// Trilinear interpolation reproduces the SDF exactly where it is linear (in front of faces); the error sits at
    /// its kinks: the medial ridges inside and the rounded contours outside edges and corners. Measured: max
    /// 0.29 * spacing (at the ridges), mean 0.008 * spacing. Stated bounds: max < 0.3 * spacing, mean < 0.01 *
    /// spacing, and the gradient equals the face normal (to 1e-3) outside a face away from its edges.
    #[test]
    fn grid_matches_the_analytic_box_sdf() {
        let h = DVec3::new(0.02, 0.012, 0.008);
        let exact = Arc::new(ExactSdf::new(&box_mesh(h)).unwrap());
        let cfg = SdfGridConfig::default();
        let grid = SdfGrid::build(exact.clone(), &cfg).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (mut max_err, mut sum_err, mut n, mut max_grad_err) = (0.0f64, 0.0, 0, 0.0f64);
        while n < 20_000 {
            let p = DVec3::new(
                rng.random_range(-0.03..0.03),
                rng.random_range(-0.02..0.02),
                rng.random_range(-0.015..0.015),
            );
            let want = box_sdf(p, h);
            if want.abs() > 0.005 {
                continue;
            }
            let (got, g) = grid.value_grad(p);
            assert!((grid.value(p) - got).abs() < 1e-12);
            let err = (got - want).abs();
            max_err = max_err.max(err);
            sum_err += err;
            n += 1;
            // Outside one face, two cells away from its edges: the gradient is the face normal.
            let q = p.abs() - h;
            let mut sorted = [q.x, q.y, q.z];
            sorted.sort_by(f64::total_cmp);
            if sorted[1] < -2.0 * cfg.spacing_m && sorted[2] > 0.0 {
                let (_, ge) = exact.value_grad(p);
                max_grad_err = max_grad_err.max((g - ge).length());
            }
        }
        let mean = sum_err / n as f64;
        eprintln!(
            "grid 1 mm: max |err| {:.4} mm, mean {:.5} mm, max grad err {max_grad_err:.2e}",
            max_err * 1e3,
            mean * 1e3
        );
        assert!(max_err < 0.3 * cfg.spacing_m, "max error {max_err}");
        assert!(mean < 0.01 * cfg.spacing_m, "mean error {mean}");
        assert!(max_grad_err < 1e-3, "gradient error {max_grad_err}");
    }

    /// Far outside the grid the extension is exact for points facing a face: value = distance to the face.
    #[test]
    fn outside_the_grid_extends_the_distance() {
        let h = DVec3::new(0.02, 0.012, 0.008);
        let exact = Arc::new(ExactSdf::new(&box_mesh(h)).unwrap());
        let grid = SdfGrid::build(exact.clone(), &SdfGridConfig::default()).unwrap();
        let p = DVec3::new(0.1, 0.003, -0.002);
        let (v, g) = grid.value_grad(p);
        assert!((v - 0.08).abs() < 1e-5, "{v}");
        assert!((g - DVec3::X).length() < 1e-3, "{g}");
        // A grid that would exceed max_nodes is made coarser to fit, and stays right.
        let too_fine = SdfGridConfig {
            spacing_m: 1e-5,
            ..Default::default()
        };
        let coarse = SdfGrid::build(exact.clone(), &too_fine).unwrap();
        let nodes: usize = coarse.dims.iter().product();
        assert!(
            nodes <= too_fine.max_nodes && nodes > too_fine.max_nodes / 2,
            "{:?}",
            coarse.dims
        );
        assert!(
            coarse.spacing > 1e-5 && coarse.spacing < 1e-3,
            "{}",
            coarse.spacing
        );
        let q = DVec3::new(0.021, 0.003, -0.002);
        assert!(
            (coarse.value(q) - 0.001).abs() < 1e-5,
            "{}",
            coarse.value(q)
        );
    }

    /// Sampling on demand gives every node the exact value at its position, and a query near one spot samples only
    /// the blocks around it.
    #[test]
    fn blocks_are_sampled_when_reached_with_the_exact_values() {
        let h = DVec3::new(0.05, 0.03, 0.01);
        let exact = Arc::new(ExactSdf::new(&box_mesh(h)).unwrap());
        let grid = SdfGrid::build(exact.clone(), &SdfGridConfig::default()).unwrap();
        assert_eq!(grid.sampled_blocks(), 0);
        let p = DVec3::new(0.01, -0.005, 0.0101);
        let (v, _) = grid.value_grad(p);
        assert!((v - 0.0001).abs() < 1e-4, "{v}");
        // One cell's 8 nodes lie in at most 8 blocks, of 14 x 9 x 5 = 630.
        let [bx, by, bz] = grid.block_dims;
        assert_eq!(bx * by * bz, grid.blocks.len());
        assert!((1..=8).contains(&grid.sampled_blocks()), "{grid:?}");
        // Every node, whenever and in whatever order it is sampled, holds the exact SDF at its position.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..2_000 {
            let (i, j, k) = (
                rng.random_range(0..grid.dims[0]),
                rng.random_range(0..grid.dims[1]),
                rng.random_range(0..grid.dims[2]),
            );
            let at = grid.origin + DVec3::new(i as f64, j as f64, k as f64) * grid.spacing;
            assert_eq!(grid.node(i, j, k), f64::from(exact.value(at) as f32));
        }
    }
    /// On soups (signed by the winding number), the exact SDF with its sign settled by the grid's nodes equals the
    /// exact SDF itself at points near and away from the surface, and spares most winding numbers: overlapping
    /// shells (a sign the pseudo-normals get wrong inside the overlap) and a non-manifold box.
    #[test]
    fn the_grid_settles_a_soups_sign_without_changing_it() {
        let h = DVec3::new(0.02, 0.01, 0.015);
        let closed = box_mesh(h);
        let shifted = closed.transformed(&glam::Affine3A::from_translation(glam::Vec3::Y * 0.005));
        let union = crate::mesh::Mesh::merged(&[closed.clone(), shifted]);
        let mut dup = closed.triangles().to_vec();
        dup.push(dup[0]);
        let non_manifold =
            crate::mesh::Mesh::from_raw(closed.vertices().to_vec(), dup, "duplicate face").unwrap();
        for (name, mesh) in [("two shells", union), ("non-manifold", non_manifold)] {
            let exact = Arc::new(ExactSdf::new(&mesh).unwrap());
            assert!(exact.uses_winding_number(), "{name}");
            let grid = SdfGrid::build(exact.clone(), &SdfGridConfig::default()).unwrap();
            let on_grid = ExactOnGrid(&grid);
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
            let (mut settled, mut near) = (0, 0);
            for _ in 0..4_000 {
                let p = DVec3::new(
                    rng.random_range(-0.03..0.03),
                    rng.random_range(-0.02..0.025),
                    rng.random_range(-0.025..0.025),
                );
                // Sample the blocks around p first (as the grid pass of a registration does).
                let _ = grid.value(p);
                let want = exact.value_grad(p);
                let (got, got_grad) = on_grid.value_grad(p);
                assert_eq!(got, want.0, "{name} at {p}");
                assert!((got_grad - want.1).length() < 1e-12, "{name} at {p}");
                assert_eq!(on_grid.value(p), exact.value(p), "{name} at {p}");
                let d = want.0.abs();
                if d > 1e-4 && d < 0.003 {
                    near += 1;
                    settled += usize::from(grid.sign_from_nodes(p, d).is_some());
                }
            }
            // Within 0.1-3 mm of the surface, most signs come from the nodes.
            assert!(near > 300, "{name}: {near}");
            assert!(
                settled as f64 > 0.9 * near as f64,
                "{name}: {settled} of {near}"
            );
        }
    }
}
