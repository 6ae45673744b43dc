//! Native file dialogs (rfd) for each [`DialogPurpose`]. Called on a background thread by the worker; where no portal
//! or dialog exists rfd returns `None` at once and the user types the path instead.

use std::path::PathBuf;

use crate::worker::DialogPurpose;

/// Show the dialog for `purpose`, starting in `start_dir` if given; `None` when cancelled or unavailable.
pub fn run(purpose: DialogPurpose, start_dir: Option<PathBuf>) -> Option<PathBuf> {
    let mut d = rfd::FileDialog::new();
    if let Some(dir) = start_dir.filter(|d| d.is_dir()) {
        d = d.set_directory(dir);
    }
    match purpose {
        DialogPurpose::OpenSession => d
            .set_title("Open session")
            .add_filter("session", &["json"])
            .pick_file(),
        DialogPurpose::SaveSessionAs => d
            .set_title("Save session as")
            .add_filter("session", &["json"])
            .set_file_name("session.json")
            .save_file(),
        DialogPurpose::OpenObjectMesh | DialogPurpose::OpenElastomerMesh => d
            .set_title("Open mesh")
            .add_filter(
                "mesh",
                &[
                    "obj", "stl", "ply", "gltf", "glb", "OBJ", "STL", "PLY", "GLTF", "GLB",
                ],
            )
            .pick_file(),
        DialogPurpose::OpenMeasured => d
            .set_title("Open measured imprint")
            .add_filter("numpy", &["npy"])
            .pick_file(),
        DialogPurpose::ExportDir => d.set_title("Export folder").pick_folder(),
        DialogPurpose::OpenDataset => d.set_title("Open dataset directory").pick_folder(),
        DialogPurpose::OpenCheckpoint => d
            .set_title("Open model checkpoint")
            .add_filter("safetensors", &["safetensors"])
            .pick_file(),
        DialogPurpose::OpenDerenderImprint => d
            .set_title("Open measured imprint (metres)")
            .add_filter("numpy", &["npy"])
            .pick_file(),
        DialogPurpose::OpenRecording => d
            .set_title("Open recording")
            .add_filter("MCAP (ROS 2 bag)", &["mcap", "MCAP"])
            .pick_file(),
        DialogPurpose::OpenRecordingFolder => d
            .set_title("Open a folder of depth frames (16-bit PNG mm, .npy m)")
            .pick_folder(),
    }
}
