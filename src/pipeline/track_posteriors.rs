//! **posteriors.json** of a track: each tracked frame's pose posterior as `track.csv` reports it (fused with the
//! earlier frames' on carried frames, [`crate::pose::fusion`]) and the frame it was fused with. With it a track is
//! scored and calibrated like `tnd eval`'s records (`tnd posterior --tracks`: the fusion is replayed under each
//! calibration tried, [`crate::metrics::coverage::calibrated`]), and a resumed track scores its earlier rows again.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::track::FrameTrack;
use super::PipelineError;
use crate::metrics::coverage::Scored;
use crate::objects::Symmetry;
use crate::pose::posterior::PosePosterior;

/// One frame's posterior in a track.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FramePosterior {
    /// [`FrameTrack::fused_with`].
    pub fused_with: Option<usize>,
    pub posterior: PosePosterior,
}

/// posteriors.json (module docs).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackPosteriors {
    /// The object's symmetry (how errors and regions are reduced).
    pub symmetry: Symmetry,
    /// By frame number.
    pub frames: BTreeMap<usize, FramePosterior>,
}

impl TrackPosteriors {
    /// Its name in a track's folder.
    pub const FILE: &'static str = "posteriors.json";

    pub fn new(symmetry: Symmetry) -> Self {
        Self {
            symmetry,
            frames: BTreeMap::new(),
        }
    }

    /// The file in the track folder `dir`; `None` where there is none (a track of an earlier version).
    pub fn read(dir: &Path) -> Result<Option<Self>, PipelineError> {
        let path = dir.join(Self::FILE);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(PipelineError::Read { path, source }),
        };
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| PipelineError::Format {
                path,
                problem: format!("not a track's posteriors: {e}"),
            })
    }

    /// Write it into the track folder `dir`, atomically.
    pub fn write(&self, dir: &Path) -> Result<(), PipelineError> {
        let path = dir.join(Self::FILE);
        let text = serde_json::to_string(self).map_err(|e| PipelineError::Write {
            path: path.clone(),
            source: std::io::Error::other(e),
        })?;
        crate::io::write_atomic(&path, text.as_bytes())
            .map_err(|source| PipelineError::Write { path, source })
    }

    /// Keep `row`'s posterior (rows without one: nothing).
    pub fn keep(&mut self, row: &FrameTrack) {
        if let Some(p) = &row.posterior {
            self.frames.insert(
                row.frame,
                FramePosterior {
                    fused_with: row.fused_with,
                    posterior: p.clone(),
                },
            );
        }
    }

    /// Give rows read back from `track.csv` their posteriors again (so that they can be scored anew).
    pub fn restore(&self, rows: &mut [FrameTrack]) {
        for row in rows.iter_mut().filter(|r| r.posterior.is_none()) {
            if let Some(f) = self.frames.get(&row.frame) {
                row.posterior = Some(f.posterior.clone());
                row.fused_with = f.fused_with;
            }
        }
    }

    /// The scored frames of `rows` (a recorded pose, an estimate and a posterior), in frame order, each carried
    /// frame linked to the frame it was fused with ([`Scored::prior`]); and how many scored frames were left out
    /// because that frame is not scored (no recorded pose): their fusion could not be replayed. The contact size
    /// of a frame is the contact its best mode predicts (noise-free, as the calibration scales by), else the
    /// imprint's pixels over the threshold.
    pub fn scored<'a>(&'a self, rows: &[FrameTrack]) -> (Vec<Scored<'a>>, usize) {
        let mut sorted: Vec<&FrameTrack> = rows.iter().collect();
        sorted.sort_by_key(|r| r.frame);
        let mut out: Vec<Scored<'a>> = Vec::new();
        let mut index: BTreeMap<usize, usize> = BTreeMap::new();
        let mut left_out = 0;
        for row in sorted {
            let (Some(f), Some(truth), Some((position_mm, theta_deg))) = (
                self.frames.get(&row.frame),
                row.recorded,
                row.estimate_error,
            ) else {
                continue;
            };
            let prior = match f.fused_with {
                None => None,
                Some(before) => match index.get(&before) {
                    Some(&i) => Some(i),
                    None => {
                        left_out += 1;
                        continue;
                    }
                },
            };
            index.insert(row.frame, out.len());
            out.push(Scored {
                posterior: &f.posterior,
                truth,
                symmetry: self.symmetry,
                position_mm,
                theta_rad: theta_deg.map(f64::to_radians),
                contact_pixels: f.posterior.predicted_contact_px.unwrap_or(row.contact_px),
                prior,
            });
        }
        (out, left_out)
    }
}
