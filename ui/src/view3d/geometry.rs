//! What the 3D view draws, in the **world** frame (table at z = 0, z up): the object mesh at its SE(2) pose, the
//! membrane at the sensor pose, the depth camera's frustum, the contact points (M⊙D back-projected through the
//! camera, paper IV.A step 2) and a table grid. Built on the simulation worker with each result; positions are stored
//! relative to [`SceneGeometry::centre`] (the membrane apex) in `f32`.

use std::collections::HashSet;

use glam::{DAffine3, DVec3, Vec3};
use tactile_derender::mesh::Mesh;
use tactile_derender::sensor::Scene;
use tactile_derender::sim::{PreparedObject, SimOutput, Simulator};

/// One vertex: position (metres, relative to the centre), normal (zero for lines: unshaded) and RGBA colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertex {
    pub pos: [f32; 3],
    pub normal: [f32; 3],
    pub color: [f32; 4],
}

/// Floats per vertex in GPU buffers.
pub const VERTEX_FLOATS: usize = 10;

const OBJECT_COLOR: [f32; 4] = [0.62, 0.68, 0.80, 1.0];
const CONTACT_COLOR: [f32; 4] = [0.95, 0.12, 0.10, 1.0];
const MEMBRANE_COLOR: [f32; 4] = [0.98, 0.78, 0.35, 0.30];
const EDGE_COLOR: [f32; 4] = [0.98, 0.70, 0.25, 0.85];
const FRUSTUM_COLOR: [f32; 4] = [0.25, 0.85, 0.35, 1.0];
const GRID_COLOR: [f32; 4] = [0.45, 0.45, 0.50, 1.0];
/// Half-size of the octahedron drawn at each contact point, metres.
const CONTACT_RADIUS: f64 = 0.0004;

/// The scene's drawable parts; triangle lists unless named `*_lines` (line lists).
#[derive(Clone, Debug, Default)]
pub struct SceneGeometry {
    /// Changes whenever the geometry does (the simulation generation).
    pub version: u64,
    /// World position that vertex coordinates are relative to (the membrane apex), metres.
    pub centre: DVec3,
    /// Radius of a sphere around the centre holding the interesting part of the scene, metres.
    pub radius: f32,
    pub object: Vec<Vertex>,
    pub contacts: Vec<Vertex>,
    pub membrane: Vec<Vertex>,
    pub membrane_lines: Vec<Vertex>,
    pub frustum_lines: Vec<Vertex>,
    pub grid_lines: Vec<Vertex>,
}

impl SceneGeometry {
    /// Build the geometry of a simulated scene.
    pub fn build(
        version: u64,
        sim: &Simulator,
        object: &PreparedObject,
        scene: &Scene,
        out: &SimOutput,
    ) -> Self {
        let t_world_object = scene.object.to_affine();
        let t_world_sensor = scene.sensor.t_world_sensor();
        let t_world_camera = sim.t_world_camera(&scene.sensor);
        let centre = t_world_sensor.transform_point3(DVec3::new(0.0, 0.0, sim.apex_height()));
        let local = |p: DVec3| (p - centre).as_vec3().to_array();

        let object_tris = triangles(&object.mesh, &t_world_object, centre, OBJECT_COLOR);
        let membrane = sim.elastomer_mesh();
        let membrane_tris = triangles(membrane, &t_world_sensor, centre, MEMBRANE_COLOR);
        let membrane_lines = edges(membrane, &t_world_sensor, centre, EDGE_COLOR);

        // Frustum: from the optical centre to the image corners at the far side of the membrane.
        let k = sim.intrinsics();
        let far = out
            .elastomer
            .range_where(|x| x > 0.0)
            .map_or(0.1, |(_, hi)| f64::from(hi));
        let (w, h) = (k.width as f64 - 0.5, k.height as f64 - 0.5);
        let eye = t_world_camera.transform_point3(DVec3::ZERO);
        let corners: Vec<DVec3> = [(-0.5, -0.5), (w, -0.5), (w, h), (-0.5, h)]
            .iter()
            .map(|&(u, v)| t_world_camera.transform_point3(k.back_project(u, v, far)))
            .collect();
        let mut frustum_lines = Vec::new();
        for (i, &c) in corners.iter().enumerate() {
            line(&mut frustum_lines, local(eye), local(c), FRUSTUM_COLOR);
            line(
                &mut frustum_lines,
                local(c),
                local(corners[(i + 1) % 4]),
                FRUSTUM_COLOR,
            );
        }

        let mut contacts = Vec::new();
        for (i, &d) in out.target.data.iter().enumerate() {
            if d > 0.0 {
                let (u, v) = ((i % out.target.width) as f64, (i / out.target.width) as f64);
                let p_world = t_world_camera.transform_point3(k.back_project(u, v, f64::from(d)));
                octahedron(&mut contacts, local(p_world), CONTACT_RADIUS as f32);
            }
        }

        // Table grid: 10 mm squares around the sensor axis, at z = 0.
        let mut grid_lines = Vec::new();
        let (gx, gy) = (
            (centre.x * 100.0).round() / 100.0,
            (centre.y * 100.0).round() / 100.0,
        );
        let half = 0.08;
        for i in -8..=8 {
            let o = f64::from(i) * 0.01;
            let a = DVec3::new(gx + o, gy - half, 0.0);
            let b = DVec3::new(gx + o, gy + half, 0.0);
            line(&mut grid_lines, local(a), local(b), GRID_COLOR);
            let a = DVec3::new(gx - half, gy + o, 0.0);
            let b = DVec3::new(gx + half, gy + o, 0.0);
            line(&mut grid_lines, local(a), local(b), GRID_COLOR);
        }

        let radius = object_tris
            .iter()
            .chain(&membrane_tris)
            .map(|v| Vec3::from_array(v.pos).length())
            .fold(0.01f32, f32::max)
            .min(0.5);
        Self {
            version,
            centre,
            radius,
            object: object_tris,
            contacts,
            membrane: membrane_tris,
            membrane_lines,
            frustum_lines,
            grid_lines,
        }
    }

    /// Flatten vertices for a GPU vertex buffer (native-endian `f32`s, [`VERTEX_FLOATS`] per vertex).
    pub fn vertex_bytes(vertices: &[Vertex]) -> Vec<u8> {
        let mut out = Vec::with_capacity(vertices.len() * VERTEX_FLOATS * 4);
        for v in vertices {
            for x in v.pos.iter().chain(&v.normal).chain(&v.color) {
                out.extend_from_slice(&x.to_ne_bytes());
            }
        }
        out
    }
}

/// Flat-shaded triangles of `mesh` moved by `t_world_mesh`, relative to `centre`.
fn triangles(mesh: &Mesh, t_world_mesh: &DAffine3, centre: DVec3, color: [f32; 4]) -> Vec<Vertex> {
    let mut out = Vec::with_capacity(mesh.triangles().len() * 3);
    for i in 0..mesh.triangles().len() {
        let p = mesh
            .triangle(i)
            .map(|v| t_world_mesh.transform_point3(v.as_dvec3()) - centre);
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        for q in p {
            out.push(Vertex {
                pos: q.as_vec3().to_array(),
                normal: n.as_vec3().to_array(),
                color,
            });
        }
    }
    out
}

/// Unique edges of `mesh` as a line list.
fn edges(mesh: &Mesh, t_world_mesh: &DAffine3, centre: DVec3, color: [f32; 4]) -> Vec<Vertex> {
    let verts: Vec<[f32; 3]> = mesh
        .vertices()
        .iter()
        .map(|v| {
            (t_world_mesh.transform_point3(v.as_dvec3()) - centre)
                .as_vec3()
                .to_array()
        })
        .collect();
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    for t in mesh.triangles() {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            if seen.insert((a.min(b), a.max(b))) {
                line(&mut out, verts[a as usize], verts[b as usize], color);
            }
        }
    }
    out
}

fn line(out: &mut Vec<Vertex>, a: [f32; 3], b: [f32; 3], color: [f32; 4]) {
    for pos in [a, b] {
        out.push(Vertex {
            pos,
            normal: [0.0; 3],
            color,
        });
    }
}

fn octahedron(out: &mut Vec<Vertex>, c: [f32; 3], r: f32) {
    let c = Vec3::from_array(c);
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    for sx in [-1.0f32, 1.0] {
        for sy in [-1.0f32, 1.0] {
            for sz in [-1.0f32, 1.0] {
                let (a, b, d) = (axes[0] * sx * r, axes[1] * sy * r, axes[2] * sz * r);
                let n = Vec3::new(sx, sy, sz).normalize();
                // Keep counter-clockwise winding seen from outside.
                let tri = if sx * sy * sz > 0.0 {
                    [a, b, d]
                } else {
                    [a, d, b]
                };
                for p in tri {
                    out.push(Vertex {
                        pos: (c + p).to_array(),
                        normal: n.to_array(),
                        color: CONTACT_COLOR,
                    });
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tactile_derender::objects::ObjectSet;
    use tactile_derender::sim::SimConfig;

    #[test]
    fn contact_points_lie_inside_the_membrane_and_on_the_object_top() {
        let sim = Simulator::new(SimConfig::default()).unwrap();
        let object = PreparedObject::new(ObjectSet::builtin().mesh("sphere_r20").unwrap()).unwrap();
        let scene = Scene {
            object: Default::default(),
            sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, 0.005),
        };
        let out = sim.simulate(&object, &scene, 0);
        let g = SceneGeometry::build(3, &sim, &object, &scene, &out);
        assert_eq!(g.version, 3);
        assert_eq!(g.contacts.len(), out.contact_pixels * 24);
        // The apex is 5 mm below the sphere's top (z = 40 mm): contact points are within 5 mm below the top and
        // within the pressed cap's radius sqrt(2 r p - p^2) ~ 13.2 mm of the axis.
        for tri in g.contacts.chunks(24) {
            let c = tri
                .iter()
                .fold(DVec3::ZERO, |s, v| s + Vec3::from_array(v.pos).as_dvec3())
                / 24.0
                + g.centre;
            assert!(c.z > 0.035 - 1e-3 && c.z < 0.040 + 1e-3, "{c}");
            assert!(c.truncate().length() < 0.0135, "{c}");
        }
        assert_eq!(g.frustum_lines.len(), 16);
        assert_eq!(
            SceneGeometry::vertex_bytes(&g.object).len(),
            g.object.len() * 40
        );
    }
}
