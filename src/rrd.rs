//! Results as a **rerun recording** (`.rrd`), the viewer robotics users already open their robot logs in: depth
//! images with the camera's pinhole intrinsics and pose, point clouds, and posed meshes, on a timeline. The rerun SDK
//! is an optional dependency (cargo feature `rerun`; it adds a few hundred crates), so without the feature
//! [`RrdLog::create`] says how to get it instead of writing anything.
//!
//! Entity layout (world frame = the table, metres): `world/object` (the object at its true pose), `world/estimate/...`
//! (the object at estimated poses), `world/posterior` (the pose posterior's 90 % position regions on the table),
//! `world/sensor/camera` (camera pose + pinhole) with the depth images under it, `world/points/...` (back-projected
//! contact points), `world/membrane`.

use std::path::{Path, PathBuf};

use glam::DAffine3;

use crate::image::Image;
use crate::mesh::Mesh;
use crate::sensor::Intrinsics;

/// Errors of writing a rerun recording.
#[derive(Debug, thiserror::Error)]
pub enum RrdError {
    #[error("{path}: this build has no rerun support; rebuild with `cargo build --release --features rerun` (the rerun SDK)")]
    NotBuilt { path: PathBuf },
    #[error("{path}: rerun: {message}")]
    Rerun { path: PathBuf, message: String },
}

/// An open `.rrd` file being written.
pub struct RrdLog {
    path: PathBuf,
    #[cfg(feature = "rerun")]
    rec: rerun::RecordingStream,
    /// The claim on the file ([`crate::io::output`]), held while it is written.
    claim: Option<crate::io::output::Claimed>,
}

/// Whether `path` is a rerun recording tnd wrote: the `.rrd` magic and, in its first message, tnd's application id.
pub fn written_by_tnd(path: &Path) -> bool {
    use std::io::Read;
    let mut head = Vec::with_capacity(4096);
    let read = std::fs::File::open(path).and_then(|f| f.take(4096).read_to_end(&mut head));
    read.is_ok()
        && head.starts_with(b"RRF")
        && head
            .windows(APPLICATION_ID.len())
            .any(|w| w == APPLICATION_ID.as_bytes())
}

/// The application id of every recording tnd writes.
const APPLICATION_ID: &str = "tactile-derender";

#[cfg(feature = "rerun")]
fn f32x3(v: glam::DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

impl RrdLog {
    /// Start a recording written to `path` (application id `tactile-derender`, recording name `name`).
    pub fn create(path: &Path, name: &str) -> Result<Self, RrdError> {
        #[cfg(feature = "rerun")]
        {
            let rec = rerun::RecordingStreamBuilder::new(APPLICATION_ID)
                .recording_name(name)
                .save(path)
                .map_err(|e| RrdError::Rerun {
                    path: path.to_path_buf(),
                    message: e.to_string(),
                })?;
            Ok(Self {
                path: path.to_path_buf(),
                rec,
                claim: None,
            })
        }
        #[cfg(not(feature = "rerun"))]
        {
            let _ = name;
            Err(RrdError::NotBuilt {
                path: path.to_path_buf(),
            })
        }
    }

    #[cfg(feature = "rerun")]
    fn err(&self, e: impl std::fmt::Display) -> RrdError {
        RrdError::Rerun {
            path: self.path.clone(),
            message: e.to_string(),
        }
    }

    /// Put what follows at step `step` of the timeline `timeline` (e.g. "frame", "pair", "sample").
    pub fn set_step(&self, timeline: &'static str, step: usize) {
        #[cfg(feature = "rerun")]
        self.rec.set_time_sequence(timeline, step as i64);
        #[cfg(not(feature = "rerun"))]
        let _ = (timeline, step);
    }

    /// A rigid transform of `entity` relative to its parent.
    pub fn transform(&self, entity: &str, t_parent_entity: &DAffine3) -> Result<(), RrdError> {
        #[cfg(feature = "rerun")]
        {
            let cols = t_parent_entity.matrix3.to_cols_array_2d();
            let m = cols.map(|c| c.map(|x| x as f32));
            self.rec
                .log(
                    entity,
                    &rerun::Transform3D::from_translation_mat3x3(
                        f32x3(t_parent_entity.translation),
                        m,
                    ),
                )
                .map_err(|e| self.err(e))
        }
        #[cfg(not(feature = "rerun"))]
        {
            let _ = (entity, t_parent_entity);
            Ok(())
        }
    }

    /// The camera at `t_world_camera` with pinhole `k` (images logged under `entity` are its views).
    pub fn camera(
        &self,
        entity: &str,
        k: &Intrinsics,
        t_world_camera: &DAffine3,
    ) -> Result<(), RrdError> {
        self.transform(entity, t_world_camera)?;
        #[cfg(feature = "rerun")]
        {
            let pinhole = rerun::Pinhole::from_focal_length_and_resolution(
                [k.fx as f32, k.fy as f32],
                [k.width as f32, k.height as f32],
            )
            .with_principal_point([k.cx as f32, k.cy as f32]);
            self.rec.log(entity, &pinhole).map_err(|e| self.err(e))
        }
        #[cfg(not(feature = "rerun"))]
        {
            let _ = k;
            Ok(())
        }
    }

    /// A depth (or imprint) image in metres.
    pub fn depth(&self, entity: &str, image: &Image) -> Result<(), RrdError> {
        #[cfg(feature = "rerun")]
        {
            let bytes: Vec<u8> = image.data.iter().flat_map(|v| v.to_le_bytes()).collect();
            let d = rerun::DepthImage::from_data_type_and_bytes(
                bytes,
                [image.width as u32, image.height as u32],
                rerun::ChannelDatatype::F32,
            )
            .with_meter(1.0);
            self.rec.log(entity, &d).map_err(|e| self.err(e))
        }
        #[cfg(not(feature = "rerun"))]
        {
            let _ = (entity, image);
            Ok(())
        }
    }

    /// Points in the parent's frame, one colour (RGB).
    pub fn points(
        &self,
        entity: &str,
        points: &[glam::DVec3],
        rgb: [u8; 3],
    ) -> Result<(), RrdError> {
        #[cfg(feature = "rerun")]
        {
            let p = rerun::Points3D::new(points.iter().map(|&q| f32x3(q)))
                .with_colors([rerun::Color::from_rgb(rgb[0], rgb[1], rgb[2])])
                .with_radii([0.0004f32]);
            self.rec.log(entity, &p).map_err(|e| self.err(e))
        }
        #[cfg(not(feature = "rerun"))]
        {
            let _ = (entity, points, rgb);
            Ok(())
        }
    }

    /// Polylines in the parent's frame, one colour (RGB), e.g. the pose posterior's region outlines.
    pub fn line_strips(
        &self,
        entity: &str,
        strips: &[Vec<glam::DVec3>],
        rgb: [u8; 3],
    ) -> Result<(), RrdError> {
        #[cfg(feature = "rerun")]
        {
            let l = rerun::LineStrips3D::new(
                strips
                    .iter()
                    .map(|strip| strip.iter().map(|&q| f32x3(q)).collect::<Vec<_>>()),
            )
            .with_colors([rerun::Color::from_rgb(rgb[0], rgb[1], rgb[2])]);
            self.rec.log(entity, &l).map_err(|e| self.err(e))
        }
        #[cfg(not(feature = "rerun"))]
        {
            let _ = (entity, strips, rgb);
            Ok(())
        }
    }

    /// A mesh placed at `t_world_mesh`.
    pub fn mesh(
        &self,
        entity: &str,
        mesh: &Mesh,
        t_world_mesh: &DAffine3,
        rgb: [u8; 3],
    ) -> Result<(), RrdError> {
        self.transform(entity, t_world_mesh)?;
        #[cfg(feature = "rerun")]
        {
            let m = rerun::Mesh3D::new(mesh.vertices().iter().map(|v| [v.x, v.y, v.z]))
                .with_triangle_indices(
                    mesh.triangles()
                        .iter()
                        .map(|t| rerun::TriangleIndices::from(*t)),
                )
                .with_albedo_factor(rerun::Rgba32::from_rgb(rgb[0], rgb[1], rgb[2]));
            self.rec.log(entity, &m).map_err(|e| self.err(e))
        }
        #[cfg(not(feature = "rerun"))]
        {
            let _ = (mesh, rgb);
            Ok(())
        }
    }

    /// Write everything out and close the file.
    /// Hold `claim` (on this recording's file) until the recording is finished.
    pub fn holding(mut self, claim: crate::io::output::Claimed) -> Self {
        self.claim = Some(claim);
        self
    }

    pub fn finish(self) -> Result<PathBuf, RrdError> {
        #[cfg(feature = "rerun")]
        self.rec.flush_blocking().map_err(|e| self.err(e))?;
        Ok(self.path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(not(feature = "rerun"))]
    #[test]
    fn without_the_feature_it_says_how_to_build_and_writes_nothing() {
        let dir = std::env::temp_dir().join("tnd-rrd-not-built");
        let path = dir.join("x.rrd");
        let e = RrdLog::create(&path, "t")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("x.rrd") && e.contains("--features rerun"), "{e}");
        assert!(!path.exists());
    }

    #[cfg(feature = "rerun")]
    #[test]
    fn a_recording_is_written_and_closed() {
        let dir = std::env::temp_dir().join(format!("tnd-rrd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).ok();
        let path = dir.join("x.rrd");
        let log = RrdLog::create(&path, "t").expect("create");
        log.set_step("frame", 0);
        let img = Image::filled(4, 3, 0.08);
        log.camera("world/cam", &Intrinsics::pico_flexx(), &DAffine3::IDENTITY)
            .and_then(|_| log.depth("world/cam/depth", &img))
            .expect("log");
        assert_eq!(log.finish().expect("finish"), path);
        assert!(std::fs::metadata(&path)
            .map(|m| m.len() > 100)
            .unwrap_or(false));
    }
}
