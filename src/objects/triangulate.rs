//! Ear-clipping triangulation of simple (possibly concave) polygons: the flat caps of extruded object meshes (object
//! library, paper V.A). Polygons are 2D outlines in metres; orientation of the input does not matter.

use glam::{DVec2, Vec2};

use super::ObjectError;

/// Signed area of a polygon in m² (shoelace formula): positive for counter-clockwise outlines.
pub fn signed_area(polygon: &[Vec2]) -> f64 {
    let n = polygon.len();
    (0..n)
        .map(|i| {
            let a = polygon[i].as_dvec2();
            let b = polygon[(i + 1) % n].as_dvec2();
            a.perp_dot(b)
        })
        .sum::<f64>()
        * 0.5
}

/// Remove consecutive duplicate vertices and vertices lying on the straight line through their neighbours, so that
/// every remaining vertex is a true corner. The closing edge (last to first) is considered too.
pub fn simplify(polygon: &[Vec2]) -> Vec<Vec2> {
    let scale = extent_squared(polygon);
    let mut points: Vec<Vec2> = polygon.to_vec();
    loop {
        let n = points.len();
        if n < 3 {
            return points;
        }
        let redundant = (0..n).find(|&i| {
            let a = points[(i + n - 1) % n].as_dvec2();
            let b = points[i].as_dvec2();
            let c = points[(i + 1) % n].as_dvec2();
            a == b || (b - a).perp_dot(c - b).abs() <= 1e-12 * scale
        });
        match redundant {
            Some(i) => {
                points.remove(i);
            }
            None => return points,
        }
    }
}

/// Triangulate a simple polygon (no self-intersections, no holes) by ear clipping, O(n³) worst case. Returns
/// triangles as indices into `polygon`, each counter-clockwise (positive area) in the xy plane whatever the input
/// orientation; their areas sum to the polygon's area. Collinear vertices that cannot be part of any ear are skipped.
///
/// ```
/// use glam::Vec2;
/// use tactile_derender::objects::triangulate::triangulate;
/// let square = [Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)];
/// assert_eq!(triangulate(&square, "square").map(|t| t.len()).ok(), Some(2));
/// ```
pub fn triangulate(polygon: &[Vec2], context: &str) -> Result<Vec<[u32; 3]>, ObjectError> {
    let fail = |message: String| ObjectError::BadPolygon {
        context: context.to_string(),
        message,
    };
    let n = polygon.len();
    if n < 3 {
        return Err(fail(format!("it has {n} vertices; pass at least 3")));
    }
    if let Some(i) = polygon.iter().position(|p| !p.is_finite()) {
        return Err(fail(format!(
            "vertex {i} is not finite; remove NaN/inf coordinates"
        )));
    }
    let area = signed_area(polygon);
    let eps = 1e-12 * extent_squared(polygon);
    if area.abs() <= eps {
        return Err(fail(
            "it has zero area; pass a non-degenerate outline".into(),
        ));
    }
    let points: Vec<DVec2> = polygon.iter().map(|p| p.as_dvec2()).collect();
    let mut remaining: Vec<usize> = if area > 0.0 {
        (0..n).collect()
    } else {
        (0..n).rev().collect()
    };
    let mut triangles = Vec::with_capacity(n - 2);
    while remaining.len() > 3 {
        let m = remaining.len();
        let corner = |i: usize| {
            let (p, c, q) = (
                remaining[(i + m - 1) % m],
                remaining[i],
                remaining[(i + 1) % m],
            );
            (
                p,
                c,
                q,
                (points[c] - points[p]).perp_dot(points[q] - points[c]),
            )
        };
        let ear = (0..m).find(|&i| {
            let (p, c, q, turn) = corner(i);
            turn > eps && !blocks_ear(&points, &remaining, [p, c, q], eps)
        });
        match ear {
            Some(i) => {
                let (p, c, q, _) = corner(i);
                triangles.push([p as u32, c as u32, q as u32]);
                remaining.remove(i);
            }
            None => match (0..m).find(|&i| corner(i).3.abs() <= eps) {
                // A collinear vertex no ear can use: drop it (its two edges become one).
                Some(i) => {
                    remaining.remove(i);
                }
                None => {
                    return Err(fail(format!(
                        "no ear found with {m} vertices left; the outline self-intersects or repeats edges \
                         (pass a simple polygon)"
                    )))
                }
            },
        }
    }
    let [p, c, q] = [remaining[0], remaining[1], remaining[2]];
    if (points[c] - points[p]).perp_dot(points[q] - points[c]) > eps {
        triangles.push([p as u32, c as u32, q as u32]);
    }
    Ok(triangles)
}

/// Whether any remaining vertex other than the ear's corners lies inside or on the (counter-clockwise) ear.
fn blocks_ear(points: &[DVec2], remaining: &[usize], ear: [usize; 3], eps: f64) -> bool {
    let [a, b, c] = ear.map(|i| points[i]);
    remaining.iter().any(|&j| {
        let p = points[j];
        !ear.contains(&j)
            && p != a
            && p != b
            && p != c
            && (b - a).perp_dot(p - a) >= -eps
            && (c - b).perp_dot(p - b) >= -eps
            && (a - c).perp_dot(p - c) >= -eps
    })
}

fn extent_squared(polygon: &[Vec2]) -> f64 {
    let (lo, hi) = polygon.iter().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p.as_dvec2()), hi.max(p.as_dvec2())),
    );
    (hi - lo).length_squared()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn tri_area(polygon: &[Vec2], t: &[u32; 3]) -> f64 {
        let [a, b, c] = t.map(|i| polygon[i as usize].as_dvec2());
        0.5 * (b - a).perp_dot(c - a)
    }

    fn check(polygon: &[Vec2]) {
        let tris = triangulate(polygon, "test").unwrap();
        assert_eq!(tris.len(), polygon.len() - 2);
        let sum: f64 = tris.iter().map(|t| tri_area(polygon, t)).sum();
        assert!(tris.iter().all(|t| tri_area(polygon, t) > 0.0));
        let area = signed_area(polygon).abs();
        assert!((sum - area).abs() < 1e-9 * area, "{sum} vs {area}");
    }

    fn l_shape() -> Vec<Vec2> {
        [
            (0.0, 0.0),
            (3.0, 0.0),
            (3.0, 1.0),
            (1.0, 1.0),
            (1.0, 2.0),
            (0.0, 2.0),
        ]
        .map(|(x, y)| Vec2::new(x, y))
        .to_vec()
    }

    fn plus_shape() -> Vec<Vec2> {
        let (a, s) = (0.006_f32, 0.025_f32);
        [
            (s, -a),
            (s, a),
            (a, a),
            (a, s),
            (-a, s),
            (-a, a),
            (-s, a),
            (-s, -a),
            (-a, -a),
            (-a, -s),
            (a, -s),
            (a, -a),
        ]
        .map(|(x, y)| Vec2::new(x, y))
        .to_vec()
    }

    #[test]
    fn concave_l_shape_area_is_preserved() {
        let l = l_shape();
        assert!((signed_area(&l) - 4.0).abs() < 1e-12);
        check(&l);
    }

    #[test]
    fn plus_shape_both_orientations() {
        let mut plus = plus_shape();
        let area = 4.0 * 0.006 * 0.006 + 4.0 * 0.012 * 0.019;
        assert!((signed_area(&plus) - area).abs() < 1e-9);
        check(&plus);
        plus.reverse();
        check(&plus);
    }

    #[test]
    fn rejects_degenerate_input() {
        assert!(triangulate(&[Vec2::ZERO, Vec2::X], "two").is_err());
        let line = [Vec2::ZERO, Vec2::X, Vec2::new(2.0, 0.0)];
        let err = triangulate(&line, "line").unwrap_err().to_string();
        assert!(err.contains("line") && err.contains("zero area"), "{err}");
    }

    #[test]
    fn simplify_drops_collinear_and_duplicates() {
        let square = [
            (0.0, 0.0),
            (0.5, 0.0),
            (1.0, 0.0),
            (1.0, 0.0),
            (1.0, 1.0),
            (0.0, 1.0),
        ]
        .map(|(x, y)| Vec2::new(x, y));
        assert_eq!(simplify(&square).len(), 4);
    }
}
