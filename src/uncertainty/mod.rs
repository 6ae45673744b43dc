//! **Uncertainty** of the pose estimate (paper V.D, last paragraph): for one tactile signature, N samples of the
//! in-contact depth from the model (default 50), each registered from one fixed initialisation; the distribution of
//! their position and θ errors as Gaussian KDEs ([`kde`], Scott's rule), with the baseline's errors as points;
//! exported as CSV and a figure in SVG and PNG ([`figure`]).
//!
//! Errors are taken against a reference pose: the true pose when it is known (evaluation), otherwise the estimate
//! of the first sample's K-start registration (then they measure the spread of the estimates). The position error is
//! [`crate::metrics::pose::position_error_m`] (mm, translation axis excluded); the θ error is signed, wrapped to
//! (−P/2, P/2] with P the symmetry period, in degrees, and absent for continuous symmetry.

pub mod analysis;
pub mod figure;
pub mod kde;
pub mod rose;

pub use kde::{GaussianKde, KdeError};

use std::fmt::Write as _;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::io::figure::{write_figure, FigureConfig};
use crate::metrics::pose::position_error_m;
use crate::objects::Symmetry;
use crate::sensor::Se2;

/// Errors writing the uncertainty outputs.
#[derive(Debug, thiserror::Error)]
pub enum UncertaintyError {
    #[error("{path}: cannot write: {source}")]
    Write {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Figure(#[from] crate::io::figure::FigureError),
}

/// One registered estimate and its errors.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SampleError {
    /// Estimated pose `t_world_object`.
    pub pose: Se2,
    /// Registration cost.
    #[serde(deserialize_with = "crate::io::null_as_nan")]
    pub cost: f64,
    /// Position error, mm.
    pub position_mm: f64,
    /// Signed θ error, degrees (`None`: continuous symmetry).
    pub theta_deg: Option<f64>,
}

impl SampleError {
    /// Errors of `pose` against `reference` for an object with `symmetry`.
    pub fn new(pose: Se2, cost: f64, reference: Se2, symmetry: &Symmetry) -> Self {
        let theta_deg = symmetry.rotation.period_rad().map(|p| {
            let e = (pose.theta - reference.theta).rem_euclid(p);
            (if e > p / 2.0 { e - p } else { e }).to_degrees()
        });
        Self {
            pose,
            cost,
            position_mm: position_error_m(pose, reference, symmetry) * 1e3,
            theta_deg,
        }
    }
}

pub use crate::pose::{MODE_POSITION_MM, MODE_THETA_DEG};

/// One of the distinct poses the samples of a signature register to.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseMode {
    /// The pose of its lowest-cost sample.
    pub pose: Se2,
    /// How many samples registered to it.
    pub samples: usize,
}

impl PoseMode {
    /// "5 samples at x -0.4 mm, y 1.3 mm, θ -168°" (millimetres and degrees, for people).
    pub fn describe(&self) -> String {
        format!(
            "{} samples at x {:.1} mm, y {:.1} mm, θ {:.0}°",
            self.samples,
            self.pose.x * 1e3,
            self.pose.y * 1e3,
            self.pose.theta.to_degrees()
        )
    }
}

pub use crate::pose::posterior::same_pose;

/// The distinct poses among `samples` for an object with `symmetry`: each sample, lowest registration cost first,
/// joins the first mode within [`MODE_POSITION_MM`] and [`MODE_THETA_DEG`] of its pose, or starts a new one; most
/// samples first.
pub fn pose_modes(samples: &[SampleError], symmetry: &Symmetry) -> Vec<PoseMode> {
    let mut order: Vec<&SampleError> = samples.iter().collect();
    order.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    let mut modes: Vec<PoseMode> = Vec::new();
    for s in order {
        match modes
            .iter_mut()
            .find(|m| same_pose(s.pose, m.pose, symmetry))
        {
            Some(m) => m.samples += 1,
            None => modes.push(PoseMode {
                pose: s.pose,
                samples: 1,
            }),
        }
    }
    // Stable: equal counts keep the lower-cost mode first.
    modes.sort_by_key(|m| std::cmp::Reverse(m.samples));
    modes
}

/// A registration of the analysis that failed (the others stand).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FailedRegistration {
    /// What was registered: `sample 3`, `baseline` or `multi-sample estimate`.
    pub what: String,
    /// The error, said once.
    pub reason: String,
}

/// The analysis of one signature: sample errors, the baseline's, and the KDE curves.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UncertaintyReport {
    /// Reference pose the errors are measured against.
    pub reference: Se2,
    /// Whether `reference` is the true pose.
    pub reference_is_truth: bool,
    /// The fixed initialisation every sample was registered from.
    pub init: Se2,
    /// One entry per model sample.
    pub samples: Vec<SampleError>,
    /// The threshold baseline's estimate, if it had contact.
    pub baseline: Option<SampleError>,
    /// The multi-sample estimate (the samples' consensus contact registered from K random starts), with two or
    /// more samples whose consensus has contact.
    #[serde(default)]
    pub multi_sample: Option<SampleError>,
    /// The signature check's posterior behind the multi-sample estimate (its pooled hypotheses), when the check ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub multi_sample_posterior: Option<crate::pose::posterior::PosePosterior>,
    /// The pose reported for the signature (`tnd pose`'s estimate, the Pose tab's single-sample fit): the first
    /// sample's K-start registration after the signature check. Set by [`crate::pipeline::estimate_pose`]; cost NaN
    /// where the check refined the pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<SampleError>,
    /// Registrations that failed; the rest of the report stands without them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub failed: Vec<FailedRegistration>,
    /// The distinct poses the registered samples fall into ([`pose_modes`]), most samples first; two or more with
    /// a fair share of the samples each say the contact is ambiguous ([`Self::ambiguous`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub modes: Vec<PoseMode>,
    /// KDE of the position errors, `(mm, density)`; empty when it cannot be fitted (fewer than 2 distinct values).
    pub position_kde: Vec<(f64, f64)>,
    /// KDE of the θ errors, `(deg, density)`; empty when it cannot be fitted or θ is excluded.
    pub theta_kde: Vec<(f64, f64)>,
    /// The object's symmetry period the θ errors are wrapped to, degrees (360 for none; `None`: continuous symmetry,
    /// or a report written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta_period_deg: Option<f64>,
}

/// A KDE curve of `values` on `points` evenly spaced points spanning the values ± 3 bandwidths; empty when no KDE
/// can be fitted.
pub fn kde_curve(values: &[f64], points: usize) -> Vec<(f64, f64)> {
    kde_curve_bounded(values, points, None)
}

/// [`kde_curve`] for values that cannot fall below `lower` (a distance cannot be negative): the kernel mass
/// beyond the bound is reflected back inside it (the density stays normalised over the support), and the curve
/// starts at the bound.
pub fn kde_curve_bounded(values: &[f64], points: usize, lower: Option<f64>) -> Vec<(f64, f64)> {
    let Ok(kde) = GaussianKde::scott_1d(values) else {
        return Vec::new();
    };
    let bw = kde.bandwidth();
    let mut lo = values.iter().copied().fold(f64::INFINITY, f64::min) - 3.0 * bw;
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max) + 3.0 * bw;
    if let Some(b) = lower {
        lo = lo.max(b);
    }
    let n = points.max(2);
    (0..n)
        .map(|i| {
            let x = lo + (hi - lo) * i as f64 / (n - 1) as f64;
            let reflected = lower.map_or(0.0, |b| kde.density(&[2.0 * b - x]));
            (x, kde.density(&[x]) + reflected)
        })
        .collect()
}

impl UncertaintyReport {
    /// The modes holding at least a quarter of the registered samples (and two of them): more than one says the
    /// samples are split between poses the contact cannot tell apart (a flat face that fits either way round, a
    /// part's two similar ends), so no single estimate is to be trusted.
    pub fn major_modes(&self) -> Vec<PoseMode> {
        let n = self.samples.len();
        self.modes
            .iter()
            .filter(|m| m.samples >= 2 && 4 * m.samples >= n)
            .copied()
            .collect()
    }

    /// More than one major mode ([`Self::major_modes`]).
    pub fn ambiguous(&self) -> bool {
        self.major_modes().len() > 1
    }

    /// Build the report and fit the KDEs (200 points per curve).
    pub fn new(
        reference: Se2,
        reference_is_truth: bool,
        init: Se2,
        samples: Vec<SampleError>,
        baseline: Option<SampleError>,
    ) -> Self {
        let pos: Vec<f64> = samples.iter().map(|s| s.position_mm).collect();
        let theta: Vec<f64> = samples.iter().filter_map(|s| s.theta_deg).collect();
        Self {
            reference,
            reference_is_truth,
            init,
            position_kde: kde_curve_bounded(&pos, 200, Some(0.0)),
            theta_kde: kde_curve(&theta, 200),
            samples,
            baseline,
            multi_sample: None,
            multi_sample_posterior: None,
            estimate: None,
            failed: Vec::new(),
            modes: Vec::new(),
            theta_period_deg: None,
        }
    }

    /// `samples.csv` text: one row per sample, one each for the baseline, the multi-sample estimate and the
    /// estimate reported (kinds `sample`, `baseline`, `multi_sample`, `estimate`).
    pub fn samples_csv(&self) -> String {
        let mut s =
            String::from("kind,index,x_m,y_m,theta_rad,cost,position_err_mm,theta_err_deg\n");
        let row = |s: &mut String, kind: &str, i: usize, e: &SampleError| {
            let theta = e.theta_deg.map(|t| t.to_string()).unwrap_or_default();
            let _ = writeln!(
                s,
                "{kind},{i},{},{},{},{},{},{theta}",
                e.pose.x, e.pose.y, e.pose.theta, e.cost, e.position_mm
            );
        };
        for (i, e) in self.samples.iter().enumerate() {
            row(&mut s, "sample", i, e);
        }
        if let Some(b) = &self.baseline {
            row(&mut s, "baseline", 0, b);
        }
        if let Some(m) = &self.multi_sample {
            row(&mut s, "multi_sample", 0, m);
        }
        if let Some(e) = &self.estimate {
            row(&mut s, "estimate", 0, e);
        }
        s
    }

    /// `kde.csv` text: `variable,value,density`.
    pub fn kde_csv(&self) -> String {
        let mut s = String::from("variable,value,density\n");
        for (name, curve) in [
            ("position_err_mm", &self.position_kde),
            ("theta_err_deg", &self.theta_kde),
        ] {
            for (x, d) in curve {
                let _ = writeln!(s, "{name},{x},{d}");
            }
        }
        s
    }

    /// Write `samples.csv`, `kde.csv` and the KDE figure (`uncertainty.svg`, `uncertainty.png`) into `dir`
    /// (atomically), the figure at the default size.
    pub fn write(&self, dir: &Path) -> Result<(), UncertaintyError> {
        self.write_with(dir, &FigureConfig::default())
    }

    /// [`Self::write`] with the figure at `figure`'s size.
    pub fn write_with(&self, dir: &Path, figure: &FigureConfig) -> Result<(), UncertaintyError> {
        let err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| UncertaintyError::Write { path, source }
        };
        std::fs::create_dir_all(dir).map_err(err(dir))?;
        let p = dir.join("samples.csv");
        crate::io::write_atomic(&p, self.samples_csv().as_bytes()).map_err(err(&p))?;
        let p = dir.join("kde.csv");
        crate::io::write_atomic(&p, self.kde_csv().as_bytes()).map_err(err(&p))?;
        write_figure(
            dir,
            "uncertainty",
            figure,
            &figure::KdeFigure { report: self },
        )?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::RotationSymmetry;

    #[test]
    fn samples_split_between_two_poses_make_two_modes() {
        // Independent truth: 6 samples near (0, 0, 0) and 4 near (6 mm, 0, π) — a part that fits either way round —
        // and one stray: three modes, the first two major, so the report is ambiguous. For a cross (4-fold) a turn by
        // π/2 is the same pose.
        let at = |x: f64, theta: f64, cost: f64| SampleError {
            pose: Se2::new(x, 0.0002 * cost, theta),
            cost,
            position_mm: 0.0,
            theta_deg: Some(0.0),
        };
        let mut samples: Vec<SampleError> =
            (0..6).map(|k| at(0.0, 0.01 * k as f64, k as f64)).collect();
        samples.extend((0..4).map(|k| at(0.006, std::f64::consts::PI, 0.5 + k as f64)));
        samples.push(at(0.02, 1.0, 9.0));
        let none = Symmetry::default();
        let modes = pose_modes(&samples, &none);
        assert_eq!(
            modes.iter().map(|m| m.samples).collect::<Vec<_>>(),
            [6, 4, 1]
        );
        assert_eq!(modes[1].pose.x, 0.006);
        let mut r =
            UncertaintyReport::new(Se2::default(), true, Se2::default(), samples.clone(), None);
        r.modes = modes;
        assert!(r.ambiguous());
        assert_eq!(r.major_modes().len(), 2);
        // A turn by π/2 of a 4-fold symmetric object is no other pose.
        let cross = crate::objects::ObjectSet::builtin()
            .find("cross_w12_s50")
            .unwrap()
            .symmetry;
        let turned = [at(0.0, 0.0, 0.0), at(0.0, std::f64::consts::FRAC_PI_2, 1.0)];
        assert_eq!(pose_modes(&turned, &cross).len(), 1);
        assert_eq!(pose_modes(&turned, &none).len(), 2);
    }

    #[test]
    fn sample_errors_are_signed_and_wrapped() {
        let sym = Symmetry {
            rotation: RotationSymmetry::NFold(4),
            translation_axis: None,
        };
        let e = SampleError::new(
            Se2::new(0.003, 0.004, 1.6),
            0.0,
            Se2::new(0.0, 0.0, 0.0),
            &sym,
        );
        assert!((e.position_mm - 5.0).abs() < 1e-9);
        // 1.6 rad mod pi/2 = 0.0292 rad.
        assert!(
            (e.theta_deg.unwrap() - (1.6 - std::f64::consts::FRAC_PI_2).to_degrees()).abs() < 1e-9
        );
        let e = SampleError::new(
            Se2::new(0.0, 0.0, -0.1),
            0.0,
            Se2::default(),
            &Symmetry::default(),
        );
        assert!((e.theta_deg.unwrap() + 0.1f64.to_degrees()).abs() < 1e-9);
    }

    #[test]
    fn report_writes_csv_and_png() {
        let samples: Vec<SampleError> = (0..20)
            .map(|i| {
                let x = 0.0002 * f64::from(i % 7);
                SampleError::new(
                    Se2::new(x, 0.0, 0.01 * f64::from(i % 5)),
                    0.0,
                    Se2::default(),
                    &Symmetry::default(),
                )
            })
            .collect();
        let base = SampleError::new(
            Se2::new(0.002, 0.0, 0.1),
            0.0,
            Se2::default(),
            &Symmetry::default(),
        );
        let r = UncertaintyReport::new(Se2::default(), true, Se2::default(), samples, Some(base));
        assert_eq!(r.position_kde.len(), 200);
        let area: f64 = r
            .position_kde
            .windows(2)
            .map(|w| (w[1].0 - w[0].0) * w[0].1)
            .sum();
        assert!((area - 1.0).abs() < 0.01, "{area}");
        // A distance cannot be negative: the curve starts at 0, its mass reflected inside.
        assert_eq!(r.position_kde[0].0, 0.0);
        assert!(r.position_kde.iter().all(|&(x, _)| x >= 0.0));
        let dir = tempfile::tempdir().unwrap();
        r.write(dir.path()).unwrap();
        let csv = std::fs::read_to_string(dir.path().join("samples.csv")).unwrap();
        assert_eq!(csv.lines().count(), 22);
        assert!(csv.lines().last().unwrap().starts_with("baseline,0,0.002"));
        let png = image::open(dir.path().join("uncertainty.png")).unwrap();
        assert_eq!((png.width(), png.height()), (2400, 1000));
        let svg = std::fs::read_to_string(dir.path().join("uncertainty.svg")).unwrap();
        for text in [
            "position error",
            "[mm]",
            "density",
            "threshold baseline",
            "KDE of 20 samples",
        ] {
            assert!(svg.contains(text), "no '{text}' in the SVG");
        }
    }
}
