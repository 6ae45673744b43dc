//! The top view of an object (paper Fig. "SE(2) fits"): the outline of its upward-facing surface, placed at a pose.
//! The Pose tab draws it, and so does the fit figure ([`super::figure`]).

use std::collections::HashMap;

use crate::mesh::Mesh;
use crate::sensor::Se2;

/// A closed polyline in the object frame, metres.
pub type Outline = Vec<[f64; 2]>;

/// The top-view outline of a mesh: the boundary loops of its upward-facing triangles (for a closed mesh resting on
/// the table this is its silhouette seen from above), in the object frame, metres. Coincident corners are welded
/// first (STL files store each triangle's corners separately), and a corner where several loops meet keeps all of
/// them.
pub fn outline(mesh: &Mesh) -> Vec<Outline> {
    let mesh = mesh.welded(WELD_M);
    let v = mesh.vertices();
    let mut count: HashMap<(u32, u32), i32> = HashMap::new();
    for t in mesh.triangles() {
        let [a, b, c] = t.map(|i| v.get(i as usize).copied().unwrap_or_default());
        let nz = (b - a).cross(c - a).z;
        if nz <= 0.0 {
            continue;
        }
        for (i, j) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            // An edge shared by two upward triangles appears once each way and cancels.
            if count.remove(&(j, i)).is_none() {
                *count.entry((i, j)).or_default() += 1;
            }
        }
    }
    // Boundary edges by their first corner (sorted, so that the loops come out the same every run).
    let mut edges: Vec<(u32, u32)> = count.into_keys().collect();
    edges.sort_unstable();
    let mut next: HashMap<u32, Vec<u32>> = HashMap::new();
    for &(i, j) in edges.iter().rev() {
        next.entry(i).or_default().push(j);
    }
    let mut loops = Vec::new();
    for &(start, _) in &edges {
        let mut line = Vec::new();
        let mut at = start;
        while let Some(to) = next.get_mut(&at).and_then(Vec::pop) {
            if let Some(p) = v.get(at as usize) {
                line.push([f64::from(p.x), f64::from(p.y)]);
            }
            at = to;
            if at == start {
                break;
            }
        }
        if let Some(p) = v.get(at as usize).filter(|_| !line.is_empty()) {
            line.push([f64::from(p.x), f64::from(p.y)]);
            loops.push(line);
        }
    }
    loops
}

/// Corners closer than this are one corner, metres.
const WELD_M: f32 = 1e-6;

/// `outline` placed at `pose` (`t_world_object`), world frame, millimetres (for plotting).
pub fn placed_mm(outline: &[Outline], pose: &Se2) -> Vec<Vec<[f64; 2]>> {
    let (s, c) = pose.theta.sin_cos();
    outline
        .iter()
        .map(|l| {
            l.iter()
                .map(|[x, y]| {
                    [
                        (pose.x + c * x - s * y) * 1e3,
                        (pose.y + s * x + c * y) * 1e3,
                    ]
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::shapes;

    #[test]
    fn a_box_outline_is_its_rectangle_and_places_by_the_pose() {
        let rect = [
            glam::DVec2::new(-0.01, -0.005),
            glam::DVec2::new(0.01, -0.005),
            glam::DVec2::new(0.01, 0.005),
            glam::DVec2::new(-0.01, 0.005),
        ]
        .map(|p| glam::Vec2::new(p.x as f32, p.y as f32));
        let mesh = shapes::extrude_z(&rect, 0.02).unwrap();
        let loops = outline(&mesh);
        assert_eq!(loops.len(), 1, "{loops:?}");
        let l = &loops[0];
        assert_eq!(l.first(), l.last());
        // The four corners, each once (plus the closing point).
        let mut corners: Vec<(i64, i64)> = l[..l.len() - 1]
            .iter()
            .map(|p| ((p[0] * 1e4).round() as i64, (p[1] * 1e4).round() as i64))
            .collect();
        corners.sort();
        corners.dedup();
        assert_eq!(
            corners,
            vec![(-100, -50), (-100, 50), (100, -50), (100, 50)]
        );
        // Quarter turn and a shift: (0.01, 0.005) -> (-0.005, 0.01) + (0.001, 0.002), in mm.
        let placed = placed_mm(
            &[vec![[0.01, 0.005]]],
            &Se2::new(0.001, 0.002, std::f64::consts::FRAC_PI_2),
        );
        assert!((placed[0][0][0] - -4.0).abs() < 1e-9 && (placed[0][0][1] - 12.0).abs() < 1e-9);
    }

    #[test]
    fn a_triangle_soup_outlines_like_the_welded_mesh() {
        // STL files store every triangle's corners separately: the outline must still be the silhouette, not every
        // edge of the top face.
        let rect = [(-0.02, -0.01), (0.02, -0.01), (0.02, 0.01), (-0.02, 0.01)]
            .map(|(x, y)| glam::Vec2::new(x, y));
        let welded = shapes::extrude_z(&rect, 0.01).unwrap();
        let soup: Vec<glam::Vec3> = welded
            .triangles()
            .iter()
            .flat_map(|t| t.map(|i| welded.vertices()[i as usize]))
            .collect();
        let tris = (0..welded.triangles().len() as u32)
            .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
            .collect();
        let soup = Mesh::from_raw(soup, tris, "soup").unwrap();
        let loops = outline(&soup);
        assert_eq!(loops.len(), 1, "{loops:?}");
        let l = &loops[0];
        assert_eq!(l.first(), l.last());
        // Every point on the rectangle's boundary.
        for p in l {
            let on_x = (p[0].abs() - 0.02).abs() < 1e-7 && p[1].abs() <= 0.01 + 1e-7;
            let on_y = (p[1].abs() - 0.01).abs() < 1e-7 && p[0].abs() <= 0.02 + 1e-7;
            assert!(on_x || on_y, "{p:?} is not on the silhouette");
        }
    }

    #[test]
    fn an_open_surface_outlines_without_closing_its_gap() {
        // Two upward triangles sharing one corner (a bow tie): both loops, each closed on itself, none jumping across.
        let v = [
            (0.0, 0.0),
            (0.01, 0.0),
            (0.0, 0.01),
            (-0.01, 0.0),
            (0.0, -0.01),
        ]
        .map(|(x, y)| glam::Vec3::new(x, y, 0.0))
        .to_vec();
        let mesh = Mesh::from_raw(v, vec![[0, 1, 2], [0, 3, 4]], "bow tie").unwrap();
        let loops = outline(&mesh);
        assert_eq!(loops.len(), 2, "{loops:?}");
        for l in &loops {
            assert_eq!(l.len(), 4, "{l:?}");
            assert_eq!(l.first(), l.last());
            let longest = l
                .windows(2)
                .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
                .fold(0.0, f64::max);
            assert!(longest < 0.015, "{l:?}");
        }
    }
}
