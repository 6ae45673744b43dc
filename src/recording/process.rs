//! From depth frames to **imprints**: every frame of a depth stream is brought to the model resolution (crop and
//! area resampling, as `tnd dataset import`), the no-contact reference R is chosen, and each frame gets
//! Y = R − S and its contact area (pixels where Y exceeds the threshold baseline's 3 mm).
//!
//! Reference detection (`ReferenceChoice::Auto`): the frame whose mean depth is largest (nothing pushes the membrane
//! towards the camera) is a first reference; the frames whose imprint against it, averaged over 5 x 5 pixel windows
//! (which divides per-pixel noise by 5), stays under `quiet_threshold_m` everywhere are the quiet frames, and R is the
//! per-pixel median of up to `quiet_frames` of them, spread over the recording, which lowers R's noise. For a noisy
//! sensor the threshold rises to five times the noise of such a window mean, measured on the recording itself
//! ([`window_noise`]).

use serde::{Deserialize, Serialize};

use super::drift::QuietStretch;
use super::source::{Recording, StreamInfo};
use super::RecordingError;
use crate::image::Image;
use crate::sensor::resample;
use crate::sensor::CameraConfig;
use crate::sim::signature::imprint;

/// Which frame is the no-contact reference R.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReferenceChoice {
    /// Detected: the median of the frames without contact (see the module docs).
    #[default]
    Auto,
    /// This frame (0-based).
    Frame(usize),
}

impl std::str::FromStr for ReferenceChoice {
    type Err = crate::error::InvalidSetting;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        crate::error::InvalidSetting::wrap("reference", || match s.trim() {
            "auto" => Ok(Self::Auto),
            n => n
                .parse()
                .map(Self::Frame)
                .map_err(|_| format!("reference '{s}' must be 'auto' or a frame number (0-based)")),
        })
    }
}

/// How a recording becomes imprints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ProcessConfig {
    pub reference: ReferenceChoice,
    /// Imprint above which a pixel counts as contact for the contact area, metres (default 3 mm, the threshold
    /// baseline's).
    pub contact_threshold_m: f64,
    /// Most quiet frames whose median makes an automatic reference (default 15).
    pub quiet_frames: usize,
    /// A frame is quiet (no contact) when its 5 x 5-averaged imprint stays under this, metres (default 1 mm).
    pub quiet_threshold_m: f64,
}

impl Default for ProcessConfig {
    fn default() -> Self {
        Self {
            reference: ReferenceChoice::Auto,
            contact_threshold_m: 0.003,
            quiet_frames: 15,
            quiet_threshold_m: 0.001,
        }
    }
}

/// A depth stream as imprints at the model resolution.
#[derive(Clone, Debug)]
pub struct ProcessedRecording {
    /// The depth stream's name.
    pub stream: String,
    /// Source frame size `[width, height]`.
    pub source_size: [usize; 2],
    /// Time stamp of each frame, nanoseconds.
    pub stamps_ns: Vec<u64>,
    /// S per frame, metres, model resolution.
    pub signatures: Vec<Image>,
    /// R, metres, model resolution: the reference of the whole recording.
    pub reference: Image,
    /// The frames R was made of.
    pub reference_frames: Vec<usize>,
    /// The runs of no-contact frames, each with its own reference and drift ([`super::drift`]; empty with a
    /// reference frame given).
    pub stretches: Vec<QuietStretch>,
    /// Per frame, how its reference is made of the stretches' references (the membrane drifting steadily between
    /// them); `None` where the stretches agree within [`super::drift::DRIFT_TOLERANCE_M`] and every imprint is
    /// against [`Self::reference`].
    pub reference_of: Option<Vec<super::drift::LocalReference>>,
    /// Y = R − S per frame, metres ([`crate::sim::signature::imprint`]: filled in where only S is missing, 0 where R
    /// is).
    pub imprints: Vec<Image>,
    /// Pixels with Y above the threshold, per frame.
    pub contact_px: Vec<usize>,
    /// Pixels the frame measured where its reference did, per frame (the others have no return: missing).
    pub measured_px: Vec<usize>,
}

/// A light press's threshold is this many times the no-contact frames' noise
/// ([`ProcessedRecording::imprint_noise_m`]): at 4σ, Gaussian noise puts 0.1 of the 4096 pixels over it.
pub const LIGHT_PRESS_SIGMAS: f64 = 4.0;

/// The lowest threshold a light press is taken in at, metres.
pub const LIGHT_PRESS_MIN_M: f64 = 0.001;

/// A recording taken in as a light press: no frame had enough contact over the contact threshold, so the frames
/// were chosen at a threshold set by the recording's own noise.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LightPress {
    /// The threshold the frames were chosen at, metres.
    pub threshold_m: f64,
    /// The no-contact frames' imprint noise it was set from, metres.
    pub noise_m: f64,
    /// The contact threshold no frame passed, metres.
    pub contact_threshold_m: f64,
}

impl LightPress {
    /// What was done, in words for a warning: no frame had `min_contact_px` over the contact threshold, so the
    /// frames were chosen at this threshold, set from this noise.
    pub fn describe(&self, min_contact_px: usize) -> String {
        format!(
            "a light press: no frame had {min_contact_px} px over {:.1} mm, so frames were chosen at {:.2} mm \
             ({LIGHT_PRESS_SIGMAS} x the no-contact frames' noise, {:.2} mm)",
            self.contact_threshold_m * 1e3,
            self.threshold_m * 1e3,
            self.noise_m * 1e3
        )
    }
}

/// Fewest measured no-contact pixels [`ProcessedRecording::imprint_noise_m`] estimates the noise from.
pub const MIN_NOISE_SAMPLES: usize = 1000;

/// Least share of the reference's measured pixels a frame must measure itself to be de-rendered and registered
/// (below it, holes are the frame's larger part: a glitch, a cable over the lens, an over-exposed frame).
pub const MIN_MEASURED_SHARE: f64 = 0.5;

/// Why a frame that measured `measured` of the `seen` pixels its reference measured cannot be used
/// ([`MIN_MEASURED_SHARE`]); `None` when it can.
pub fn too_few_returns(measured: usize, seen: usize) -> Option<String> {
    if seen == 0 {
        return Some(
            "its reference has no pixel with a return (are the depths in the units the reader assumed?)".into(),
        );
    }
    ((measured as f64) < MIN_MEASURED_SHARE * seen as f64).then(|| {
        format!(
            "only {measured} of the membrane's {seen} pixels have a return (fewer than {:.0} %)",
            100.0 * MIN_MEASURED_SHARE
        )
    })
}

/// Pixels measured (depth > 0) in both `reference` and `frame`.
pub fn measured_pixels(reference: &Image, frame: &Image) -> usize {
    reference
        .data
        .iter()
        .zip(&frame.data)
        .filter(|(&r, &s)| r > 0.0 && s > 0.0)
        .count()
}

impl ProcessedRecording {
    /// Number of frames.
    pub fn len(&self) -> usize {
        self.imprints.len()
    }

    pub fn is_empty(&self) -> bool {
        self.imprints.is_empty()
    }

    /// The reference frame `frame`'s imprint was taken against: [`Self::reference`], or with a drifting membrane
    /// its stretches' references blended at the frame's time ([`super::drift::LocalReference`]).
    pub fn reference_for(&self, frame: usize) -> std::borrow::Cow<'_, Image> {
        let local = self.reference_of.as_ref().and_then(|of| of.get(frame));
        match local.map(|l| l.blend(&self.stretches)) {
            Some(Some(r)) => r,
            _ => std::borrow::Cow::Borrowed(&self.reference),
        }
    }

    /// Whether the frames reach `camera`'s model resolution by area resampling (native or cropped frames; what
    /// `--model auto` picks its model by, [`crate::sensor::resample::is_resampled`]).
    pub fn frames_resampled(&self, camera: &crate::sensor::CameraConfig) -> bool {
        let [w, h] = self.source_size;
        crate::sensor::resample::is_resampled(camera, w, h)
    }

    /// The membrane's largest drift between no-contact stretches, metres ([`super::drift`]).
    pub fn drift_m(&self) -> f64 {
        super::drift::largest_drift(&self.stretches)
    }

    /// Why frame `frame` cannot be used (too few of its pixels have a return, [`MIN_MEASURED_SHARE`]), in one line
    /// naming the frame; `None` when it can.
    pub fn unusable(&self, frame: usize) -> Option<String> {
        let seen = self.reference_for(frame).count_nonzero();
        let measured = self.measured_px.get(frame).copied().unwrap_or(0);
        too_few_returns(measured, seen).map(|why| format!("frame {frame}: {why}; skipped"))
    }

    /// The imprint's noise where nothing touches, metres: 1.4826 × the median absolute imprint over the pixels
    /// the no-contact (reference) frames measured, each against its own reference; `None` with fewer than
    /// [`MIN_NOISE_SAMPLES`] such pixels (no no-contact frames: a given reference). Slightly low, as the
    /// references are means of these frames.
    pub fn imprint_noise_m(&self) -> Option<f64> {
        let mut magnitudes: Vec<f32> = Vec::new();
        for &k in &self.reference_frames {
            let (Some(y), Some(s)) = (self.imprints.get(k), self.signatures.get(k)) else {
                continue;
            };
            let r = self.reference_for(k);
            magnitudes.extend(
                y.data
                    .iter()
                    .zip(&s.data)
                    .zip(&r.data)
                    .filter(|((_, &s), &r)| s > 0.0 && r > 0.0)
                    .map(|((&y, _), _)| y.abs()),
            );
        }
        if magnitudes.len() < MIN_NOISE_SAMPLES {
            return None;
        }
        let mid = magnitudes.len() / 2;
        let (_, median, _) = magnitudes.select_nth_unstable_by(mid, f32::total_cmp);
        Some(1.4826 * f64::from(*median))
    }

    /// Whether frame `k` was found to touch nothing: a frame the reference was made of, or one of a run of
    /// no-contact frames ([`Self::stretches`]).
    pub fn is_no_contact(&self, k: usize) -> bool {
        self.reference_frames.contains(&k)
            || self
                .stretches
                .iter()
                .any(|s| (s.first..=s.last).contains(&k))
    }

    /// The light-press threshold of this recording ([`LightPress`]): [`LIGHT_PRESS_SIGMAS`] times
    /// [`Self::imprint_noise_m`], at least [`LIGHT_PRESS_MIN_M`], with each frame's contact pixels over it (as
    /// [`Self::contact_px`] at that threshold; 0 for the no-contact frames, [`Self::is_no_contact`]: the noise's
    /// tail can put a few pixels of a frame that touches nothing over a threshold set by the noise); `None` where
    /// the noise cannot be measured or the threshold would not be below `contact_threshold_m`.
    pub fn light_press(&self, contact_threshold_m: f64) -> Option<(LightPress, Vec<usize>)> {
        let noise_m = self.imprint_noise_m()?;
        let threshold_m = (LIGHT_PRESS_SIGMAS * noise_m).max(LIGHT_PRESS_MIN_M);
        if threshold_m >= contact_threshold_m {
            return None;
        }
        let counts = self
            .imprints
            .iter()
            .enumerate()
            .map(|(k, y)| {
                if self.is_no_contact(k) {
                    0
                } else {
                    contact_pixels(y, threshold_m)
                }
            })
            .collect();
        Some((
            LightPress {
                threshold_m,
                noise_m,
                contact_threshold_m,
            },
            counts,
        ))
    }

    /// Seconds from the first frame, per frame.
    pub fn times_s(&self) -> Vec<f64> {
        let t0 = self.stamps_ns.first().copied().unwrap_or(0);
        self.stamps_ns
            .iter()
            .map(|&t| t.saturating_sub(t0) as f64 / 1e9)
            .collect()
    }
}

fn contact_pixels(y: &Image, threshold: f64) -> usize {
    let t = threshold as f32;
    y.data.iter().filter(|&&v| v > t).count()
}

fn mean_valid(img: &Image) -> f64 {
    let (s, n) = img
        .data
        .iter()
        .filter(|&&d| d > 0.0)
        .fold((0.0f64, 0usize), |(s, n), &d| (s + f64::from(d), n + 1));
    if n == 0 {
        0.0
    } else {
        s / n as f64
    }
}

fn median_image(images: &[&Image]) -> Image {
    median_where_measured(images, 0.0)
}

/// Per-pixel median of `images` over those that measured the pixel (> 0), where at least `min_share` of them did
/// (0 elsewhere).
pub(crate) fn median_where_measured(images: &[&Image], min_share: f64) -> Image {
    let first = images[0];
    let mut out = Image::filled(first.width, first.height, 0.0);
    let mut vals = Vec::with_capacity(images.len());
    for (i, o) in out.data.iter_mut().enumerate() {
        vals.clear();
        vals.extend(images.iter().map(|im| im.data[i]).filter(|&d| d > 0.0));
        if !vals.is_empty() && vals.len() as f64 >= min_share * images.len() as f64 {
            vals.sort_by(f32::total_cmp);
            let m = vals.len() / 2;
            *o = if vals.len() % 2 == 1 {
                vals[m]
            } else {
                0.5 * (vals[m - 1] + vals[m])
            };
        }
    }
    out
}

/// Read every frame of `stream`, bring it to `camera`'s model resolution and compute the imprints.
/// `progress(done, total)` returning false cancels.
pub fn process(
    rec: &Recording,
    stream: &StreamInfo,
    camera: &CameraConfig,
    config: &ProcessConfig,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<ProcessedRecording, RecordingError> {
    let n = stream.messages;
    let frames_err = |message: String| RecordingError::Frames {
        path: rec.path().to_path_buf(),
        message,
    };
    if n == 0 {
        return Err(frames_err(format!("{} has no frames", stream.name)));
    }
    let mut signatures = Vec::with_capacity(n);
    let mut stamps_ns = Vec::with_capacity(n);
    let mut source_size = [0, 0];
    for i in 0..n {
        let f = rec.depth_frame(stream, i, &camera.native)?;
        let size = [f.depth.width, f.depth.height];
        if i == 0 {
            source_size = size;
        } else if size != source_size {
            return Err(frames_err(format!(
                "frame {i} is {}x{} but frame 0 is {}x{}",
                size[0], size[1], source_size[0], source_size[1]
            )));
        }
        let s = resample::to_model(camera, &f.depth)
            .map_err(|m| frames_err(format!("frame {i}: {m}")))?;
        signatures.push(s);
        stamps_ns.push(f.stamp_ns);
        if !progress(i + 1, n) {
            return Err(RecordingError::Cancelled);
        }
    }
    let (reference_frames, stretches) = match config.reference {
        ReferenceChoice::Frame(k) if k < n => (vec![k], Vec::new()),
        ReferenceChoice::Frame(k) => {
            return Err(frames_err(format!(
                "reference frame {k} is beyond the last frame {}",
                n - 1
            )))
        }
        ReferenceChoice::Auto => {
            let quiet = all_quiet_frames(&signatures, config);
            let stretches = quiet_stretches(&signatures, &quiet, config.quiet_frames);
            (spread_picks(quiet, config.quiet_frames), stretches)
        }
    };
    let refs: Vec<&Image> = reference_frames.iter().map(|&k| &signatures[k]).collect();
    let reference = median_image(&refs);
    let reference_of = (stretches.len() >= 2
        && super::drift::largest_drift(&stretches) > super::drift::DRIFT_TOLERANCE_M)
        .then(|| super::drift::local_references(&stretches, &stamps_ns));
    let mut processed = ProcessedRecording {
        stream: stream.name.clone(),
        source_size,
        stamps_ns,
        signatures,
        reference,
        reference_frames,
        stretches,
        reference_of,
        imprints: Vec::new(),
        contact_px: Vec::new(),
        measured_px: Vec::new(),
    };
    let (mut imprints, mut contact_px, mut measured_px) = (Vec::new(), Vec::new(), Vec::new());
    for (k, s) in processed.signatures.iter().enumerate() {
        let r = processed.reference_for(k);
        let y = imprint(&r, s);
        contact_px.push(contact_pixels(&y, config.contact_threshold_m));
        measured_px.push(measured_pixels(&r, s));
        imprints.push(y);
    }
    processed.imprints = imprints;
    processed.contact_px = contact_px;
    processed.measured_px = measured_px;
    Ok(processed)
}

/// Mean of `y` over the (2·radius+1)² window around each pixel, clipped to the image (pixels that are 0 in `y`
/// count as 0), row-major.
pub(crate) fn box_means(y: &Image, radius: usize) -> Vec<f64> {
    let (w, h) = (y.width, y.height);
    // Summed-area table.
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for v in 0..h {
        let mut row = 0.0;
        for u in 0..w {
            row += f64::from(y.get(u, v));
            sat[(v + 1) * (w + 1) + u + 1] = sat[v * (w + 1) + u + 1] + row;
        }
    }
    let mut out = Vec::with_capacity(w * h);
    for v in 0..h {
        let (v0, v1) = (v.saturating_sub(radius), (v + radius + 1).min(h));
        for u in 0..w {
            let (u0, u1) = (u.saturating_sub(radius), (u + radius + 1).min(w));
            let sum = sat[v1 * (w + 1) + u1] - sat[v0 * (w + 1) + u1] - sat[v1 * (w + 1) + u0]
                + sat[v0 * (w + 1) + u0];
            out.push(sum / ((v1 - v0) * (u1 - u0)) as f64);
        }
    }
    out
}

/// Largest mean of `y` over the (2·radius+1)² windows around each pixel.
#[cfg(test)]
fn box_max(y: &Image, radius: usize) -> f64 {
    box_means(y, radius)
        .into_iter()
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Median of `x` (reordered); 0 for an empty slice.
pub(crate) fn median_of(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let m = x.len() / 2;
    let (_, &mut v, _) = x.select_nth_unstable_by(m, f64::total_cmp);
    v
}

/// The noise of a 5 x 5-window mean of the difference of two frames, metres: for each pair of frames one and two
/// apart, the robust spread (1.4826 × median absolute value) of that difference's window means over the windows
/// both frames measure, and the median of those near the least over the pairs. Somewhere in a recording two nearby frames hold the
/// same contact or none (a press held, the rest before it), so a contact, however large, does not inflate it, nor
/// does a short recording whose every consecutive pair spans a press (rest, press, rest: the first and last frames
/// are two apart). `None` with fewer than two frames.
pub fn window_noise(signatures: &[Image]) -> Option<f64> {
    let n = signatures.len();
    let pair = |a: &Image, b: &Image| {
        let means = box_means(&imprint(a, b), 2);
        let mut seen: Vec<f64> = (0..means.len())
            .filter(|&i| a.data[i] > 0.0 && b.data[i] > 0.0)
            .map(|i| means[i].abs())
            .collect();
        (!seen.is_empty()).then(|| 1.4826 * median_of(&mut seen))
    };
    let mut per_pair: Vec<f64> = (0..n.saturating_sub(1))
        .flat_map(|k| [(k, k + 1), (k, k + 2)])
        .filter(|&(_, j)| j < n)
        .filter_map(|(i, j)| pair(&signatures[i], &signatures[j]))
        .collect();
    // The pairs of noise alone cluster near the least (each estimate is within ~10 % of the truth; the least of
    // many is biased low), those spanning a change of contact lie far above: the median of the cluster.
    let least = per_pair.iter().copied().reduce(f64::min)?;
    per_pair.retain(|&e| e <= 2.0 * least);
    Some(median_of(&mut per_pair))
}

/// Whether the imprint `y` of a frame against a no-contact frame shows no contact: its largest 5 x 5-window mean
/// stays under `threshold`, or under five times `window_noise` (what the noise of two frames gives such a mean,
/// [`window_noise`]), so that a noisy sensor's frames without contact are still found.
fn is_quiet(y: &Image, threshold: f64, window_noise: f64) -> bool {
    let max = box_means(y, 2)
        .into_iter()
        .fold(f64::NEG_INFINITY, f64::max);
    max <= threshold.max(5.0 * window_noise)
}

/// Every quiet frame of the recording ([`is_quiet`] against the frame of largest mean depth), in order; that frame
/// alone when none is quiet.
fn all_quiet_frames(signatures: &[Image], config: &ProcessConfig) -> Vec<usize> {
    if signatures.is_empty() {
        return Vec::new();
    }
    let means: Vec<f64> = signatures.iter().map(mean_valid).collect();
    let first = (0..signatures.len())
        .max_by(|&a, &b| means[a].total_cmp(&means[b]))
        .unwrap_or(0);
    let r = &signatures[first];
    let noise = window_noise(signatures).unwrap_or(0.0);
    // Judged on what a drift of the whole membrane cannot explain, so that the no-contact frames of a drifting
    // membrane are still found; the drift is fitted on the membrane's outer part, where contacts seldom are (one
    // at the apex would otherwise pass for a drift).
    let shape = super::drift::profile(r);
    let seen = r.count_nonzero();
    let quiet: Vec<usize> = signatures
        .iter()
        .enumerate()
        // A frame that lost most of its returns is no picture of the membrane (its imprint is mostly filled in).
        .filter(|(_, s)| too_few_returns(measured_pixels(r, s), seen).is_none())
        .filter(|(_, s)| {
            let (rest, _) = super::drift::without_drift(&imprint(r, s), &shape, |i| {
                r.data[i] > 0.0 && s.data[i] > 0.0 && shape[i] < super::drift::OUTER_PROFILE
            });
            is_quiet(&rest, config.quiet_threshold_m, noise)
        })
        .map(|(i, _)| i)
        .collect();
    if quiet.is_empty() {
        vec![first]
    } else {
        quiet
    }
}

/// Up to `k` of `quiet`, evenly spaced over the recording.
fn spread_picks(quiet: Vec<usize>, k: usize) -> Vec<usize> {
    let k = k.max(1);
    if quiet.len() <= k {
        return quiet;
    }
    (0..k)
        .map(|j| quiet[j * (quiet.len() - 1) / (k - 1).max(1)])
        .collect()
}

/// The stretches of no-contact frames ([`super::drift`]): each the median of its last `k` frames, with its drift
/// from the first stretch.
fn quiet_stretches(signatures: &[Image], quiet: &[usize], k: usize) -> Vec<QuietStretch> {
    let mut stretches: Vec<QuietStretch> = super::drift::runs(quiet)
        .into_iter()
        .map(|(first, last)| {
            let start = (last + 1).saturating_sub(k.max(1)).max(first);
            let frames: Vec<usize> = (start..=last).collect();
            let refs: Vec<&Image> = frames.iter().map(|&f| &signatures[f]).collect();
            QuietStretch {
                first,
                last,
                reference: median_image(&refs),
                reference_frames: frames,
                drift_m: 0.0,
            }
        })
        .collect();
    if let Some(first) = stretches.first().map(|s| s.reference.clone()) {
        for s in &mut stretches {
            s.drift_m = super::drift::drift_between(&first, &s.reference);
        }
    }
    stretches
}

/// The frames an automatic reference is made of (see the module docs; a frame is quiet as [`is_quiet`] says).
pub fn quiet_frames(signatures: &[Image], config: &ProcessConfig) -> Vec<usize> {
    spread_picks(all_quiet_frames(signatures, config), config.quiet_frames)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn median_ignores_missing_pixels_and_reference_parses() {
        let a = Image::from_vec(2, 1, vec![1.0, 0.0]).unwrap();
        let b = Image::from_vec(2, 1, vec![3.0, 2.0]).unwrap();
        let c = Image::from_vec(2, 1, vec![2.0, 4.0]).unwrap();
        assert_eq!(median_image(&[&a, &b, &c]).data, vec![2.0, 3.0]);
        assert_eq!("auto".parse::<ReferenceChoice>(), Ok(ReferenceChoice::Auto));
        assert_eq!(
            "7".parse::<ReferenceChoice>(),
            Ok(ReferenceChoice::Frame(7))
        );
        assert!("x".parse::<ReferenceChoice>().is_err());
    }

    #[test]
    fn quiet_frames_are_those_without_contact() {
        // Frames 0, 1, 4 are flat at 90 mm; frames 2, 3 have a 5 mm press over 10 pixels.
        let flat = Image::filled(16, 16, 0.09);
        let mut pressed = flat.clone();
        for d in pressed.data.iter_mut().take(10) {
            *d = 0.085;
        }
        let frames = vec![flat.clone(), flat.clone(), pressed.clone(), pressed, flat];
        let q = quiet_frames(&frames, &ProcessConfig::default());
        assert_eq!(q, vec![0, 1, 4]);
    }

    #[test]
    fn box_max_is_the_largest_window_mean() {
        let mut y = Image::filled(11, 11, 0.0);
        *y.get_mut(5, 5) = 25.0;
        assert!((box_max(&y, 2) - 1.0).abs() < 1e-12);
        // At a corner the window is clipped to the image: 3 x 3 pixels.
        let mut c = Image::filled(7, 7, 0.0);
        *c.get_mut(0, 0) = 9.0;
        assert!((box_max(&c, 2) - 1.0).abs() < 1e-12);
    }
}
