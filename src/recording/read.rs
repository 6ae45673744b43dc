//! **How a recording is read**: its depth topic, the no-contact reference, the contact threshold and a frame
//! folder's units and rate — one config (clap + serde) that `tnd recording info|track|frames`, `tnd calibrate`, `tnd
//! dataset import` and the workbench's Recording tab all take, so that the same recording reads the same everywhere.

use serde::{Deserialize, Serialize};

use super::{FolderOptions, ProcessConfig, ReferenceChoice};

/// How a recording is read (module docs). Lengths in metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct ReadConfig {
    /// Depth topic of an MCAP file (sensor_msgs/Image or PointCloud2); default: its only depth topic.
    #[arg(long)]
    pub topic: Option<String>,
    /// No-contact reference frame: "auto" (median of the frames without contact) or a frame number (0-based).
    #[arg(long, default_value = "auto")]
    pub reference: ReferenceChoice,
    /// Imprint above which a pixel counts as contact, metres (the threshold baseline's 3 mm).
    #[arg(long = "contact-threshold", default_value_t = ProcessConfig::default().contact_threshold_m)]
    pub contact_threshold_m: f64,
    /// Metres per unit of .npy/.npz depth arrays (1 = metres, 0.001 = millimetres).
    #[arg(long, default_value_t = FolderOptions::default().npy_scale)]
    pub npy_scale: f64,
    /// Metres per unit of 16-bit PNG depth images (default: millimetres).
    #[arg(long, default_value_t = FolderOptions::default().png_scale)]
    pub png_scale: f64,
    /// Folder recordings: frames per second (for the time stamps).
    #[arg(long, default_value_t = FolderOptions::default().fps)]
    pub fps: f64,
}

impl Default for ReadConfig {
    fn default() -> Self {
        let folder = FolderOptions::default();
        Self {
            topic: None,
            reference: ReferenceChoice::default(),
            contact_threshold_m: ProcessConfig::default().contact_threshold_m,
            npy_scale: folder.npy_scale,
            png_scale: folder.png_scale,
            fps: folder.fps,
        }
    }
}

impl ReadConfig {
    /// How a frame folder is scaled and stamped.
    pub fn folder(&self) -> FolderOptions {
        FolderOptions {
            npy_scale: self.npy_scale,
            png_scale: self.png_scale,
            fps: self.fps,
        }
    }

    /// How the frames become imprints.
    pub fn process(&self) -> ProcessConfig {
        ProcessConfig {
            reference: self.reference,
            contact_threshold_m: self.contact_threshold_m,
            ..ProcessConfig::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        read: ReadConfig,
    }

    #[test]
    fn the_command_lines_defaults_are_the_configs_and_each_option_sets_its_setting() {
        let parse = |args: &[&str]| {
            Cli::try_parse_from(std::iter::once("tnd").chain(args.iter().copied())).map(|c| c.read)
        };
        assert_eq!(parse(&[]).unwrap(), ReadConfig::default());
        assert_eq!(
            serde_json::from_str::<ReadConfig>("{}").unwrap(),
            ReadConfig::default()
        );
        let c = parse(&[
            "--topic",
            "/depth",
            "--reference",
            "3",
            "--contact-threshold",
            "0.002",
            "--npy-scale",
            "0.001",
            "--fps",
            "15",
        ])
        .unwrap();
        assert_eq!(c.topic.as_deref(), Some("/depth"));
        assert_eq!(c.process().reference, ReferenceChoice::Frame(3));
        assert_eq!(c.process().contact_threshold_m, 0.002);
        assert_eq!(c.folder().npy_scale, 0.001);
        assert_eq!(c.folder().fps, 15.0);
        assert_eq!(c.folder().png_scale, FolderOptions::default().png_scale);
        let back: ReadConfig = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, c);
    }
}
