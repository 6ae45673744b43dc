//! **Frames out**: a recording's depth frames as the files `tnd pose` and numpy take — each frame at the camera's
//! native resolution as a float32 `.npy` in metres with NaN where the camera had no return (REP 118's convention),
//! the no-contact reference the recording's processing chose as `reference.npy` (the per-pixel median of its
//! frames, native; with a drifting membrane also each no-contact stretch's, [`super::drift`], and for a frame between
//! two stretches their blend at its time, `reference_for_<frame>.npy`), and `frames.csv` with each frame's time
//! stamp, contact area (model pixels, as [`ProcessedRecording::contact_px`]), the native frame's measured pixels and
//! the reference file its imprint is against.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::process::ProcessedRecording;
use super::source::{Recording, StreamInfo};
use super::RecordingError;
use crate::image::Image;
use crate::sensor::Intrinsics;

/// The table written beside the frames.
pub const FRAMES_CSV: &str = "frames.csv";
/// The reference frame's file.
pub const REFERENCE_NPY: &str = "reference.npy";

/// One frame written.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameFile {
    /// Frame number in the recording (0-based).
    pub frame: usize,
    pub file: PathBuf,
    pub stamp_ns: u64,
    /// Contact area at the model resolution, pixels ([`ProcessedRecording::contact_px`]).
    pub contact_px: usize,
    /// Pixels of the native frame with a return.
    pub measured_px: usize,
    /// Whether the frame is one the reference was made of (no contact).
    pub reference: bool,
    /// The reference file its imprint is taken against: [`REFERENCE_NPY`], or with a drifting membrane the
    /// reference of its no-contact stretch (`reference_<first frame>.npy`) or its own blend of the stretches'
    /// before and after it (`reference_for_<frame>.npy`).
    pub reference_file: String,
}

/// The reference file of frame `frame` of `processed`: [`REFERENCE_NPY`], or with a drifting membrane the reference
/// of the no-contact stretch it uses (`reference_<first frame>.npy`), or, between two stretches, its own blend of
/// theirs (`reference_for_<frame>.npy`, [`super::drift::LocalReference`]).
fn reference_file(processed: &ProcessedRecording, frame: usize) -> String {
    if blended(processed, frame).is_some() {
        return format!("reference_for_{frame:06}.npy");
    }
    let stretch = processed
        .reference_of
        .as_ref()
        .and_then(|of| of.get(frame))
        .map(|l| if l.weight >= 1.0 { l.after } else { l.before });
    match stretch.and_then(|s| processed.stretches.get(s)) {
        Some(s) => format!("reference_{:06}.npy", s.first),
        None => REFERENCE_NPY.to_string(),
    }
}

/// Frame `frame`'s blend of two stretches' references, when it is strictly between them.
fn blended(processed: &ProcessedRecording, frame: usize) -> Option<super::drift::LocalReference> {
    let l = *processed.reference_of.as_ref()?.get(frame)?;
    (l.after != l.before && l.weight > 0.0 && l.weight < 1.0).then_some(l)
}

/// The file name of frame `k`.
pub fn frame_name(k: usize) -> String {
    format!("frame_{k:06}.npy")
}

/// A native frame with its missing pixels (0) as NaN, as drivers and numpy mark them.
fn with_nan(depth: &Image) -> Image {
    Image {
        width: depth.width,
        height: depth.height,
        data: depth
            .data
            .iter()
            .map(|&d| if d > 0.0 { d } else { f32::NAN })
            .collect(),
    }
}

/// Per-pixel median of `frames` over the frames that measured the pixel, where at least half did (0 elsewhere).
fn median_native(frames: &[Image]) -> Option<Image> {
    let refs: Vec<&Image> = frames.iter().collect();
    (!refs.is_empty()).then(|| super::process::median_where_measured(&refs, 0.5))
}

/// Write `frames` of `stream` (all of them when empty), the reference and [`FRAMES_CSV`] into the folder `dir`
/// (which the caller owns: created, files of these names replaced atomically). `processed` is the same stream
/// processed; `native` projects point clouds. `progress(done, total)` returning false cancels.
pub fn write_frames(
    rec: &Recording,
    stream: &StreamInfo,
    processed: &ProcessedRecording,
    native: &Intrinsics,
    frames: &[usize],
    dir: &Path,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<Vec<FrameFile>, RecordingError> {
    let all: Vec<usize> = (0..processed.len()).collect();
    let frames = if frames.is_empty() { &all[..] } else { frames };
    if let Some(&k) = frames.iter().find(|&&k| k >= processed.len()) {
        return Err(RecordingError::Frames {
            path: rec.path().to_path_buf(),
            message: format!(
                "there is no frame {k}: the recording has {} (0..{})",
                processed.len(),
                processed.len().saturating_sub(1)
            ),
        });
    }
    std::fs::create_dir_all(dir).map_err(|e| RecordingError::io(dir, e))?;
    let write = |name: &str, img: &Image| -> Result<PathBuf, RecordingError> {
        let path = dir.join(name);
        crate::io::npy::write_image(&path, img).map_err(|e| RecordingError::Format {
            path: path.clone(),
            message: e.to_string(),
        })?;
        Ok(path)
    };
    // With a drifting membrane every stretch's reference too (their frames).
    let mut reference_sets: Vec<(String, Vec<usize>)> = vec![(
        REFERENCE_NPY.to_string(),
        processed.reference_frames.clone(),
    )];
    if processed.reference_of.is_some() {
        for s in &processed.stretches {
            reference_sets.push((
                format!("reference_{:06}.npy", s.first),
                s.reference_frames.clone(),
            ));
        }
    }
    let total = frames.len() + reference_sets.iter().map(|(_, f)| f.len()).sum::<usize>();
    let mut done = 0;
    let mut medians = Vec::with_capacity(reference_sets.len());
    for (name, set) in &reference_sets {
        let mut refs = Vec::with_capacity(set.len());
        for &k in set {
            refs.push(rec.depth_frame(stream, k, native)?.depth);
            done += 1;
            if !progress(done, total) {
                return Err(RecordingError::Cancelled);
            }
        }
        let median = median_native(&refs);
        if let Some(r) = &median {
            write(name, &with_nan(r))?;
        }
        medians.push(median);
    }
    let mut rows = Vec::with_capacity(frames.len());
    for &k in frames {
        let f = rec.depth_frame(stream, k, native)?;
        let file = write(&frame_name(k), &with_nan(&f.depth))?;
        let mut reference_file = reference_file(processed, k);
        if let Some(l) = blended(processed, k) {
            // The stretches' native references (after the recording's own, first in `medians`) blended as the
            // frame's model-resolution reference is; without both, the stretch before it.
            let pair = (medians.get(l.before + 1), medians.get(l.after + 1));
            if let (Some(Some(a)), Some(Some(b))) = pair {
                write(
                    &reference_file,
                    &with_nan(&super::drift::blend(a, b, l.weight)),
                )?;
            } else if let Some(s) = processed.stretches.get(l.before) {
                reference_file = format!("reference_{:06}.npy", s.first);
            }
        }
        rows.push(FrameFile {
            frame: k,
            file,
            stamp_ns: f.stamp_ns,
            contact_px: processed.contact_px[k],
            measured_px: f.depth.data.iter().filter(|&&d| d > 0.0).count(),
            reference: processed.reference_frames.contains(&k),
            reference_file,
        });
        done += 1;
        if !progress(done, total) {
            return Err(RecordingError::Cancelled);
        }
    }
    let mut csv =
        String::from("frame,file,stamp_ns,contact_px,measured_px,reference,reference_file\n");
    for r in &rows {
        csv += &format!(
            "{},{},{},{},{},{},{}\n",
            r.frame,
            frame_name(r.frame),
            r.stamp_ns,
            r.contact_px,
            r.measured_px,
            u8::from(r.reference),
            r.reference_file
        );
    }
    let path = dir.join(FRAMES_CSV);
    crate::io::write_atomic(&path, csv.as_bytes()).map_err(|e| RecordingError::io(&path, e))?;
    Ok(rows)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_reference_is_the_median_of_the_frames_that_returned() {
        let a = Image::from_vec(3, 1, vec![0.09, 0.0, 0.0]).unwrap();
        let b = Image::from_vec(3, 1, vec![0.08, 0.07, 0.0]).unwrap();
        let c = Image::from_vec(3, 1, vec![0.10, 0.05, 0.06]).unwrap();
        // Pixel 1: two of three returned (their mean); pixel 2: one of three (missing).
        let m = median_native(&[a, b, c]).unwrap();
        assert_eq!(m.data[0], 0.09);
        assert!(
            (m.data[1] - 0.06).abs() < 1e-7 && m.data[2] == 0.0,
            "{:?}",
            m.data
        );
        let nan = with_nan(&m);
        assert_eq!(nan.data[..2], m.data[..2]);
        assert!(nan.data[2].is_nan());
    }
}
