//! Session files (`sessions/*.json`): the [`State`] as pretty JSON, written atomically; reading validates the file and
//! names it in every error, so a bad file changes nothing.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};
use tactile_derender::io::write_atomic;

use crate::state::{State, SESSION_VERSION};

/// Read and validate a session file.
pub fn read(path: &Path) -> Result<State> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read session file", path.display()))?;
    let state: State = serde_json::from_str(&text)
        .map_err(|e| anyhow!("{}: not a valid session file: {e}", path.display()))?;
    if state.version > SESSION_VERSION {
        return Err(anyhow!(
            "{}: session version {} is newer than this workbench ({SESSION_VERSION}); update the workbench",
            path.display(),
            state.version
        ));
    }
    validate(&state).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let mut state = state;
    // Saved before the bundled posterior calibration had one for resampled frames: the bundled one it held.
    state.pose.posterior = state.pose.posterior.upgraded();
    if let Some(dir) = path.parent() {
        resolve_beside(&mut state, dir);
    }
    Ok(state)
}

/// The files a session names are kept as they were typed, relative to where the workbench ran. Opened from another
/// directory, a relative path that does not exist from here but does beside the session file is taken from there
/// (a session saved next to its data opens from anywhere).
fn resolve_beside(state: &mut State, session_dir: &Path) {
    let fix = |p: &mut PathBuf| {
        if p.is_relative() && !p.exists() {
            let beside = session_dir.join(&*p);
            if beside.exists() {
                *p = beside;
            }
        }
    };
    match &mut state.scene.object {
        crate::state::ObjectSource::File { path, .. } => fix(path),
        crate::state::ObjectSource::Library { set, .. } if set != "builtin" => {
            let mut p = PathBuf::from(&*set);
            fix(&mut p);
            *set = p.display().to_string();
        }
        crate::state::ObjectSource::Library { .. } => {}
    }
    for p in [
        state.sim.elastomer.mesh_file.as_mut(),
        state.calibration.measured.as_mut(),
        state.model.path.as_mut(),
        state.dataset.path.as_mut(),
        state.recording.path.as_mut(),
    ]
    .into_iter()
    .flatten()
    {
        fix(p);
    }
}

/// Write `state` to `path` atomically (temp file + rename), holding the file's output lock while writing, so that a
/// `tnd` run or another workbench writing the same file at that moment is refused rather than interleaved.
pub fn write(path: &Path, state: &State) -> Result<()> {
    let text = serde_json::to_string_pretty(state).context("cannot encode the session")?;
    let _lock = tactile_derender::io::lock::OutputLock::acquire(path)?;
    write_atomic(path, format!("{text}\n").as_bytes())
        .map_err(|e| anyhow!("cannot save the session: {e}"))
}

/// Check the numbers a session can carry that the simulator would reject or that make no sense on screen.
pub fn validate(state: &State) -> Result<(), String> {
    let s = &state.scene;
    let finite = [
        s.object_pose.x,
        s.object_pose.y,
        s.object_pose.theta,
        s.sensor_x,
        s.sensor_y,
        s.sensor_yaw,
        s.press,
    ];
    if finite.iter().any(|v| !v.is_finite()) {
        return Err("scene pose and press must be finite numbers".into());
    }
    if s.press < 0.0 {
        return Err(format!("press depth must be >= 0 m, got {}", s.press));
    }
    state.sim.camera.validate().map_err(|e| e.to_string())?;
    state.sim.signature.validate().map_err(|e| e.to_string())?;
    state.sim.elastomer.validate().map_err(|e| e.to_string())?;
    let c = &state.calibration;
    tactile_derender::sim::calibration::inflation_values(c.lo, c.hi, c.steps)
        .map_err(|e| e.to_string())?;
    state
        .derender
        .config
        .validate(None)
        .map_err(|e| e.to_string())?;
    state.pose.validate().map_err(|e| e.to_string())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths_missing_here_are_taken_from_beside_the_session() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("part.obj"),
            "v 0 0 0\nv 0.01 0 0\nv 0 0.01 0\nf 1 2 3\n",
        )
        .unwrap();
        std::fs::create_dir(dir.path().join("ds")).unwrap();
        let mut state = State::default();
        state.scene.object = crate::state::ObjectSource::File {
            path: "part.obj".into(),
            units: tactile_derender::mesh::Units::M,
        };
        state.dataset.path = Some("ds".into());
        // Not beside the session either: left as typed (the load then names it).
        state.model.path = Some("runs/none.safetensors".into());
        let p = dir.path().join("s.json");
        write(&p, &state).unwrap();
        let back = read(&p).unwrap();
        assert_eq!(
            back.scene.object,
            crate::state::ObjectSource::File {
                path: dir.path().join("part.obj"),
                units: tactile_derender::mesh::Units::M,
            }
        );
        assert_eq!(back.dataset.path, Some(dir.path().join("ds")));
        assert_eq!(
            back.model.path,
            Some(PathBuf::from("runs/none.safetensors"))
        );
    }

    #[test]
    fn round_trip_and_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.json");
        let mut state = State {
            seed: 77,
            ..Default::default()
        };
        state.scene.press = 0.0042;
        write(&p, &state).unwrap();
        assert_eq!(read(&p).unwrap(), state);

        std::fs::write(&p, "{ \"scene\": ").unwrap();
        let err = read(&p).unwrap_err().to_string();
        assert!(
            err.contains("s.json") && err.contains("not a valid session"),
            "{err}"
        );

        std::fs::write(&p, r#"{"scene": {"press": -0.01}}"#).unwrap();
        let err = read(&p).unwrap_err().to_string();
        assert!(err.contains("press"), "{err}");

        // Missing fields take their defaults (serde(default)).
        std::fs::write(&p, r#"{"seed": 5}"#).unwrap();
        let s = read(&p).unwrap();
        assert_eq!((s.seed, s.scene), (5, State::default().scene));
    }

    #[test]
    fn sessions_from_before_the_shared_sampler_config_still_load() {
        use tactile_derender::model::{SamplerConfig, SamplerName, TimestepSpacing};
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("old.json");
        // The De-render settings as sessions stored them before `SamplerConfig` (`ddim_steps`).
        std::fs::write(
            &p,
            r#"{"derender": {"sampler": "ddim", "ddim_steps": 40, "eta": 0.5, "spacing": "leading", "samples": 3}}"#,
        )
        .unwrap();
        let s = read(&p).unwrap();
        assert_eq!(
            s.derender.config.sampler,
            SamplerConfig {
                kind: SamplerName::Ddim,
                steps: 40,
                eta: 0.5,
                spacing: TimestepSpacing::Leading
            }
        );
        assert_eq!(s.derender.config.samples, 3);
        // Written back with the shared names, and read the same.
        write(&p, &s).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(
            text.contains("\"steps\": 40") && !text.contains("ddim_steps"),
            "{text}"
        );
        assert_eq!(read(&p).unwrap(), s);
        // A bad value is refused with the setting named.
        std::fs::write(&p, r#"{"derender": {"sampler": "ddim", "steps": 0}}"#).unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("DDIM steps"));
    }

    /// Regenerates `sessions/example.json`: `cargo test -p tnd-workbench -- --ignored write_example_session`.
    #[test]
    #[ignore]
    fn write_example_session() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sessions/example.json");
        write(&p, &State::default()).unwrap();
    }

    #[test]
    fn a_session_saved_before_the_resampled_frames_calibration_gets_the_bundled_one() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("old.json");
        let mut old = serde_json::to_value(State::default()).unwrap();
        let posterior = &mut old["pose"]["posterior"];
        assert!(posterior["resampled_frames"].is_object());
        posterior
            .as_object_mut()
            .unwrap()
            .remove("resampled_frames");
        std::fs::write(&p, old.to_string()).unwrap();
        assert_eq!(read(&p).unwrap(), State::default());
        // A calibration of the user's own stays one calibration for every frame.
        old["pose"]["posterior"]["temperature"] = serde_json::json!(2.5);
        std::fs::write(&p, old.to_string()).unwrap();
        let mine = read(&p).unwrap().pose.posterior;
        assert!(mine.resampled_frames.is_none() && mine.temperature == 2.5);
    }

    #[test]
    fn committed_example_session_is_the_default_scene() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sessions/example.json");
        assert_eq!(read(&p).unwrap(), State::default());
    }
}
