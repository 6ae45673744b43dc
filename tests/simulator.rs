//! End-to-end checks of the contact-depth simulator against analytic geometry and invariants.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use glam::{DAffine3, DVec3, Vec3};
use tactile_derender::image::Image;
use tactile_derender::mesh::{Mesh, RayCaster, SignedDistance};
use tactile_derender::sensor::{Intrinsics, Scene, Se2, SensorPose};
use tactile_derender::sim::{render, PreparedObject, SimConfig, Simulator};

/// Closed box with half extents `h`, resting on the table (z from 0 to 2 h.z).
fn box_on_table(h: Vec3) -> Mesh {
    let v: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -h.x } else { h.x },
                if i & 2 == 0 { -h.y } else { h.y },
                if i & 4 == 0 { 0.0 } else { 2.0 * h.z },
            )
        })
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let t = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Mesh::from_raw(v, t, "box").unwrap()
}

/// UV sphere of radius `r` centred at `c` (closed, outward).
fn uv_sphere(r: f32, c: Vec3, stacks: u32, slices: u32) -> Mesh {
    let mut v = vec![c + Vec3::new(0.0, 0.0, r), c - Vec3::new(0.0, 0.0, r)];
    for i in 1..stacks {
        let phi = std::f32::consts::PI * i as f32 / stacks as f32;
        for j in 0..slices {
            let th = std::f32::consts::TAU * j as f32 / slices as f32;
            v.push(c + r * Vec3::new(phi.sin() * th.cos(), phi.sin() * th.sin(), phi.cos()));
        }
    }
    let ring = |i: u32, j: u32| 2 + (i - 1) * slices + j % slices;
    let mut t = Vec::new();
    for j in 0..slices {
        t.push([0, ring(1, j), ring(1, j + 1)]);
        t.push([1, ring(stacks - 1, j + 1), ring(stacks - 1, j)]);
        for i in 1..stacks - 1 {
            t.push([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)]);
            t.push([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]);
        }
    }
    Mesh::from_raw(v, t, "sphere").unwrap()
}

fn noiseless() -> SimConfig {
    let mut cfg = SimConfig::default();
    cfg.signature.noise_std = 0.0;
    cfg
}

#[test]
fn depth_of_a_plane_matches_ray_plane_intersection() {
    // A wide box whose top face (z = 0.02) fills the view; a tilted sensor makes depth vary across the image.
    let sim = Simulator::new(noiseless()).unwrap();
    let object = PreparedObject::new(box_on_table(Vec3::new(0.5, 0.5, 0.01))).unwrap();
    let sensor = SensorPose {
        position: [0.003, -0.002, 0.15],
        yaw: 0.4,
        tilt: [0.15, -0.1],
    };
    let scene = Scene {
        object: Se2::default(),
        sensor,
    };
    let depth = sim.render_depth(&object, &scene);
    let k = sim.intrinsics();
    let t_world_camera = sim.t_world_camera(&sensor);
    for v in 0..k.height {
        for u in 0..k.width {
            let o = t_world_camera.translation;
            let d = t_world_camera.matrix3 * k.ray_dir(u as f64, v as f64);
            let t = (0.02 - o.z) / d.z; // ray parameter = z-depth (unit camera-z direction)
            let got = f64::from(depth.get(u, v));
            assert!((got - t).abs() < 1e-6, "pixel ({u},{v}): {got} vs {t}");
        }
    }
}

#[test]
fn depth_of_a_sphere_matches_analytic_within_tessellation_error() {
    let (r, c) = (0.03f32, Vec3::new(0.0, 0.0, 0.0));
    let (stacks, slices) = (90, 180);
    let caster = RayCaster::new(&uv_sphere(r, c, stacks, slices)).unwrap();
    let k = Intrinsics::pico_flexx()
        .cropped((20, 160), (25, 200))
        .resized(64, 64);
    // Camera 0.1 m above the centre looking down (-z).
    let rot = glam::DMat3::from_rotation_x(std::f64::consts::PI);
    let t_world_camera = DAffine3::from_mat3_translation(rot, DVec3::new(0.001, 0.002, 0.1));
    let depth = render::render_depth(&caster, &k, &t_world_camera);
    // Inscribed polyhedron: a face lies at most r (1 - cos(pi / stacks)) inside the sphere; along an oblique ray the
    // depth error grows by 1/cos(incidence), bounded here by checking only rays at < 60 degrees incidence.
    let sag = f64::from(r) * (1.0 - (std::f64::consts::PI / stacks as f64).cos());
    let mut checked = 0;
    for v in 0..k.height {
        for u in 0..k.width {
            let o = t_world_camera.translation;
            let d = t_world_camera.matrix3 * k.ray_dir(u as f64, v as f64);
            // |o + t d - c|^2 = r^2
            let oc = o - c.as_dvec3();
            let (a, b, cc) = (d.dot(d), 2.0 * oc.dot(d), oc.dot(oc) - f64::from(r * r));
            let disc = b * b - 4.0 * a * cc;
            let got = f64::from(depth.get(u, v));
            if disc < 0.0 {
                assert_eq!(got, 0.0, "pixel ({u},{v}) should miss");
                continue;
            }
            let t = (-b - disc.sqrt()) / (2.0 * a);
            let n = (o + d * t - c.as_dvec3()).normalize();
            let cos_inc = -n.dot(d.normalize());
            if cos_inc < 0.5 {
                continue;
            }
            assert!(got >= t - 1e-6, "tessellated surface is inside the sphere");
            assert!(
                got - t <= sag / cos_inc + 1e-6,
                "pixel ({u},{v}): {got} vs {t}"
            );
            checked += 1;
        }
    }
    assert!(checked > 200, "only {checked} pixels checked");
}

#[test]
fn nominal_elastomer_depth_matches_the_analytic_half_ellipsoid() {
    let mut cfg = noiseless();
    cfg.elastomer.rings = 96;
    cfg.elastomer.segments = 384;
    let sim = Simulator::new(cfg.clone()).unwrap();
    let e = sim.nominal_depth();
    let k = sim.intrinsics();
    let (a, b, h) = (0.06, 0.04, 0.03);
    let cam = DVec3::from_array(cfg.mount.position);
    let mut max_err = 0.0f64;
    for v in 0..k.height {
        for u in 0..k.width {
            let d = k.ray_dir(u as f64, v as f64);
            // Far root of ((x/a)^2 + (y/b)^2 + (z/h)^2 = 1) along cam + t d (sensor frame = camera axes).
            let s = DVec3::new(1.0 / a, 1.0 / b, 1.0 / h);
            let (o, dd) = (cam * s, d * s);
            let (qa, qb, qc) = (dd.dot(dd), 2.0 * o.dot(dd), o.dot(o) - 1.0);
            let t = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
            max_err = max_err.max((f64::from(e.get(u, v)) - t).abs());
        }
    }
    // 96 rings x 384 segments: the inscribed mesh departs from the ellipsoid by < 0.1 mm near the apex.
    assert!(max_err < 1e-4, "max error {max_err} m");
    // Defaults put the apex in the camera's 0.05–0.15 m range.
    let apex = f64::from(e.get(k.width / 2, k.height / 2));
    assert!((0.05..0.15).contains(&apex), "apex depth {apex}");
}

#[test]
fn back_projected_contact_points_lie_on_the_object_and_inside_the_membrane() {
    let sim = Simulator::new(noiseless()).unwrap();
    let mesh = uv_sphere(0.02, Vec3::new(0.0, 0.0, 0.02), 48, 96);
    let object = PreparedObject::new(mesh.clone()).unwrap();
    let scene = Scene {
        object: Se2::new(0.004, -0.003, 0.0),
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, 0.008),
    };
    let out = sim.simulate(&object, &scene, 0);
    assert!(out.contact_pixels > 50, "{}", out.contact_pixels);
    let object_sdf = SignedDistance::new(&mesh).unwrap();
    let membrane_sdf = SignedDistance::new(sim.elastomer_mesh()).unwrap();
    let t_world_camera = sim.t_world_camera(&scene.sensor);
    let t_object_world = scene.object.to_affine().inverse();
    let k = sim.intrinsics();
    for v in 0..k.height {
        for u in 0..k.width {
            let d = out.depth.get(u, v);
            if d == 0.0 {
                continue;
            }
            let p_cam = k.back_project(u as f64, v as f64, f64::from(d));
            let p_obj = t_object_world.transform_point3(t_world_camera.transform_point3(p_cam));
            assert!(
                object_sdf.distance(p_obj.as_vec3()).abs() < 2e-6,
                "D point off the surface"
            );
            let p_sensor = sim.t_sensor_camera().transform_point3(p_cam);
            let inside = membrane_sdf.distance(p_sensor.as_vec3()) < 0.0;
            assert_eq!(
                inside,
                out.mask.get(u, v) == 1.0,
                "mask disagrees with the SDF at ({u},{v})"
            );
            let x0 = out.target.get(u, v);
            assert_eq!(x0, if inside { d } else { 0.0 });
        }
    }
}

fn contact_pixels(cfg: &SimConfig, mesh: &Mesh, press: f64) -> usize {
    let sim = Simulator::new(cfg.clone()).unwrap();
    let object = PreparedObject::new(mesh.clone()).unwrap();
    let scene = Scene {
        object: Se2::new(0.002, 0.001, 0.3),
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, press),
    };
    sim.simulate(&object, &scene, 0).contact_pixels
}

#[test]
fn contact_area_grows_with_press_depth_and_with_inflation() {
    let mesh = uv_sphere(0.025, Vec3::new(0.0, 0.0, 0.025), 32, 64);
    let cfg = noiseless();
    let areas: Vec<usize> = [0.001, 0.003, 0.006, 0.01, 0.015]
        .iter()
        .map(|&p| contact_pixels(&cfg, &mesh, p))
        .collect();
    assert!(areas.windows(2).all(|w| w[0] < w[1]), "press: {areas:?}");
    // Fixed sensor height, more inflation: the membrane reaches further into the object.
    let sim = Simulator::new(cfg.clone()).unwrap();
    let object = PreparedObject::new(box_on_table(Vec3::new(0.03, 0.02, 0.01))).unwrap();
    let sensor = sim.pressing_pose(&object, 0.0, 0.0, 0.0, 0.002);
    let areas: Vec<usize> = [0.030, 0.032, 0.035, 0.04]
        .iter()
        .map(|&h| {
            let mut c = cfg.clone();
            c.elastomer.inflation = h;
            let sim = Simulator::new(c).unwrap();
            let scene = Scene {
                object: Se2::default(),
                sensor,
            };
            sim.simulate(&object, &scene, 0).contact_pixels
        })
        .collect();
    assert!(
        areas.windows(2).all(|w| w[0] < w[1]),
        "inflation: {areas:?}"
    );
}

#[test]
fn object_out_of_reach_gives_an_empty_mask_and_pure_noise_imprint() {
    let sim = Simulator::new(noiseless()).unwrap();
    let object = PreparedObject::new(uv_sphere(0.02, Vec3::new(0.0, 0.0, 0.02), 24, 48)).unwrap();
    // Apex 5 mm above the object's top.
    let scene = Scene {
        object: Se2::default(),
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, -0.005),
    };
    let out = sim.simulate(&object, &scene, 0);
    assert_eq!(out.contact_pixels, 0);
    assert!(out.target.data.iter().all(|&x| x == 0.0));
    assert_eq!(out.signature, out.elastomer);
    assert!(out.imprint.data.iter().all(|&x| x == 0.0));
}

#[test]
fn pixels_beyond_the_shadow_width_equal_the_nominal_depth() {
    let sim = Simulator::new(noiseless()).unwrap();
    let object = PreparedObject::new(uv_sphere(0.015, Vec3::new(0.0, 0.0, 0.015), 32, 64)).unwrap();
    let scene = Scene {
        object: Se2::new(0.005, 0.0, 0.0),
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, 0.006),
    };
    let out = sim.simulate(&object, &scene, 0);
    assert!(out.contact_pixels > 10);
    let k = sim.intrinsics();
    let (sx, sy) = k.pixel_size_in(&sim.config().camera.native);
    let shadow = sim.config().signature.shadow_px;
    let contact: Vec<(usize, usize)> = (0..k.height)
        .flat_map(|v| (0..k.width).map(move |u| (u, v)))
        .filter(|&(u, v)| out.mask.get(u, v) == 1.0)
        .collect();
    let (mut far, mut near_changed) = (0, 0);
    for v in 0..k.height {
        for u in 0..k.width {
            let dist = contact
                .iter()
                .map(|&(cu, cv)| ((cu as f64 - u as f64) * sx).hypot((cv as f64 - v as f64) * sy))
                .fold(f64::INFINITY, f64::min);
            let (s, e) = (out.signature.get(u, v), out.elastomer.get(u, v));
            if dist >= shadow {
                assert_eq!(s, e, "pixel ({u},{v}) at {dist:.1} native px");
                far += 1;
            } else if dist > 0.0 && s < e {
                near_changed += 1;
            }
        }
    }
    assert!(
        far > 100 && near_changed > 10,
        "far={far} near_changed={near_changed}"
    );
}

#[test]
fn same_seed_same_output_and_noise_only_changes_with_seed() {
    let sim = Simulator::new(SimConfig::default()).unwrap();
    let object = PreparedObject::new(uv_sphere(0.02, Vec3::new(0.0, 0.0, 0.02), 24, 48)).unwrap();
    let scene = Scene {
        object: Se2::default(),
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, 0.005),
    };
    let a = sim.simulate(&object, &scene, 7);
    let b = sim.simulate(&object, &scene, 7);
    let c = sim.simulate(&object, &scene, 8);
    assert_eq!(a, b);
    assert_ne!(a.imprint, c.imprint);
    assert_eq!(a.target, c.target, "the target is noise-free");
    let _: &Image = &a.imprint;
}

#[test]
fn the_contact_hint_finds_a_high_point_outside_the_membrane() {
    // A wide low plate (4 mm) with a pillar (12 mm) 45 mm off the bounding-box centre: pressing 3 mm into the
    // object's top over the centre touches nothing, and the hint's pose brings the pillar under the apex.
    let plate = box_on_table(Vec3::new(0.05, 0.01, 0.002));
    let pillar = box_on_table(Vec3::new(0.003, 0.003, 0.006)).transformed(
        &glam::Affine3A::from_translation(Vec3::new(0.045, 0.0, 0.0)),
    );
    let mesh = Mesh::merged(&[plate, pillar]).rest_on_table();
    let object = PreparedObject::new(mesh).unwrap();
    assert!((object.top_z - 0.012).abs() < 1e-6);
    assert!((object.top_xy[0] - 0.045).abs() <= 0.0031 && object.top_xy[1].abs() <= 0.0031);
    let sim = Simulator::new(SimConfig::default()).unwrap();
    let at = |pose: Se2| Scene {
        object: pose,
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, 0.003),
    };
    let pose = Se2::new(0.0, 0.0, 0.3);
    assert_eq!(sim.simulate(&object, &at(pose), 0).contact_pixels, 0);
    let hint = sim.contact_hint(&object, &at(pose));
    assert!((hint.press_m - 0.003).abs() < 1e-9, "{hint:?}");
    let top = glam::DVec2::from_array(object.top_xy).length();
    assert!((hint.offset_m - top).abs() < 1e-9, "{hint:?}");
    assert_eq!(hint.centred.theta, pose.theta);
    assert!(sim.simulate(&object, &at(hint.centred), 0).contact_pixels > 20);
    assert!(sim.contact_hint(&object, &at(hint.centred)).offset_m < 1e-9);
    assert!(
        hint.to_string()
            .contains(&format!("{:.1} mm sideways", top * 1e3)),
        "{hint}"
    );
}
