//! One pipeline, two front ends: the workbench's De-render and Pose jobs (driven through their buttons) and the
//! `tnd sample` / `tnd pose` commands, given the same scene, settings and seed, give bit-identical samples and poses.
//! The commands run as the built `tnd` binary (`cargo test --workspace` builds it beside this test).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::support;

use std::process::Command;
use std::time::Duration;

use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use tactile_derender::io::npy;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::state::{State, Tab};

/// Waits for the workbench's jobs: longer than the other UI tests allow, the debug-build sampler is slow.
fn wait_for(h: &mut Harness<'_, WorkbenchApp>, what: &str, done: impl Fn(&WorkbenchApp) -> bool) {
    support::wait_for_within(h, what, Duration::from_secs(300), done);
}

fn tnd(args: &[&str]) -> serde_json::Value {
    let out = Command::new(support::tnd_binary())
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "tnd {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    serde_json::from_str(stdout.trim()).unwrap()
}

#[test]
fn workbench_jobs_and_cli_commands_give_bit_identical_samples_and_poses() {
    let dir = tempfile::tempdir().unwrap();
    let mut state = State::default();
    state.view.tab = Tab::Derender;
    let d = &mut state.derender.config;
    d.samples = 3;
    d.sampler.steps = 4;
    d.seed = 5;
    let config = d.clone();
    let scene = state.scene.clone();
    assert_eq!(
        (scene.sensor_x, scene.sensor_y, scene.sensor_yaw),
        (0.0, 0.0, 0.0)
    );

    // The workbench: simulate the default scene, de-render it, register the samples.
    let mut h = support::harness(WorkbenchApp::with_state(state));
    wait_for(&mut h, "the simulation", |a| a.sim.is_some());
    h.get_by_label("Run de-rendering").click();
    h.run_ok();
    wait_for(&mut h, "the samples", |a| {
        !a.analysis.derender.running && a.analysis.derender.result.is_some()
    });
    h.get_by_label("Pose").click();
    h.run_ok();
    h.get_by_label("Register samples").click();
    h.run_ok();
    wait_for(&mut h, "the registration", |a| {
        !a.analysis.pose.running && a.analysis.pose.result.is_some()
    });
    assert!(h.state().errors.is_empty(), "{:?}", h.state().errors);
    let run = h.state().analysis.derender.result.as_ref().unwrap();
    let posed = h.state().analysis.pose.result.as_ref().unwrap();
    let context = run.input.pose.as_ref().unwrap();

    // The same imprint and signature through the command line.
    let imprint = dir.path().join("imprint.npy");
    let signature = dir.path().join("signature.npy");
    npy::write_image(&imprint, &run.input.imprint).unwrap();
    npy::write_image(&signature, &context.signature).unwrap();
    let common = [
        "--model".to_string(),
        "default".into(),
        "--imprint".into(),
        imprint.display().to_string(),
        "--samples".into(),
        config.samples.to_string(),
        "--steps".into(),
        config.sampler.steps.to_string(),
        "--seed".into(),
        config.seed.to_string(),
    ];
    let sample_dir = dir.path().join("sample");
    let mut args: Vec<String> = vec!["sample".into()];
    args.extend(common.iter().cloned());
    // With the signature, guided towards the imprint as the workbench's run was.
    assert!(run.guided);
    args.extend([
        "--signature".into(),
        signature.display().to_string(),
        "--out".into(),
        sample_dir.display().to_string(),
    ]);
    tnd(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let cli_samples = npy::read(&sample_dir.join("samples.npy")).unwrap();
    let wb: Vec<u32> = run
        .samples
        .iter()
        .flat_map(|s| s.data.iter().map(|v| v.to_bits()))
        .collect();
    let cli: Vec<u32> = cli_samples.data.iter().map(|v| v.to_bits()).collect();
    assert_eq!(cli_samples.shape, vec![3, 64, 64]);
    assert!(wb == cli, "the samples differ");

    let truth = scene.object_pose;
    let pose_dir = dir.path().join("pose");
    let mut args: Vec<String> = vec!["pose".into()];
    args.extend(common.iter().cloned());
    args.extend([
        "--object".into(),
        scene.object.display_name(),
        "--signature".into(),
        signature.display().to_string(),
        "--truth".into(),
        format!("{},{},{}", truth.x, truth.y, truth.theta),
        "--press".into(),
        scene.press.to_string(),
        "--out".into(),
        pose_dir.display().to_string(),
    ]);
    let summary = tnd(&args.iter().map(String::as_str).collect::<Vec<_>>());
    // The single-sample estimate: the signature check's pick (the scene has a signature), in both.
    assert!(posed.checked.is_some() && summary["signature_checked"] == true);
    let best = posed.single_estimate().unwrap();
    let cli_best: tactile_derender::sensor::Se2 =
        serde_json::from_value(summary["estimate"].clone()).unwrap();
    assert_eq!(
        (
            cli_best.x.to_bits(),
            cli_best.y.to_bits(),
            cli_best.theta.to_bits()
        ),
        (best.x.to_bits(), best.y.to_bits(), best.theta.to_bits()),
        "{cli_best:?} vs {best:?}"
    );
    // Its error against --truth (the cross has no translational symmetry: the plain distance).
    let err = summary["estimate_error"]["position_mm"].as_f64().unwrap();
    let expected = (best.x - truth.x).hypot(best.y - truth.y) * 1e3;
    assert!((err - expected).abs() < 1e-9, "{err} vs {expected}");
    // Every sample's, the baseline's and the multi-sample estimate's pose, cost and errors, in shortest
    // round-trip decimal (so equal text is equal bits), and the KDE curves.
    let csv = std::fs::read_to_string(pose_dir.join("samples.csv")).unwrap();
    assert_eq!(csv, posed.report.samples_csv());
    assert!(
        csv.lines().filter(|l| l.starts_with("sample,")).count() >= 1,
        "{csv}"
    );
    assert!(
        csv.contains("baseline,") && csv.contains("multi_sample,"),
        "{csv}"
    );
    let kde = std::fs::read_to_string(pose_dir.join("kde.csv")).unwrap();
    assert_eq!(kde, posed.report.kde_csv());
}
