//! End-to-end registration: simulated contacts of an asymmetric object (a lying prism with a scalene triangular
//! profile, pressed near one end) are back-projected and registered from random starts; the estimate must match the
//! simulated pose. Also the press the sensor is placed at, found from a contact (the registration's other unknown).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use glam::{DVec3, Vec2};
use tactile_derender::mesh::Mesh;
use tactile_derender::objects::shapes;
use tactile_derender::pose::{
    register, InitStrategy, Registration, RegistrationProblem, SdfRegistration,
    SdfRegistrationConfig,
};
use tactile_derender::recon::{back_project, free_space_points, FreeSpaceConfig};
use tactile_derender::sensor::{Scene, Se2};
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};

/// Scalene triangle profile (y, z), 40 mm long: no rotational symmetry about z, and its ends are in view.
fn asymmetric_prism() -> Mesh {
    let profile = [
        Vec2::new(-0.015, 0.0),
        Vec2::new(0.018, 0.0),
        Vec2::new(-0.004, 0.016),
    ];
    shapes::prism_lying(&profile, 0.04).unwrap()
}

struct Contact {
    surface: Vec<DVec3>,
    free: Vec<DVec3>,
}

/// Simulate the object at `truth` with the sensor pressing `press` metres at object-frame point `at_obj`.
fn simulate(mesh: &Mesh, truth: Se2, at_obj: (f64, f64), press: f64) -> Contact {
    let mut cfg = SimConfig::default();
    cfg.signature.noise_std = 0.0;
    let sim = Simulator::new(cfg).unwrap();
    let object = PreparedObject::new(mesh.clone()).unwrap();
    let at = truth
        .to_affine()
        .transform_point3(DVec3::new(at_obj.0, at_obj.1, 0.0));
    let sensor = sim.pressing_pose(&object, at.x, at.y, 0.2, press);
    let scene = Scene {
        object: truth,
        sensor,
    };
    let out = sim.simulate(&object, &scene, 0);
    assert!(
        out.contact_pixels > 50,
        "{} contact pixels",
        out.contact_pixels
    );
    let t_world_camera = sim.t_world_camera(&sensor);
    let surface = back_project(&out.target, sim.intrinsics(), &t_world_camera).p_world;
    let free = free_space_points(
        &out.target,
        sim.nominal_depth(),
        sim.intrinsics(),
        &t_world_camera,
        &FreeSpaceConfig::default(),
        1,
    );
    Contact { surface, free }
}

fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

#[test]
fn registration_recovers_the_simulated_pose_from_random_starts() {
    let mesh = asymmetric_prism();
    let reg = SdfRegistration::new(&mesh, SdfRegistrationConfig::default()).unwrap();
    for (k, (truth, at)) in [
        (Se2::new(0.004, -0.003, 0.6), (0.024, 0.0)),
        (Se2::new(-0.006, 0.002, -2.2), (-0.026, 0.002)),
    ]
    .into_iter()
    .enumerate()
    {
        let c = simulate(&mesh, truth, at, 0.005);
        let problem = RegistrationProblem {
            surface: &c.surface,
            free: &c.free,
        };
        let hyps = register(
            &reg,
            &problem,
            &InitStrategy::Random {
                count: 10,
                radius_m: 0.01,
                seed: k as u64,
            },
        )
        .unwrap();
        assert_eq!(hyps.len(), 10);
        assert!(hyps.windows(2).all(|w| w[0].cost <= w[1].cost));
        let best = hyps[0].pose;
        let dpos = ((best.x - truth.x).powi(2) + (best.y - truth.y).powi(2)).sqrt();
        let dtheta = angle_diff(best.theta, truth.theta);
        eprintln!(
            "case {k}: {} surface, {} free points; error {:.4} mm, {:.5} rad, cost {:.3e}",
            c.surface.len(),
            c.free.len(),
            dpos * 1e3,
            dtheta,
            hyps[0].cost
        );
        assert!(dpos < 0.0005, "position error {} mm", dpos * 1e3);
        assert!(dtheta < 0.01, "theta error {dtheta} rad");
    }
}

/// The prism as users' meshes come: open (its bottom face, which the table hides, removed: a 40 x 33 mm hole) and
/// inward-facing, then a two-shell union of overlapping halves (a convex decomposition). Registration signs the
/// distance with the winding number and must find the same poses as on the clean mesh.
#[test]
fn registration_works_on_open_inward_and_multi_shell_meshes() {
    let closed = asymmetric_prism();
    let bottom = |t: &[u32; 3]| {
        t.iter()
            .all(|&i| closed.vertices()[i as usize].z.abs() < 1e-7)
    };
    let open_tris: Vec<[u32; 3]> = closed
        .triangles()
        .iter()
        .copied()
        .filter(|t| !bottom(t))
        .collect();
    assert!(open_tris.len() < closed.triangles().len());
    let open = Mesh::from_raw(closed.vertices().to_vec(), open_tris, "open prism").unwrap();
    assert!(!open.welded(1e-6).report().closed);
    let inward_open = open.flipped();
    // Two overlapping 24 mm pieces of the same prism cover its 40 mm length.
    let piece = |x0: f32| {
        let profile = [
            Vec2::new(-0.015, 0.0),
            Vec2::new(0.018, 0.0),
            Vec2::new(-0.004, 0.016),
        ];
        shapes::prism_lying(&profile, 0.024)
            .unwrap()
            .transformed(&glam::Affine3A::from_translation(glam::Vec3::X * x0))
    };
    let shells = Mesh::merged(&[piece(-0.008), piece(0.008)]);
    for (name, mesh) in [
        ("open", open),
        ("open, inward", inward_open),
        ("two shells", shells),
    ] {
        let reg = SdfRegistration::new(&mesh, SdfRegistrationConfig::default())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let truth = Se2::new(0.004, -0.003, 0.6);
        let c = simulate(&mesh, truth, (0.012, 0.0), 0.005);
        let problem = RegistrationProblem {
            surface: &c.surface,
            free: &c.free,
        };
        let strategy = InitStrategy::Random {
            count: 10,
            radius_m: 0.01,
            seed: 3,
        };
        let best = register(&reg, &problem, &strategy).unwrap()[0].pose;
        let dpos = ((best.x - truth.x).powi(2) + (best.y - truth.y).powi(2)).sqrt();
        let dtheta = angle_diff(best.theta, truth.theta);
        eprintln!("{name}: error {:.4} mm, {:.5} rad", dpos * 1e3, dtheta);
        assert!(dpos < 0.0005, "{name}: position error {} mm", dpos * 1e3);
        assert!(dtheta < 0.01, "{name}: theta error {dtheta} rad");
    }
}

#[test]
fn cost_is_minimal_at_the_true_pose() {
    let mesh = asymmetric_prism();
    let truth = Se2::new(0.004, -0.003, 0.6);
    let c = simulate(&mesh, truth, (0.024, 0.0), 0.005);
    let reg = SdfRegistration::new(&mesh, SdfRegistrationConfig::default()).unwrap();
    let problem = RegistrationProblem {
        surface: &c.surface,
        free: &c.free,
    };
    let at_truth = reg.cost(&problem, truth);
    // Simulated points are exact up to f32 rounding: the cost at the truth is ~ (1 µm)² / 2.
    assert!(at_truth < 1e-12, "{at_truth}");
    for (dx, dy, dt) in [
        (0.0005, 0.0, 0.0),
        (-0.0005, 0.0, 0.0),
        (0.0, 0.0005, 0.0),
        (0.0, -0.0005, 0.0),
        (0.0, 0.0, 0.01),
        (0.0, 0.0, -0.01),
        (0.003, -0.002, 0.1),
    ] {
        let other = reg.cost(
            &problem,
            Se2::new(truth.x + dx, truth.y + dy, truth.theta + dt),
        );
        assert!(
            other > 10.0 * at_truth.max(1e-14),
            "{dx} {dy} {dt}: {other} vs {at_truth}"
        );
    }
    // The fixed-init mode returns one hypothesis, refined from the given start.
    let hyps = register(
        &reg,
        &problem,
        &InitStrategy::Fixed(Se2::new(
            truth.x + 0.002,
            truth.y - 0.001,
            truth.theta + 0.1,
        )),
    )
    .unwrap();
    assert_eq!(hyps.len(), 1);
    assert!(
        (hyps[0].pose.x - truth.x).abs() < 5e-4
            && angle_diff(hyps[0].pose.theta, truth.theta) < 0.01
    );
    assert_eq!(reg.name(), "sdf-lm");
}

#[test]
fn press_from_the_true_contact_puts_its_highest_point_on_the_object_s_top() {
    // Independent truth: the press the simulator placed the sensor at. The object's top is under the sensor at these
    // poses, so the highest point of the true in-contact depth lies on it and the press comes back; a press is
    // never over-estimated (no contact point lies above the top).
    use tactile_derender::pipeline::press::press_from_samples;
    let mut quiet = SimConfig::default();
    quiet.signature.noise_std = 0.0;
    let sim = Simulator::new(quiet).unwrap();
    let cross = PreparedObject::new(
        tactile_derender::objects::ObjectSet::builtin()
            .mesh("cross_w12_s50")
            .unwrap(),
    )
    .unwrap();
    let eval = tactile_derender::pose::PoseConfig::default();
    for (pose, press) in [
        (Se2::new(0.003, -0.002, 0.4), 0.002),
        (Se2::new(0.003, -0.002, 0.4), 0.006),
        (Se2::new(-0.005, 0.004, 1.2), 0.004),
    ] {
        let scene = Scene {
            object: pose,
            sensor: sim.pressing_pose(&cross, 0.0, 0.0, 0.0, press),
        };
        let out = sim.simulate(&cross, &scene, 0);
        let got = press_from_samples(
            &sim,
            &cross,
            std::slice::from_ref(&out.target),
            Some(&out.signature),
            &out.imprint,
            &tactile_derender::pose::Estimator::new(eval.clone()),
            0.03,
        )
        .unwrap()
        .unwrap();
        assert!(
            (got - press).abs() < 3e-4,
            "press {press} at {pose:?}: estimated {got}"
        );
    }
    // No contact, no press.
    let empty = tactile_derender::image::Image::filled(64, 64, 0.0);
    let none = press_from_samples(
        &sim,
        &cross,
        std::slice::from_ref(&empty),
        Some(&empty),
        &empty,
        &tactile_derender::pose::Estimator::new(eval.clone()),
        0.03,
    );
    assert_eq!(none.unwrap(), None);
}
