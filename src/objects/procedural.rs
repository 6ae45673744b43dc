//! **Procedural training objects**: seeded generators of many distinct rigid objects, far more varied than the
//! paper's seven parametric families (object library, paper V.A), so that a de-rendering model trained on them has
//! seen the contact shapes users' own objects make — sharp edges and corners, flat faces, thin walls, small bumps,
//! concavities, lumps — at every size.
//!
//! Kinds ([`Kind`]): superquadrics (boxes to diamonds to pills), random convex polytopes (flat faces, sharp corners),
//! smooth noise-displaced blobs, creased rocks, random outlines extruded upright with a chamfered or filleted top rim,
//! random profiles extruded lying down, unions of overlapping primitives (a self-intersecting soup, like a convex
//! decomposition), thin fins standing on edge, blocks with small bumps (1–5 mm) on top, and (module [`super::sweeps`])
//! plates with through-holes and stepped hubs, and swept limbs (knots, rods, bodies with legs). Each object's largest
//! extent is drawn in [`ProceduralConfig::extent_m`]; about a third are tilted at random before resting on the table.
//!
//! Object `i` of a set depends only on `(seed, i)`, so sets are reproducible and can be extended. Meshes are in
//! metres, in their resting pose (lowest point at z = 0, bounding box centred on z). All are closed except the
//! unions, which are several overlapping closed shells.

use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

use glam::{Affine3A, DVec3, Quat, Vec2, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::shapes::{extrude_z, icosphere_directions, sphere};
use super::sweeps;
use super::triangulate::{signed_area, simplify, triangulate};
use super::{ObjectEntry, ObjectError, RotationSymmetry, Split, Symmetry};
use crate::mesh::Mesh;
use crate::seed::mix64;

/// What to generate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ProceduralConfig {
    /// Number of objects (default 2 000).
    pub count: usize,
    /// Seed; object `i` depends only on `(seed, i)` (default 0).
    pub seed: u64,
    /// Range of each object's largest bounding-box extent, metres (default 0.015..0.065; the camera sees about
    /// 70 x 55 mm at the membrane).
    pub extent_m: [f64; 2],
    /// The kinds drawn, each with its [`Kind::WEIGHTED`] frequency (default: all of [`Kind::ALL`]). The nine kinds
    /// of [`Kind::V1`] reproduce the sets made before plates and limbs existed, object for object.
    pub kinds: Vec<Kind>,
}

impl Default for ProceduralConfig {
    fn default() -> Self {
        Self {
            count: 2000,
            seed: 0,
            extent_m: [0.015, 0.065],
            kinds: Kind::ALL.to_vec(),
        }
    }
}

/// The generator families.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    Superquadric,
    Polytope,
    Blob,
    Rock,
    Extrusion,
    LyingExtrusion,
    Union,
    Fin,
    Bumps,
    Plate,
    Limbs,
}

impl Kind {
    /// Every kind, in [`Kind::WEIGHTED`] order.
    pub const ALL: [Kind; 11] = [
        Kind::Superquadric,
        Kind::Polytope,
        Kind::Blob,
        Kind::Rock,
        Kind::Extrusion,
        Kind::LyingExtrusion,
        Kind::Union,
        Kind::Fin,
        Kind::Bumps,
        Kind::Plate,
        Kind::Limbs,
    ];

    /// The nine kinds of the first procedural sets (2026-11-24 to 26): with these, `(seed, i)` gives the objects it
    /// gave then.
    pub const V1: &'static [Kind] = Kind::ALL.split_at(9).0;

    /// All kinds with their relative frequency.
    pub const WEIGHTED: [(Kind, u32); 11] = [
        (Kind::Superquadric, 3),
        (Kind::Polytope, 3),
        (Kind::Blob, 2),
        (Kind::Rock, 2),
        (Kind::Extrusion, 3),
        (Kind::LyingExtrusion, 2),
        (Kind::Union, 3),
        (Kind::Fin, 1),
        (Kind::Bumps, 2),
        (Kind::Plate, 3),
        (Kind::Limbs, 3),
    ];

    /// Snake-case name, used in object names (`proc_<kind>_<index>`).
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::Superquadric => "superquadric",
            Kind::Polytope => "polytope",
            Kind::Blob => "blob",
            Kind::Rock => "rock",
            Kind::Extrusion => "extrusion",
            Kind::LyingExtrusion => "lying_extrusion",
            Kind::Union => "union",
            Kind::Fin => "fin",
            Kind::Bumps => "bumps",
            Kind::Plate => "plate",
            Kind::Limbs => "limbs",
        }
    }

    /// Parse a snake-case kind name.
    pub fn parse(name: &str) -> Option<Kind> {
        Self::ALL.into_iter().find(|k| k.as_str() == name)
    }

    /// One of `kinds` (in [`Kind::WEIGHTED`] order, whatever order they are listed in), by weight.
    fn draw(rng: &mut ChaCha8Rng, kinds: &[Kind]) -> Kind {
        let chosen = || {
            Self::WEIGHTED
                .into_iter()
                .filter(|(k, _)| kinds.contains(k))
        };
        let total: u32 = chosen().map(|(_, w)| w).sum();
        let mut r = rng.random_range(0..total.max(1));
        for (kind, w) in chosen() {
            if r < w {
                return kind;
            }
            r -= w;
        }
        Kind::Blob
    }
}

/// One generated object: its manifest entry (file name `<name>.obj`, metres) and mesh in its resting pose.
pub struct ProceduralObject {
    pub entry: ObjectEntry,
    pub kind: Kind,
    pub mesh: Mesh,
}

/// Generate object `index` of the set described by `config` (`index` may exceed `config.count`).
pub fn generate(config: &ProceduralConfig, index: usize) -> Result<ProceduralObject, ObjectError> {
    let [lo, hi] = config.extent_m;
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= lo) {
        return Err(ObjectError::BadShape {
            shape: "procedural",
            message: format!("extent range [{lo}, {hi}] m must satisfy 0 < min <= max"),
        });
    }
    if config.kinds.is_empty() {
        return Err(ObjectError::BadShape {
            shape: "procedural",
            message: "no kinds to draw from; list at least one".into(),
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(mix64(mix64(config.seed) ^ index as u64));
    let kind = Kind::draw(&mut rng, &config.kinds);
    let extent = lo + (hi - lo) * rng.random::<f64>();
    let (mesh, mut symmetry) = match kind {
        Kind::Superquadric => superquadric(&mut rng)?,
        Kind::Polytope => (polytope(&mut rng)?, Symmetry::default()),
        Kind::Blob => (blob(&mut rng, false)?, Symmetry::default()),
        Kind::Rock => (blob(&mut rng, true)?, Symmetry::default()),
        Kind::Extrusion => (extrusion(&mut rng)?, Symmetry::default()),
        Kind::LyingExtrusion => lying_extrusion(&mut rng)?,
        Kind::Union => (union(&mut rng)?, Symmetry::default()),
        Kind::Fin => (fin(&mut rng)?, Symmetry::default()),
        Kind::Bumps => (bumps(&mut rng)?, Symmetry::default()),
        Kind::Plate => (sweeps::plate(&mut rng)?, Symmetry::default()),
        Kind::Limbs => (sweeps::limbs(&mut rng)?, Symmetry::default()),
    };
    // Tilt a third of the compact shapes (long lying ones keep their axis on the table).
    let tilt = kind != Kind::LyingExtrusion && rng.random::<f64>() < 0.33;
    let mesh = if tilt {
        symmetry = Symmetry::default();
        let axis = Vec3::new(rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5, 0.0);
        let angle = (rng.random::<f64>() * FRAC_PI_2) as f32;
        mesh.transformed(&Affine3A::from_quat(Quat::from_axis_angle(
            axis.try_normalize().unwrap_or(Vec3::X),
            angle,
        )))
    } else {
        mesh
    };
    let mesh = scale_to_extent(&mesh, extent).rest_on_table();
    let name = format!("proc_{}_{index:05}", kind.as_str());
    let (bb_lo, bb_hi) = mesh.aabb();
    let size = (bb_hi - bb_lo).as_dvec3();
    let dimensions = BTreeMap::from([
        ("size_x".to_string(), round_um(size.x)),
        ("size_y".to_string(), round_um(size.y)),
        ("size_z".to_string(), round_um(size.z)),
    ]);
    Ok(ProceduralObject {
        entry: ObjectEntry {
            mesh: format!("{name}.obj"),
            name,
            family: None,
            scale_to_m: 1.0,
            rotation: None,
            split: Split::Seen,
            symmetry,
            dimensions,
            weight: 1.0,
        },
        kind,
        mesh,
    })
}

fn round_um(m: f64) -> f64 {
    (m * 1e6).round() / 1e6
}

/// Scale uniformly so the largest bounding-box extent is `extent` metres.
fn scale_to_extent(mesh: &Mesh, extent: f64) -> Mesh {
    let largest = mesh.largest_extent().max(1e-9);
    mesh.transformed(&Affine3A::from_scale(Vec3::splat(
        (extent / largest) as f32,
    )))
}

pub(super) fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

pub(super) fn log_uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    (lo.ln() + (hi.ln() - lo.ln()) * rng.random::<f64>()).exp()
}

pub(super) fn unit_vector(rng: &mut ChaCha8Rng) -> DVec3 {
    let z = uniform(rng, -1.0, 1.0);
    let phi = uniform(rng, 0.0, TAU);
    let r = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub(super) fn mesh_error(shape: &'static str) -> impl Fn(crate::mesh::MeshError) -> ObjectError {
    move |source| ObjectError::Mesh {
        name: shape.to_string(),
        source,
    }
}

/// A star-shaped closed surface: the icosphere's directions `d` moved to `radius(d) * d`.
fn radial(
    subdivisions: u32,
    shape: &'static str,
    radius: impl Fn(DVec3) -> f64,
) -> Result<Mesh, ObjectError> {
    let (dirs, triangles) = icosphere_directions(subdivisions);
    let vertices = dirs.iter().map(|&d| (d * radius(d)).as_vec3()).collect();
    Mesh::from_raw(vertices, triangles, shape).map_err(mesh_error(shape))
}

/// Superellipsoid `(|x/a|^(2/e2) + |y/b|^(2/e2))^(e2/e1) + |z/c|^(2/e1) = 1`: exponents near 0 give boxes and
/// cylinders with sharp edges, 1 ellipsoids, 2 octahedra (diamonds). Symmetry: 2-fold about z, 4-fold if a = b,
/// continuous if also e2 = 1.
fn superquadric(rng: &mut ChaCha8Rng) -> Result<(Mesh, Symmetry), ObjectError> {
    let e1 = log_uniform(rng, 0.2, 2.0);
    let round = rng.random::<f64>() < 0.3;
    let e2 = if round {
        1.0
    } else {
        log_uniform(rng, 0.2, 2.0)
    };
    let a = uniform(rng, 0.3, 1.0);
    let square = rng.random::<f64>() < 0.35;
    let b = if square { a } else { uniform(rng, 0.3, 1.0) };
    let c = uniform(rng, 0.2, 1.0);
    let rotation = match (square, round) {
        (true, true) => RotationSymmetry::Continuous,
        (true, false) => RotationSymmetry::NFold(4),
        _ => RotationSymmetry::NFold(2),
    };
    let mesh = radial(4, "superquadric", |d| {
        let xy = ((d.x / a).abs().powf(2.0 / e2) + (d.y / b).abs().powf(2.0 / e2)).powf(e2 / e1);
        let f = xy + (d.z / c).abs().powf(2.0 / e1);
        f.max(1e-12).powf(-e1 / 2.0)
    })?;
    Ok((
        mesh,
        Symmetry {
            rotation,
            translation_axis: None,
        },
    ))
}

/// Convex hull of 6–60 random points on a random ellipsoid: flat faces, sharp edges and corners.
fn polytope(rng: &mut ChaCha8Rng) -> Result<Mesh, ObjectError> {
    let n = rng.random_range(6..=60);
    let axes = DVec3::new(
        uniform(rng, 0.3, 1.0),
        uniform(rng, 0.3, 1.0),
        uniform(rng, 0.2, 1.0),
    );
    let points: Vec<Vec3> = (0..n)
        .map(|_| (unit_vector(rng) * axes).as_vec3())
        .collect();
    let (vertices, triangles) =
        parry3d::transformation::try_convex_hull(&points).map_err(|e| ObjectError::BadShape {
            shape: "polytope",
            message: format!("convex hull failed: {e:?}"),
        })?;
    let mesh = Mesh::from_raw(vertices, triangles, "polytope").map_err(mesh_error("polytope"))?;
    // parry's hull is outward; make sure (a negative volume would mean inward faces).
    Ok(if mesh.report().volume_m3 < 0.0 {
        mesh.flipped()
    } else {
        mesh
    })
}

/// A smooth lumpy blob (sum of random plane waves on the sphere of directions), or with `creased` a rock whose
/// ridges come from folded (absolute-value) waves; then stretched along random axes.
fn blob(rng: &mut ChaCha8Rng, creased: bool) -> Result<Mesh, ObjectError> {
    let waves: Vec<(DVec3, f64, f64, f64)> = (0..rng.random_range(3..=9))
        .map(|_| {
            let dir = unit_vector(rng);
            let freq = uniform(rng, 1.0, if creased { 7.0 } else { 4.0 });
            let amp = uniform(rng, 0.02, 0.12) / freq.sqrt();
            (dir, freq, amp, uniform(rng, 0.0, TAU))
        })
        .collect();
    let stretch = DVec3::new(
        uniform(rng, 0.5, 1.0),
        uniform(rng, 0.5, 1.0),
        uniform(rng, 0.35, 1.0),
    );
    let mesh = radial(4, if creased { "rock" } else { "blob" }, |d| {
        let bump: f64 = waves
            .iter()
            .map(|&(w, f, a, phase)| {
                let s = (f * w.dot(d) * PI + phase).sin();
                if creased {
                    a * (1.0 - 2.0 * s.abs())
                } else {
                    a * s
                }
            })
            .sum();
        (1.0 + bump).max(0.3)
    })?;
    Ok(mesh.transformed(&Affine3A::from_scale(stretch.as_vec3())))
}

/// A random star-shaped outline about the origin with 3–12 corners, optionally rounded by Chaikin corner cutting
/// (in-plane fillets), counter-clockwise, radius about 1.
pub(super) fn outline(rng: &mut ChaCha8Rng) -> Vec<Vec2> {
    let n = rng.random_range(3..=12);
    let mut angles: Vec<f64> = (0..n)
        .map(|k| (k as f64 + uniform(rng, -0.35, 0.35)) * TAU / n as f64)
        .collect();
    angles.sort_by(f64::total_cmp);
    let concave = rng.random::<f64>() < 0.5;
    let mut points: Vec<Vec2> = angles
        .iter()
        .map(|&a| {
            let r = if concave {
                uniform(rng, 0.35, 1.0)
            } else {
                uniform(rng, 0.75, 1.0)
            };
            Vec2::new((r * a.cos()) as f32, (r * a.sin()) as f32)
        })
        .collect();
    for _ in 0..rng.random_range(0..=3u32) {
        points = chaikin(&points);
    }
    let mut points = simplify(&points);
    if signed_area(&points) < 0.0 {
        points.reverse();
    }
    points
}

/// One round of Chaikin corner cutting of a closed polygon.
fn chaikin(points: &[Vec2]) -> Vec<Vec2> {
    let n = points.len();
    (0..n)
        .flat_map(|i| {
            let (p, q) = (points[i], points[(i + 1) % n]);
            [p * 0.75 + q * 0.25, p * 0.25 + q * 0.75]
        })
        .collect()
}

/// Rings of one star-shaped outline stacked along z: ring `k` is the outline scaled by `s_k` at height `z_k`,
/// closed with ear-clipped caps. Outward-facing for a counter-clockwise outline and increasing z.
fn loft(outline: &[Vec2], rings: &[(f64, f64)], shape: &'static str) -> Result<Mesh, ObjectError> {
    let cap = triangulate(outline, shape)?;
    let n = outline.len() as u32;
    let mut vertices = Vec::with_capacity(outline.len() * rings.len());
    for &(z, s) in rings {
        vertices.extend(outline.iter().map(|p| (*p * s as f32).extend(z as f32)));
    }
    let last = (rings.len() as u32 - 1) * n;
    let mut triangles: Vec<[u32; 3]> = cap.iter().map(|&[a, b, c]| [a, c, b]).collect();
    triangles.extend(cap.iter().map(|t| t.map(|i| i + last)));
    for r in 0..rings.len() as u32 - 1 {
        let (lo, hi) = (r * n, (r + 1) * n);
        for i in 0..n {
            let j = (i + 1) % n;
            triangles.push([lo + i, lo + j, hi + j]);
            triangles.push([lo + i, hi + j, hi + i]);
        }
    }
    Mesh::from_raw(vertices, triangles, shape).map_err(mesh_error(shape))
}

/// A random outline extruded upright, its top rim sharp, chamfered or filleted (the outline shrunk towards its
/// centre over the rim's height).
fn extrusion(rng: &mut ChaCha8Rng) -> Result<Mesh, ObjectError> {
    let shape = outline(rng);
    let height = uniform(rng, 0.15, 0.9);
    let rim = uniform(rng, 0.05, 0.25).min(0.5 * height);
    let rings: Vec<(f64, f64)> = match rng.random_range(0..3) {
        0 => vec![(0.0, 1.0), (height, 1.0)],
        1 => vec![(0.0, 1.0), (height - rim, 1.0), (height, 1.0 - rim)],
        _ => {
            let mut r = vec![(0.0, 1.0)];
            r.extend((0..=6).map(|k| {
                let phi = FRAC_PI_2 * f64::from(k) / 6.0;
                (height - rim + rim * phi.sin(), 1.0 - rim + rim * phi.cos())
            }));
            r
        }
    };
    loft(&shape, &rings, "extrusion")
}

/// A random profile extruded along object x, lying on the table (long ones are position-ambiguous along x).
fn lying_extrusion(rng: &mut ChaCha8Rng) -> Result<(Mesh, Symmetry), ObjectError> {
    let profile = outline(rng);
    let length = uniform(rng, 1.0, 4.0);
    let mesh = loft(&profile, &[(0.0, 1.0), (length, 1.0)], "lying_extrusion")?;
    // (u, v, w) -> (x, y, z) = (w, u, v): a proper rotation putting the extrusion axis along x.
    let t = Affine3A::from_mat3(glam::Mat3::from_cols(Vec3::Y, Vec3::Z, Vec3::X));
    let symmetry = Symmetry {
        rotation: RotationSymmetry::None,
        translation_axis: (length > 3.0).then_some([1.0, 0.0]),
    };
    Ok((mesh.transformed(&t), symmetry))
}

fn box_mesh(size: DVec3) -> Result<Mesh, ObjectError> {
    let (x, y) = (0.5 * size.x as f32, 0.5 * size.y as f32);
    let rect = [
        Vec2::new(-x, -y),
        Vec2::new(x, -y),
        Vec2::new(x, y),
        Vec2::new(-x, y),
    ];
    extrude_z(&rect, size.z)
}

fn cylinder_upright(radius: f64, height: f64) -> Result<Mesh, ObjectError> {
    extrude_z(&sweeps::circle(glam::DVec2::ZERO, radius, 48), height)
}

/// A random primitive of size about `s`, centred on the origin.
fn primitive(rng: &mut ChaCha8Rng, s: f64) -> Result<Mesh, ObjectError> {
    let mesh = match rng.random_range(0..4) {
        0 => box_mesh(DVec3::new(
            s * uniform(rng, 0.3, 1.0),
            s * uniform(rng, 0.3, 1.0),
            s * uniform(rng, 0.3, 1.0),
        ))?,
        1 => sphere(0.5 * s * uniform(rng, 0.4, 1.0), 3)?,
        2 => cylinder_upright(0.5 * s * uniform(rng, 0.3, 1.0), s * uniform(rng, 0.3, 1.0))?,
        _ => superquadric(rng)?
            .0
            .transformed(&Affine3A::from_scale(Vec3::splat(0.5 * s as f32))),
    };
    let (lo, hi) = mesh.aabb();
    let rotation = Quat::from_axis_angle(
        unit_vector(rng).as_vec3(),
        (rng.random::<f64>() * TAU) as f32,
    );
    Ok(mesh.transformed(
        &(Affine3A::from_quat(rotation) * Affine3A::from_translation(-0.5 * (lo + hi))),
    ))
}

/// 2–5 overlapping primitives as one soup (self-intersecting, several shells), like a convex decomposition.
fn union(rng: &mut ChaCha8Rng) -> Result<Mesh, ObjectError> {
    let parts = (0..rng.random_range(2..=5))
        .map(|k| {
            let centre = if k == 0 {
                DVec3::ZERO
            } else {
                DVec3::new(
                    uniform(rng, -0.35, 0.35),
                    uniform(rng, -0.35, 0.35),
                    uniform(rng, -0.25, 0.25),
                )
            };
            let s = uniform(rng, 0.35, 0.8);
            Ok(primitive(rng, s)?.transformed(&Affine3A::from_translation(centre.as_vec3())))
        })
        .collect::<Result<Vec<_>, ObjectError>>()?;
    Ok(Mesh::merged(&parts))
}

/// A thin wall (thickness 3–12 % of its size) of random outline standing on edge: contacts are thin lines.
fn fin(rng: &mut ChaCha8Rng) -> Result<Mesh, ObjectError> {
    let shape = outline(rng);
    let thickness = uniform(rng, 0.03, 0.12);
    let wall = loft(&shape, &[(0.0, 1.0), (thickness, 1.0)], "fin")?;
    // Stand it up: object z becomes the outline's y.
    let t = Affine3A::from_mat3(glam::Mat3::from_cols(Vec3::X, Vec3::Z, -Vec3::Y));
    Ok(wall.transformed(&t))
}

/// A block or disc with 1–8 small hemispherical bumps (1–5 mm on a ~40 mm object) on its flat top.
fn bumps(rng: &mut ChaCha8Rng) -> Result<Mesh, ObjectError> {
    let (w, d, h) = (1.0, uniform(rng, 0.5, 1.0), uniform(rng, 0.15, 0.5));
    let base = if rng.random::<f64>() < 0.5 {
        box_mesh(DVec3::new(w, d, h))?
    } else {
        cylinder_upright(0.5 * d, h)?
    };
    let mut parts = vec![base];
    for _ in 0..rng.random_range(1..=8) {
        let r = uniform(rng, 0.025, 0.125);
        let (x, y) = (uniform(rng, -0.3, 0.3) * d, uniform(rng, -0.3, 0.3) * d);
        // sphere() rests on the table (centre at z = r); put its centre 0.3 r below the top face.
        let z = h - 0.3 * r - r;
        parts.push(
            sphere(r, 2)?.transformed(&Affine3A::from_translation(Vec3::new(
                x as f32, y as f32, z as f32,
            ))),
        );
    }
    Ok(Mesh::merged(&parts))
}

/// Objects `0..config.count`, in index order.
pub fn entries(
    config: &ProceduralConfig,
) -> impl Iterator<Item = Result<ProceduralObject, ObjectError>> + '_ {
    (0..config.count).map(move |i| generate(config, i))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn objects_are_reproducible_sized_and_rest_on_the_table() {
        let config = ProceduralConfig {
            count: 90,
            seed: 3,
            ..Default::default()
        };
        let mut kinds = std::collections::BTreeSet::new();
        for i in 0..config.count {
            let o = generate(&config, i).unwrap();
            kinds.insert(o.kind);
            let again = generate(&config, i).unwrap();
            assert_eq!(o.mesh, again.mesh, "object {i} not reproducible");
            let (lo, hi) = o.mesh.aabb();
            let largest = o.mesh.largest_extent();
            assert!(
                largest >= config.extent_m[0] - 1e-6 && largest <= config.extent_m[1] + 1e-6,
                "{}: extent {largest}",
                o.entry.name
            );
            assert!(
                lo.z.abs() < 1e-6 && (lo.x + hi.x).abs() < 1e-6,
                "{}: not rested",
                o.entry.name
            );
            let report = o.mesh.report();
            if o.kind != Kind::Union && o.kind != Kind::Bumps {
                assert!(report.closed, "{}: {report:?}", o.entry.name);
                assert!(
                    report.volume_m3 > 0.0,
                    "{}: inward ({report:?})",
                    o.entry.name
                );
            }
        }
        assert_eq!(kinds.len(), Kind::WEIGHTED.len(), "kinds seen: {kinds:?}");
        let other = generate(
            &ProceduralConfig {
                seed: 4,
                ..config.clone()
            },
            0,
        )
        .unwrap();
        assert_ne!(other.mesh, generate(&config, 0).unwrap().mesh);
    }

    #[test]
    fn kinds_restrict_the_draw() {
        let v1 = ProceduralConfig {
            count: 60,
            seed: 2,
            kinds: Kind::V1.to_vec(),
            ..Default::default()
        };
        for i in 0..v1.count {
            let kind = generate(&v1, i).unwrap().kind;
            assert!(Kind::V1.contains(&kind), "object {i}: {kind:?}");
        }
        let only = ProceduralConfig {
            kinds: vec![Kind::Limbs, Kind::Plate],
            ..v1.clone()
        };
        let kinds: std::collections::BTreeSet<Kind> =
            (0..20).map(|i| generate(&only, i).unwrap().kind).collect();
        assert_eq!(kinds, [Kind::Plate, Kind::Limbs].into());
        let none = ProceduralConfig {
            kinds: vec![],
            ..v1
        };
        assert!(generate(&none, 0).is_err());
    }

    #[test]
    fn superquadric_with_unit_exponents_is_an_ellipsoid() {
        // e1 = e2 = 1: every vertex satisfies (x/a)^2 + (y/b)^2 + (z/c)^2 = 1.
        let (a, b, c) = (0.9, 0.5, 0.3);
        let mesh = radial(3, "test", |d| {
            let f = (d.x / a).powi(2) + (d.y / b).powi(2) + (d.z / c).powi(2);
            f.powf(-0.5)
        })
        .unwrap();
        for v in mesh.vertices() {
            let v = v.as_dvec3();
            let f = (v.x / a).powi(2) + (v.y / b).powi(2) + (v.z / c).powi(2);
            assert!((f - 1.0).abs() < 1e-5, "{f}");
        }
        let expected = 4.0 / 3.0 * PI * a * b * c;
        let rel = (mesh.report().volume_m3 - expected).abs() / expected;
        assert!(rel < 0.02, "volume off by {rel}");
    }

    #[test]
    fn chamfered_extrusion_loses_the_expected_volume() {
        // A unit square extruded to 1 with a 45-degree-free scaled top ring: frustum volume is analytic.
        let square = vec![
            Vec2::new(-1.0, -1.0),
            Vec2::new(1.0, -1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(-1.0, 1.0),
        ];
        let mesh = loft(&square, &[(0.0, 1.0), (0.5, 1.0), (1.0, 0.5)], "test").unwrap();
        let report = mesh.report();
        assert!(report.closed && report.volume_m3 > 0.0, "{report:?}");
        // Prism 4 * 0.5 plus a frustum of height 0.5 between areas 4 and 1.
        let frustum = 0.5 / 3.0 * (4.0 + 1.0 + 2.0);
        assert!(
            (report.volume_m3 - (2.0 + frustum)).abs() < 1e-5,
            "{report:?}"
        );
    }
}
