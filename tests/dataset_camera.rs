//! Pairs of `tnd dataset gen` seen through the sensor's depth camera ([`tactile_derender::dataset::camera_pass`]):
//! the truth stays the scene's, the model's inputs are what the camera and the import's resampling make of it.

use std::path::Path;

use crate::dataset::assert_same_tree;
use crate::dataset_common::{gen_config, sim_config, small_set};
use tactile_derender::dataset::{generate, Dataset, GenConfig, SplitName};

#[test]
fn a_depth_camera_changes_what_the_model_sees_not_the_truth() {
    use tactile_derender::sim::DepthCameraConfig;
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let gen = |out: &Path, camera: DepthCameraConfig, noise: f64, threads: usize| {
        let mut c = sim_config();
        c.depth_camera = camera;
        c.signature.noise_std = noise;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| generate(out, &c, &set, &gen_config(12), &|_| {}))
            .unwrap();
        Dataset::open(out).unwrap()
    };
    let tof = DepthCameraConfig {
        dropout: 0.7,
        noise_exponent: 2.0,
        flying_jump_m: 0.005,
        fixed_pattern_m: 0.001,
        ..DepthCameraConfig::default()
    };
    let ideal = gen(
        &tmp.path().join("ideal"),
        DepthCameraConfig::default(),
        0.00138,
        2,
    );
    let cam = gen(&tmp.path().join("cam"), tof.clone(), 0.00138, 2);
    // Reproducible whatever the thread count.
    gen(&tmp.path().join("cam1"), tof, 0.00138, 1);
    assert_same_tree(&tmp.path().join("cam"), &tmp.path().join("cam1"));
    let (mut missing, mut seen, mut differ) = (0usize, 0usize, 0usize);
    for split in SplitName::ALL {
        assert_eq!(ideal.len(split), cam.len(split));
        for i in 0..cam.len(split) {
            let (p, q) = (ideal.pair(split, i).unwrap(), cam.pair(split, i).unwrap());
            // The truth is the scene's, whatever the camera: the same draw, contact and target.
            assert_eq!(
                (p.meta.object_pose, p.meta.press),
                (q.meta.object_pose, q.meta.press)
            );
            assert_eq!((&p.mask, &p.target), (&q.mask, &q.target), "{split} {i}");
            // What the model sees is the camera's: pixels without a return (0 in the signature; 70 % of native pixels
            // dropped leaves many model pixels under half covered), and an imprint without holes.
            for k in 0..q.signature.data.len() {
                if p.signature.data[k] > 0.0 {
                    seen += 1;
                    missing += usize::from(q.signature.data[k] == 0.0);
                }
            }
            assert!(q.imprint.data.iter().all(|y| y.is_finite()));
            differ += usize::from(p.imprint != q.imprint);
        }
    }
    assert!(
        missing > seen / 10 && missing < seen,
        "{missing} of {seen} missing"
    );
    assert_eq!(differ, 12, "every pair's imprint is the camera's");

    // A fixed pattern is the same in the contact frame and the no-contact frames, so the imprint R − S cancels it:
    // without noise, a 3 mm pattern moves the imprint by far less than it moves the signature (both datasets seen
    // through the camera, the first's pattern negligible).
    let pattern = |m: f64| DepthCameraConfig {
        fixed_pattern_m: m,
        ..DepthCameraConfig::default()
    };
    let flat = gen(&tmp.path().join("flat"), pattern(1e-9), 0.0, 2);
    let patterned = gen(&tmp.path().join("pattern"), pattern(0.003), 0.0, 2);
    let mean_abs = |a: &tactile_derender::image::Image, b: &tactile_derender::image::Image| {
        let d: Vec<f64> = a
            .data
            .iter()
            .zip(&b.data)
            .filter(|(x, y)| **x > 0.0 && **y > 0.0)
            .map(|(x, y)| f64::from(x - y).abs())
            .collect();
        d.iter().sum::<f64>() / d.len().max(1) as f64
    };
    let (mut signature_moved, mut imprint_moved) = (0.0, 0.0);
    for i in 0..flat.len(SplitName::Train) {
        let (p, q) = (
            flat.pair(SplitName::Train, i).unwrap(),
            patterned.pair(SplitName::Train, i).unwrap(),
        );
        signature_moved += mean_abs(&p.signature, &q.signature);
        imprint_moved += mean_abs(&p.imprint, &q.imprint);
    }
    assert!(
        signature_moved > 1e-4 && imprint_moved < 0.05 * signature_moved,
        "imprint moved {imprint_moved}, signature {signature_moved}"
    );
}

#[test]
fn native_frames_are_as_quiet_as_imported_ones_and_keep_the_truth() {
    // `native_frames` with an ideal camera: each pair rendered natively and area-resampled to the model's size, as an
    // import brings a recording's frames. The noise an imprint carries (noisy minus noise-free, same draws) is, at
    // the model's resolution, √2 σ (reference and signature each σ: an analytic truth); through the native path the
    // resampling averages several native pixels and the reference is a median of frames, so it is far quieter.
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let gen = |name: &str, native_frames: bool, noise: f64| {
        let mut c = sim_config();
        c.signature.noise_std = noise;
        let cfg = GenConfig {
            native_frames,
            ..gen_config(8)
        };
        let out = tmp.path().join(name);
        generate(&out, &c, &set, &cfg, &|_| {}).unwrap();
        Dataset::open(&out).unwrap()
    };
    let sigma = 0.00138;
    let rms_noise = |noisy: &Dataset, clean: &Dataset| {
        let (mut sum, mut n) = (0.0, 0usize);
        for i in 0..noisy.len(SplitName::Train) {
            let (p, q) = (
                noisy.pair(SplitName::Train, i).unwrap(),
                clean.pair(SplitName::Train, i).unwrap(),
            );
            assert_eq!((&p.mask, &p.target), (&q.mask, &q.target));
            for (a, b) in p.imprint.data.iter().zip(&q.imprint.data) {
                sum += f64::from(a - b).powi(2);
                n += 1;
            }
        }
        (sum / n as f64).sqrt()
    };
    let model_res = rms_noise(&gen("m1", false, sigma), &gen("m0", false, 0.0));
    let native = rms_noise(&gen("n1", true, sigma), &gen("n0", true, 0.0));
    let analytic = 2f64.sqrt() * sigma;
    assert!(
        (model_res / analytic - 1.0).abs() < 0.1,
        "{model_res} against {analytic}"
    );
    assert!(
        native < 0.6 * model_res,
        "native {native}, model resolution {model_res}"
    );
    // The truth is the same draws' either way.
    let (a, b) = (gen("m2", false, sigma), gen("n2", true, sigma));
    for i in 0..a.len(SplitName::Train) {
        let (p, q) = (
            a.pair(SplitName::Train, i).unwrap(),
            b.pair(SplitName::Train, i).unwrap(),
        );
        assert_eq!(
            (&p.mask, &p.target, p.meta.press),
            (&q.mask, &q.target, q.meta.press)
        );
    }
}
