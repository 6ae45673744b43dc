//! The workbench's saved **State**: every parameter, seed and file path the user sets (scene, elastomer, sensor,
//! calibration, view, model). Only this is written to `sessions/*.json` and to eframe persistence; caches, textures,
//! GPU buffers and running jobs live in the app outside it. Units are metres and radians, as in the core; the panels
//! show millimetres and degrees.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use tactile_derender::dataset::SplitName;
use tactile_derender::mesh::Units;
use tactile_derender::pose::PoseConfig;
use tactile_derender::sensor::Se2;
use tactile_derender::sim::SimConfig;

pub use crate::analysis_settings::{DatasetSettings, DerenderInput, DerenderSettings};
pub use tactile_derender::model::{SamplerConfig, SamplerName};

/// Version of the session format written by this build.
pub const SESSION_VERSION: u32 = 1;

/// Everything a session holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct State {
    /// Session format version ([`SESSION_VERSION`]).
    pub version: u32,
    /// The object and where object and sensor are.
    pub scene: SceneState,
    /// Camera, camera mount, elastomer and signature parameters (the core's simulator configuration).
    pub sim: SimConfig,
    /// Seed of the signature noise.
    pub seed: u64,
    /// Inflation calibration settings.
    pub calibration: CalibrationSettings,
    /// How things are displayed.
    pub view: ViewState,
    /// The diffusion model used by the de-rendering panels.
    pub model: ModelSettings,
    /// Dataset inspector: the open dataset, filters and selection.
    pub dataset: DatasetSettings,
    /// De-rendering runs: sampler, sample count, seed, input.
    pub derender: DerenderSettings,
    /// The open sensor recording, its topic, reference and timeline position.
    pub recording: crate::recording_view::RecordingSettings,
    /// Pose estimation (the Pose tab and the Recording tab's track): the core's [`PoseConfig`], the same settings
    /// and defaults as `tnd pose`, `tnd eval` and `tnd recording track` (`check_signature`, `imprint_proposals`,
    /// `anchor_to_signature`, `inits`, the signature check's and the posterior's settings, ...).
    pub pose: PoseConfig,
}

impl Default for State {
    fn default() -> Self {
        Self {
            version: SESSION_VERSION,
            scene: SceneState::default(),
            sim: SimConfig::default(),
            seed: 1,
            calibration: CalibrationSettings::default(),
            view: ViewState::default(),
            model: ModelSettings::default(),
            dataset: DatasetSettings::default(),
            derender: DerenderSettings::default(),
            recording: Default::default(),
            pose: PoseConfig::default(),
        }
    }
}

/// Where the object comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectSource {
    /// An object of an object set: `set` is `"builtin"` or a directory holding `objects.json`.
    Library { set: String, name: String },
    /// A mesh file (OBJ, STL, PLY, glTF/GLB) in `units`, placed in its resting pose (lowest point on the table).
    File { path: PathBuf, units: Units },
}

impl ObjectSource {
    /// The core's description of this object, which loads it as `tnd` does.
    pub fn spec(&self) -> tactile_derender::pipeline::ObjectSpec {
        use tactile_derender::pipeline::ObjectSpec;
        match self {
            Self::Library { set, name } => ObjectSpec::library(set, name),
            Self::File { path, units } => ObjectSpec::file(path, *units),
        }
    }

    /// Short name for display.
    pub fn display_name(&self) -> String {
        match self {
            Self::Library { name, .. } => name.clone(),
            Self::File { path, .. } => path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| path.display().to_string()),
        }
    }
}

/// The scene: object, its SE(2) pose on the table, and the sensor pressing it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SceneState {
    /// The object.
    pub object: ObjectSource,
    /// Object pose on the table relative to the sensor axis: x, y metres, theta radians.
    pub object_pose: Se2,
    /// Sensor axis position on the table, x, metres.
    pub sensor_x: f64,
    /// Sensor axis position on the table, y, metres.
    pub sensor_y: f64,
    /// Sensor rotation about the vertical, radians.
    pub sensor_yaw: f64,
    /// Press depth of the membrane apex below the object's highest point, metres.
    pub press: f64,
}

impl Default for SceneState {
    fn default() -> Self {
        Self {
            object: ObjectSource::Library {
                set: "builtin".into(),
                name: "cross_w12_s50".into(),
            },
            object_pose: Se2::new(0.002, -0.001, 0.35),
            sensor_x: 0.0,
            sensor_y: 0.0,
            sensor_yaw: 0.0,
            press: tactile_derender::sim::DEFAULT_PRESS_M,
        }
    }
}

/// Inflation calibration sweep settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CalibrationSettings {
    /// Lowest inflation of the sweep, metres.
    pub lo: f64,
    /// Highest inflation of the sweep, metres.
    pub hi: f64,
    /// Number of inflation values.
    pub steps: usize,
    /// A measured imprint Y to compare against: a `.npy` file (metres, at the sensor resolution) or a dataset
    /// directory (`tnd dataset gen` / `import`), of which pair `measured_index` of `measured_split` is used.
    pub measured: Option<PathBuf>,
    /// Split of the dataset pair used as the measurement.
    pub measured_split: SplitName,
    /// Index of the dataset pair within its split.
    pub measured_index: usize,
    /// Pixels of the measured imprint above this depth count as contact, metres.
    pub threshold: f64,
}

impl Default for CalibrationSettings {
    fn default() -> Self {
        Self {
            lo: 0.020,
            hi: 0.040,
            steps: 21,
            measured: None,
            measured_split: SplitName::Train,
            measured_index: 0,
            threshold: 0.003,
        }
    }
}

/// Colour range of the simulated images.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RangeMode {
    /// Each image's own range.
    Auto,
    /// The fixed ranges of [`ViewState`].
    Fixed,
}

/// How the elastomer is drawn in the 3D view.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MembraneStyle {
    Translucent,
    Wireframe,
    Hidden,
}

/// The central view's tabs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Tab {
    /// Simulated images and the 3D view.
    Scene,
    /// Inflation calibration plot.
    Calibration,
    /// Dataset inspector (thumbnail grid, one pair at full size).
    Dataset,
    /// De-rendering runs (samples, mean and std maps, metrics).
    Derender,
    /// Pose registration of the samples and KDE uncertainty.
    Pose,
    /// A real sensor recording: timeline, imprint per frame, contact area over time.
    Recording,
}

/// Orbit camera of the 3D view, around a target point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OrbitCamera {
    /// Rotation about the world vertical, radians.
    pub yaw: f64,
    /// Elevation above the table plane, radians.
    pub pitch: f64,
    /// Distance from the target, metres.
    pub distance: f64,
    /// Target offset from the scene centre (the pressed point on the object), world frame, metres.
    pub pan: [f64; 3],
}

impl Default for OrbitCamera {
    fn default() -> Self {
        Self {
            yaw: -0.9,
            pitch: 0.45,
            distance: 0.17,
            pan: [0.0, 0.0, 0.0],
        }
    }
}

/// Display settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ViewState {
    /// Selected central tab.
    pub tab: Tab,
    /// Automatic or fixed colour ranges.
    pub range: RangeMode,
    /// Fixed colour range of the depth images (D, E, M⊙D, S), metres.
    pub depth_range: (f32, f32),
    /// Fixed colour range of the imprint Y, metres.
    pub imprint_range: (f32, f32),
    /// Elastomer drawing style in the 3D view.
    pub membrane: MembraneStyle,
    /// Draw the camera frustum.
    pub show_frustum: bool,
    /// Draw the contact points (back-projected M⊙D).
    pub show_contacts: bool,
    /// The 3D view's camera.
    pub camera: OrbitCamera,
    /// Directory that exported PNG / .npy files are written to.
    pub export_dir: PathBuf,
}

impl Default for ViewState {
    fn default() -> Self {
        Self {
            tab: Tab::Scene,
            range: RangeMode::Auto,
            depth_range: (0.060, 0.095),
            imprint_range: (-0.002, 0.010),
            membrane: MembraneStyle::Translucent,
            show_frustum: true,
            show_contacts: true,
            camera: OrbitCamera::default(),
            export_dir: PathBuf::from("exports"),
        }
    }
}

/// The de-rendering model (used by the analysis panels).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ModelSettings {
    /// Checkpoint directory or file; `None` uses the bundled model matched to the input (`--model auto`).
    pub path: Option<PathBuf>,
}
