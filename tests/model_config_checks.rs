//! Configs are checked before anything is allocated, and a diffusers folder's files are read as a whole: an absurd
//! U-Net size in a `config.json` or a `--config` is refused at once naming the field and the file; a misplaced key is
//! refused; `scheduler_config.json` is honoured where `config.json` is silent and refused where it contradicts it;
//! `tnd model export --force` replaces the folder whole.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::cli_common;

use std::path::Path;

use cli_common::{stderr, tnd_in};
use std::time::{Duration, Instant};

use tactile_derender::model::{DiffusionModel, PredictionType};

fn edit_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

/// The small model exported as a diffusers folder `name` in `dir`.
fn export(dir: &Path, name: &str) {
    let o = tnd_in(
        dir,
        &["model", "export", "--model", "small", "--diffusers", name],
    );
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn absurd_sizes_are_refused_at_once_naming_the_field_and_file() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, serde_json::Value, &str); 5] = [
        (
            "block_out_channels",
            serde_json::json!([1_000_000_000u64, 16, 16, 16]),
            "block_out_channels 1000000000 is out of range",
        ),
        (
            "block_out_channels",
            serde_json::json!([0, 16, 16, 16]),
            "block_out_channels 0 is out of range",
        ),
        (
            "layers_per_block",
            serde_json::json!(100_000),
            "layers_per_block 100000 is out of range",
        ),
        (
            "num_train_timesteps",
            serde_json::json!(1_000_000_000_000u64),
            "num_train_timesteps 1000000000000 is out of range",
        ),
        (
            "sample_size",
            serde_json::json!(1u64 << 40),
            "sample_size 1099511627776 is out of range",
        ),
    ];
    for (i, (field, value, expected)) in cases.iter().enumerate() {
        let name = format!("m{i}");
        export(dir.path(), &name);
        let config = dir.path().join(&name).join("config.json");
        edit_json(&config, |v| v[*field] = value.clone());
        for args in [
            vec![
                "sample",
                "--model",
                name.as_str(),
                "--imprint",
                "none.npy",
                "--out",
                "s",
            ],
            vec![
                "model",
                "import",
                "--diffusers",
                name.as_str(),
                "--out",
                "m.safetensors",
            ],
        ] {
            let t0 = Instant::now();
            let o = tnd_in(dir.path(), &args);
            let err = stderr(&o);
            assert!(!o.status.success(), "{field}: {err}");
            assert_eq!(o.status.code(), Some(1), "{field}: not an abort: {err}");
            assert!(
                err.contains(expected) && err.contains("config.json"),
                "{field}: {err}"
            );
            assert_eq!(err.trim().lines().count(), 1, "{err}");
            assert!(
                t0.elapsed() < Duration::from_secs(1),
                "{field}: {:?}",
                t0.elapsed()
            );
        }
        // The same config given to `tnd train --config` is refused before any data is read.
        let o = tnd_in(
            dir.path(),
            &[
                "train",
                "--data",
                "none",
                "--out",
                "run",
                "--config",
                config.to_str().unwrap(),
            ],
        );
        let err = stderr(&o);
        assert!(
            err.contains(expected) && err.contains("config.json"),
            "{err}"
        );
        assert!(!dir.path().join("run/model.safetensors").exists());
    }
}

#[test]
fn a_misplaced_key_is_refused_and_the_bundled_configs_load() {
    let dir = tempfile::tempdir().unwrap();
    export(dir.path(), "m");
    let config = dir.path().join("m/config.json");
    edit_json(&config, |v| {
        v["prediction_type"] = "v_prediction".into();
    });
    let e = DiffusionModel::load(&dir.path().join("m"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("config.json")
            && e.contains(
                "\"prediction_type\" at the top level; it belongs under \"tactile_derender\""
            ),
        "{e}"
    );
    edit_json(&config, |v| {
        v.as_object_mut().unwrap().remove("prediction_type");
        v["layers_per_blocks"] = 2.into();
    });
    let e = DiffusionModel::load(&dir.path().join("m"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("unknown key \"layers_per_blocks\""), "{e}");
    // The repository's own configs are valid as they stand.
    for file in [
        "assets/models/wide1_config.json",
        "assets/models/gpu/wide_config.json",
        "tests/fixtures/unet_small/unet_ref_config.json",
        "tests/fixtures/unet_variant/unet_ref_config.json",
    ] {
        let text = std::fs::read_to_string(file).unwrap();
        tactile_derender::model::UNet2DConfig::from_json(&text, file)
            .unwrap_or_else(|e| panic!("{file}: {e}"));
    }
}

#[test]
fn the_scheduler_config_is_honoured_or_a_contradiction_refused() {
    let dir = tempfile::tempdir().unwrap();
    export(dir.path(), "m");
    let folder = dir.path().join("m");
    let bundled = DiffusionModel::load(Path::new("small")).unwrap();
    let ours = bundled.config().tactile_derender.prediction_type;
    let other = match ours {
        PredictionType::Epsilon => "v_prediction",
        PredictionType::VPrediction => "epsilon",
    };
    // A contradiction: refused, naming both files.
    edit_json(&folder.join("scheduler_config.json"), |v| {
        v["prediction_type"] = other.into();
    });
    let e = DiffusionModel::load(&folder).err().unwrap().to_string();
    assert!(
        e.contains("scheduler_config.json")
            && e.contains("contradicts")
            && e.contains("config.json"),
        "{e}"
    );
    // A plain diffusers folder (no tactile_derender section): the scheduler's prediction type and steps are taken.
    edit_json(&folder.join("config.json"), |v| {
        let t = v
            .as_object_mut()
            .unwrap()
            .remove("tactile_derender")
            .unwrap();
        // Keep the normalisation (diffusers knows none) but not what the scheduler owns.
        let mut t = t.as_object().unwrap().clone();
        t.remove("prediction_type");
        t.remove("num_train_timesteps");
        v["tactile_derender"] = serde_json::Value::Object(t);
    });
    edit_json(&folder.join("scheduler_config.json"), |v| {
        v["num_train_timesteps"] = 500.into();
    });
    let m = DiffusionModel::load(&folder).unwrap();
    let t = &m.config().tactile_derender;
    assert_ne!(t.prediction_type, ours);
    assert_eq!(t.num_train_timesteps, 500);
    // A schedule we do not implement is refused, not replaced by ours.
    edit_json(&folder.join("scheduler_config.json"), |v| {
        v["beta_schedule"] = "linear".into();
    });
    let e = DiffusionModel::load(&folder).err().unwrap().to_string();
    assert!(
        e.contains("beta_schedule \"linear\" is not supported"),
        "{e}"
    );
    // Only a PyTorch pickle: said so, with the conversion.
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    std::fs::write(bin.join("config.json"), "{}").unwrap();
    std::fs::write(bin.join("diffusion_pytorch_model.bin"), "pickle").unwrap();
    let e = DiffusionModel::load(&bin).err().unwrap().to_string();
    assert!(
        e.contains("diffusion_pytorch_model.bin") && e.contains("safe_serialization=True"),
        "{e}"
    );
}

/// `--force` replaces the folder whole: the new files together, a file of the user's kept, nothing left beside it.
#[test]
fn export_force_replaces_the_folder_whole() {
    let dir = tempfile::tempdir().unwrap();
    let o = tnd_in(
        dir.path(),
        &["model", "export", "--model", "small", "--diffusers", "out"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::write(dir.path().join("out/notes.txt"), "mine").unwrap();
    let o = tnd_in(
        dir.path(),
        &["model", "export", "--diffusers", "out", "--force"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let m = DiffusionModel::load(&dir.path().join("out")).unwrap();
    let default = DiffusionModel::load(Path::new("default")).unwrap();
    assert_eq!(m.config(), default.config());
    assert_eq!(
        std::fs::read_to_string(dir.path().join("out/notes.txt")).unwrap(),
        "mine"
    );
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["out".to_string()]);
}
