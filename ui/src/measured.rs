//! Measured imprints for the inflation calibration: a `.npy` file (Y in metres, at the sensor resolution) or one pair
//! of a dataset directory written by `tnd dataset gen` / `tnd dataset import` (paper V.A), whose metadata can also
//! place the scene (object, its pose and the sensor pose) as it was measured.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};
use tactile_derender::dataset::{Dataset, SplitName};
use tactile_derender::image::Image;
use tactile_derender::io::npy;
use tactile_derender::sensor::{Se2, SensorPose};

use crate::state::{ObjectSource, SceneState};

/// Where a dataset pair's object and sensor were.
#[derive(Clone, Debug, PartialEq)]
pub struct PairScene {
    pub object: ObjectSource,
    pub object_pose: Se2,
    /// Sensor pose in the world; `position[2]` is NaN for imported pairs without a known press.
    pub sensor: SensorPose,
}

/// A loaded measured imprint.
#[derive(Clone, Debug)]
pub struct Measured {
    /// The `.npy` file or the dataset directory.
    pub path: PathBuf,
    /// Y, metres.
    pub imprint: Image,
    /// One line for the UI.
    pub description: String,
    /// The pair's scene, for dataset pairs.
    pub scene: Option<PairScene>,
}

/// Load `path`: a dataset directory (pair `index` of `split`) or a `.npy` image.
pub fn load(path: &Path, split: SplitName, index: usize) -> Result<Measured> {
    if path.is_dir() {
        let ds = Dataset::open(path)?;
        let pair = ds
            .pair(split, index)
            .with_context(|| format!("{}: pair {index} of {split}", path.display()))?;
        let set = ds.object_set()?;
        let m = &pair.meta;
        let press = if m.press.is_finite() {
            format!("press {:.1} mm", m.press * 1e3)
        } else {
            "press unknown".into()
        };
        Ok(Measured {
            path: path.to_path_buf(),
            description: format!(
                "{split} pair {index} of {} ({}x{}): {}, {press}, {} contact px",
                ds.len(split),
                pair.imprint.width,
                pair.imprint.height,
                m.object,
                m.contact_pixels
            ),
            scene: Some(PairScene {
                object: ObjectSource::Library {
                    set: set.spec(),
                    name: m.object.clone(),
                },
                object_pose: m.object_pose,
                sensor: m.sensor,
            }),
            imprint: pair.imprint,
        })
    } else {
        let imprint = npy::read_metres_image(path)?;
        Ok(Measured {
            path: path.to_path_buf(),
            description: format!("{} ({}x{})", path.display(), imprint.width, imprint.height),
            scene: None,
            imprint,
        })
    }
}

/// The workbench scene that puts the sensor where the pair's sensor was: its base at the same height, so that the
/// press depth (measured from the apex of a membrane inflated `apex_height` metres) is `top_z - (base_z -
/// apex_height)`. `top_z` is the object's height in its resting pose, metres.
pub fn scene_for(
    pair: &PairScene,
    current: &SceneState,
    apex_height: f64,
    top_z: f64,
) -> Result<SceneState> {
    let [x, y, z] = pair.sensor.position;
    if !(x.is_finite() && y.is_finite() && pair.sensor.yaw.is_finite()) {
        return Err(anyhow!("the pair's sensor pose is not finite"));
    }
    if pair.sensor.tilt != [0.0, 0.0] {
        return Err(anyhow!(
            "the pair's sensor is tilted ({:?} rad); the workbench places untilted sensors",
            pair.sensor.tilt
        ));
    }
    let press = if z.is_finite() {
        top_z - (z - apex_height)
    } else {
        current.press
    };
    Ok(SceneState {
        object: pair.object.clone(),
        object_pose: pair.object_pose,
        sensor_x: x,
        sensor_y: y,
        sensor_yaw: pair.sensor.yaw,
        press: press.max(0.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_keeps_the_sensor_base_height() {
        // Pair measured with a 26 mm dome pressed 2 mm into a 20 mm tall object: base at 20 - 2 + 26 = 44 mm.
        let pair = PairScene {
            object: SceneState::default().object,
            object_pose: Se2::new(0.001, 0.002, 0.3),
            sensor: SensorPose {
                position: [0.0, 0.0, 0.044],
                yaw: 0.1,
                tilt: [0.0, 0.0],
            },
        };
        // With a 30 mm dome the same base presses 6 mm.
        let s = scene_for(&pair, &SceneState::default(), 0.030, 0.020).unwrap();
        assert!((s.press - 0.006).abs() < 1e-12, "{}", s.press);
        assert_eq!((s.object_pose, s.sensor_yaw), (pair.object_pose, 0.1));
        let tilted = PairScene {
            sensor: SensorPose {
                tilt: [0.1, 0.0],
                ..pair.sensor
            },
            ..pair
        };
        assert!(scene_for(&tilted, &SceneState::default(), 0.03, 0.02).is_err());
    }
}
