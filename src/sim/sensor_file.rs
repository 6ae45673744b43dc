//! **Sensor files**: a whole sensor ([`SimConfig`]: camera, camera mount, membrane, signature) as one JSON file, as
//! `tnd calibrate` writes it and every command reads it (`--sensor FILE`). Unknown keys are refused, naming the key,
//! so a misspelt setting cannot silently fall back to its default; a membrane mesh path is read relative to the
//! file, so the file works from any directory.

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::SimConfig;

/// Errors reading or writing a sensor file; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum SensorFileError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a sensor file: {message}")]
    Format { path: PathBuf, message: String },
}

/// Keys of `value` (recursively) that `template` does not have, as dotted paths.
fn unknown_keys(value: &Value, template: &Value, prefix: &str, out: &mut Vec<String>) {
    if let (Value::Object(v), Value::Object(t)) = (value, template) {
        for (k, child) in v {
            let path = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            match t.get(k) {
                Some(tc) => unknown_keys(child, tc, &path, out),
                None => out.push(path),
            }
        }
    }
}

/// Read a sensor file (module docs).
pub fn load(path: &Path) -> Result<SimConfig, SensorFileError> {
    let format = |message: String| SensorFileError::Format {
        path: path.to_path_buf(),
        message,
    };
    let text = crate::io::input::read_text_capped(path, crate::io::input::MAX_SETTINGS_BYTES)
        .map_err(|source| SensorFileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    let value: Value = serde_json::from_str(&text).map_err(|e| format(e.to_string()))?;
    if !value.is_object() {
        return Err(format("expected a JSON object".into()));
    }
    let mut template =
        serde_json::to_value(SimConfig::default()).map_err(|e| format(e.to_string()))?;
    // An ideal depth camera is left out of files, not out of what they may hold.
    if let Value::Object(m) = &mut template {
        let camera = serde_json::to_value(super::DepthCameraConfig::default())
            .map_err(|e| format(e.to_string()))?;
        m.insert("depth_camera".into(), camera);
    }
    let mut unknown = Vec::new();
    unknown_keys(&value, &template, "", &mut unknown);
    if !unknown.is_empty() {
        return Err(format(format!(
            "unknown setting(s) {}; a sensor file has camera, mount, elastomer, signature and depth_camera",
            unknown.join(", ")
        )));
    }
    let mut config: SimConfig = serde_json::from_value(value).map_err(|e| format(e.to_string()))?;
    config
        .camera
        .validate()
        .and_then(|()| super::bounds::check_settings(&config))
        .and_then(|()| config.signature.validate())
        .and_then(|()| config.depth_camera.validate())
        .map_err(|e| {
            format(if e.message.starts_with(e.setting) {
                e.message
            } else {
                format!("{}: {}", e.setting, e.message)
            })
        })?;
    if let Some(mesh) = &config.elastomer.mesh_file {
        if mesh.is_relative() {
            let dir = path.parent().unwrap_or(Path::new(""));
            config.elastomer.mesh_file = Some(dir.join(mesh));
        }
    }
    Ok(config)
}

/// Whether `path` looks like a sensor file [`save`] wrote: a JSON object with every section (camera, mount,
/// elastomer, signature), as `tnd calibrate --out` writes them; a hand-written partial file is not.
pub fn written_by_tnd(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    serde_json::from_str::<Value>(&text).is_ok_and(|v| {
        ["camera", "mount", "elastomer", "signature"]
            .iter()
            .all(|k| v.get(k).is_some_and(Value::is_object))
    })
}

/// Write `config` as a sensor file, atomically.
pub fn save(path: &Path, config: &SimConfig) -> Result<(), SensorFileError> {
    let text = serde_json::to_string_pretty(config).map_err(|e| SensorFileError::Format {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    crate::io::write_atomic(path, format!("{text}\n").as_bytes()).map_err(|source| {
        SensorFileError::Io {
            path: path.to_path_buf(),
            source,
        }
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_sensor_file_round_trips_and_refuses_unknown_keys() {
        let dir = std::env::temp_dir().join(format!("tnd-sensor-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut c = SimConfig::default();
        c.elastomer.inflation = 0.0321;
        c.mount.position = [0.001, 0.0, -0.058];
        let p = dir.join("sensor.json");
        save(&p, &c).unwrap();
        assert_eq!(load(&p).unwrap(), c);
        std::fs::write(&p, r#"{"elastomer": {"inflaton": 0.03}}"#).unwrap();
        let e = load(&p).unwrap_err().to_string();
        assert!(
            e.contains("sensor.json") && e.contains("elastomer.inflaton"),
            "{e}"
        );
        // A partial file keeps the defaults for what it leaves out; a mesh path is relative to the file.
        std::fs::write(&p, r#"{"elastomer": {"mesh_file": "bubble.obj"}}"#).unwrap();
        let l = load(&p).unwrap();
        assert_eq!(l.elastomer.mesh_file, Some(dir.join("bubble.obj")));
        assert_eq!(l.camera, SimConfig::default().camera);
        // A depth camera setting out of range is named with the file, once, as every other setting is.
        std::fs::write(&p, r#"{"depth_camera": {"dropout": -0.5}}"#).unwrap();
        let e = load(&p).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!(
                "{}: not a sensor file: depth_camera.dropout must be",
                p.display()
            )),
            "{e}"
        );
        assert_eq!(e.matches("depth_camera.dropout").count(), 1, "{e}");
        std::fs::write(&p, "[1, 2]").unwrap();
        assert!(load(&p).unwrap_err().to_string().contains("JSON object"));
        assert!(load(&dir.join("missing.json"))
            .unwrap_err()
            .to_string()
            .contains("missing.json"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
