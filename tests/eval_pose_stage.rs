//! The pose stage inside the evaluation loop and against the pose use case: depth anchoring undoes a common offset,
//! the imprint's proposals recover what a wrong sample misses, the estimate's steps are counted and named, and an
//! eval record holds the estimate `tnd pose` gives for the same samples.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use tactile_derender::metrics::evaluate::{EvalConfig, EvalError, PairSource};
use tactile_derender::metrics::sources::{SimSource, SimSpec};
use tactile_derender::objects::ObjectSet;
use tactile_derender::pipeline::evaluate::Evaluator;
use tactile_derender::pose::PoseConfig;
use tactile_derender::sensor::Se2;
use tactile_derender::sim::SimConfig;

use crate::eval_loop::source;

/// The true X0 with every contact depth moved by `offset_m`: what a model trained on the nominal membrane
/// generates when the bubble's inflation has drifted.
struct OffsetTruth {
    offset_m: f32,
}

impl tactile_derender::metrics::evaluate::Generator for OffsetTruth {
    fn name(&self) -> String {
        "offset truth".into()
    }
    fn generate(
        &self,
        pair: &tactile_derender::metrics::evaluate::EvalPair,
        _ctx: &tactile_derender::pose::SensorContext,
        n: usize,
        _seed: u64,
    ) -> Result<Vec<tactile_derender::image::Image>, EvalError> {
        let mut x0 = pair.target.clone();
        for d in x0.data.iter_mut().filter(|d| **d > 0.0) {
            *d += self.offset_m;
        }
        Ok(vec![x0; n])
    }
}

#[test]
fn depth_anchoring_undoes_a_common_depth_offset() {
    let src = source();
    // Anchoring alone: the signature check (which would also undo the offset, below) is off.
    let run = |anchor: bool, check: bool| {
        let eval = Evaluator::new(EvalConfig {
            pose: PoseConfig {
                anchor_to_signature: anchor,
                check_signature: check,
                ..PoseConfig::default()
            },
            ..EvalConfig::default()
        });
        eval.evaluate(&src, &OffsetTruth { offset_m: 0.003 }, 7, &mut |_, _| true)
            .unwrap()
    };
    let (anchored, raw) = (run(true, false), run(false, false));
    for (a, r) in anchored.records.iter().zip(&raw.records) {
        let (pa, pr) = (a.model.pose.unwrap(), r.model.pose.unwrap());
        eprintln!(
            "{}: anchored {:.3} mm, raw {:.3} mm",
            a.name, pa.position_mm, pr.position_mm
        );
        // Anchored onto the signature (the true depth plus σ = 1.38 mm noise), the estimate registers as the
        // truth does (< 0.5 mm, the ground-truth test's bound).
        assert!(pa.position_mm < 0.5, "{}: {} mm", a.name, pa.position_mm);
        // Depth metrics score the estimate as generated: 3 mm off on the contact.
        assert_eq!(a.model.depth.l1_mm, r.model.depth.l1_mm);
    }
    // Without anchoring, the SE(2) fit (no height freedom) trades the offset for a lateral error: 0.5, 6.8 and
    // 4.4 mm on these three pairs when measured.
    assert!(
        raw.model.position_mm.mean > 2.0,
        "{:?}",
        raw.model.position_mm
    );
    // The signature check without anchoring: the offset hypotheses predict a signature the sensor did not measure;
    // the check moves each estimate back to a pose that explains it (within the noise, < 1 mm).
    let checked = run(false, true);
    for r in &checked.records {
        let p = r.model.pose.unwrap();
        assert!(p.position_mm < 1.0, "{}: {} mm", r.name, p.position_mm);
    }
}

/// A contact the object did not make: a small patch at the image's corner, on the measured membrane and 1 mm into
/// it, and nothing where the object pressed. A sample like that registers far from the truth, beyond what the
/// signature check's local search recovers; the imprint's own contact is where the pose is.
struct CornerContact;

impl CornerContact {
    fn apply(signature: &tactile_derender::image::Image) -> tactile_derender::image::Image {
        let mut out =
            tactile_derender::image::Image::filled(signature.width, signature.height, 0.0);
        let (x0, y0) = (signature.width / 8, signature.height / 8);
        for y in y0..y0 + 6 {
            for x in x0..x0 + 6 {
                let i = y * signature.width + x;
                out.data[i] = signature.data[i] - 0.001;
            }
        }
        out
    }
}

impl tactile_derender::metrics::evaluate::Generator for CornerContact {
    fn name(&self) -> String {
        "corner contact".into()
    }
    fn generate(
        &self,
        pair: &tactile_derender::metrics::evaluate::EvalPair,
        _ctx: &tactile_derender::pose::SensorContext,
        n: usize,
        _seed: u64,
    ) -> Result<Vec<tactile_derender::image::Image>, EvalError> {
        Ok(vec![Self::apply(&pair.signature); n])
    }
}

#[test]
fn imprint_proposals_recover_the_pose_a_wrong_sample_misses() {
    let src = source();
    let run = |imprint_proposals: bool| {
        Evaluator::new(EvalConfig {
            pose: PoseConfig {
                imprint_proposals,
                ..PoseConfig::default()
            },
            ..EvalConfig::default()
        })
        .evaluate(&src, &CornerContact, 7, &mut |_, _| true)
        .unwrap()
    };
    let with = run(true);
    for r in &with.records {
        let m = r.model.pose.unwrap().position_mm;
        let c = r.model_combined.as_ref().unwrap().pose.unwrap().position_mm;
        let b = r
            .baseline_checked
            .as_ref()
            .unwrap()
            .pose
            .unwrap()
            .position_mm;
        eprintln!("{}: sample {m:.2} mm, with the imprint's proposals {c:.2} mm, baseline + check {b:.2} mm", r.name);
        // Measured: 10-38 mm from the corner patch; 0.07-0.38 mm with the imprint's hypotheses (the baseline
        // with the check alone: 0.06-0.20 mm).
        assert!(m > 5.0, "{}: the corner patch alone gave {m} mm", r.name);
        assert!(c < 1.0, "{}: {c} mm with the imprint's proposals", r.name);
    }
    assert!(with.model_combined.is_some());
    // Off: no row, the records hold none, and the sample's own row is unchanged.
    let without = run(false);
    assert!(without.model_combined.is_none());
    assert!(without.records.iter().all(|r| r.model_combined.is_none()));
    assert_eq!(without.model.position_mm, with.model.position_mm);

    // `estimate_pose` (tnd pose, the workbench) pools the same proposals into its single-sample estimate and says
    // where the pick came from.
    use tactile_derender::pipeline::{estimate_pose, ObjectSpec, Observation, PoseInput};
    let sim = tactile_derender::sim::Simulator::new(SimConfig::default()).unwrap();
    // The cross (pair 1, the lying cylinder, leaves its axis free: errors along it are not errors).
    let pair = src.pair(0).unwrap();
    let object = ObjectSpec::library("builtin", &pair.object).load().unwrap();
    let samples = [CornerContact::apply(&pair.signature)];
    let input = PoseInput {
        t_world_camera: pair.t_world_camera,
        observation: Observation {
            samples: &samples,
            imprint: &pair.imprint,
            signature: Some(&pair.signature),
            truth: Some(pair.object_pose),
            prior: None,
            camera_path: None,
        },
    };
    let pose = |imprint_proposals: bool| {
        let config = PoseConfig {
            imprint_proposals,
            ..PoseConfig::default()
        };
        let engine = tactile_derender::pose::Estimator::new(config);
        estimate_pose(&object, &sim, &input, &engine, 7, &mut |_, _| true).unwrap()
    };
    let error = |p: Se2| (p.x - pair.object_pose.x).hypot(p.y - pair.object_pose.y) * 1e3;
    let (pooled, alone) = (pose(true), pose(false));
    assert!(pooled.checked_from_imprint && !alone.checked_from_imprint);
    let (e_pooled, e_alone) = (error(pooled.best().unwrap()), error(alone.best().unwrap()));
    assert!(
        e_pooled < 1.0 && e_alone > 5.0,
        "{e_pooled} mm pooled, {e_alone} mm alone"
    );
    // The report (its CSV and figure) carries the pose reported, scored like the samples.
    for p in [&pooled, &alone] {
        let e = p.report.estimate.unwrap();
        assert_eq!(e.pose, p.best().unwrap());
        assert!((e.position_mm - error(e.pose)).abs() < 1e-9);
        assert!(p
            .report
            .samples_csv()
            .lines()
            .any(|l| l.starts_with("estimate,0,")));
    }
}

/// `estimate_pose` (tnd pose, the workbench's Pose tab) counts its steps as `pose_steps` says, the same numbers with
/// or without a measured signature (no baseline then), and `pose_stage` names the step in progress.
#[test]
fn pose_estimate_steps_are_counted_and_named() {
    use tactile_derender::pipeline::{
        estimate_pose, pose_stage, pose_steps, ObjectSpec, Observation, PoseInput,
    };
    let src = source();
    let sim = tactile_derender::sim::Simulator::new(SimConfig::default()).unwrap();
    let pair = src.pair(0).unwrap();
    let object = ObjectSpec::library("builtin", &pair.object).load().unwrap();
    let samples = [pair.target.clone(), pair.target.clone()];
    for signature in [Some(&pair.signature), None] {
        let input = PoseInput {
            t_world_camera: pair.t_world_camera,
            observation: Observation {
                samples: &samples,
                imprint: &pair.imprint,
                signature,
                truth: Some(pair.object_pose),
                prior: None,
                camera_path: None,
            },
        };
        let mut seen = Vec::new();
        estimate_pose(
            &object,
            &sim,
            &input,
            &tactile_derender::pose::Estimator::new(PoseConfig::default()),
            7,
            &mut |d, t| {
                seen.push((d, t));
                true
            },
        )
        .unwrap();
        // First registration, 2 samples, the baseline (counted when absent too), the multi-sample estimate.
        let total = pose_steps(2);
        assert_eq!(total, 5);
        let expected: Vec<_> = if signature.is_some() {
            (1..=total).map(|d| (d, total)).collect()
        } else {
            [1, 2, 3, 5].map(|d| (d, total)).to_vec()
        };
        assert_eq!(seen, expected, "signature: {}", signature.is_some());
    }
    assert_eq!(
        pose_stage(0, 2),
        "registering the first sample from random starts"
    );
    assert_eq!(pose_stage(2, 2), "registering sample 2 of 2");
    assert_eq!(pose_stage(3, 2), "registering the threshold baseline");
    assert!(pose_stage(4, 2).starts_with("multi-sample estimate"));
    // One sample: no multi-sample step.
    assert_eq!(pose_steps(1), 3);
    assert_eq!(pose_stage(3, 1), "finishing");
}

/// Samples that differ from one another, as a model's do: the true contact with seeded depth noise and a tenth of
/// its pixels dropped, one image per sample.
struct NoisyTruth;

impl tactile_derender::metrics::evaluate::Generator for NoisyTruth {
    fn name(&self) -> String {
        "noisy truth".into()
    }
    fn generate(
        &self,
        pair: &tactile_derender::metrics::evaluate::EvalPair,
        _ctx: &tactile_derender::pose::SensorContext,
        n: usize,
        seed: u64,
    ) -> Result<Vec<tactile_derender::image::Image>, EvalError> {
        use rand::{Rng, SeedableRng};
        Ok((0..n)
            .map(|k| {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed.wrapping_add(k as u64));
                let mut x = pair.target.clone();
                for v in x.data.iter_mut().filter(|v| **v > 0.0) {
                    if rng.random::<f32>() < 0.1 {
                        *v = 0.0;
                    } else {
                        *v += rng.random_range(-5e-4..5e-4);
                    }
                }
                x
            })
            .collect())
    }
}

/// The parity of the front ends: the eval record of a pair holds the estimate, posterior and multi-sample estimate
/// that the pose use case (`tnd pose`, the workbench's Pose tab) gives for the same samples, seed and settings, and
/// pose.json carries them unchanged — at the defaults and at a configuration that is not (17 samples, more than
/// the multi-sample estimate's 16 proposals; another posterior temperature; fewer starts; no imprint proposals).
#[test]
fn the_eval_record_and_pose_json_hold_the_estimate_the_pose_use_case_gives() {
    use tactile_derender::metrics::evaluate::pair_seed;
    use tactile_derender::pipeline::pose_record::{PoseRecord, RecordSource};
    use tactile_derender::pipeline::{place_and_estimate, ObjectSpec, Observation, Placement};
    use tactile_derender::pose::posterior::PosteriorConfig;
    use tactile_derender::pose::Estimator;
    // The cross and the sphere (the lying cylinder adds nothing here but time).
    let specs = [
        SimSpec {
            object: "cross_w12_s50".into(),
            pose: Se2::new(0.003, -0.002, 0.4),
            press: 0.006,
            seed: 1,
        },
        SimSpec {
            object: "sphere_r20".into(),
            pose: Se2::new(0.004, 0.001, 0.0),
            press: 0.006,
            seed: 3,
        },
    ];
    let src = SimSource::new(SimConfig::default(), ObjectSet::builtin(), specs.to_vec()).unwrap();
    let sim = tactile_derender::sim::Simulator::new(SimConfig::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let other = EvalConfig {
        pose: PoseConfig {
            inits: 6,
            imprint_proposals: false,
            posterior: PosteriorConfig {
                temperature: PosteriorConfig::default().temperature * 2.0,
                ..PosteriorConfig::default()
            },
            ..PoseConfig::default()
        },
        pose_samples: 17,
        ..EvalConfig::default()
    };
    for config in [EvalConfig::default(), other] {
        let seed = 11;
        let mut seen = Vec::new();
        let report = Evaluator::new(config.clone())
            .evaluate_observed(&src, &NoisyTruth, seed, &mut |_, _| true, &mut |i, _, s| {
                seen.push((i, s.to_vec()))
            })
            .unwrap();
        assert_eq!(report.records.len(), src.len(), "{:?}", report.failed);
        let proposals = config.pose.imprint_proposals;
        for (r, (i, samples)) in report.records.iter().zip(&seen) {
            let pair = src.pair(*i).unwrap();
            let object = ObjectSpec::library("builtin", &pair.object).load().unwrap();
            let observation = Observation {
                samples,
                imprint: &pair.imprint,
                signature: Some(&pair.signature),
                truth: Some(pair.object_pose),
                prior: None,
                camera_path: None,
            };
            let engine = Estimator::new(config.pose.clone());
            let placed = place_and_estimate(
                &object,
                None,
                &sim,
                &observation,
                Placement::Camera(pair.t_world_camera),
                &engine,
                pair_seed(seed, *i),
                &mut |_, _| true,
            )
            .unwrap();
            let e = &placed.estimate;
            // What `tnd pose` reports is the combined row with the imprint's proposals, else the model's row.
            let row = if proposals {
                r.model_combined.as_ref().unwrap()
            } else {
                assert!(r.model_combined.is_none());
                &r.model
            };
            let name = format!("{} ({} samples)", r.name, samples.len());
            assert!(e.best().is_some(), "{name}");
            assert_eq!(row.estimate, e.best(), "{name}");
            assert!(e.posterior.is_some(), "{name}");
            assert_eq!(row.posterior, e.posterior, "{name}");
            assert_eq!(row.truth_region, e.truth_region, "{name}");
            if samples.len() > 1 {
                let multi = r.model_multi.as_ref().unwrap();
                assert!(e.report.multi_sample.is_some(), "{name}");
                assert_eq!(
                    multi.estimate,
                    e.report.multi_sample.map(|m| m.pose),
                    "{name}"
                );
                assert_eq!(multi.posterior, e.report.multi_sample_posterior, "{name}");
            } else {
                assert!(r.model_multi.is_none());
            }
            // pose.json, written and read back: the same estimate and posterior, and the hypotheses with costs.
            let record = PoseRecord::new(
                &placed,
                Some(pair.object_pose),
                &object.symmetry,
                RecordSource::default(),
            );
            let path = dir.path().join("pose.json");
            record.write(&path).unwrap();
            let back = PoseRecord::read(&path).unwrap();
            // (As JSON: a refined pose's cost is NaN, written as null, and NaN is unequal to itself.)
            let json = |r: &PoseRecord| serde_json::to_value(r).unwrap();
            assert_eq!(json(&back), json(&record), "{name}");
            assert_eq!(back.estimate, row.estimate, "{name}");
            assert_eq!(back.posterior, row.posterior, "{name}");
            assert_eq!(back.hypotheses, e.hypotheses, "{name}");
            assert_eq!(back.imprint_hypotheses.is_empty(), !proposals, "{name}");
        }
    }
}
