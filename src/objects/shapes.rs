//! Procedural object meshes for the object library (paper V.A): closed, outward-oriented triangle meshes in metres,
//! each returned in its resting pose (lowest point at z = 0, bounding box centred on the z axis).
//!
//! Lying shapes (cylinders, prisms) have their axis along object x; extruded outlines (crosses) are extruded along z;
//! bodies of revolution (spheres, bullets) have their axis along z. Curved surfaces are inscribed polygons, so
//! volumes are slightly below the analytic ones (by about (2*pi/segments)^2 / 6 relative).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use glam::{Affine3A, Mat3, Vec2, Vec3};

use super::triangulate::{signed_area, simplify, triangulate};
use super::ObjectError;
use crate::mesh::Mesh;

/// A polygon outline extruded along z from z = 0 to `height` metres, then rested on the table. `polygon` is a simple
/// (possibly concave) outline in the xy plane, metres, either orientation; duplicate and collinear points are removed.
pub fn extrude_z(polygon: &[Vec2], height: f64) -> Result<Mesh, ObjectError> {
    Ok(extrude(polygon, height, "extrude_z")?.rest_on_table())
}

/// A prism lying on the table: `profile` is a simple (possibly concave) outline in the object's (y, z) plane, metres,
/// extruded over `length` metres along object x, then rested on the table.
pub fn prism_lying(profile: &[Vec2], length: f64) -> Result<Mesh, ObjectError> {
    let mesh = extrude(profile, length, "prism_lying")?;
    // (u, v, w) -> (x, y, z) = (w, u, v): a cyclic permutation, i.e. a proper rotation (determinant +1).
    let t_object_extrusion = Affine3A::from_mat3(Mat3::from_cols(Vec3::Y, Vec3::Z, Vec3::X));
    Ok(mesh.transformed(&t_object_extrusion).rest_on_table())
}

/// A circular cylinder of `radius` and `length` metres lying on the table, axis along object x. The cross-section is
/// a regular `segments`-gon (at least 3; a multiple of 4 keeps a vertex at the bottom, top and sides).
pub fn cylinder_lying(radius: f64, length: f64, segments: u32) -> Result<Mesh, ObjectError> {
    positive("cylinder_lying", "radius", radius)?;
    positive("cylinder_lying", "length", length)?;
    at_least("cylinder_lying", "segments", segments, 3)?;
    let profile: Vec<Vec2> = (0..segments)
        .map(|k| {
            let angle = -FRAC_PI_2 + TAU * f64::from(k) / f64::from(segments);
            Vec2::new((radius * angle.cos()) as f32, (radius * angle.sin()) as f32)
        })
        .collect();
    prism_lying(&profile, length)
}

/// A sphere of `radius` metres: an icosahedron with a vertex at each pole, subdivided `subdivisions` times (each
/// quadruples the 20 faces; 3 gives 1280 triangles) and projected onto the sphere.
pub fn sphere(radius: f64, subdivisions: u32) -> Result<Mesh, ObjectError> {
    positive("sphere", "radius", radius)?;
    if subdivisions > 6 {
        return Err(ObjectError::BadShape {
            shape: "sphere",
            message: format!(
                "{subdivisions} subdivisions is too many (81920+ triangles); use at most 6"
            ),
        });
    }
    let (vertices, triangles) = icosphere_directions(subdivisions);
    let vertices = vertices.iter().map(|v| (*v * radius).as_vec3()).collect();
    Ok(Mesh::from_raw(vertices, triangles, "sphere")
        .map_err(mesh_error("sphere"))?
        .rest_on_table())
}

/// A bullet standing upright: a cylinder of `radius` from z = 0 to `body_length` metres, capped with a hemisphere on
/// top (total height `body_length + radius`) and a flat bottom. `segments` (at least 4) is the number of sides around
/// z; the hemisphere gets `segments / 4` rings so its facets are about square.
pub fn bullet(radius: f64, body_length: f64, segments: u32) -> Result<Mesh, ObjectError> {
    positive("bullet", "radius", radius)?;
    positive("bullet", "body_length", body_length)?;
    at_least("bullet", "segments", segments, 4)?;
    let rings = (segments / 4).max(1);
    let mut profile = vec![(0.0, 0.0), (radius, 0.0)];
    profile.extend((0..rings).map(|k| {
        let phi = FRAC_PI_2 * f64::from(k) / f64::from(rings);
        (radius * phi.cos(), body_length + radius * phi.sin())
    }));
    profile.push((0.0, body_length + radius));
    Ok(revolve(&profile, segments, "bullet")?.rest_on_table())
}

/// Outline of a plus-shaped cross in the xy plane, counter-clockwise: four arms of `arm_width` metres, tip to tip
/// `span` metres. With `arc_segments = None` the arm ends are square; with `Some(k)` they are semicircles of radius
/// `arm_width / 2` made of `k` segments. Requires `span > 2 * arm_width`.
pub fn cross_outline(
    arm_width: f64,
    span: f64,
    arc_segments: Option<u32>,
) -> Result<Vec<Vec2>, ObjectError> {
    positive("cross", "arm_width", arm_width)?;
    positive("cross", "span", span)?;
    if span <= 2.0 * arm_width {
        return Err(ObjectError::BadShape {
            shape: "cross",
            message: format!("span {span} m must exceed twice the arm width {arm_width} m"),
        });
    }
    let (a, s) = (0.5 * arm_width, 0.5 * span);
    // One arm along +x, counter-clockwise from its lower end to the inner corner that leads to the +y arm.
    let mut arm: Vec<(f64, f64)> = match arc_segments {
        None => vec![(s, -a), (s, a)],
        Some(k) => {
            let k = k.max(2);
            (0..=k)
                .map(|i| {
                    let angle = -FRAC_PI_2 + PI * f64::from(i) / f64::from(k);
                    (s - a + a * angle.cos(), a * angle.sin())
                })
                .collect()
        }
    };
    arm.push((a, a));
    // Rotating by 90 degrees maps (x, y) to (-y, x).
    let outline = (0..4)
        .flat_map(|quarter| {
            arm.iter().map(move |&(x, y)| {
                let (x, y) = (0..quarter).fold((x, y), |(x, y), _| (-y, x));
                Vec2::new(x as f32, y as f32)
            })
        })
        .collect();
    Ok(outline)
}

/// A plus-shaped cross with square arm ends (see [`cross_outline`]), extruded to `height` metres with a flat top.
pub fn cross(arm_width: f64, span: f64, height: f64) -> Result<Mesh, ObjectError> {
    extrude_z(&cross_outline(arm_width, span, None)?, height)
}

/// A plus-shaped cross whose arm ends are semicircles of `arc_segments` segments (see [`cross_outline`]), extruded
/// to `height` metres with a flat top.
pub fn round_cross(
    arm_width: f64,
    span: f64,
    height: f64,
    arc_segments: u32,
) -> Result<Mesh, ObjectError> {
    extrude_z(&cross_outline(arm_width, span, Some(arc_segments))?, height)
}

/// Extrude an outline along +z from 0 to `height` (not rested). Bottom ring vertices are `0..n`, top ring `n..2n`.
fn extrude(polygon: &[Vec2], height: f64, shape: &'static str) -> Result<Mesh, ObjectError> {
    positive(shape, "height/length", height)?;
    let mut outline = simplify(polygon);
    if outline.len() >= 3 && signed_area(&outline) < 0.0 {
        outline.reverse();
    }
    let cap = triangulate(&outline, shape)?;
    let n = outline.len() as u32;
    let h = height as f32;
    let mut vertices: Vec<Vec3> = outline.iter().map(|p| p.extend(0.0)).collect();
    vertices.extend(outline.iter().map(|p| p.extend(h)));
    let mut triangles = Vec::with_capacity(2 * cap.len() + 2 * n as usize);
    // Top cap counter-clockwise seen from +z; bottom cap reversed (seen from -z).
    triangles.extend(cap.iter().map(|t| t.map(|i| i + n)));
    triangles.extend(cap.iter().map(|&[a, b, c]| [a, c, b]));
    for i in 0..n {
        let j = (i + 1) % n;
        // The wall to the right of edge i -> j of a counter-clockwise outline faces outwards.
        triangles.push([i, j, j + n]);
        triangles.push([i, j + n, i + n]);
    }
    Mesh::from_raw(vertices, triangles, shape).map_err(mesh_error(shape))
}

/// Surface of revolution about z of a profile `(r, z)` in metres that starts and ends on the axis (r = 0) and runs
/// bottom to top around the outside. Points on the axis become single pole vertices.
fn revolve(
    profile: &[(f64, f64)],
    segments: u32,
    shape: &'static str,
) -> Result<Mesh, ObjectError> {
    let mut vertices = Vec::new();
    // For each profile point, the index of its ring's first vertex and whether it is a pole.
    let mut rings: Vec<(u32, bool)> = Vec::with_capacity(profile.len());
    for &(r, z) in profile {
        let pole = r <= 0.0;
        rings.push((vertices.len() as u32, pole));
        let count = if pole { 1 } else { segments };
        vertices.extend((0..count).map(|k| {
            let angle = TAU * f64::from(k) / f64::from(segments);
            Vec3::new((r * angle.cos()) as f32, (r * angle.sin()) as f32, z as f32)
        }));
    }
    let index =
        |(start, pole): (u32, bool), k: u32| if pole { start } else { start + k % segments };
    let mut triangles = Vec::new();
    for pair in rings.windows(2) {
        let (lower, upper) = (pair[0], pair[1]);
        for k in 0..segments {
            let [a, b] = [index(lower, k), index(lower, k + 1)];
            let [d, c] = [index(upper, k), index(upper, k + 1)];
            // Quad a -> b (around +z) -> c -> d (up the profile) has its normal t_theta x t_profile: outwards.
            if !lower.1 {
                triangles.push([a, b, c]);
            }
            if !upper.1 {
                triangles.push([a, c, d]);
            }
        }
    }
    Mesh::from_raw(vertices, triangles, shape).map_err(mesh_error(shape))
}

/// Unit vectors of an icosphere (an icosahedron subdivided `subdivisions` times, 20 * 4^k outward triangles), for
/// star-shaped surfaces built by moving each direction to its radius.
pub(crate) fn icosphere_directions(subdivisions: u32) -> (Vec<glam::DVec3>, Vec<[u32; 3]>) {
    let (mut vertices, mut triangles) = icosahedron();
    for _ in 0..subdivisions {
        (vertices, triangles) = subdivide(&vertices, &triangles);
    }
    (vertices, triangles)
}

/// Unit icosahedron with vertices at the poles and two staggered rings of five (centrally symmetric, so the
/// bounding box of every subdivision is centred on the origin).
fn icosahedron() -> (Vec<glam::DVec3>, Vec<[u32; 3]>) {
    let z = 1.0 / 5f64.sqrt();
    let r = 2.0 * z;
    let ring = |offset: f64, z: f64| {
        (0..5).map(move |k| {
            let angle = TAU * (f64::from(k) + offset) / 5.0;
            glam::DVec3::new(r * angle.cos(), r * angle.sin(), z)
        })
    };
    let mut vertices = vec![glam::DVec3::Z];
    vertices.extend(ring(0.0, z)); // 1..=5
    vertices.extend(ring(0.5, -z)); // 6..=10
    vertices.push(-glam::DVec3::Z); // 11
    let mut triangles = Vec::with_capacity(20);
    for k in 0..5u32 {
        let (u0, u1) = (1 + k, 1 + (k + 1) % 5);
        let (l0, l1) = (6 + k, 6 + (k + 1) % 5);
        triangles.push([0, u0, u1]);
        triangles.push([u0, l0, u1]);
        triangles.push([u1, l0, l1]);
        triangles.push([11, l1, l0]);
    }
    (vertices, triangles)
}

/// Split every triangle into four at its edge midpoints (shared between neighbours) and project onto the unit sphere.
fn subdivide(
    vertices: &[glam::DVec3],
    triangles: &[[u32; 3]],
) -> (Vec<glam::DVec3>, Vec<[u32; 3]>) {
    let mut vertices = vertices.to_vec();
    let mut midpoints = std::collections::HashMap::new();
    let mut midpoint = |a: u32, b: u32| {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            vertices.push((vertices[a as usize] + vertices[b as usize]).normalize());
            (vertices.len() - 1) as u32
        })
    };
    let mut out = Vec::with_capacity(triangles.len() * 4);
    for &[a, b, c] in triangles {
        let (ab, bc, ca) = (midpoint(a, b), midpoint(b, c), midpoint(c, a));
        out.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    (vertices, out)
}

fn positive(shape: &'static str, what: &str, value: f64) -> Result<(), ObjectError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ObjectError::BadShape {
            shape,
            message: format!("{what} must be a positive number of metres, got {value}"),
        })
    }
}

fn at_least(shape: &'static str, what: &str, value: u32, min: u32) -> Result<(), ObjectError> {
    if value >= min {
        Ok(())
    } else {
        Err(ObjectError::BadShape {
            shape,
            message: format!("{what} must be at least {min}, got {value}"),
        })
    }
}

fn mesh_error(shape: &'static str) -> impl Fn(crate::mesh::MeshError) -> ObjectError {
    move |source| ObjectError::Mesh {
        name: shape.to_string(),
        source,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// Closed, outward, resting on the table, and volume within `rel_tol` of `expected` m³.
    fn check(mesh: &Mesh, expected: f64, rel_tol: f64) {
        let report = mesh.report();
        assert!(report.closed, "{report:?}");
        let rel = (report.volume_m3 - expected).abs() / expected;
        assert!(
            rel < rel_tol,
            "volume {} vs {expected} (rel {rel})",
            report.volume_m3
        );
        let (lo, hi) = mesh.aabb();
        assert!(lo.z.abs() < 1e-6, "lowest z {}", lo.z);
        assert!(
            (lo.x + hi.x).abs() < 1e-6 && (lo.y + hi.y).abs() < 1e-6,
            "not centred: {lo} {hi}"
        );
    }

    #[test]
    fn cylinder_matches_polygon_and_analytic_volume() {
        let (r, l, n) = (0.015, 0.09, 64);
        let mesh = cylinder_lying(r, l, n).unwrap();
        let polygon = 0.5 * f64::from(n) * r * r * (TAU / f64::from(n)).sin() * l;
        check(&mesh, polygon, 1e-5);
        check(&mesh, PI * r * r * l, 2e-3);
        let (lo, hi) = mesh.aabb();
        assert!(((hi - lo).x - l as f32).abs() < 1e-6 && ((hi.z) - 2.0 * r as f32).abs() < 1e-6);
    }

    #[test]
    fn prisms_have_exact_volume() {
        let triangle = [
            Vec2::new(-0.0125, 0.0),
            Vec2::new(0.0125, 0.0),
            Vec2::new(0.0, 0.02),
        ];
        check(
            &prism_lying(&triangle, 0.09).unwrap(),
            0.5 * 0.025 * 0.02 * 0.09,
            1e-5,
        );
        // Concave (U-shaped) profile, given clockwise.
        let u = [
            (0.0, 0.0),
            (0.0, 0.02),
            (0.01, 0.02),
            (0.01, 0.01),
            (0.02, 0.01),
            (0.02, 0.02),
            (0.03, 0.02),
        ];
        let mut u: Vec<Vec2> = u.iter().map(|&(y, z)| Vec2::new(y, z)).collect();
        u.push(Vec2::new(0.03, 0.0));
        check(
            &prism_lying(&u, 0.05).unwrap(),
            (0.03 * 0.02 - 0.01 * 0.01) * 0.05,
            1e-5,
        );
    }

    #[test]
    fn sphere_and_bullet_volumes() {
        let r = 0.02;
        let s = sphere(r, 3).unwrap();
        assert_eq!(s.triangles().len(), 1280);
        check(&s, 4.0 / 3.0 * PI * r * r * r, 0.02);
        assert!((s.aabb().1.z - 2.0 * r as f32).abs() < 1e-6);
        let (r, body) = (0.01, 0.02);
        let b = bullet(r, body, 48).unwrap();
        check(&b, PI * r * r * body + 2.0 / 3.0 * PI * r * r * r, 0.01);
        assert!((b.aabb().1.z - (r + body) as f32).abs() < 1e-6);
    }

    #[test]
    fn crosses_have_expected_volume() {
        let (w, s, h) = (0.012, 0.05, 0.02);
        check(&cross(w, s, h).unwrap(), (2.0 * w * s - w * w) * h, 1e-5);
        let a = w / 2.0;
        let area = 4.0 * a * a + 8.0 * a * (s / 2.0 - 2.0 * a) + 2.0 * PI * a * a;
        let round = round_cross(w, s, h, 16).unwrap();
        check(&round, area * h, 3e-3);
        let (lo, hi) = round.aabb();
        assert!(((hi - lo).x - s as f32).abs() < 1e-6 && ((hi - lo).y - s as f32).abs() < 1e-6);
    }

    #[test]
    fn bad_parameters_are_errors() {
        assert!(cylinder_lying(-0.01, 0.1, 32).is_err());
        assert!(cylinder_lying(0.01, 0.1, 2).is_err());
        assert!(sphere(f64::NAN, 2).is_err());
        let err = cross(0.02, 0.03, 0.01).unwrap_err().to_string();
        assert!(err.contains("span"), "{err}");
    }
}
