//! `--rerun FILE.rrd` for `tnd sim`, `sample`, `pose` and `eval`: the same results as the files they write, as a
//! rerun recording ([`tactile_derender::rrd`]): the camera with its intrinsics and pose, depth images under it,
//! contact points and the object at its true and estimated poses in the world (the table) frame.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use glam::DAffine3;
use tactile_derender::image::Image;
use tactile_derender::mesh::Mesh;
use tactile_derender::recon::back_project;
use tactile_derender::rrd::RrdLog;
use tactile_derender::sensor::{Intrinsics, Se2};

/// Colours: the object at its true pose, at an estimate, contact points.
pub const TRUTH_RGB: [u8; 3] = [120, 170, 255];
pub const ESTIMATE_RGB: [u8; 3] = [255, 150, 60];
pub const CONTACT_RGB: [u8; 3] = [230, 40, 40];

#[derive(Args, Debug, Clone, Default)]
pub struct RerunArgs {
    /// Also write a rerun recording: depth images with the camera's intrinsics and pose, contact points, the posed
    /// object, on a timeline (open with `rerun FILE.rrd`; needs a tnd built with `--features rerun`).
    #[arg(long, value_name = "FILE.rrd")]
    pub rerun: Option<PathBuf>,
}

impl RerunArgs {
    /// Start the recording (before any long work, so a build without rerun fails at once). An existing file is
    /// replaced only when tnd wrote it, or with `force`; never one of `inputs`.
    pub fn open(&self, name: &str, force: bool, inputs: &[&Path]) -> Result<Option<RrdLog>> {
        self.rerun
            .as_ref()
            .map(|p| {
                let claim = crate::outputs::file(
                    "--rerun",
                    p,
                    force,
                    inputs,
                    &tactile_derender::rrd::written_by_tnd,
                )?;
                let log = RrdLog::create(claim.path(), name)?;
                Ok(log.holding(claim))
            })
            .transpose()
    }
}

/// The camera and its images under `world/sensor/camera`, and the contact points of `contact` (an in-contact depth
/// image) in the world.
pub fn camera_views(
    log: &RrdLog,
    k: &Intrinsics,
    t_world_camera: &DAffine3,
    images: &[(&str, &Image)],
    contact: Option<(&str, &Image)>,
) -> Result<()> {
    log.camera("world/sensor/camera", k, t_world_camera)?;
    for (name, img) in images {
        log.depth(&format!("world/sensor/camera/{name}"), img)?;
    }
    if let Some((name, depth)) = contact {
        let cloud = back_project(depth, k, t_world_camera);
        log.points(&format!("world/points/{name}"), &cloud.p_world, CONTACT_RGB)?;
    }
    Ok(())
}

/// The object mesh at `pose` (its resting frame placed on the table by the SE(2) pose).
pub fn object_at(log: &RrdLog, entity: &str, mesh: &Mesh, pose: Se2, rgb: [u8; 3]) -> Result<()> {
    log.mesh(entity, mesh, &pose.to_affine(), rgb)?;
    Ok(())
}

/// Close the recording and say where it is.
pub fn finish(log: Option<RrdLog>) -> Result<Option<PathBuf>> {
    Ok(log.map(RrdLog::finish).transpose()?)
}
