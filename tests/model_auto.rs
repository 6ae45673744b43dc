//! `--model auto`: the bundled model matched to how the input's frames reached the model resolution (the recording
//! model for frames resampled from a camera's own size, the default otherwise), end to end through `tnd sample`.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::process::Command;

use tactile_derender::image::Image;
use tactile_derender::io::npy;
use tactile_derender::model::DiffusionModel;

/// `--model auto` (the default of sample, pose, eval and track): frames brought to the model's size by area
/// resampling from the camera's own (a native 224 x 171 frame) are de-rendered by the bundled recording model, frames
/// at the model's size by the default — the same samples as naming each model.
#[test]
fn auto_picks_the_recording_model_for_resampled_frames_and_the_default_otherwise() {
    use tactile_derender::model::checkpoint::{matched_model, AUTO_MODEL_NAME};
    let dent = |w: usize, h: usize, r: f32| {
        Image::from_vec(
            w,
            h,
            (0..w * h)
                .map(|i| {
                    let (x, y) = (
                        (i % w) as f32 - w as f32 / 2.0,
                        (i / w) as f32 - h as f32 / 2.0,
                    );
                    if x * x + y * y < r * r {
                        0.01
                    } else {
                        0.0
                    }
                })
                .collect(),
        )
        .unwrap()
    };
    let dir = tempfile::tempdir().unwrap();
    npy::write_image(&dir.path().join("model.npy"), &dent(64, 64, 10.0)).unwrap();
    npy::write_image(&dir.path().join("native.npy"), &dent(224, 171, 27.0)).unwrap();
    let sample = |input: &str, model: Option<&str>, out: &str| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_tnd"));
        c.current_dir(dir.path())
            .args([
                "sample",
                "--imprint",
                input,
                "--n",
                "1",
                "--sampler",
                "ddim",
            ])
            .args(["--steps", "3", "--seed", "4", "--out", out]);
        if let Some(m) = model {
            c.args(["--model", m]);
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (
            npy::read(&dir.path().join(out).join("samples.npy"))
                .unwrap()
                .data,
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (auto_model, quiet) = sample("model.npy", None, "a");
    assert_eq!(auto_model, sample("model.npy", Some("default"), "b").0);
    assert!(!quiet.contains("recording model"), "{quiet}");
    let (auto_native, said) = sample("native.npy", None, "c");
    assert_eq!(auto_native, sample("native.npy", Some("recording"), "d").0);
    assert_ne!(auto_native, sample("native.npy", Some("default"), "e").0);
    assert!(said.contains("the bundled recording model"), "{said}");
    // The rule itself, and the models: the recording model is the default's architecture with its own weights.
    let auto = Path::new(AUTO_MODEL_NAME);
    assert_eq!(matched_model(auto, true), Path::new("recording"));
    assert_eq!(matched_model(auto, false), Path::new("default"));
    assert_eq!(matched_model(Path::new("small"), true), Path::new("small"));
    let (recording, default) = (
        DiffusionModel::load(Path::new("recording")).unwrap(),
        DiffusionModel::load(Path::new("default")).unwrap(),
    );
    assert_eq!(recording.config(), default.config());
}
