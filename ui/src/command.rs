//! User intent as one [`Command`] enum, applied in one function ([`crate::app::WorkbenchApp::apply`], in
//! `app/dispatch.rs`): panels only push commands, so sessions, tests and undo have a single door into the
//! [`crate::state::State`].

use std::path::PathBuf;

use tactile_derender::sim::SimConfig;

use crate::images::ImageKind;
use crate::state::{
    CalibrationSettings, DatasetSettings, DerenderSettings, ModelSettings, SceneState, ViewState,
};
use crate::worker::DialogPurpose;

/// What the user asked for.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// Replace the scene (object, poses, press).
    SetScene(SceneState),
    /// Replace the simulator configuration (camera, mount, elastomer, signature).
    SetSim(SimConfig),
    /// Set the noise seed.
    SetSeed(u64),
    /// Replace the calibration settings.
    SetCalibration(CalibrationSettings),
    /// Replace the display settings (no re-simulation).
    SetView(ViewState),
    /// Start over from the default scene (the session file is forgotten).
    NewSession,
    /// Open a session file; a bad file shows an error and changes nothing.
    OpenSession(PathBuf),
    /// Save the state to a session file (atomically).
    SaveSession(PathBuf),
    /// Show a native file dialog; its answer becomes another command.
    Browse(DialogPurpose),
    /// Load a measured imprint (`.npy`, metres, or a dataset directory's pair) for the calibration.
    LoadMeasured(PathBuf),
    /// Place the scene where the measured dataset pair was taken (object, poses; the sensor base at its height).
    UseMeasuredScene,
    /// Forget the measured imprint.
    ClearMeasured,
    /// Run the inflation sweep in the background.
    RunCalibration,
    /// Cancel the running sweep.
    CancelCalibration,
    /// Use this inflation height (metres).
    PickInflation(f64),
    /// Write one image to the export folder as a PNG with colour bar or as `.npy`.
    Export { image: ImageKind, png: bool },
    /// Clear the error list.
    DismissErrors,
    /// Open a dataset directory in the inspector.
    OpenDataset(PathBuf),
    /// Replace the inspector's settings (split, object filter, selection, thumbnail size).
    SetDataset(DatasetSettings),
    /// Use the selected dataset pair as the de-rendering input.
    SendPairToDerender,
    /// Place the simulated scene where the selected dataset pair was taken.
    PlacePairScene,
    /// Replace the de-rendering settings (sampler, samples, seed, input).
    SetDerender(DerenderSettings),
    /// Choose the model checkpoint (`None`: the bundled model matched to the input).
    SetModel(ModelSettings),
    /// Sample the current input in the background.
    RunDerender,
    /// Cancel the running de-rendering.
    CancelDerender,
    /// Register the current samples and the baseline to the object.
    RunPose,
    /// Forget the running pose analysis.
    CancelPose,
    /// Write the pose numbers (`samples.csv`, `kde.csv`) and the KDE plot (`uncertainty.png`) to the export folder.
    ExportPose,
    /// Highlight one sample in the Pose tab's plots (`None`: none), as the pointer hovers it.
    HighlightSample(Option<usize>),
    /// Replace the pose engine's settings (the Pose tab's check boxes: the signature check, imprint proposals);
    /// they apply to the next registration and the track.
    SetPose(Box<tactile_derender::pose::PoseConfig>),
    /// Undo the last scene, sensor or elastomer edit.
    Undo,
    /// Redo the last undone edit.
    Redo,
    /// Open a file dropped on the window as what it is (mesh, session, imprint, model, dataset).
    OpenDropped(PathBuf),
    /// Open a recording (`.mcap` file or depth-frame folder) in the Recording tab.
    OpenRecording(PathBuf),
    /// Replace the Recording tab's settings (a new topic or reference reloads; a new frame moves the cursor).
    SetRecording(crate::recording_view::RecordingSettings),
    /// Stop reading the recording.
    CancelRecording,
    /// De-render the frame under the timeline cursor (and, with `pose`, register the samples when they are in).
    DerenderFrame { pose: bool },
    /// Estimate the object's pose on every contact frame of the recording.
    TrackRecording,
    /// Stop the track.
    CancelTrack,
    /// Fit the sensor (membrane, camera position, noise) to the recording's no-contact frames and use it.
    CalibrateSensor,
    /// Stop the sensor calibration.
    CancelSensorCalibration,
    /// Write the calibrated sensor as a sensor file beside the recording.
    SaveSensorFile,
    /// Write the track as a CSV file beside the recording.
    SaveTrack,
    /// Show an analysis image enlarged in its own window (`None`: close it).
    ZoomImage(Option<crate::analysis_runs::ZoomTarget>),
}
