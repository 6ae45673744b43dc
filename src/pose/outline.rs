//! The top view of an object (paper Fig. "SE(2) fits"): the outline of its upward-facing surface, placed at a pose.
//! The Pose tab draws it, and so does the fit figure ([`super::figure`]).

use std::collections::HashMap;

use crate::mesh::Mesh;
use crate::sensor::Se2;

/// A closed polyline in the object frame, metres.
pub type Outline = Vec<[f64; 2]>;

/// The top-view outline of a mesh: the boundary loops of its upward-facing triangles (for a closed mesh resting on
/// the table this is its silhouette seen from above), in the object frame, metres.
pub fn outline(mesh: &Mesh) -> Vec<Outline> {
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
    let mut next: HashMap<u32, u32> = count.keys().copied().collect();
    let mut loops = Vec::new();
    while let Some((&start, _)) = next.iter().next() {
        let mut line = Vec::new();
        let mut at = start;
        while let Some(to) = next.remove(&at) {
            if let Some(p) = v.get(at as usize) {
                line.push([f64::from(p.x), f64::from(p.y)]);
            }
            at = to;
            if at == start {
                break;
            }
        }
        if let Some(&first) = line.first() {
            line.push(first);
            loops.push(line);
        }
    }
    loops
}

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
}
