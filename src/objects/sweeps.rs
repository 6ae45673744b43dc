//! Two more kinds of procedural training objects, for the contacts real parts and scans make that the other kinds
//! do not: **plates with through-holes** (flanges, couplings, brackets, levers, hinges: flat faces broken by bolt
//! circles, central bores and slots, optionally with a stepped hub on top) and **swept limbs** (tubes along curves:
//! knots and rings, bent rods and hooks, and bodies with legs, horns or tails — thin branches that end in the
//! middle of a contact).
//!
//! The geometry builders are exact and closed: [`holed_plate`] triangulates its caps with earcut (outer ring and
//! holes) and walls every ring; [`tube`] sweeps a circle along a polyline with parallel-transported frames (the
//! twist of a closed loop spread evenly over its rings) and caps open ends. The random generators ([`plate`],
//! [`limbs`]) combine them, in the same unit-size convention as the other kinds (largest extent about 2, scaled to
//! the drawn extent afterwards).

use std::f64::consts::{PI, TAU};

use glam::{Affine3A, DVec2, DVec3, Vec2, Vec3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::procedural::{log_uniform, mesh_error, outline, uniform, unit_vector};
use super::shapes::sphere;
use super::triangulate::{signed_area, simplify};
use super::ObjectError;
use crate::mesh::Mesh;

/// A regular `segments`-gon approximating a circle of `radius` about `centre`, counter-clockwise.
pub fn circle(centre: DVec2, radius: f64, segments: usize) -> Vec<Vec2> {
    (0..segments)
        .map(|k| {
            let a = TAU * k as f64 / segments as f64;
            (centre + radius * DVec2::new(a.cos(), a.sin())).as_vec2()
        })
        .collect()
}

/// A slot (stadium: a rectangle of `length` x `2 radius` with round ends) centred on `centre`, its axis at `angle`
/// radians, counter-clockwise.
fn slot(centre: DVec2, length: f64, radius: f64, angle: f64) -> Vec<Vec2> {
    let axis = DVec2::new(angle.cos(), angle.sin());
    let half = 0.5 * length * axis;
    let base = angle - 0.5 * PI;
    let mut points = Vec::with_capacity(26);
    for (end, from) in [(centre + half, base), (centre - half, base + PI)] {
        points.extend((0..=12).map(|k| {
            let a = from + PI * f64::from(k) / 12.0;
            (end + radius * DVec2::new(a.cos(), a.sin())).as_vec2()
        }));
    }
    points
}

/// A plate of `thickness` metres from z = 0 up: the simple polygon `outer` (either orientation) with the simple
/// polygons `holes` cut through it (each strictly inside `outer`, none overlapping another). Closed and outward:
/// caps by earcut, walls around the outer ring and into every hole.
pub fn holed_plate(
    outer: &[Vec2],
    holes: &[Vec<Vec2>],
    thickness: f64,
) -> Result<Mesh, ObjectError> {
    if !(thickness.is_finite() && thickness > 0.0) {
        return Err(ObjectError::BadShape {
            shape: "holed_plate",
            message: format!("thickness must be > 0 m, got {thickness}"),
        });
    }
    // Outer ring counter-clockwise, holes clockwise: then one wall rule faces every wall out of the solid.
    let oriented = |ring: &[Vec2], ccw: bool| -> Result<Vec<Vec2>, ObjectError> {
        let mut ring = simplify(ring);
        if ring.len() < 3 || signed_area(&ring).abs() < 1e-12 {
            return Err(ObjectError::BadShape {
                shape: "holed_plate",
                message: format!("a ring of {} points has no area", ring.len()),
            });
        }
        if (signed_area(&ring) > 0.0) != ccw {
            ring.reverse();
        }
        Ok(ring)
    };
    let mut rings = vec![oriented(outer, true)?];
    for hole in holes {
        rings.push(oriented(hole, false)?);
    }
    let points: Vec<[f64; 2]> = rings
        .iter()
        .flatten()
        .map(|p| [f64::from(p.x), f64::from(p.y)])
        .collect();
    let mut hole_starts = Vec::with_capacity(holes.len());
    let mut start = 0u32;
    for ring in &rings[..rings.len() - 1] {
        start += ring.len() as u32;
        hole_starts.push(start);
    }
    let mut flat: Vec<u32> = Vec::new();
    earcut::Earcut::new().earcut(points.iter().copied(), &hole_starts, &mut flat);
    if flat.is_empty() {
        return Err(ObjectError::BadShape {
            shape: "holed_plate",
            message: "earcut found no triangles (self-intersecting rings?)".into(),
        });
    }
    let n = points.len() as u32;
    let mut vertices: Vec<Vec3> = rings.iter().flatten().map(|p| p.extend(0.0)).collect();
    vertices.extend(rings.iter().flatten().map(|p| p.extend(thickness as f32)));
    let mut triangles = Vec::with_capacity(2 * flat.len() / 3 + 2 * points.len());
    for t in flat.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]];
        let [pa, pb, pc] = [a, b, c].map(|i| DVec2::from(points[i as usize]));
        let ccw = (pb - pa).perp_dot(pc - pa) > 0.0;
        let (b, c) = if ccw { (b, c) } else { (c, b) };
        triangles.push([a + n, b + n, c + n]); // top, facing +z
        triangles.push([a, c, b]); // bottom, facing -z
    }
    let mut base = 0u32;
    for ring in &rings {
        let m = ring.len() as u32;
        for i in 0..m {
            let (lo_i, lo_j) = (base + i, base + (i + 1) % m);
            triangles.push([lo_i, lo_j, lo_j + n]);
            triangles.push([lo_i, lo_j + n, lo_i + n]);
        }
        base += m;
    }
    Mesh::from_raw(vertices, triangles, "holed_plate").map_err(mesh_error("holed_plate"))
}

/// A tube of circular cross-section (`segments` sides) swept along the polyline `path` (at least 2 points, no two
/// consecutive ones equal), of radius `radius(s)` at arc-length fraction `s` in 0..=1. A `closed` path joins its
/// last point to its first (a ring or knot); an open one gets flat end caps. Frames are parallel-transported along
/// the path, so the tube does not twist; a closed loop's leftover twist is spread evenly over its rings.
pub fn tube(
    path: &[DVec3],
    radius: impl Fn(f64) -> f64,
    closed: bool,
    segments: usize,
) -> Result<Mesh, ObjectError> {
    let bad = |message: String| ObjectError::BadShape {
        shape: "tube",
        message,
    };
    let n = path.len();
    if n < 2 || segments < 3 {
        return Err(bad(format!(
            "needs at least 2 path points and 3 segments, got {n} and {segments}"
        )));
    }
    let next = |i: usize| {
        if closed {
            (i + 1) % n
        } else {
            (i + 1).min(n - 1)
        }
    };
    let prev = |i: usize| {
        if closed {
            (i + n - 1) % n
        } else {
            i.saturating_sub(1)
        }
    };
    let mut tangents = Vec::with_capacity(n);
    for i in 0..n {
        let t = (path[next(i)] - path[prev(i)]).try_normalize();
        tangents.push(t.ok_or_else(|| bad(format!("path point {i} repeats its neighbours")))?);
    }
    // Arc length for the radius profile.
    let mut arc = vec![0.0; n];
    for i in 1..n {
        arc[i] = arc[i - 1] + path[i].distance(path[i - 1]);
    }
    let total = arc[n - 1].max(1e-12);
    // Parallel transport: project the previous normal onto the new normal plane.
    let t0 = tangents[0];
    let seed = if t0.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let mut normals = vec![(seed - seed.dot(t0) * t0).normalize()];
    for i in 1..n {
        let t = tangents[i];
        let p = normals[i - 1] - normals[i - 1].dot(t) * t;
        normals.push(
            p.try_normalize()
                .unwrap_or_else(|| t.any_orthonormal_vector()),
        );
    }
    let twist = if closed {
        // Transport once more round to the start and measure the angle it comes back rotated by.
        let back = normals[n - 1] - normals[n - 1].dot(t0) * t0;
        let back = back.try_normalize().unwrap_or(normals[0]);
        let b0 = t0.cross(normals[0]);
        back.dot(b0).atan2(back.dot(normals[0]))
    } else {
        0.0
    };
    let mut vertices = Vec::with_capacity(n * segments + 2);
    for i in 0..n {
        let t = tangents[i];
        let spread = -twist * i as f64 / n as f64;
        let (s, c) = spread.sin_cos();
        let b = t.cross(normals[i]);
        let (nn, bb) = (c * normals[i] + s * b, c * b - s * normals[i]);
        let r = radius(arc[i] / total);
        if !(r.is_finite() && r > 0.0) {
            return Err(bad(format!("radius at point {i} must be > 0, got {r}")));
        }
        for k in 0..segments {
            let a = TAU * k as f64 / segments as f64;
            vertices.push((path[i] + r * (a.cos() * nn + a.sin() * bb)).as_vec3());
        }
    }
    let seg = segments as u32;
    let ring = |i: usize, k: u32| i as u32 * seg + k % seg;
    let mut triangles = Vec::with_capacity(2 * n * segments + 2 * segments);
    let spans = if closed { n } else { n - 1 };
    for i in 0..spans {
        let j = (i + 1) % n;
        for k in 0..seg {
            triangles.push([ring(i, k), ring(i, k + 1), ring(j, k + 1)]);
            triangles.push([ring(i, k), ring(j, k + 1), ring(j, k)]);
        }
    }
    if !closed {
        let (first, last) = (vertices.len() as u32, vertices.len() as u32 + 1);
        vertices.push(path[0].as_vec3());
        vertices.push(path[n - 1].as_vec3());
        for k in 0..seg {
            triangles.push([first, ring(0, k + 1), ring(0, k)]);
            triangles.push([last, ring(n - 1, k), ring(n - 1, k + 1)]);
        }
    }
    Mesh::from_raw(vertices, triangles, "tube").map_err(mesh_error("tube"))
}

fn point_in_polygon(p: DVec2, polygon: &[Vec2]) -> bool {
    let mut inside = false;
    let n = polygon.len();
    for i in 0..n {
        let (a, b) = (polygon[i].as_dvec2(), polygon[(i + n - 1) % n].as_dvec2());
        if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) {
            inside = !inside;
        }
    }
    inside
}

fn distance_to_polygon(p: DVec2, polygon: &[Vec2]) -> f64 {
    let n = polygon.len();
    (0..n)
        .map(|i| {
            let (a, b) = (polygon[i].as_dvec2(), polygon[(i + 1) % n].as_dvec2());
            let ab = b - a;
            let t = ((p - a).dot(ab) / ab.length_squared().max(1e-18)).clamp(0.0, 1.0);
            p.distance(a + t * ab)
        })
        .fold(f64::INFINITY, f64::min)
}

/// A flat part with through-holes: a disc or a random outline, pierced by a bolt circle (with or without a central
/// bore), scattered round holes, or slots; two in five get a stepped hub on top (sharing the central bore).
pub fn plate(rng: &mut ChaCha8Rng) -> Result<Mesh, ObjectError> {
    let outer = if rng.random::<f64>() < 0.4 {
        circle(DVec2::ZERO, 1.0, 64)
    } else {
        outline(rng)
    };
    let thickness = log_uniform(rng, 0.06, 0.4);
    let margin = 0.05;
    // Circles (centre, radius) that must stay apart; slots are kept as polygons with a bounding circle.
    let mut holes: Vec<(DVec2, f64, Vec<Vec2>)> = Vec::new();
    let fits = |holes: &[(DVec2, f64, Vec<Vec2>)], c: DVec2, r: f64| {
        point_in_polygon(c, &outer)
            && distance_to_polygon(c, &outer) > r + margin
            && holes
                .iter()
                .all(|(o, ro, _)| o.distance(c) > r + ro + margin)
    };
    let central = rng.random::<f64>() < 0.5;
    if central {
        let r = uniform(rng, 0.08, 0.3);
        if fits(&holes, DVec2::ZERO, r) {
            holes.push((DVec2::ZERO, r, circle(DVec2::ZERO, r, 32)));
        }
    }
    match rng.random_range(0..3) {
        0 => {
            // Bolt circle.
            let count = rng.random_range(3..=8);
            let ring = uniform(rng, 0.4, 0.8);
            let r = uniform(rng, 0.04, 0.12).min(0.8 * ring * (PI / count as f64).sin());
            let phase = uniform(rng, 0.0, TAU);
            for k in 0..count {
                let a = phase + TAU * k as f64 / count as f64;
                let c = ring * DVec2::new(a.cos(), a.sin());
                if fits(&holes, c, r) {
                    holes.push((c, r, circle(c, r, 20)));
                }
            }
        }
        1 => {
            for _ in 0..rng.random_range(1..=6) {
                let r = log_uniform(rng, 0.04, 0.25);
                for _ in 0..30 {
                    let c = DVec2::new(uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0));
                    if fits(&holes, c, r) {
                        holes.push((c, r, circle(c, r, 24)));
                        break;
                    }
                }
            }
        }
        _ => {
            for _ in 0..rng.random_range(1..=3) {
                let (length, r) = (uniform(rng, 0.15, 0.6), uniform(rng, 0.04, 0.12));
                let angle = uniform(rng, 0.0, PI);
                for _ in 0..30 {
                    let c = DVec2::new(uniform(rng, -0.8, 0.8), uniform(rng, -0.8, 0.8));
                    if fits(&holes, c, 0.5 * length + r) {
                        holes.push((c, 0.5 * length + r, slot(c, length, r, angle)));
                        break;
                    }
                }
            }
        }
    }
    let base = holed_plate(
        &outer,
        &holes.iter().map(|h| h.2.clone()).collect::<Vec<_>>(),
        thickness,
    )?;
    if rng.random::<f64>() >= 0.4 {
        return Ok(base);
    }
    // Stepped hub: a disc on top that keeps clear of every hole but the central bore, which goes through it.
    let mut hub_r = uniform(rng, 0.25, 0.6).min(distance_to_polygon(DVec2::ZERO, &outer) - margin);
    for (c, r, _) in &holes {
        if c.length() > 1e-9 {
            hub_r = hub_r.min(c.length() - r - margin);
        }
    }
    let bore: Vec<Vec<Vec2>> = holes
        .iter()
        .filter(|(c, r, _)| c.length() < 1e-9 && *r < hub_r - margin)
        .map(|h| h.2.clone())
        .collect();
    if hub_r < 0.12 || !point_in_polygon(DVec2::ZERO, &outer) {
        return Ok(base);
    }
    let height = uniform(rng, 0.1, 0.5);
    let hub = holed_plate(&circle(DVec2::ZERO, hub_r, 48), &bore, height)?.transformed(
        &Affine3A::from_translation(Vec3::new(0.0, 0.0, thickness as f32)),
    );
    Ok(Mesh::merged(&[base, hub]))
}

/// A smooth random curve from `from` heading along `direction`, `length` long, bending by up to `bend` radians
/// over its length, as `points` points.
fn bent_path(
    rng: &mut ChaCha8Rng,
    from: DVec3,
    direction: DVec3,
    length: f64,
    bend: f64,
    points: usize,
) -> Vec<DVec3> {
    let side = direction.any_orthonormal_vector();
    let axis = direction.cross(side);
    let rotation = uniform(rng, 0.0, TAU);
    let (s, c) = rotation.sin_cos();
    let bend_dir = c * side + s * axis;
    let curl = uniform(rng, -1.0, 1.0) * bend;
    let step = length / (points - 1) as f64;
    let mut p = from;
    let mut out = vec![p];
    for i in 1..points {
        let f = i as f64 / (points - 1) as f64;
        let angle = curl * f;
        let heading = angle.cos() * direction + angle.sin() * bend_dir;
        p += step * heading;
        out.push(p);
    }
    out
}

/// Tubes: a ring or torus knot, a bent rod or hook with capped ends, or a body (ellipsoid) with 2–8 tapering limbs
/// (legs, horns, tails) radiating from it.
pub fn limbs(rng: &mut ChaCha8Rng) -> Result<Mesh, ObjectError> {
    match rng.random_range(0..3) {
        0 => {
            let (p, q) = [(1, 0), (2, 3), (2, 5), (3, 4), (3, 5)][rng.random_range(0..5)];
            let a = if q == 0 { 0.0 } else { uniform(rng, 0.3, 0.5) };
            let r = uniform(rng, 0.1, 0.25);
            let n = 96 * p.max(1);
            let path: Vec<DVec3> = (0..n)
                .map(|i| {
                    let phi = TAU * i as f64 / n as f64;
                    let rho = 1.0 + a * (f64::from(q) * phi).cos();
                    let pf = f64::from(p);
                    DVec3::new(
                        rho * (pf * phi).cos(),
                        rho * (pf * phi).sin(),
                        -a * (f64::from(q) * phi).sin(),
                    )
                })
                .collect();
            tube(&path, |_| r, true, 20)
        }
        1 => {
            // At the smallest extents (15 mm) a thinner rod could not make a contact a pixel wide.
            let r = uniform(rng, 0.1, 0.25);
            let taper = uniform(rng, 0.5, 1.0);
            let bend = uniform(rng, 0.0, 2.5);
            let path = bent_path(rng, DVec3::new(-1.0, 0.0, 0.0), DVec3::X, 2.0, bend, 48);
            tube(&path, |s| r * (1.0 - (1.0 - taper) * s), false, 20)
        }
        _ => {
            let body = DVec3::new(
                uniform(rng, 0.25, 0.6),
                uniform(rng, 0.2, 0.5),
                uniform(rng, 0.15, 0.4),
            );
            let mut parts = vec![sphere(1.0, 3)?
                .transformed(&Affine3A::from_scale(body.as_vec3()))
                .transformed(&Affine3A::from_translation(Vec3::new(
                    0.0,
                    0.0,
                    -body.z as f32,
                )))];
            for _ in 0..rng.random_range(2..=8) {
                // Sideways or down (legs, tails, horns on a lying body): a limb pointing up would be all a press
                // touched, its tip too thin to make a contact a pixel wide.
                let mut d = unit_vector(rng);
                d.z = -0.4 * d.z.abs();
                let d = d.try_normalize().unwrap_or(DVec3::X);
                let length = uniform(rng, 0.5, 1.2);
                let r = uniform(rng, 0.05, 0.14);
                let tip = uniform(rng, 0.5, 1.0);
                let bend = uniform(rng, 0.0, 1.5);
                let path = bent_path(rng, DVec3::ZERO, d, length, bend, 24);
                parts.push(tube(&path, |s| r * (1.0 - (1.0 - tip) * s), false, 12)?);
            }
            Ok(Mesh::merged(&parts))
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn holed_plate_is_closed_with_the_area_of_its_rings_times_its_thickness() {
        let outer = circle(DVec2::ZERO, 1.0, 64);
        let holes = vec![
            circle(DVec2::new(0.5, 0.0), 0.2, 24),
            slot(DVec2::new(-0.4, 0.2), 0.4, 0.1, 0.7),
            circle(DVec2::ZERO, 0.15, 16),
        ];
        let mesh = holed_plate(&outer, &holes, 0.25).unwrap();
        let report = mesh.report();
        assert!(report.closed, "{report:?}");
        let area = signed_area(&outer) - holes.iter().map(|h| signed_area(h).abs()).sum::<f64>();
        let expected = area * 0.25;
        assert!(
            (report.volume_m3 - expected).abs() < 1e-5 * expected,
            "{} vs {expected}",
            report.volume_m3
        );
        // A ray down the middle of a hole passes through; one beside it hits the top.
        let caster = crate::mesh::query::RayCaster::new(&mesh).unwrap();
        let down = Vec3::new(0.0, 0.0, -1.0);
        assert!(caster.cast(Vec3::new(0.5, 0.0, 1.0), down, 10.0).is_none());
        let hit = caster.cast(Vec3::new(0.5, 0.3, 1.0), down, 10.0).unwrap();
        assert!((hit - 0.75).abs() < 1e-5, "{hit}");
    }

    #[test]
    fn a_ring_tube_has_the_volume_of_pappus() {
        // A circle of radius R swept by a disc of radius r: V = 2 pi^2 R r^2 (inscribed polygons: slightly less).
        let (big, small, n, segments) = (1.0, 0.2, 256, 48);
        let path: Vec<DVec3> = (0..n)
            .map(|i| {
                let a = TAU * i as f64 / n as f64;
                DVec3::new(big * a.cos(), big * a.sin(), 0.0)
            })
            .collect();
        let mesh = tube(&path, |_| small, true, segments).unwrap();
        let report = mesh.report();
        assert!(report.closed, "{report:?}");
        let expected = 2.0 * PI * PI * big * small * small;
        let rel = (report.volume_m3 - expected) / expected;
        assert!((-0.01..0.0).contains(&rel), "volume off by {rel}");
    }

    #[test]
    fn an_open_tapered_tube_is_a_closed_frustum() {
        // Straight path: a frustum of radii 0.3 -> 0.1 over length 2, V = pi h (R^2 + R r + r^2) / 3.
        let path: Vec<DVec3> = (0..11)
            .map(|i| DVec3::new(0.2 * i as f64, 0.0, 0.0))
            .collect();
        let mesh = tube(&path, |s| 0.3 - 0.2 * s, false, 64).unwrap();
        let report = mesh.report();
        assert!(report.closed && report.volume_m3 > 0.0, "{report:?}");
        let expected = PI * 2.0 * (0.09 + 0.03 + 0.01) / 3.0;
        let rel = (report.volume_m3 - expected) / expected;
        assert!((-0.01..0.0).contains(&rel), "volume off by {rel}");
    }

    #[test]
    fn bad_rings_and_paths_are_errors() {
        assert!(holed_plate(&circle(DVec2::ZERO, 1.0, 8), &[], 0.0).is_err());
        let line = vec![Vec2::ZERO, Vec2::X, Vec2::new(2.0, 0.0)];
        assert!(holed_plate(&line, &[], 0.1).is_err());
        let stuck = vec![DVec3::ZERO, DVec3::ZERO];
        assert!(tube(&stuck, |_| 0.1, false, 8).is_err());
        let path = vec![DVec3::ZERO, DVec3::X];
        assert!(tube(&path, |_| -1.0, false, 8).is_err());
    }
}
