//! The signature check's camera path (`pose::camera_path`) against what it stands for: the native render of the
//! whole crop, area-resampled (its window must change nothing); the membrane where the object is far; and a frame
//! made at native pixels and brought down as the import brings it, which the camera path explains better than one
//! ray per model pixel does.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use tactile_derender::image::Image;
use tactile_derender::mesh::RayCaster;
use tactile_derender::objects::ObjectSet;
use tactile_derender::pose::camera_path::CameraPath;
use tactile_derender::pose::signature_check::{
    SignatureCheck, SignatureCheckConfig, SignatureModel,
};
use tactile_derender::sensor::resample::{crop, resample_depth, to_model};
use tactile_derender::sensor::{Scene, Se2, SensorPose};
use tactile_derender::sim::render::render_depth;
use tactile_derender::sim::shadows::tactile_signature;
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};

struct Native {
    config: SimConfig,
    sim: Simulator,
    native: Simulator,
    caster: RayCaster,
    prepared: PreparedObject,
}

fn native(object: &str, noise_std: f64) -> Native {
    let mut config = SimConfig::default();
    config.signature.noise_std = noise_std;
    let mesh = ObjectSet::builtin().mesh(object).unwrap();
    Native {
        sim: Simulator::new(config.clone()).unwrap(),
        native: Simulator::native(config.clone()).unwrap(),
        config,
        caster: RayCaster::new(&mesh).unwrap(),
        prepared: PreparedObject::new(mesh).unwrap(),
    }
}

/// The whole crop rendered at native pixels, cloaked and area-resampled: the camera path without its window, on the
/// nominal membrane.
fn full_crop_prediction(n: &Native, scene: &Scene) -> Image {
    let camera = &n.config.camera;
    let t_object_camera = scene.object.to_affine().inverse() * n.sim.t_world_camera(&scene.sensor);
    let depth = render_depth(&n.caster, &camera.crop(), &t_object_camera);
    let membrane = crop(n.native.nominal_depth(), camera.crop_rows, camera.crop_cols);
    let mask = depth.zip_map(&membrane, |d, e| {
        f32::from(u8::from(d > 0.0 && e > 0.0 && d < e))
    });
    let signature = tactile_signature(
        &depth,
        &membrane,
        &mask,
        n.config.signature.shadow_px,
        (1.0, 1.0),
    );
    let (w, h) = camera.resolution;
    resample_depth(&signature, w, h)
}

/// The camera path's prediction with the object at `pose`, the sensor at `sensor`, on `membrane`.
fn path_prediction(n: &Native, sensor: &SensorPose, pose: Se2, membrane: &Image) -> Image {
    let path = CameraPath::new(&n.config).unwrap();
    let on = path.for_membrane(membrane).expect("the model's resolution");
    let t_world_camera = n.sim.t_world_camera(sensor);
    // The object's depth at the model's resolution, one ray per pixel (what the check renders).
    let coarse = render_depth(
        &n.caster,
        n.sim.intrinsics(),
        &(pose.to_affine().inverse() * t_world_camera),
    );
    on.predict(
        &n.caster,
        &t_world_camera,
        pose,
        &coarse,
        n.config.signature.shadow_px,
    )
}

fn largest_difference(a: &Image, b: &Image) -> f32 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
}

#[test]
fn the_window_renders_what_the_whole_crop_would() {
    let n = native("cross_w12_s50", 0.0);
    let membrane = to_model(&n.config.camera, n.native.nominal_depth()).unwrap();
    for (pose, press) in [
        (Se2::new(0.004, -0.003, 0.7), 0.006),
        (Se2::new(-0.01, 0.008, 2.0), 0.003),
    ] {
        let sensor = n.sim.pressing_pose(&n.prepared, 0.0, 0.0, 0.0, press);
        let scene = Scene {
            object: pose,
            sensor,
        };
        let predicted = path_prediction(&n, &sensor, pose, &membrane);
        let full = full_crop_prediction(&n, &scene);
        let changed = full
            .data
            .iter()
            .zip(&membrane.data)
            .filter(|(s, e)| (*s - *e).abs() > 1e-4)
            .count();
        assert!(changed > 50, "the press deforms the membrane: {changed} px");
        let worst = largest_difference(&predicted, &full);
        assert!(
            worst < 1e-6,
            "largest difference {worst} m at press {press}"
        );
    }
}

#[test]
fn an_object_away_from_the_membrane_predicts_the_membrane() {
    let n = native("cylinder_r15", 0.0);
    // A drifted membrane (1 mm nearer the camera everywhere) is kept as given.
    let mut membrane = n.sim.nominal_depth().clone();
    for e in membrane.data.iter_mut().filter(|e| **e > 0.0) {
        *e -= 0.001;
    }
    // Pressed 20 mm short of the membrane: no model pixel comes within reach of it.
    let sensor = n.sim.pressing_pose(&n.prepared, 0.0, 0.0, 0.0, -0.02);
    let pose = Se2::new(0.0, 0.0, 0.3);
    assert_eq!(path_prediction(&n, &sensor, pose, &membrane), membrane);
    // Another size of membrane has no path.
    let path = CameraPath::new(&n.config).unwrap();
    assert!(path.for_membrane(&Image::filled(8, 8, 0.09)).is_none());
}

/// The cost at `pose` of a frame of `n`'s sensor pressed on `truth`, made at native pixels (seed 5) and brought down as
/// the import brings it (cropped, area-resampled), with the camera path and with one ray per model pixel.
fn costs_of_a_resampled_frame(n: &Native, truth: Se2, poses: &[Se2]) -> Vec<(f64, f64)> {
    let sensor = n.sim.pressing_pose(&n.prepared, 0.0, 0.0, 0.0, 0.005);
    let scene = Scene {
        object: truth,
        sensor,
    };
    let out = n.native.simulate(&n.prepared, &scene, 5);
    let signature = to_model(&n.config.camera, &out.signature).unwrap();
    let membrane = to_model(&n.config.camera, n.native.nominal_depth()).unwrap();
    let path = CameraPath::new(&n.config).unwrap();
    let config = SignatureCheckConfig::default();
    let check = |camera_path| SignatureCheck {
        caster: &n.caster,
        intrinsics: n.sim.intrinsics(),
        membrane: &membrane,
        t_world_camera: n.sim.t_world_camera(&sensor),
        signature: &signature,
        model: SignatureModel::of_simulator(&n.sim),
        config: &config,
        camera_path,
    };
    let (with_path, per_pixel) = (check(path.for_membrane(&membrane)), check(None));
    poses
        .iter()
        .map(|&p| (with_path.cost(p), per_pixel.cost(p)))
        .collect()
}

#[test]
fn a_resampled_frame_is_explained_better_by_the_camera_path() {
    let truth = Se2::new(0.003, 0.002, -0.4);
    // Without noise, what is left at the true pose is the model's error: the camera path's is a fraction of the
    // per-pixel render's (the simulator decides contact by the membrane's signed distance, the check by D < E).
    let clean = costs_of_a_resampled_frame(&native("cross_w12_s50", 0.0), truth, &[truth]);
    let (a, b) = clean[0];
    assert!(
        a < 0.25 * b,
        "at the true pose the camera path leaves {a:e} m², one ray per pixel {b:e} m²"
    );
    // With the sensor's noise it still tells the truth from poses 1 mm and 0.05 rad off.
    let poses = [
        truth,
        Se2::new(truth.x + 0.001, truth.y, truth.theta),
        Se2::new(truth.x, truth.y - 0.001, truth.theta),
        Se2::new(truth.x, truth.y, truth.theta + 0.05),
    ];
    let noisy = costs_of_a_resampled_frame(&native("cross_w12_s50", 1.38e-3), truth, &poses);
    for (pose, c) in poses.iter().zip(&noisy).skip(1) {
        assert!(
            c.0 > noisy[0].0,
            "{pose:?}: {} against {} at the truth",
            c.0,
            noisy[0].0
        );
    }
}
