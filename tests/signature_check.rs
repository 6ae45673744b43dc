//! The signature check against the simulator it inverts: at the true pose it predicts the simulator's own noise-free
//! signature, it ranks the true pose above wrong ones on a noisy signature, refines a perturbed pose back, and
//! rejects images that do not fit the camera.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use tactile_derender::image::Image;
use tactile_derender::mesh::RayCaster;
use tactile_derender::objects::ObjectSet;
use tactile_derender::pose::signature_check::{
    SignatureCheck, SignatureCheckConfig, SignatureModel,
};
use tactile_derender::sensor::{Scene, Se2};
use tactile_derender::sim::{PreparedObject, SimConfig, SimOutput, Simulator};

struct Setup {
    sim: Simulator,
    caster: RayCaster,
    scene: Scene,
    out: SimOutput,
}

fn setup(object: &str, pose: Se2, press: f64, noise_std: f64) -> Setup {
    let mut config = SimConfig::default();
    config.signature.noise_std = noise_std;
    let sim = Simulator::new(config).unwrap();
    let mesh = ObjectSet::builtin().mesh(object).unwrap();
    let caster = RayCaster::new(&mesh).unwrap();
    let prepared = PreparedObject::new(mesh).unwrap();
    let sensor = sim.pressing_pose(&prepared, 0.0, 0.0, 0.0, press);
    let scene = Scene {
        object: pose,
        sensor,
    };
    let out = sim.simulate(&prepared, &scene, 11);
    Setup {
        sim,
        caster,
        scene,
        out,
    }
}

fn model(sim: &Simulator) -> SignatureModel {
    SignatureModel {
        shadow_px: sim.config().signature.shadow_px,
        spacing: sim.intrinsics().pixel_size_in(&sim.config().camera.native),
        noise_std: sim.config().signature.noise_std,
    }
}

fn check<'a>(
    s: &'a Setup,
    signature: &'a Image,
    config: &'a SignatureCheckConfig,
) -> SignatureCheck<'a> {
    SignatureCheck {
        caster: &s.caster,
        intrinsics: s.sim.intrinsics(),
        membrane: s.sim.nominal_depth(),
        t_world_camera: s.sim.t_world_camera(&s.scene.sensor),
        signature,
        model: model(&s.sim),
        config,
        camera_path: None,
    }
}

#[test]
fn prediction_at_the_true_pose_is_the_simulated_signature() {
    let pose = Se2::new(0.004, -0.003, 0.7);
    let s = setup("cross_w12_s50", pose, 0.006, 0.0);
    assert!(s.out.contact_pixels > 200, "{}", s.out.contact_pixels);
    let config = SignatureCheckConfig::default();
    let predicted = check(&s, &s.out.signature, &config).predict(pose);
    // The simulator decides contact with the elastomer's signed distance, the check by D < E along each ray: the
    // same set up to pixels grazing the membrane, whose depth then differs from E by almost nothing.
    let worst = predicted
        .data
        .iter()
        .zip(&s.out.signature.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 2e-4, "largest difference {worst} m");
    assert!(check(&s, &s.out.signature, &config).cost(pose) < 1e-9);
}

#[test]
fn the_true_pose_explains_a_noisy_signature_best_and_is_found_again() {
    let truth = Se2::new(0.003, 0.002, -0.4);
    let s = setup("cross_w12_s50", truth, 0.005, 1.38e-3);
    let config = SignatureCheckConfig::default();
    let c = check(&s, &s.out.signature, &config);
    let at_truth = c.cost(truth);
    for wrong in [
        Se2::new(truth.x + 0.002, truth.y, truth.theta),
        Se2::new(truth.x, truth.y - 0.002, truth.theta),
        Se2::new(truth.x, truth.y, truth.theta + 0.2),
    ] {
        assert!(c.cost(wrong) > at_truth, "{wrong:?}");
    }
    // Hypotheses as a registration might give them: one far off, one rotated, one near the truth.
    let hypotheses = [
        Se2::new(truth.x + 0.008, truth.y - 0.005, truth.theta + 1.0),
        Se2::new(truth.x, truth.y, truth.theta + std::f64::consts::FRAC_PI_4),
        Se2::new(truth.x + 0.0006, truth.y - 0.0004, truth.theta + 0.03),
    ];
    let picked = c.select(&hypotheses).unwrap().expect("a pose");
    // With noise the best explanation need not be the truth itself, but it explains the signature at least as well
    // and lies in the truth's basin (the noise moves it a fraction of a millimetre), not at the wrong hypotheses.
    assert!(
        picked.cost <= at_truth,
        "{picked:?}; cost at the truth {at_truth}"
    );
    assert_eq!(picked.from, 2);
    let error_mm = (picked.pose.x - truth.x).hypot(picked.pose.y - truth.y) * 1e3;
    assert!(error_mm < 1.0, "{picked:?}: {error_mm} mm");
    assert!((picked.pose.theta - truth.theta).abs() < 0.05, "{picked:?}");
    assert!(picked.cost <= c.cost(hypotheses[2]));
    assert!(c.select(&[]).unwrap().is_none());
}

#[test]
fn images_that_do_not_fit_the_camera_and_bad_settings_are_errors() {
    let s = setup("sphere_r20", Se2::default(), 0.004, 0.0);
    let config = SignatureCheckConfig::default();
    let small = Image::filled(8, 8, 0.08);
    let err = check(&s, &small, &config)
        .select(&[Se2::default()])
        .unwrap_err()
        .to_string();
    assert!(err.contains("signature is 8x8"), "{err}");
    let bad = SignatureCheckConfig {
        scale_m: 0.0,
        ..Default::default()
    };
    let err = check(&s, &s.out.signature, &bad)
        .select(&[Se2::default()])
        .unwrap_err()
        .to_string();
    assert!(err.contains("scale_m must be positive"), "{err}");
}

#[test]
fn poses_the_signature_cannot_tell_apart_keep_the_registrations_pick_with_a_margin() {
    // A sphere turned about the table normal leaves the same signature up to its tessellation: far less than 3 nats
    // of log-likelihood apart, so with that margin the check keeps the registration's best (the first hypothesis),
    // whichever order the two come in.
    let truth = Se2::new(0.002, -0.001, 0.3);
    let s = setup("sphere_r20", truth, 0.005, 1.38e-3);
    let config = SignatureCheckConfig {
        margin_nats: 3.0,
        refine: 0,
        ..Default::default()
    };
    let c = check(&s, &s.out.signature, &config);
    let turned = Se2::new(truth.x, truth.y, truth.theta + 1.0);
    let nats =
        (c.cost(truth) - c.cost(turned)).abs() * c.measured_pixels() as f64 / 1.38e-3f64.powi(2);
    assert!(nats < 1.0, "{nats} nats apart");
    for (first, second) in [(truth, turned), (turned, truth)] {
        let picked = c.select(&[first, second]).unwrap().unwrap();
        assert_eq!(picked.from, 0, "{picked:?}");
        assert_eq!(picked.pose, first);
        // The other pose is the pick's rival, and the check says it cannot tell the two apart.
        let rival = picked.rival.expect("a rival");
        assert_eq!(rival.pose, second);
        assert!(rival.ambiguous() && rival.nats.abs() < 1.0, "{rival:?}");
    }
    // A clearly better explanation still wins over the first hypothesis, and the loser is no match for it.
    let off = Se2::new(truth.x + 0.004, truth.y, truth.theta);
    let picked = c.select(&[off, truth]).unwrap().unwrap();
    assert_eq!(picked.from, 1);
    let rival = picked.rival.expect("a rival");
    assert_eq!(rival.pose, off);
    assert!(!rival.ambiguous(), "{rival:?}");
    // A pose within 2 mm and 15° of the pick is the same pose, not a rival.
    let near = Se2::new(truth.x + 0.001, truth.y, truth.theta + 0.1);
    assert!(c.select(&[truth, near]).unwrap().unwrap().rival.is_none());
}

#[test]
fn the_press_is_found_from_the_contact_and_the_noisy_signature() {
    // Independent truth: the press the simulator placed the sensor at (the sensor never measures it). With the true
    // contact as the sample, the signature's search lands within half a millimetre of it, as does the samples'
    // highest point alone (no signature); a fixed press is taken as given.
    use tactile_derender::pipeline::press::{PressChoice, SensorPlacement};
    use tactile_derender::pipeline::ObjectSpec;
    use tactile_derender::pose::PoseConfig;
    let object = ObjectSpec::library("builtin", "cross_w12_s50")
        .load()
        .unwrap();
    let prepared = PreparedObject::new(object.mesh.clone()).unwrap();
    let eval = PoseConfig::default();
    for press in [0.003, 0.0045, 0.007] {
        let s = setup(
            "cross_w12_s50",
            Se2::new(0.003, -0.002, 0.4),
            press,
            0.00138,
        );
        let engine = tactile_derender::pose::Estimator::new(eval.clone());
        let at = SensorPlacement {
            sim: &s.sim,
            object: &object,
            prepared: &prepared,
            engine: &engine,
            camera_path: None,
        };
        let samples = std::slice::from_ref(&s.out.target);
        let (sig, imprint) = (&s.out.signature, &s.out.imprint);
        let searched = at
            .press(PressChoice::Auto, samples, Some(sig), imprint, None, 0)
            .unwrap();
        let highest = at
            .press(PressChoice::Auto, samples, None, imprint, None, 0)
            .unwrap();
        for (how, got) in [("searched", searched), ("highest point", highest)] {
            let got = got.unwrap();
            assert!((got - press).abs() < 5e-4, "{how}: {got} for {press}");
        }
        // A track's previous frame, 1 mm off the press and a little off the pose: searched around it, the press
        // simulated.
        let prior = tactile_derender::pose::PosePrior {
            poses: vec![Se2::new(0.0035, -0.002, 0.45)],
            random_starts: 0,
            press_m: Some(press + 0.001),
            posterior: None,
        };
        let carried = at
            .press(
                PressChoice::Auto,
                samples,
                Some(sig),
                imprint,
                Some(&prior),
                0,
            )
            .unwrap()
            .unwrap();
        assert!(
            (carried - press).abs() < 5e-4,
            "carried: {carried} for {press}"
        );
        let fixed = at.press(
            PressChoice::Fixed(0.006),
            samples,
            Some(sig),
            imprint,
            None,
            0,
        );
        assert_eq!(fixed.unwrap(), Some(0.006));
    }
}

#[test]
fn the_frames_noise_is_measured_from_its_signature_robustly() {
    // Independent truth: the σ the simulator drew the signature's noise with, one draw per pixel.
    let truth = Se2::new(0.002, -0.001, 0.3);
    for sigma in [0.5e-3, 1.38e-3, 3e-3] {
        let s = setup("cross_w12_s50", truth, 0.006, sigma);
        let config = SignatureCheckConfig::default();
        let c = check(&s, &s.out.signature, &config);
        let at_truth = c.residual_noise(truth).unwrap();
        assert!(
            (at_truth / sigma - 1.0).abs() < 0.08,
            "σ {sigma}: measured {at_truth}"
        );
        // A pose 2 mm off mispredicts the contact's pixels; the median absolute deviation ignores them.
        let off = c
            .residual_noise(Se2::new(truth.x + 0.002, truth.y, truth.theta))
            .unwrap();
        assert!(
            (off / sigma - 1.0).abs() < 0.25,
            "σ {sigma}: 2 mm off {off}"
        );
    }
    // Too few measured pixels to say: none.
    let s = setup("cross_w12_s50", truth, 0.006, 1e-3);
    let config = SignatureCheckConfig::default();
    let blank = Image::filled(s.out.signature.width, s.out.signature.height, 0.0);
    assert!(check(&s, &blank, &config).residual_noise(truth).is_none());
}

#[test]
fn the_contacts_misfit_is_the_frames_noise_at_the_truth_and_more_off_it() {
    // Independent truth: at the true pose the signature differs from its prediction by the noise the simulator
    // drew (σ per pixel) alone, on the contact as everywhere; a pose 2 mm off leaves the contact unexplained.
    let truth = Se2::new(0.002, -0.001, 0.3);
    for sigma in [0.5e-3, 1.38e-3] {
        let s = setup("cross_w12_s50", truth, 0.006, sigma);
        let config = SignatureCheckConfig::default();
        let c = check(&s, &s.out.signature, &config);
        let at_truth = c.contact_misfit(truth, 0.003).unwrap();
        assert!(
            (at_truth / sigma - 1.0).abs() < 0.2,
            "σ {sigma}: misfit at the truth {at_truth}"
        );
        // 2 mm off, only the cross's edges are mispredicted (noise pixels over the threshold dilute them on a
        // noisy frame); turned by 0.4 rad, its arms.
        let off = c
            .contact_misfit(Se2::new(truth.x + 0.002, truth.y, truth.theta), 0.003)
            .unwrap();
        let turned = c
            .contact_misfit(Se2::new(truth.x, truth.y, truth.theta + 0.4), 0.003)
            .unwrap();
        assert!(
            off > at_truth && turned > 1.3 * at_truth,
            "σ {sigma}: 2 mm off {off}, turned {turned}, against {at_truth}"
        );
    }
    let s = setup("cross_w12_s50", truth, 0.006, 1e-3);
    let config = SignatureCheckConfig::default();
    let blank = Image::filled(s.out.signature.width, s.out.signature.height, 0.0);
    assert!(check(&s, &blank, &config)
        .contact_misfit(truth, 0.003)
        .is_none());
}
