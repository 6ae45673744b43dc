//! Tests of [`super`]: recordings by off-nominal sensors (the simulator's, an independent truth) calibrated back.
#![allow(clippy::unwrap_used)]

use super::*;
use crate::objects::ObjectSet;
use crate::recording::synth::{write_press_recording, DepthEncoding, PressSequence};
use crate::recording::FolderOptions;
use crate::sensor::Se2;
use crate::sim::{PreparedObject, Simulator};

/// Calibrate starting from the nominal sensor.
fn nominal(
    rec: &Recording,
    stream: &StreamInfo,
    config: &CalibrateConfig,
) -> Result<(SensorCalibration, CalibrationImages), RecordingError> {
    calibrate(rec, stream, &SimConfig::default(), config, &mut |_, _| true)
}

/// A press recording of `object` by the sensor `truth`.
fn recording(
    dir: &std::path::Path,
    truth: &SimConfig,
    object: &str,
    encoding: DepthEncoding,
    seed: u64,
) -> Recording {
    let mut seq = PressSequence::down_and_up(Se2::new(0.003, -0.002, 0.7), 0.007, 5, 6);
    seq.encoding = encoding;
    seq.seed = seed;
    let path = dir.join(format!("{object}.mcap"));
    let obj = PreparedObject::new(ObjectSet::builtin().mesh(object).unwrap()).unwrap();
    write_press_recording(&path, truth, &obj, &seq).unwrap();
    Recording::open(&path, &FolderOptions::default()).unwrap()
}

#[test]
fn an_off_nominal_sensor_is_recovered_from_its_recording_without_the_object() {
    // The simulator made the recording at the native resolution (its tessellated membrane, its noise, 16-bit
    // millimetres); the calibration starts from the nominal sensor and is not told the object.
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            0.0322,
            -0.0585,
            0.0018,
            28.0,
            "cylinder_r12",
            DepthEncoding::Mm16,
        ),
        (
            0.0274,
            -0.0620,
            0.0011,
            15.0,
            "cross_w12_s50",
            DepthEncoding::F32,
        ),
    ];
    for (k, (inflation, camera_z, noise, shadow, object, encoding)) in cases.into_iter().enumerate()
    {
        let mut truth = SimConfig::default();
        truth.elastomer.inflation = inflation;
        truth.mount.position[2] = camera_z;
        truth.signature.noise_std = noise;
        truth.signature.shadow_px = shadow;
        let rec = recording(dir.path(), &truth, object, encoding, 10 + k as u64);
        let stream = rec.depth_stream(None).unwrap().clone();
        let (cal, images) = nominal(&rec, &stream, &CalibrateConfig::default()).unwrap();
        // The ten frames lifted off the object, and no frame pressed deeper than 3 mm (a light touch hides in
        // the noise; the robust fit does not mind it).
        let rest: Vec<usize> = (0..5).chain(16..21).collect();
        assert!(
            rest.iter().all(|f| cal.no_contact_frames.contains(f)),
            "{cal:?}"
        );
        assert!(
            cal.no_contact_frames.iter().all(|f| !(7..=13).contains(f)),
            "{cal:?}"
        );
        assert!((cal.inflation_m - inflation).abs() < 3e-4, "{cal:?}");
        assert!(
            (cal.camera_position_m[2] - camera_z).abs() < 5e-4,
            "{cal:?}"
        );
        let s = cal.noise_std_m.unwrap();
        assert!((s - noise).abs() < 0.1 * noise, "noise {s} for {noise}");
        assert_eq!(cal.sensor.elastomer.inflation, cal.inflation_m);
        assert_eq!(cal.sensor.signature.noise_std, s);
        assert!(cal.warnings.is_empty(), "{:?}", cal.warnings);
        assert!(cal.model_error_rms_m < 1e-4, "{cal:?}");
        assert_eq!((images.residual.width, images.residual.height), (224, 171));
        assert_eq!(cal.depth_step_m.is_some(), encoding == DepthEncoding::Mm16);
    }
}

#[test]
fn a_dented_membrane_is_named_and_a_recording_without_contact_free_frames_is_refused_or_warned() {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(
        dir.path(),
        &SimConfig::default(),
        "cylinder_r12",
        DepthEncoding::F32,
        1,
    );
    let stream = rec.depth_stream(None).unwrap().clone();
    // One given frame: no noise measurement, and a warning that says so.
    let config = CalibrateConfig {
        reference: ReferenceChoice::Frame(0),
        ..CalibrateConfig::default()
    };
    let (cal, _) = nominal(&rec, &stream, &config).unwrap();
    assert!(cal.noise_std_m.is_none());
    assert!(
        cal.warnings
            .iter()
            .any(|w| w.contains("noise cannot be measured")),
        "{:?}",
        cal.warnings
    );
    assert!((cal.inflation_m - 0.03).abs() < 1e-3, "{cal:?}");
    let config = CalibrateConfig {
        reference: ReferenceChoice::Frame(99),
        ..CalibrateConfig::default()
    };
    let e = nominal(&rec, &stream, &config).unwrap_err();
    assert!(e.to_string().contains("reference frame 99"), "{e}");
    // A membrane mesh is checked, not fitted; a cancel is a cancel.
    let mut c = SimConfig::default();
    c.elastomer.mesh_file = Some(dir.path().join("bubble.obj"));
    let dome = SimConfig::default().elastomer.build().unwrap();
    crate::mesh::obj::write(&dir.path().join("bubble.obj"), &dome).unwrap();
    let (cal, _) = calibrate(
        &rec,
        &stream,
        &c,
        &CalibrateConfig::default(),
        &mut |_, _| true,
    )
    .unwrap();
    assert!(!cal.membrane_fitted);
    assert!(
        cal.warnings.iter().any(|w| w.contains("bubble.obj")),
        "{:?}",
        cal.warnings
    );
    assert!(cal.model_error_rms_m < 1e-4, "{cal:?}");
    assert!(matches!(
        calibrate(
            &rec,
            &stream,
            &SimConfig::default(),
            &CalibrateConfig::default(),
            &mut |_, _| false
        ),
        Err(RecordingError::Cancelled)
    ));
    // A membrane that is no half-ellipsoid (a 3 mm bulge beside the apex, as a dent pushed out): the fit is the
    // nearest dome, and the warning names the residual.
    let flat: Vec<glam::Vec3> = dome
        .vertices()
        .iter()
        .map(|v| {
            let d2 = (v.x - 0.01).powi(2) + v.y.powi(2);
            let bulge = if v.z > 0.0 {
                0.003 * (-d2 / (2.0 * 0.008f32.powi(2))).exp()
            } else {
                0.0
            };
            glam::Vec3::new(v.x, v.y, v.z + bulge)
        })
        .collect();
    let sag = crate::mesh::Mesh::from_raw(flat, dome.triangles().to_vec(), "sag").unwrap();
    crate::mesh::obj::write(&dir.path().join("sag.obj"), &sag).unwrap();
    let mut truth = SimConfig::default();
    truth.elastomer.mesh_file = Some(dir.path().join("sag.obj"));
    let rec = recording(dir.path(), &truth, "cylinder_r12", DepthEncoding::F32, 2);
    let stream = rec.depth_stream(None).unwrap().clone();
    let (cal, images) = nominal(&rec, &stream, &CalibrateConfig::default()).unwrap();
    assert!(
        cal.warnings.iter().any(|w| w.contains("does not explain")),
        "{:?}",
        cal.warnings
    );
    // The measured membrane explains it: rendered by the simulator it is the bulged membrane, to a fraction of the
    // parametric fit's error.
    let mesh = crate::recording::measured_membrane::measured_membrane(&cal, &images).unwrap();
    assert!(mesh.report().closed && mesh.report().volume_m3 > 0.0);
    crate::mesh::obj::write(&dir.path().join("measured.obj"), &mesh).unwrap();
    let mut measured = cal.sensor.clone();
    measured.elastomer.mesh_file = Some(dir.path().join("measured.obj"));
    let rms = |a: &Image, b: &Image| {
        let d: Vec<f64> = a
            .data
            .iter()
            .zip(&b.data)
            .filter(|(x, y)| **x > 0.0 && **y > 0.0)
            .map(|(x, y)| f64::from(x - y))
            .collect();
        (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt()
    };
    let e_truth = Simulator::native(truth).unwrap().nominal_depth().clone();
    let e_measured = Simulator::native(measured).unwrap().nominal_depth().clone();
    let e_dome = Simulator::native(cal.sensor.clone())
        .unwrap()
        .nominal_depth()
        .clone();
    let (with, without) = (rms(&e_measured, &e_truth), rms(&e_dome, &e_truth));

    assert!(
        with < 1.5e-4 && with < 0.5 * without,
        "measured {with}, dome {without}"
    );
}

#[test]
fn spread_about_the_mean_is_unbiased_and_ignores_a_slipped_contact() {
    // Two frames a and b: about their mean each deviates by ±(a − b)/2, so the unbiased spread is |a − b|/√2.
    let a = Image::from_vec(4, 1, vec![1.0, 2.0, 3.0, 4.0]).unwrap();
    let b = Image::from_vec(4, 1, vec![1.2, 1.8, 3.2, 3.8]).unwrap();
    let m = mean_image(&[&a, &b]);
    let s = spread_about(&[&a, &b], &m).unwrap();
    assert!((s - 0.2 / 2f64.sqrt()).abs() < 1e-6, "{s}");
    assert!(spread_about(&[&a], &a).is_none());
    assert_eq!(
        depth_step(&Image::from_vec(2, 1, vec![0.09, 0.0]).unwrap()),
        Some(1e-3)
    );
    assert_eq!(
        depth_step(&Image::from_vec(1, 1, vec![0.0905]).unwrap()),
        None
    );
}

/// A short recording (rest, press, rest: three frames) never takes its pressed frame for one without contact: the
/// calibration uses the two others, says so, and its noise at the model resolution agrees with a long recording's
/// of the same sensor (it came out 4.6x too large when the pressed frame was in the set it was measured on).
#[test]
fn a_short_recording_never_calibrates_on_its_pressed_frame() {
    let dir = tempfile::tempdir().unwrap();
    let truth = SimConfig::default();
    let obj = PreparedObject::new(ObjectSet::builtin().mesh("cross_w12_s50").unwrap()).unwrap();
    let calibrated = |name: &str, rest: usize, ramp: usize| {
        let mut seq = PressSequence::down_and_up(Se2::new(0.0, 0.0, 0.0), 0.008, rest, ramp);
        seq.seed = 4;
        let path = dir.path().join(name);
        write_press_recording(&path, &truth, &obj, &seq).unwrap();
        let rec = Recording::open(&path, &FolderOptions::default()).unwrap();
        let stream = rec.depth_stream(None).unwrap().clone();
        nominal(&rec, &stream, &CalibrateConfig::default())
            .unwrap()
            .0
    };
    let short = calibrated("short.mcap", 1, 0);
    assert_eq!(short.frames, 3);
    assert_eq!(short.no_contact_frames, vec![0, 2], "{short:?}");
    assert!(
        short
            .warnings
            .iter()
            .any(|w| w.contains("only 2 frame(s) without contact")),
        "{:?}",
        short.warnings
    );
    let long = calibrated("long.mcap", 6, 2);
    let (s, l) = (
        short.noise_std_model_m.unwrap(),
        long.noise_std_model_m.unwrap(),
    );
    assert!(
        (s / l - 1.0).abs() < 0.3,
        "model-resolution noise {s} against {l}"
    );
    // The recording's reader agrees: frame 1 is no reference.
    let rec = Recording::open(&dir.path().join("short.mcap"), &FolderOptions::default()).unwrap();
    let stream = rec.depth_stream(None).unwrap().clone();
    let processed = crate::recording::process::process(
        &rec,
        &stream,
        &truth.camera,
        &ProcessConfig::default(),
        &mut |_, _| true,
    )
    .unwrap();
    assert_eq!(processed.reference_frames, vec![0, 2]);
}

/// Frames of constant depth show no membrane: the calibration is refused, naming the impossible inflation, instead
/// of writing a sensor inflated 2.3e-9 m with a warning that it is "30.0 mm from the given 30.0 mm".
#[test]
fn constant_frames_give_no_sensor() {
    let (w, h) = (224, 171);
    let frames = vec![Image::filled(w, h, 0.09); 3];
    let e = calibrate_references(frames, &SimConfig::default(), &CalibrateConfig::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("cannot exist") && e.contains("inflation"), "{e}");
}
