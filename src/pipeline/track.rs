//! # Tracking: the object's pose on every contact frame of a recording
//!
//! [`Tracker::track`] is the De-render and Pose use cases ([`super::derender()`], [`super::place_and_estimate`]) on one
//! frame of a processed recording ([`crate::recording::ProcessedRecording`]): N samples of the in-contact depth, the
//! single-sample estimate, the multi-sample estimate and the threshold baseline, scored against the recorded pose
//! when the recording has one (the estimate never sees it). Each frame has its own seed (`seed + frame`).
//!
//! One tracker keeps one pose engine for all frames (the object is prepared once) and **carries each frame's
//! estimate to the next** ([`TrackingConfig`]): the object does not move while the sensor presses it, so a frame
//! whose contact overlaps the previous one's draws fewer samples with fewer steps, registers from the previous
//! frame's poses (a [`PosePrior`]) plus a few random starts, searches the press near the previous press, and has its
//! posterior reweighed by the previous one ([`crate::pose::fusion`]). A contact's first frame, and every frame with
//! [`TrackingConfig::per_frame`], is estimated from scratch. What a frame hands on ([`Carry`]) is saved beside the
//! track, so a track can stop and resume anywhere and give the same rows.
//!
//! The sensor is placed over the object as [`super::press`] says ([`PressChoice::Auto`] by default: per frame, from the
//! samples and the signature).

use serde::{Deserialize, Serialize};

pub use super::press::PressChoice;
pub use super::tracker::{
    Carry, TrackContext, Tracker, TrackingConfig, DEFAULT_CARRIED_POSES,
    DEFAULT_CARRIED_RANDOM_STARTS, DEFAULT_CARRIED_SAMPLES, DEFAULT_CARRIED_STEPS,
    DEFAULT_MIN_CONTACT_PX, DEFAULT_MIN_OVERLAP,
};
use crate::objects::Symmetry;
use crate::sensor::Se2;
use crate::uncertainty::SampleError;

/// One frame of a track.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameTrack {
    /// Frame number in the recording (0-based).
    pub frame: usize,
    /// Time stamp, nanoseconds.
    pub stamp_ns: u64,
    /// Imprint pixels over the contact threshold.
    pub contact_px: usize,
    /// The press the sensor was placed at, metres (`None`: no sample had contact).
    pub press_m: Option<f64>,
    /// Samples drawn, and how many of them registered.
    pub samples: usize,
    pub registered: usize,
    /// The single-sample estimate `t_world_object` (`None`: no sample had contact).
    pub estimate: Option<Se2>,
    /// The multi-sample estimate (from two samples).
    pub multi_sample: Option<Se2>,
    /// The threshold baseline's pose.
    pub baseline: Option<Se2>,
    /// How far the registered samples' poses spread (from two): RMS distance of their positions from their mean,
    /// mm, and the standard deviation of their θ against the estimate's, degrees (`None`: continuous symmetry).
    /// The paper's uncertainty, one number each: a large spread says the frame's pose is not to be trusted.
    pub spread_mm: Option<f64>,
    pub theta_spread_deg: Option<f64>,
    /// How many distinct poses hold a fair share of the registered samples
    /// ([`crate::uncertainty::UncertaintyReport::major_modes`]): 1 is one pose, 2 or more an ambiguous contact, 0
    /// too few samples to say.
    pub pose_modes: usize,
    /// The recorded pose and press, when the recording (or the pose table) has them for this frame.
    pub recorded: Option<Se2>,
    pub recorded_press_m: Option<f64>,
    /// Errors against the recorded pose ([`Self::score`]): position mm, θ degrees (`None` θ: continuous
    /// symmetry), both reduced by the object's symmetry as `tnd eval` does.
    pub estimate_error: Option<(f64, Option<f64>)>,
    pub multi_sample_error: Option<(f64, Option<f64>)>,
    pub baseline_error: Option<(f64, Option<f64>)>,
    /// Modes of the pose posterior ([`crate::pose::posterior`]; 0: none), the weight of the one holding the
    /// estimate, and the posterior's covariance about the estimate over (x m, y m, θ rad)
    /// ([`crate::pose::export::covariance_about`]), as a `PoseWithCovariance` takes it.
    pub posterior_modes: usize,
    pub estimate_weight: Option<f64>,
    pub covariance: Option<crate::pose::posterior::Mat3>,
    /// The frame carried the previous frame's estimate forward ([`Tracker`]: fewer samples, registrations from
    /// its poses, the press searched near its press); `false`: estimated from scratch.
    pub carried: bool,
    /// The probability mass of the posterior's smallest region holding the recorded pose
    /// ([`crate::pose::posterior::PosePosterior::region_mass`], as `tnd eval`'s `truth_region`): the recorded pose is
    /// inside the track's p region when this is ≤ p. `None` without a recorded pose or a posterior, and for rows read
    /// back from a track and scored against other poses than before (the posterior is not in the CSV).
    pub truth_region: Option<f64>,
    /// Half-widths of the central intervals about the estimate's mode holding 68 % of it — x, y (metres), θ
    /// (radians; [`crate::pose::posterior::PosePosterior::estimate_half_widths`]): the covariance's spread read as
    /// a Gaussian's ±σ, which heavy tails make far narrower than the standard deviation.
    #[serde(default)]
    pub half_width_68: Option<[f64; 3]>,
    /// The frame's pose posterior while the row is in memory (for [`Self::score`]; not in the CSV: a track keeps it
    /// in [`super::track_posteriors::TrackPosteriors`]).
    #[serde(skip)]
    pub posterior: Option<crate::pose::posterior::PosePosterior>,
    /// The earlier frame whose posterior reweighed this one's ([`crate::pose::fusion`]; `None`: the frame's own).
    #[serde(skip)]
    pub fused_with: Option<usize>,
}

/// Columns of [`FrameTrack::csv_row`].
const CSV_COLUMNS: [&str; 41] = [
    "frame",
    "stamp_ns",
    "contact_px",
    "press_m",
    "samples",
    "registered",
    "x",
    "y",
    "theta",
    "multi_x",
    "multi_y",
    "multi_theta",
    "baseline_x",
    "baseline_y",
    "baseline_theta",
    "spread_mm",
    "theta_spread_deg",
    "pose_modes",
    "recorded_x",
    "recorded_y",
    "recorded_theta",
    "recorded_press_m",
    "position_err_mm",
    "theta_err_deg",
    "multi_position_err_mm",
    "multi_theta_err_deg",
    "baseline_position_err_mm",
    "baseline_theta_err_deg",
    "posterior_modes",
    "estimate_weight",
    "cov_xx",
    "cov_xy",
    "cov_xtheta",
    "cov_yy",
    "cov_ytheta",
    "cov_thetatheta",
    "carried",
    "truth_region",
    "half_x_68",
    "half_y_68",
    "half_theta_68",
];

/// Columns of a track written before the posterior's (read back with none).
const CSV_COLUMNS_V1: usize = 28;
/// Columns of a track written before tracks carried estimates (every row from scratch).
const CSV_COLUMNS_V2: usize = 36;
/// Columns of a track written before the truth's region (read back with none).
const CSV_COLUMNS_V3: usize = 37;
/// Columns of a track written before the half-widths (read back with none).
const CSV_COLUMNS_V4: usize = 38;

impl FrameTrack {
    /// A frame with nothing estimated yet.
    pub fn new(frame: usize, stamp_ns: u64, contact_px: usize, samples: usize) -> Self {
        Self {
            frame,
            stamp_ns,
            contact_px,
            press_m: None,
            samples,
            registered: 0,
            estimate: None,
            multi_sample: None,
            baseline: None,
            spread_mm: None,
            theta_spread_deg: None,
            pose_modes: 0,
            recorded: None,
            recorded_press_m: None,
            estimate_error: None,
            multi_sample_error: None,
            baseline_error: None,
            posterior_modes: 0,
            estimate_weight: None,
            covariance: None,
            carried: false,
            truth_region: None,
            half_width_68: None,
            posterior: None,
            fused_with: None,
        }
    }

    /// The CSV header of [`Self::csv_row`].
    pub fn csv_header() -> String {
        CSV_COLUMNS.join(",")
    }

    /// `rows` as a CSV table (what `tnd recording track` writes as track.csv).
    pub fn csv(rows: &[FrameTrack]) -> String {
        let mut text = format!("{}\n", Self::csv_header());
        for r in rows {
            text.push_str(&r.csv_row());
            text.push('\n');
        }
        text
    }

    /// The frame as one CSV row (metres, radians; spreads and errors in mm and degrees; empty where unknown). Numbers
    /// are written so that [`Self::from_csv_row`] reads them back exactly.
    pub fn csv_row(&self) -> String {
        let num = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
        let pose = |p: Option<Se2>| match p {
            Some(p) => format!("{},{},{}", p.x, p.y, p.theta),
            None => ",,".into(),
        };
        let err = |e: Option<(f64, Option<f64>)>| match e {
            Some((mm, deg)) => format!("{mm},{}", num(deg)),
            None => ",".into(),
        };
        [
            self.frame.to_string(),
            self.stamp_ns.to_string(),
            self.contact_px.to_string(),
            num(self.press_m),
            self.samples.to_string(),
            self.registered.to_string(),
            pose(self.estimate),
            pose(self.multi_sample),
            pose(self.baseline),
            num(self.spread_mm),
            num(self.theta_spread_deg),
            self.pose_modes.to_string(),
            pose(self.recorded),
            num(self.recorded_press_m),
            err(self.estimate_error),
            err(self.multi_sample_error),
            err(self.baseline_error),
            self.posterior_modes.to_string(),
            num(self.estimate_weight),
            match self.covariance {
                Some(c) => [c[0][0], c[0][1], c[0][2], c[1][1], c[1][2], c[2][2]]
                    .map(|v| v.to_string())
                    .join(","),
                None => ",,,,,".into(),
            },
            u8::from(self.carried).to_string(),
            num(self.truth_region),
            match self.half_width_68 {
                Some(h) => h.map(|v| v.to_string()).join(","),
                None => ",,".into(),
            },
        ]
        .join(",")
    }

    /// Read a row written by [`Self::csv_row`].
    pub fn from_csv_row(line: &str) -> Result<Self, crate::error::InvalidInput> {
        crate::error::InvalidInput::wrap("track.csv row", || {
            let cells: Vec<&str> = line.split(',').collect();
            let mut cells = cells;
            if cells.len() == CSV_COLUMNS_V1 {
                // A track of an earlier version: no posterior.
                cells.extend(["0", "", "", "", "", "", "", ""]);
            }
            if cells.len() == CSV_COLUMNS_V2 {
                cells.push("0");
            }
            if cells.len() == CSV_COLUMNS_V3 {
                cells.push("");
            }
            if cells.len() == CSV_COLUMNS_V4 {
                cells.extend(["", "", ""]);
            }
            if cells.len() != CSV_COLUMNS.len() {
                return Err(format!(
                    "{} columns, a track row has {}",
                    cells.len(),
                    CSV_COLUMNS.len()
                ));
            }
            let num = |k: usize| -> Result<Option<f64>, String> {
                match cells[k] {
                    "" => Ok(None),
                    c => c
                        .parse::<f64>()
                        .map(Some)
                        .map_err(|_| format!("{} '{c}' is not a number", CSV_COLUMNS[k])),
                }
            };
            let int = |k: usize| -> Result<u64, String> {
                cells[k]
                    .parse::<u64>()
                    .map_err(|_| format!("{} '{}' is not a whole number", CSV_COLUMNS[k], cells[k]))
            };
            let pose = |k: usize| -> Result<Option<Se2>, String> {
                Ok(match (num(k)?, num(k + 1)?, num(k + 2)?) {
                    (Some(x), Some(y), Some(t)) => Some(Se2::new(x, y, t)),
                    _ => None,
                })
            };
            let err = |k: usize| -> Result<Option<(f64, Option<f64>)>, String> {
                Ok(num(k)?.map(|mm| (mm, num(k + 1).ok().flatten())))
            };
            Ok(Self {
                frame: int(0)? as usize,
                stamp_ns: int(1)?,
                contact_px: int(2)? as usize,
                press_m: num(3)?,
                samples: int(4)? as usize,
                registered: int(5)? as usize,
                estimate: pose(6)?,
                multi_sample: pose(9)?,
                baseline: pose(12)?,
                spread_mm: num(15)?,
                theta_spread_deg: num(16)?,
                pose_modes: int(17)? as usize,
                recorded: pose(18)?,
                recorded_press_m: num(21)?,
                estimate_error: err(22)?,
                multi_sample_error: err(24)?,
                baseline_error: err(26)?,
                posterior_modes: int(28)? as usize,
                estimate_weight: num(29)?,
                covariance: match [30, 31, 32, 33, 34, 35].map(num) {
                    [Ok(Some(xx)), Ok(Some(xy)), Ok(Some(xt)), Ok(Some(yy)), Ok(Some(yt)), Ok(Some(tt))] => {
                        Some([[xx, xy, xt], [xy, yy, yt], [xt, yt, tt]])
                    }
                    _ => None,
                },
                carried: match cells[36] {
                    "0" => false,
                    "1" => true,
                    c => return Err(format!("carried '{c}' is neither 0 nor 1")),
                },
                truth_region: num(37)?,
                half_width_68: match [38, 39, 40].map(num) {
                    [Ok(Some(x)), Ok(Some(y)), Ok(Some(t))] => Some([x, y, t]),
                    _ => None,
                },
                posterior: None,
                fused_with: None,
            })
        })
    }

    /// Score the estimates against the recorded pose and press of the frame (none: no errors), for an object with
    /// `symmetry`.
    pub fn score(&mut self, recorded: Option<(Se2, Option<f64>)>, symmetry: &Symmetry) {
        let pose = recorded.map(|r| r.0);
        // Against the pose it was scored with, a row keeps its region (a row read back from track.csv has no
        // posterior to compute it again, and a row in memory need not: the integral is 4 000 draws).
        if pose != self.recorded || self.truth_region.is_none() {
            self.truth_region = self.posterior.as_ref().zip(pose).and_then(|(p, t)| {
                p.region_mass(t, symmetry, crate::metrics::evaluate::REGION_DRAWS)
            });
        }
        self.recorded = pose;
        self.recorded_press_m = recorded.and_then(|r| r.1);
        let error = |pose: Option<Se2>| {
            pose.zip(self.recorded).map(|(p, r)| {
                let e = SampleError::new(p, 0.0, r, symmetry);
                (e.position_mm, e.theta_deg)
            })
        };
        self.estimate_error = error(self.estimate);
        self.multi_sample_error = error(self.multi_sample);
        self.baseline_error = error(self.baseline);
    }
}

/// RMS distance of `poses` from their mean position, mm (from two poses).
pub(super) fn position_spread_mm(poses: &[Se2]) -> Option<f64> {
    if poses.len() < 2 {
        return None;
    }
    let n = poses.len() as f64;
    let (mx, my) = (
        poses.iter().map(|p| p.x).sum::<f64>() / n,
        poses.iter().map(|p| p.y).sum::<f64>() / n,
    );
    let ms = poses
        .iter()
        .map(|p| (p.x - mx).powi(2) + (p.y - my).powi(2))
        .sum::<f64>()
        / n;
    Some(ms.sqrt() * 1e3)
}

/// Standard deviation of `values` (from two).
pub(super) fn std_dev(values: &[f64]) -> Option<f64> {
    if values.len() < 2 {
        return None;
    }
    let n = values.len() as f64;
    let m = values.iter().sum::<f64>() / n;
    Some((values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_rows_have_the_header_s_columns_and_read_back_exactly() {
        let columns = FrameTrack::csv_header().split(',').count();
        // A row as an earlier version wrote it: the first `columns` cells.
        let written_before = |row: &FrameTrack, columns: usize| {
            row.csv_row()
                .split(',')
                .take(columns)
                .collect::<Vec<_>>()
                .join(",")
        };
        let mut row = FrameTrack::new(3, 100, 40, 2);
        assert_eq!(row.csv_row().split(',').count(), columns);
        assert_eq!(FrameTrack::from_csv_row(&row.csv_row()), Ok(row.clone()));
        row.press_m = Some(0.004);
        row.estimate = Some(Se2::new(0.001, 0.002, 0.3));
        row.baseline = Some(Se2::new(1.0 / 3.0, -0.002, -2.9));
        row.spread_mm = Some(0.25);
        row.score(
            Some((Se2::new(0.0, 0.0, 0.0), Some(0.005))),
            &Symmetry::default(),
        );
        let cells: Vec<String> = row.csv_row().split(',').map(String::from).collect();
        assert_eq!(cells.len(), columns);
        assert_eq!(cells[6..9], ["0.001", "0.002", "0.3"]);
        // Independent truth: |(1, 2)| mm and 0.3 rad in degrees.
        let (mm, deg) = row.estimate_error.unwrap();
        assert!(
            (mm - 5f64.sqrt()).abs() < 1e-9 && (deg.unwrap() - 0.3f64.to_degrees()).abs() < 1e-9
        );
        assert_eq!(row.multi_sample_error, None);
        row.posterior_modes = 2;
        row.estimate_weight = Some(0.75);
        row.covariance = Some([[1e-6, 2e-7, 3e-5], [2e-7, 4e-6, -1e-5], [3e-5, -1e-5, 0.01]]);
        assert_eq!(FrameTrack::from_csv_row(&row.csv_row()), Ok(row.clone()));
        row.carried = true;
        assert_eq!(FrameTrack::from_csv_row(&row.csv_row()), Ok(row.clone()));
        row.truth_region = Some(0.4375);
        assert_eq!(FrameTrack::from_csv_row(&row.csv_row()), Ok(row.clone()));
        row.half_width_68 = Some([1.0 / 3.0 * 1e-3, 2e-4, 0.0123]);
        assert_eq!(FrameTrack::from_csv_row(&row.csv_row()), Ok(row.clone()));
        // A row of a track written before the half-widths reads back without them.
        let v4 = written_before(&row, 38);
        let read = FrameTrack::from_csv_row(&v4).unwrap();
        assert_eq!(
            (read.half_width_68, read.truth_region),
            (None, Some(0.4375))
        );
        row.half_width_68 = None;
        // A row of a track written before the truth's region reads back without one.
        let v3 = written_before(&row, 37);
        assert_eq!(FrameTrack::from_csv_row(&v3).unwrap().truth_region, None);
        row.truth_region = None;
        // A row of a track written before carried frames reads back as estimated from scratch.
        let v2 = written_before(&row, 36);
        let read = FrameTrack::from_csv_row(&v2).unwrap();
        assert!(!read.carried);
        assert_eq!(read.covariance, row.covariance);
        // A row of a track written before the posterior's columns reads back without one.
        let old = written_before(&row, 28);
        let read = FrameTrack::from_csv_row(&old).unwrap();
        assert_eq!((read.posterior_modes, read.covariance), (0, None));
        assert_eq!(read.estimate, row.estimate);
        assert!(FrameTrack::from_csv_row("1,2,3")
            .unwrap_err()
            .message
            .contains("3 columns"));
    }

    #[test]
    fn the_truths_region_comes_from_the_frames_posterior_and_survives_the_csv() {
        use crate::pose::posterior::{PosePosterior, PosteriorMode};
        let symmetry = Symmetry::default();
        let sigma: f64 = 0.001;
        let mode = PosteriorMode {
            weight: 1.0,
            mean: [0.0, 0.0, 0.0],
            cov: [
                [sigma * sigma, 0.0, 0.0],
                [0.0, sigma * sigma, 0.0],
                [0.0, 0.0, 0.01],
            ],
            nats: 0.0,
            hessian: [[0.0; 3]; 3],
            tails: Default::default(),
        };
        let mut row = FrameTrack::new(5, 0, 100, 2);
        row.estimate = Some(Se2::new(0.0, 0.0, 0.0));
        row.posterior = Some(PosePosterior {
            modes: vec![mode],
            contact_px: 100,
            predicted_contact_px: None,
            noise: None,
            distinct_nats: Vec::new(),
        });
        // Independent truth: for one Gaussian the region through a pose at Mahalanobis distance d holds
        // P(chi²₃ ≤ d²); at (1.5 σ, 0, 0) that is erf(1.5/√2) − √(2/π)·1.5·e^(−1.125) = 0.1912.
        let truth = Se2::new(1.5 * sigma, 0.0, 0.0);
        row.score(Some((truth, None)), &symmetry);
        let d: f64 = 1.5;
        let chi2 =
            erf(d / 2f64.sqrt()) - (2.0 / std::f64::consts::PI).sqrt() * d * (-d * d / 2.0).exp();
        let region = row.truth_region.unwrap();
        assert!((region - chi2).abs() < 0.02, "{region} against {chi2}");
        // Read back from the CSV (no posterior): the same pose keeps the region, another one has none.
        let mut read = FrameTrack::from_csv_row(&row.csv_row()).unwrap();
        read.score(Some((truth, None)), &symmetry);
        assert_eq!(read.truth_region, Some(region));
        read.score(Some((Se2::new(0.0, 0.0, 0.0), None)), &symmetry);
        assert_eq!(read.truth_region, None);
        row.score(None, &symmetry);
        assert_eq!(row.truth_region, None);
    }

    /// erf by Abramowitz and Stegun 7.1.26 (|error| < 1.5e-7): an independent reference for the test above.
    fn erf(x: f64) -> f64 {
        let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
        let poly = t
            * (0.254_829_592
                + t * (-0.284_496_736
                    + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
        let y = 1.0 - poly * (-x * x).exp();
        if x >= 0.0 {
            y
        } else {
            -y
        }
    }

    #[test]
    fn spreads_are_rms_distances_and_standard_deviations() {
        let poses = [Se2::new(0.001, 0.0, 0.0), Se2::new(-0.001, 0.0, 0.0)];
        assert!((position_spread_mm(&poses).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(position_spread_mm(&poses[..1]), None);
        assert!((std_dev(&[1.0, 3.0]).unwrap() - 1.0).abs() < 1e-12);
    }
}
