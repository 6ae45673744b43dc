//! Sensor calibration from a recording, as a user with an off-nominal sensor meets it: `tnd recording simulate`
//! with a sensor that is not the nominal one (the independent truth), `tnd calibrate --from` told nothing but the
//! nominal sensor, the sensor file it writes taken by other commands (`--sensor`), and `tnd dataset import --from`
//! calibrating by default so that its presses are the recorded ones.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::process::{Command, Output};

use serde_json::Value;
use tactile_derender::objects::ObjectSet;
use tactile_derender::sensor::{Scene, Se2};
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};

fn tnd(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tnd"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

/// The last stdout line of a successful run, as JSON.
fn json(dir: &Path, args: &[&str]) -> (Value, String) {
    let out = tnd(dir, args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "tnd {args:?}: {stderr}");
    let stdout = String::from_utf8(out.stdout).unwrap();
    (
        serde_json::from_str(stdout.lines().last().unwrap()).unwrap(),
        stderr,
    )
}

#[test]
fn an_off_nominal_sensor_is_calibrated_from_its_recording_and_used_by_the_import() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (inflation, camera, noise) = (0.0322, 0.0585, 0.0018);
    let (rec, _) = json(
        d,
        &[
            "recording",
            "simulate",
            "drift.mcap",
            "--object",
            "cylinder_r12",
            "--pose",
            "0.003,-0.002,0.5",
            "--inflation",
            "0.0322",
            "--camera-offset",
            "0.0585",
            "--noise-std",
            "0.0018",
            "--shadow-px",
            "28",
            "--seed",
            "7",
        ],
    );
    // Calibrated without the object, from the nominal sensor.
    let (cal, _) = json(
        d,
        &[
            "calibrate",
            "--from",
            "drift.mcap",
            "--json",
            "--out",
            "sensor.json",
            "--figure",
            "fit.png",
        ],
    );
    let got = cal["inflation_m"].as_f64().unwrap();
    assert!((got - inflation).abs() < 3e-4, "{cal}");
    let z = cal["camera_position_m"][2].as_f64().unwrap();
    assert!((z + camera).abs() < 5e-4, "{cal}");
    let s = cal["noise_std_m"].as_f64().unwrap();
    assert!((s - noise).abs() < 0.1 * noise, "{cal}");
    assert!(cal["residual_rms_m"].as_f64().unwrap() > 0.0);
    assert_eq!(cal["warnings"], Value::Array(vec![]), "{cal}");
    assert!(std::fs::read(d.join("fit.png"))
        .unwrap()
        .starts_with(b"\x89PNG"));
    // Told the object, the contact frames (with the recorded pose topic) give the shadow width as well.
    let (with_object, _) = json(
        d,
        &[
            "calibrate",
            "--from",
            "drift.mcap",
            "--object",
            "cylinder_r12",
            "--json",
        ],
    );
    let shadow = with_object["sensor"]["signature"]["shadow_px"]
        .as_f64()
        .unwrap();
    assert!((shadow - 28.0).abs() <= 2.0, "{with_object}");
    // The sensor file is what every command takes; a misspelt key in one is named.
    let file: Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("sensor.json")).unwrap()).unwrap();
    assert_eq!(file["elastomer"]["inflation"].as_f64(), Some(got));
    let (sim, _) = json(
        d,
        &[
            "sim",
            "--sensor",
            "sensor.json",
            "--object",
            "cylinder_r12",
            "--out",
            "sim",
        ],
    );
    assert!(sim["contact_pixels"].as_u64().unwrap() > 0, "{sim}");
    std::fs::write(d.join("bad.json"), r#"{"elastomer": {"inflaton": 0.03}}"#).unwrap();
    let bad = tnd(
        d,
        &[
            "sim",
            "--sensor",
            "bad.json",
            "--object",
            "cylinder_r12",
            "--out",
            "sim2",
        ],
    );
    let e = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && e.contains("bad.json") && e.contains("elastomer.inflaton"),
        "{e}"
    );

    // The import calibrates by default and says so; its press estimates are then the recorded presses, while the
    // nominal membrane (2.2 mm lower) puts them off by about that much.
    let presses: Vec<f64> = rec["presses_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_f64().unwrap())
        .collect();
    let import = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "dataset",
            "import",
            "--from",
            "drift.mcap",
            "--object",
            "cylinder_r12",
            "--out",
            out,
            "--split",
            "unseen_objects",
        ];
        args.extend_from_slice(extra);
        json(d, &args)
    };
    let (calibrated, stderr) = import("ds", &[]);
    assert!(
        stderr.contains("sensor calibrated from") && stderr.contains("elastomer.inflation"),
        "{stderr}"
    );
    assert!((calibrated["calibration"]["inflation_m"].as_f64().unwrap() - inflation).abs() < 3e-4);
    // Each pair names its frame and time stamp (frames.csv): the frames with contact, 1/30 s apart.
    let table = std::fs::read_to_string(d.join("ds/frames.csv")).unwrap();
    let rows: Vec<Vec<u64>> = table
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    assert_eq!(
        rows.len() as u64,
        calibrated["pairs"].as_u64().unwrap(),
        "{table}"
    );
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r[0], k as u64);
        assert!(presses[r[1] as usize] > 0.0, "{table}");
        let t = r[2] - 1_700_000_000_000_000_000;
        assert!((t as f64 - r[1] as f64 * 1e9 / 30.0).abs() < 2.0, "{table}");
    }
    // The contact frames with their recorded pose give the tactile-shadow width (28 px).
    let shadow = calibrated["calibration"]["changes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["setting"] == "signature.shadow_px")
        .map(|c| c["calibrated"].as_f64().unwrap())
        .unwrap();
    assert!((shadow - 28.0).abs() <= 2.0, "{shadow}");
    let (nominal, _) = import("ds_nominal", &["--no-calibrate"]);
    assert_eq!(nominal["calibration"], Value::Null);
    let manifest = |ds: &str| -> Value {
        serde_json::from_str(&std::fs::read_to_string(d.join(ds).join("manifest.json")).unwrap())
            .unwrap()
    };
    assert!(
        (manifest("ds")["sim"]["elastomer"]["inflation"]
            .as_f64()
            .unwrap()
            - inflation)
            .abs()
            < 3e-4
    );
    assert_eq!(
        manifest("ds_nominal")["sim"]["elastomer"]["inflation"].as_f64(),
        Some(0.03)
    );
    // The nearest contact point of the deepest frame (min X0) against the simulator's with the true sensor at the
    // recorded pose and press: the calibrated membrane puts it where it is, the nominal one (0.7 mm nearer the camera) further off.
    let mut truth = SimConfig::default();
    truth.elastomer.inflation = inflation;
    truth.mount.position[2] = -camera;
    truth.signature.noise_std = 0.0;
    let sim = Simulator::new(truth).unwrap();
    let object = PreparedObject::new(ObjectSet::builtin().mesh("cylinder_r12").unwrap()).unwrap();
    let deepest = presses.iter().copied().fold(f64::MIN, f64::max);
    let scene = Scene {
        object: Se2::new(0.003, -0.002, 0.5),
        sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, deepest),
    };
    let (_, target) = sim.contact(&sim.render_depth(&object, &scene));
    let nearest = target.range_where(|v| v > 0.0).unwrap().0;
    let nearest_error = |ds: &str| -> f64 {
        let (stats, _) = json(d, &["dataset", "stats", ds, "--json"]);
        (stats["target_range_m"][0].as_f64().unwrap() - f64::from(nearest)).abs()
    };
    let (with, without) = (nearest_error("ds"), nearest_error("ds_nominal"));
    assert!(
        with < 2e-4 && without > 2.0 * with,
        "calibrated {with}, nominal {without}"
    );
}
