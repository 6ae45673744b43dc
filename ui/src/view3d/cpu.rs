//! The 3D view's **CPU fallback**, used where no wgpu device exists (e.g. egui_kittest, or a glow build): triangles are
//! projected on the CPU, flat shaded, sorted back to front (painter's algorithm) and handed to egui as one mesh.

use egui::{Color32, Pos2, Rect, Stroke};
use glam::{Mat4, Vec3, Vec4};

use super::geometry::{SceneGeometry, Vertex};
use super::DrawFlags;
use crate::state::MembraneStyle;

/// Draw `geom` into `rect` with the view-projection `m` seen from `eye` (relative to the scene centre).
pub fn paint(
    painter: &egui::Painter,
    rect: Rect,
    geom: &SceneGeometry,
    flags: &DrawFlags,
    eye: Vec3,
    m: Mat4,
) {
    let painter = painter.with_clip_rect(rect);
    let project = |p: [f32; 3]| -> Option<(Pos2, f32)> {
        let c = m * Vec4::new(p[0], p[1], p[2], 1.0);
        if c.w <= 1e-6 {
            return None;
        }
        let n = c.truncate() / c.w;
        Some((
            Pos2::new(
                rect.left() + (n.x + 1.0) * 0.5 * rect.width(),
                rect.top() + (1.0 - n.y) * 0.5 * rect.height(),
            ),
            n.z,
        ))
    };
    let light = eye.normalize_or_zero();
    let mut tris: Vec<([Pos2; 3], f32, Color32)> = Vec::new();
    let mut add = |verts: &[Vertex], cull: bool| {
        for t in verts.chunks_exact(3) {
            let n = Vec3::from_array(t[0].normal);
            if cull && n.dot(eye - Vec3::from_array(t[0].pos)) < 0.0 {
                continue;
            }
            let (Some(a), Some(b), Some(c)) =
                (project(t[0].pos), project(t[1].pos), project(t[2].pos))
            else {
                continue;
            };
            let shade = 0.35 + 0.65 * n.dot(light).abs();
            let [r, g, bl, al] = t[0].color;
            let color = Color32::from_rgba_unmultiplied(
                (r * shade * 255.0) as u8,
                (g * shade * 255.0) as u8,
                (bl * shade * 255.0) as u8,
                (al * 255.0) as u8,
            );
            tris.push(([a.0, b.0, c.0], (a.1 + b.1 + c.1) / 3.0, color));
        }
    };
    add(&geom.object, true);
    if flags.contacts {
        add(&geom.contacts, true);
    }
    if flags.membrane == MembraneStyle::Translucent {
        add(&geom.membrane, false);
    }
    // Far first.
    tris.sort_by(|a, b| b.1.partial_cmp(&a.1).unwrap_or(std::cmp::Ordering::Equal));
    let mut mesh = egui::Mesh::default();
    for (p, _, color) in tris {
        let base = mesh.vertices.len() as u32;
        for q in p {
            mesh.colored_vertex(q, color);
        }
        mesh.add_triangle(base, base + 1, base + 2);
    }
    let lines = |verts: &[Vertex]| {
        for l in verts.chunks_exact(2) {
            if let (Some(a), Some(b)) = (project(l[0].pos), project(l[1].pos)) {
                let [r, g, bl, al] = l[0].color;
                let c = Color32::from_rgba_unmultiplied(
                    (r * 255.0) as u8,
                    (g * 255.0) as u8,
                    (bl * 255.0) as u8,
                    (al * 255.0) as u8,
                );
                painter.line_segment([a.0, b.0], Stroke::new(1.0, c));
            }
        }
    };
    lines(&geom.grid_lines);
    painter.add(egui::Shape::mesh(mesh));
    if flags.membrane == MembraneStyle::Wireframe {
        lines(&geom.membrane_lines);
    }
    if flags.frustum {
        lines(&geom.frustum_lines);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::OrbitCamera;
    use crate::view3d::camera;
    use tactile_derender::objects::ObjectSet;
    use tactile_derender::sensor::Scene;
    use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};

    #[test]
    fn fallback_draws_the_visible_triangles_inside_the_view() {
        let sim = Simulator::new(SimConfig::default()).unwrap();
        let object = PreparedObject::new(ObjectSet::builtin().mesh("sphere_r20").unwrap()).unwrap();
        let scene = Scene {
            object: Default::default(),
            sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, 0.005),
        };
        let out = sim.simulate(&object, &scene, 0);
        let geom = SceneGeometry::build(1, &sim, &object, &scene, &out);
        let rect = Rect::from_min_size(Pos2::new(10.0, 20.0), egui::vec2(400.0, 300.0));
        let flags = DrawFlags {
            membrane: MembraneStyle::Hidden,
            frustum: false,
            contacts: false,
        };
        let (eye, m) = camera::view_proj(&OrbitCamera::default(), rect.width() / rect.height());
        let mut h =
            egui_kittest::Harness::new_ui(|ui| paint(ui.painter(), rect, &geom, &flags, eye, m));
        h.run_ok();
        let meshes: Vec<&egui::Mesh> = h
            .output()
            .shapes
            .iter()
            .filter_map(|c| match &c.shape {
                egui::Shape::Mesh(mesh) => Some(&**mesh),
                _ => None,
            })
            .collect();
        assert_eq!(meshes.len(), 1);
        let tris = meshes[0].indices.len() / 3;
        // A closed sphere seen from outside: back-face culling keeps about half of its triangles.
        let total = geom.object.len() / 3;
        assert!(
            tris > total / 3 && tris < 2 * total / 3,
            "{tris} of {total}"
        );
        // The default camera looks at the apex: the sphere is in front and within the view.
        assert!(meshes[0]
            .vertices
            .iter()
            .all(|v| rect.expand(1.0).contains(v.pos)));
    }
}
