//! The evaluation loop on pairs made by the simulator, with the ground truth as the (ideal) generator: Table I is
//! perfect for it, Table II recovers the simulated poses, and the exclusions follow the objects' symmetry tags.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use tactile_derender::metrics::evaluate::{
    EvalConfig, EvalError, GroundTruthGenerator, PairSource,
};
use tactile_derender::metrics::sources::{SimSource, SimSpec};
use tactile_derender::objects::ObjectSet;
use tactile_derender::pipeline::evaluate::Evaluator;
use tactile_derender::pose::PoseConfig;
use tactile_derender::sensor::Se2;
use tactile_derender::sim::SimConfig;

/// Three simulated contacts of built-in objects (a cross, a lying cylinder, a sphere), shared with
/// [`crate::eval_pose_stage`].
pub(crate) fn source() -> SimSource {
    let specs = vec![
        SimSpec {
            object: "cross_w12_s50".into(),
            pose: Se2::new(0.003, -0.002, 0.4),
            press: 0.006,
            seed: 1,
        },
        SimSpec {
            object: "cylinder_r15".into(),
            pose: Se2::new(-0.002, 0.004, 1.1),
            press: 0.006,
            seed: 2,
        },
        SimSpec {
            object: "sphere_r20".into(),
            pose: Se2::new(0.004, 0.001, 0.0),
            press: 0.006,
            seed: 3,
        },
    ];
    SimSource::new(SimConfig::default(), ObjectSet::builtin(), specs).unwrap()
}

#[test]
fn ground_truth_generator_gives_perfect_depth_and_recovers_poses() {
    let src = source();
    assert_eq!(src.len(), 3);
    // The registration of the exact contact, taken as registered (the signature check would trade it for the noisy
    // signature's optimum: tests/signature_check.rs).
    let eval = Evaluator::new(EvalConfig {
        pose: PoseConfig {
            check_signature: false,
            ..PoseConfig::default()
        },
        ..EvalConfig::default()
    });
    let mut calls = 0;
    let report = eval
        .evaluate(&src, &GroundTruthGenerator, 7, &mut |done, total| {
            calls += 1;
            assert_eq!(total, 3);
            done <= total
        })
        .unwrap();
    assert_eq!(calls, 3);
    assert_eq!(report.pairs, 3);
    let m = &report.model;
    assert_eq!((m.l1_mm.mean, m.l1_mm.std, m.l1_mm.n), (0.0, 0.0, 3));
    assert_eq!(m.ssim.mean, 1.0);
    // Identical images have an infinite PSNR: excluded and counted.
    assert_eq!((m.psnr_db.n, m.psnr_db.excluded), (0, 3));
    assert_eq!(m.no_contact, 0);
    // Sphere: no theta; lying cylinder: position along its axis excluded.
    assert_eq!(m.theta_excluded_symmetry, 1);
    assert_eq!(m.position_axis_excluded, 1);
    assert_eq!(m.theta_rad.n, 2);
    for r in &report.records {
        let p = r.model.pose.unwrap();
        assert!(p.position_mm < 0.5, "{}: {} mm", r.name, p.position_mm);
        assert!(
            p.theta_rad.is_none_or(|t| t < 0.01),
            "{}: {:?}",
            r.name,
            p.theta_rad
        );
    }
    // The baseline sees only the noisy signature: worse depth, but it still has contact.
    let b = &report.baseline;
    assert!(b.l1_mm.mean > 0.0 && b.psnr_db.n == 3 && b.ssim.mean < 1.0);
    assert_eq!(b.no_contact, 0);
    let json = serde_json::to_string(&report).unwrap();
    assert!(json.contains("\"generator\":\"ground-truth\""));
}

#[test]
fn progress_can_cancel() {
    let src = source();
    let eval = Evaluator::new(EvalConfig::default());
    let r = eval.evaluate(&src, &GroundTruthGenerator, 0, &mut |_, _| false);
    assert!(matches!(r, Err(EvalError::Cancelled)));
}

#[test]
fn uncertainty_analysis_reports_each_registration_and_can_cancel() {
    use tactile_derender::pose::threshold_contact;
    use tactile_derender::uncertainty::analysis::{analyse_with_progress, Signature};
    let src = source();
    let eval = tactile_derender::pose::Estimator::new(PoseConfig::default());
    let pair = src.pair(0).unwrap();
    let ctx = src.context();
    let object = eval.object(&ctx.objects, &pair.object).unwrap();
    let base = threshold_contact(&pair.signature, &pair.imprint, &eval.config.baseline);
    let samples = vec![pair.target.clone(), pair.target.clone()];
    let sig = Signature {
        t_world_camera: pair.t_world_camera,
        samples: &samples,
        baseline: Some(&base),
        truth: Some(pair.object_pose),
        init: None,
        measured: Some((&pair.signature, &pair.imprint)),
        prior: None,
    };
    // K-start search + 2 samples + baseline + the multi-sample estimate.
    let mut seen = Vec::new();
    let report = analyse_with_progress(&eval, &object, ctx, &sig, 3, &mut |d, t| {
        seen.push((d, t));
        true
    })
    .unwrap();
    assert_eq!(seen, vec![(1, 5), (2, 5), (3, 5), (4, 5), (5, 5)]);
    assert_eq!(report.samples.len(), 2);
    // Two identical true samples: their consensus is the truth, registered from K starts.
    let multi = report.multi_sample.as_ref().expect("multi-sample estimate");
    assert!(multi.position_mm < 0.5, "{multi:?}");
    assert!(
        report.samples.iter().all(|s| s.position_mm < 0.5),
        "{:?}",
        report.samples
    );
    // Stopping after the second registration: no report, and no further registration ran.
    let mut calls = 0;
    let r = analyse_with_progress(&eval, &object, ctx, &sig, 3, &mut |d, _| {
        calls += 1;
        d < 2
    });
    assert!(matches!(r, Err(EvalError::Cancelled)));
    assert_eq!(calls, 2);

    // A sample that cannot be registered (wrong size for this sensor) is recorded; the other fits stand.
    let wrong = tactile_derender::image::Image::filled(8, 8, 0.08);
    let samples = vec![pair.target.clone(), wrong, pair.target.clone()];
    let sig = Signature {
        samples: &samples,
        ..sig
    };
    let report = analyse_with_progress(&eval, &object, ctx, &sig, 3, &mut |_, _| true).unwrap();
    assert_eq!(report.samples.len(), 2);
    assert!(report.baseline.is_some());
    let what: Vec<&str> = report.failed.iter().map(|f| f.what.as_str()).collect();
    assert_eq!(
        what,
        ["sample 1", "multi-sample estimate"],
        "{:?}",
        report.failed
    );
    assert!(
        report.failed[0].reason.contains("8x8"),
        "{:?}",
        report.failed
    );
}

#[test]
fn dataset_split_source_feeds_the_loop() {
    use tactile_derender::dataset::{generate, Dataset, GenConfig, SplitName};
    use tactile_derender::metrics::sources::DatasetSource;
    let dir = tempfile::tempdir().unwrap();
    let cfg = GenConfig {
        pairs: 40,
        seed: 5,
        ..Default::default()
    };
    generate(
        dir.path(),
        &SimConfig::default(),
        &ObjectSet::builtin(),
        &cfg,
        &|_| {},
    )
    .unwrap();
    let ds = Dataset::open(dir.path()).unwrap();
    let src = DatasetSource::new(&ds, SplitName::UnseenObjects, Some(2)).unwrap();
    assert_eq!(src.len(), 2.min(ds.len(SplitName::UnseenObjects)));
    let report = Evaluator::new(EvalConfig::default())
        .evaluate(&src, &GroundTruthGenerator, 1, &mut |_, _| true)
        .unwrap();
    assert_eq!(report.model.l1_mm.mean, 0.0);
    for r in &report.records {
        // The dataset's stored pose and sensor reproduce the contact: registration lands on the truth.
        assert!(
            r.model.pose.unwrap().position_mm < 0.5,
            "{}: {:?}",
            r.name,
            r.model.pose
        );
        assert_eq!(
            r.truth,
            src.pair(r.name.rsplit('/').next().unwrap().parse().unwrap())
                .unwrap()
                .object_pose
        );
    }
}

#[test]
fn the_diffusion_model_is_a_generator() {
    use glam::DAffine3;
    use tactile_derender::image::Image;
    use tactile_derender::metrics::evaluate::{EvalPair, Generator};
    use tactile_derender::metrics::model_generator::ModelGenerator;
    use tactile_derender::model::{DiffusionModel, GuidanceConfig, SamplerKind};
    use tactile_derender::pose::signature_check::SignatureModel;
    use tactile_derender::pose::SensorContext;
    // The model team's tiny 8x8 reference checkpoint (untrained weights): this checks the wiring, not the quality.
    let path = std::path::Path::new("tests/fixtures/unet_small/unet_ref.safetensors");
    let sampler = SamplerKind::Ddim {
        steps: 3,
        eta: 0.0,
        spacing: Default::default(),
    };
    let generator = ModelGenerator {
        model: DiffusionModel::load(path).unwrap(),
        sampler,
        guidance: GuidanceConfig::default(),
    };
    // A context without the sensor's cloak: nothing to guide with, so the model's own samples.
    let ctx = SensorContext {
        intrinsics: SimConfig::default().camera.intrinsics().resized(8, 8),
        membrane: Image::filled(8, 8, 0.09),
        objects: ObjectSet::builtin(),
        signature_model: None,
        unmeasured: None,
        camera_path: None,
    };
    let imprint = Image::from_vec(8, 8, (0..64).map(|i| 0.0001 * i as f32).collect()).unwrap();
    let pair = EvalPair {
        name: "tiny".into(),
        object: "none".into(),
        object_pose: Se2::default(),
        t_world_camera: DAffine3::IDENTITY,
        target: Image::filled(8, 8, 0.0),
        signature: Image::filled(8, 8, 0.0),
        imprint: imprint.clone(),
    };
    let a = generator.generate(&pair, &ctx, 2, 9).unwrap();
    assert_eq!(a.len(), 2);
    assert!(a
        .iter()
        .all(|x| (x.width, x.height) == (8, 8) && x.data.iter().all(|v| v.is_finite())));
    // Exactly what the model's own sampler returns for the same imprint and seed.
    let direct = DiffusionModel::load(path)
        .unwrap()
        .sample(&imprint, 2, sampler, 9, &mut |_, _| true)
        .unwrap();
    assert_eq!(a, direct);
    assert!(generator.name().contains("ddim 3 steps"));
    // A wrong-size imprint is a generator error naming the checkpoint.
    let big = EvalPair {
        imprint: Image::filled(16, 16, 0.0),
        ..pair
    };
    let err = generator
        .generate(&big, &ctx, 1, 0)
        .unwrap_err()
        .to_string();
    assert!(err.contains("unet_ref.safetensors"), "{err}");
    // With the cloak known the samples are guided towards the imprint: reproducible, and not the unguided ones.
    let guided_ctx = SensorContext {
        signature_model: Some(SignatureModel {
            shadow_px: 21.0,
            spacing: (2.7, 2.2),
            noise_std: 0.00138,
        }),
        ..ctx
    };
    let pair = EvalPair {
        imprint: Image::from_vec(8, 8, (0..64).map(|i| 0.0002 * (i % 8) as f32).collect()).unwrap(),
        signature: Image::filled(8, 8, 0.085),
        ..big
    };
    let g1 = generator.generate(&pair, &guided_ctx, 2, 9).unwrap();
    assert_eq!(g1, generator.generate(&pair, &guided_ctx, 2, 9).unwrap());
    let unguided = ModelGenerator {
        model: DiffusionModel::load(path).unwrap(),
        sampler,
        guidance: GuidanceConfig {
            enabled: false,
            ..GuidanceConfig::default()
        },
    };
    assert_ne!(g1, unguided.generate(&pair, &guided_ctx, 2, 9).unwrap());
    assert!(generator.name().contains("imprint-guided"));
}
