//! The Pose tab driven by egui_kittest through its labels: samples of a generated dataset pair registered to the
//! object (the pose recovered, the KDEs fitted), cancelling a registration, and the signature check and imprint
//! proposals switched from the tab.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::{Duration, Instant};

use egui_kittest::kittest::Queryable;
use tactile_derender::dataset::{Dataset, SplitName};
use tnd_workbench::app::WorkbenchApp;

use crate::support;
use support::{
    harness, open_dataset, select_pair, small_dataset, tiny_model, use_checkpoint, wait_for,
};

#[test]
fn registering_ground_truth_like_samples_recovers_the_pose_and_fits_the_kdes() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_dataset(dir.path());
    let model_path = tiny_model(dir.path());
    let pair = Dataset::open(&data)
        .unwrap()
        .pair(SplitName::Train, 0)
        .unwrap();

    let mut h = harness(WorkbenchApp::default());
    open_dataset(&mut h, &data);
    select_pair(&mut h, "train pair 0");
    h.get_by_label("Send to de-render").click();
    h.run_ok();
    use_checkpoint(&mut h, &model_path);
    let mut d = h.state().state.derender.clone();
    d.config.sampler.steps = 2;
    d.config.samples = 4;
    h.state_mut()
        .apply(tnd_workbench::command::Command::SetDerender(d));
    h.get_by_label("Run de-rendering").click();
    wait_for(&mut h, "the samples", |a| !a.analysis.derender.running);
    // An untrained model's samples say nothing about the pose: replace them by the true X0 moved 0, 0.1, 0.2 and
    // 0.3 mm further from the camera, whose registrations must land on the true pose.
    let samples: Vec<_> = (0..4)
        .map(|k| {
            let mut s = pair.target.clone();
            for v in s.data.iter_mut().filter(|v| **v > 0.0) {
                *v += 1e-4 * k as f32;
            }
            s
        })
        .collect();
    h.state_mut()
        .analysis
        .derender
        .result
        .as_mut()
        .unwrap()
        .samples = samples;

    h.get_by_label("Pose").click();
    h.run_ok();
    h.get_by_label("Register samples").click();
    wait_for(&mut h, "the registration", |a| !a.analysis.pose.running);
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let r = h.state().analysis.pose.result.as_ref().unwrap();
    assert_eq!(r.truth, Some(pair.meta.object_pose));
    assert_eq!(r.object, pair.meta.object);
    assert!(!r.hypotheses.is_empty() && !r.contacts.is_empty() && !r.outline.is_empty());
    assert!(r.hypotheses.windows(2).all(|w| w[0].cost <= w[1].cost));
    assert_eq!(r.report.samples.len(), 4);
    for s in &r.report.samples {
        assert!(s.position_mm < 1.5, "{:?}", r.report.samples);
    }
    assert!(!r.report.position_kde.is_empty(), "no position KDE");
    // θ as an angle too: the circular histogram of the four samples' θ errors, over the object's symmetry period.
    assert!(r
        .report
        .theta_period_deg
        .is_some_and(|p| p > 0.0 && p <= 360.0));
    assert!(h
        .query_by_label_contains("θ error circular histogram, 4 samples")
        .is_some());
    assert!(r.report.baseline.is_some(), "the baseline found no contact");
    assert!(h
        .query_by_label_contains("4 of 4 samples registered")
        .is_some());
    // The multi-sample estimate (consensus of the four samples) is shown beside the single-sample fits.
    let multi = r
        .report
        .multi_sample
        .as_ref()
        .expect("multi-sample estimate");
    assert!(multi.position_mm < 1.5, "{multi:?}");
    assert!(h
        .query_by_label_contains("multi-sample estimate (consensus of 4 samples)")
        .is_some());
    // The signature check ran (the scene has a signature): its pick is the single-sample estimate, shown by name.
    let checked = r.checked.expect("signature-checked estimate");
    let truth = r.truth.unwrap();
    assert!(
        (checked.x - truth.x).hypot(checked.y - truth.y) < 1.5e-3,
        "{checked:?}"
    );
    assert!(h.query_by_label_contains("signature check: x").is_some());
    // The posterior: modes with weights, σ about the estimate, the error beside it and where the truth lies in it.
    let post = r.posterior.as_ref().expect("pose posterior");
    assert!(!post.modes.is_empty());
    assert!(
        r.truth_region.is_some_and(|m| m <= 0.9),
        "{:?}",
        r.truth_region
    );
    assert!(h.query_by_label_contains("posterior: ").is_some());
    assert!(h
        .query_by_label_contains("that it is none of them); σ x")
        .is_some());
    assert!(h.query_by_label_contains("; error x").is_some());
    assert!(h.query_by_label_contains("(68 % within ±").is_some());
    assert!(h
        .query_by_label_contains("the truth is inside its")
        .is_some());
    // It says whose hypothesis won: the sample's or the imprint's threshold contact's.
    let source = if r.checked_from_imprint {
        "the imprint's proposal"
    } else {
        "the sample's proposal"
    };
    assert!(h.query_by_label_contains(source).is_some());
    // Depth anchoring ran (the scene has a signature) and says what it did to the registered sample.
    assert_eq!(r.anchor_shift_m.len(), 4);
    assert!(
        h.query_by_label_contains("contact depths as generated")
            .is_some()
            || h.query_by_label_contains("contact depths anchored to the signature")
                .is_some()
    );

    // Hovering the position KDE highlights the sample nearest to the pointer: at the plot's left edge (the first
    // point right of the y axis where hovering picks a sample: x ≤ 0, below every error) the smallest error, near its
    // right end the largest.
    let by_error = |pick_max: bool| {
        let r = h.state().analysis.pose.result.as_ref().unwrap();
        let k = (0..r.report.samples.len())
            .max_by(|&a, &b| {
                let (ea, eb) = (
                    r.report.samples[a].position_mm,
                    r.report.samples[b].position_mm,
                );
                if pick_max {
                    ea.total_cmp(&eb)
                } else {
                    eb.total_cmp(&ea)
                }
            })
            .unwrap();
        r.sample_of(k)
    };
    let (smallest, largest) = (by_error(false), by_error(true));
    assert_ne!(
        smallest, largest,
        "the four samples should have distinct errors"
    );
    let rect = h.get_by_label("position error (mm) KDE").rect();
    let at = |f: f32| rect.left() + f * rect.width();
    let mut left_edge = None;
    for step in 0..40 {
        h.hover_at(egui::pos2(at(0.01 * step as f32), rect.center().y));
        h.run_ok();
        if h.state().analysis.pose.highlight.is_some() {
            left_edge = h.state().analysis.pose.highlight;
            break;
        }
    }
    assert_eq!(left_edge, smallest, "at the left edge");
    h.hover_at(egui::pos2(at(0.95), rect.center().y));
    h.run_ok();
    assert_eq!(
        h.state().analysis.pose.highlight,
        largest,
        "near the right end"
    );

    // Export: the evaluation stage's CSV and PNG.
    let mut v = h.state().state.view.clone();
    v.export_dir = dir.path().join("out");
    h.state_mut()
        .apply(tnd_workbench::command::Command::SetView(v));
    h.run_ok();
    h.get_by_label("Export CSV, figures, PLY").click();
    h.run_ok();
    for f in [
        "samples.csv",
        "kde.csv",
        "uncertainty.png",
        "uncertainty.svg",
        "fit.svg",
        "fit.png",
        "contact_points.ply",
        "free_space_points.ply",
        "consensus_points.ply",
        "object_estimate.ply",
        "object_truth.ply",
    ] {
        assert!(
            dir.path().join("out/pose").join(f).is_file(),
            "no {f}: {:?}",
            h.state().errors
        );
    }
    let csv = std::fs::read_to_string(dir.path().join("out/pose/samples.csv")).unwrap();
    // Header, four samples, the baseline, the multi-sample estimate and the estimate reported.
    assert_eq!(csv.lines().count(), 1 + 4 + 1 + 1 + 1, "{csv}");
    assert!(csv.contains("\nmulti_sample,0,"), "{csv}");
    assert!(csv.contains("\nestimate,0,"), "{csv}");

    // A cancelled registration leaves no result (even if its thread was about to finish) and no error.
    h.get_by_label("Register samples").click();
    h.run_ok();
    assert!(h.state().analysis.pose.running);
    h.get_by_label("Cancel registration").click();
    h.run_ok();
    assert!(!h.state().analysis.pose.running);
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(3) {
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    h.run_ok();
    assert!(h.state().analysis.pose.result.is_none());
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    assert!(h.query_by_label("Register samples").is_some());

    // With the signature check unticked the registration's best hypothesis is the estimate, and the tab says no
    // check ran.
    h.get_by_label("signature check").click();
    h.run_ok();
    assert!(!h.state().state.pose.check_signature);
    // The setting is the session's, stored as the core's PoseConfig (`tnd pose --no-signature-check`).
    assert_eq!(
        serde_json::to_value(&h.state().state).unwrap()["pose"]["check_signature"],
        false
    );
    h.get_by_label("Register samples").click();
    wait_for(&mut h, "the registration without the check", |a| {
        !a.analysis.pose.running && a.analysis.pose.result.is_some()
    });
    let r = h.state().analysis.pose.result.as_ref().unwrap();
    assert!(r.checked.is_none());
    assert_eq!(r.single_estimate(), r.hypotheses.first().map(|h| h.pose));
    assert!(h.query_by_label_contains("signature check: x").is_none());

    // With the check back on and the imprint's proposals off, the check judges the sample's hypotheses alone, so
    // its pick cannot come from the imprint.
    h.get_by_label("signature check").click();
    h.run_ok();
    h.get_by_label("imprint proposals").click();
    h.run_ok();
    assert!(!h.state().state.pose.imprint_proposals);
    h.get_by_label("Register samples").click();
    wait_for(&mut h, "the registration without imprint proposals", |a| {
        !a.analysis.pose.running && a.analysis.pose.result.is_some()
    });
    let r = h.state().analysis.pose.result.as_ref().unwrap();
    assert!(r.checked.is_some() && !r.checked_from_imprint);
    assert!(h.query_by_label_contains("the sample's proposal").is_some());

    // The native-pixel check is the session's too (`tnd pose --check-native false`), on by default.
    assert!(h.state().state.pose.signature_check.native);
    h.get_by_label("native-pixel check").click();
    h.run_ok();
    assert_eq!(
        serde_json::to_value(&h.state().state).unwrap()["pose"]["signature_check"]["native"],
        false
    );
}
