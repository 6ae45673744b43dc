//! **Pose posterior**: what the measured signature says about the pose, as weighted Gaussian modes in (x, y, θ).
//!
//! The signature check ([`super::signature_check`]) refines the registration's hypotheses to the poses that explain
//! the measured signature best; distinct ones are distinct explanations. Each becomes a mode:
//!
//! * **weight** ∝ exp(−Δ / τ): Δ is how much worse (nats, the sensor's Gaussian noise with independent pixels) the
//!   mode explains the signature than the best one, τ the [`PosteriorConfig::temperature`]. Neighbouring pixels of a
//!   tactile signature are far from independent (the shadow cloak, the membrane, the model's own errors), so the
//!   raw likelihood is overconfident by orders of magnitude; τ tempers it and is fitted on validation data.
//! * **covariance**: the Laplace approximation τ·H⁻¹ with H the Hessian of the negative log-likelihood at the mode
//!   (central differences of the check's cost), its flat directions capped at [`PosteriorConfig::max_sigma_m`], plus
//!   a floor ([`PosteriorConfig::floor_position_m`], [`PosteriorConfig::floor_theta_rad`]) for the error the
//!   curvature cannot see (a sensor unlike its model, a contact the sample got wrong).
//!
//! Poses are `t_world_object` (metres, radians); θ is circular and taken modulo the object's symmetry period, the
//! position along a translation axis is not identifiable and left out of region tests ([`reduced_difference`]).
//! [`PosePosterior::region_mass`] gives the probability mass of the highest-density region that just reaches a
//! pose: the truth lies inside the reported p region when it is ≤ p.

use std::path::Path;

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::register::wrap_angle;
use crate::error::InvalidInput;
use crate::objects::Symmetry;
use crate::sensor::Se2;

/// A 3x3 matrix, row-major, over (x m, y m, θ rad).
pub type Mat3 = [[f64; 3]; 3];

/// How the check's likelihood becomes a calibrated posterior (module docs). The defaults were fitted
/// (`tnd posterior --fit`) to the bundled model's records on 42 real meshes pressed by three off-nominal sensors and
/// checked on five others (`docs/uncertainty.md`): the truth inside the 90 % region in 94 % of those pairs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PosteriorConfig {
    /// τ: the log-likelihood is divided by this (≥ 1; 1 trusts every pixel as independent).
    pub temperature: f64,
    /// Standard deviation added to every mode's x and y, metres.
    pub floor_position_m: f64,
    /// Standard deviation added to every mode's θ, radians.
    pub floor_theta_rad: f64,
    /// The floors hold for a contact of this many pixels (the signature's pixels in front of the membrane by more
    /// than `contact_threshold_m`); they scale by (this / contact pixels)^`floor_exponent`, so that a small contact,
    /// which says less about the pose, gets wider regions.
    pub floor_contact_px: f64,
    /// See `floor_contact_px` (0: the same floors for every contact).
    pub floor_exponent: f64,
    /// Depth in front of the membrane that counts as contact for `floor_contact_px`, metres (the threshold
    /// baseline's 3 mm).
    pub contact_threshold_m: f64,
    /// Modes lighter than this are left out (and the rest renormalised).
    pub min_weight: f64,
    /// Most modes kept (the lowest Δ first); each costs a Hessian (18 predicted signatures).
    pub max_modes: usize,
    /// Central-difference step of the Hessian, metres (θ: this over `lever_m`).
    pub step_m: f64,
    /// Lever arm converting rotation to length for the Hessian's step and its caps, metres.
    pub lever_m: f64,
    /// Largest standard deviation along any direction the signature leaves flat (rotation as arc at `lever_m`),
    /// metres.
    pub max_sigma_m: f64,
}

impl Default for PosteriorConfig {
    fn default() -> Self {
        Self {
            temperature: 16.0,
            floor_position_m: 0.001,
            floor_theta_rad: 20f64.to_radians(),
            floor_contact_px: 300.0,
            floor_exponent: 0.5,
            contact_threshold_m: 0.003,
            min_weight: 1e-3,
            max_modes: 10,
            step_m: 5e-4,
            lever_m: 0.02,
            max_sigma_m: 0.03,
        }
    }
}

impl PosteriorConfig {
    /// A posterior calibration from a JSON file (every field optional, the defaults for the others), checked. The
    /// error says what is wrong; the caller names the file.
    pub fn read(path: &Path) -> Result<Self, InvalidInput> {
        const WHAT: &str = "posterior calibration";
        let text = crate::io::input::read_text_capped(path, crate::io::input::MAX_SETTINGS_BYTES)
            .map_err(|e| InvalidInput::new(WHAT, format!("cannot read: {e}")))?;
        let config: Self = serde_json::from_str(&text)
            .map_err(|e| InvalidInput::new(WHAT, format!("not a posterior calibration: {e}")))?;
        config
            .validate()
            .map_err(|e| InvalidInput::new(WHAT, e.to_string()))?;
        Ok(config)
    }

    /// Every setting in range; the error names the first that is not.
    pub fn validate(&self) -> Result<(), super::PoseError> {
        super::check_settings(
            "posterior: ",
            &[
                ("temperature", self.temperature),
                ("step_m", self.step_m),
                ("lever_m", self.lever_m),
                ("max_sigma_m", self.max_sigma_m),
                ("floor_contact_px", self.floor_contact_px),
                ("contact_threshold_m", self.contact_threshold_m),
            ],
            &[
                ("floor_exponent", self.floor_exponent),
                ("floor_position_m", self.floor_position_m),
                ("floor_theta_rad", self.floor_theta_rad),
                ("min_weight", self.min_weight),
            ],
        )?;
        // Upper bounds: past them the covariances overflow (null in JSON) and coverage reads 0 %.
        for (name, value, max, why) in [
            (
                "temperature",
                self.temperature,
                1e6,
                "a posterior that trusts no pixel",
            ),
            (
                "floor_position_m",
                self.floor_position_m,
                1.0,
                "beyond any sensor's reach",
            ),
            (
                "floor_theta_rad",
                self.floor_theta_rad,
                std::f64::consts::TAU,
                "more than a turn",
            ),
            (
                "max_sigma_m",
                self.max_sigma_m,
                1.0,
                "beyond any sensor's reach",
            ),
            ("lever_m", self.lever_m, 1.0, "beyond any sensor's reach"),
            ("step_m", self.step_m, 0.01, "wider than a contact"),
            (
                "contact_threshold_m",
                self.contact_threshold_m,
                0.1,
                "deeper than the sensor",
            ),
            (
                "floor_exponent",
                self.floor_exponent,
                4.0,
                "steeper than any contact law",
            ),
            (
                "floor_contact_px",
                self.floor_contact_px,
                1e7,
                "more pixels than an image has",
            ),
        ] {
            if value > max {
                let show = |v: f64| {
                    if v.abs() >= 1e5 {
                        format!("{v:e}")
                    } else {
                        format!("{v}")
                    }
                };
                return Err(super::PoseError::Config(format!(
                    "posterior: {name} {} is above {} ({why})",
                    show(value),
                    show(max)
                )));
            }
        }
        if self.max_modes == 0 || self.min_weight >= 1.0 {
            return Err(super::PoseError::Config(
                "posterior: max_modes must be at least 1 and min_weight below 1".into(),
            ));
        }
        Ok(())
    }
}

/// What the signature check measured at one distinct refined pose, before calibration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModeEvidence {
    pub pose: Se2,
    /// Negative log-likelihood above the best mode's, nats (independent pixels, the sensor's noise σ).
    pub nats: f64,
    /// Hessian of the negative log-likelihood at `pose` over (x m, y m, θ rad), nats.
    pub hessian: Mat3,
}

/// One mode of a [`PosePosterior`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PosteriorMode {
    /// Probability of this mode (the modes' weights sum to 1).
    pub weight: f64,
    /// `[x, y, theta]` of `t_world_object`, metres and radians (θ in (−π, π]).
    pub mean: [f64; 3],
    /// Covariance of `[x, y, theta]`, m², m·rad, rad².
    pub cov: Mat3,
    /// The evidence it was made from (its Δ nats and Hessian), so that another calibration can be applied later.
    pub nats: f64,
    pub hessian: Mat3,
}

impl PosteriorMode {
    /// The mean as a pose.
    pub fn pose(&self) -> Se2 {
        Se2::new(self.mean[0], self.mean[1], self.mean[2])
    }

    /// Standard deviations of x and y (metres) and θ (radians).
    pub fn sigmas(&self) -> [f64; 3] {
        [0, 1, 2].map(|i| self.cov[i][i].max(0.0).sqrt())
    }

    /// The `p` ellipse of the position marginal, `n` points (x, y in metres): the contour holding probability `p`
    /// of this mode's (x, y).
    pub fn ellipse_xy(&self, p: f64, n: usize) -> Vec<[f64; 2]> {
        let r = (-2.0 * (1.0 - p.clamp(0.0, 1.0 - 1e-12)).ln()).sqrt();
        let [[a, b, _], [_, d, _], _] = self.cov;
        // Cholesky of the 2x2 block.
        let l11 = a.max(0.0).sqrt();
        let l21 = if l11 > 0.0 { b / l11 } else { 0.0 };
        let l22 = (d - l21 * l21).max(0.0).sqrt();
        (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / n as f64;
                let (u, v) = (r * t.cos(), r * t.sin());
                [self.mean[0] + l11 * u, self.mean[1] + l21 * u + l22 * v]
            })
            .collect()
    }
}

/// Weighted Gaussian modes of `t_world_object` (module docs), heaviest first.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PosePosterior {
    pub modes: Vec<PosteriorMode>,
    /// The signature's contact pixels the floors were scaled by ([`PosteriorConfig::floor_contact_px`]).
    #[serde(default)]
    pub contact_px: usize,
}

/// `estimate − reference` in the coordinates the object's symmetry leaves identifiable: the position difference with
/// its component along the translation axis (object frame, turned by the reference's θ) removed, as one coordinate
/// across the axis or two (x, y), then θ wrapped to (−P/2, P/2] for the symmetry period P, or no θ for continuous
/// symmetry. Returns the coordinates and the rows (over x, y, θ) that make them.
pub fn reduced_difference(
    estimate: Se2,
    reference: Se2,
    symmetry: &Symmetry,
) -> (Vec<f64>, Vec<[f64; 3]>) {
    let (dx, dy) = (estimate.x - reference.x, estimate.y - reference.y);
    let mut rows: Vec<[f64; 3]> = Vec::with_capacity(3);
    match symmetry.translation_axis {
        Some([ax, ay]) if ax.hypot(ay) > 0.0 => {
            let (s, c) = reference.theta.sin_cos();
            let (ax, ay) = (ax / ax.hypot(ay), ay / ax.hypot(ay));
            // Across the axis in the world: R(θ) (−a_y, a_x).
            rows.push([c * -ay - s * ax, s * -ay + c * ax, 0.0]);
        }
        _ => rows.extend([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
    }
    let mut e: Vec<f64> = rows.iter().map(|r| r[0] * dx + r[1] * dy).collect();
    if let Some(period) = symmetry.rotation.period_rad() {
        let d = (estimate.theta - reference.theta).rem_euclid(period);
        e.push(if d > period / 2.0 { d - period } else { d });
        rows.push([0.0, 0.0, 1.0]);
    }
    (e, rows)
}

/// Whether `a` and `b` are one pose of an object with `symmetry`: within [`super::MODE_POSITION_MM`] and
/// [`super::MODE_THETA_DEG`], both reduced by the symmetry.
pub fn same_pose(a: Se2, b: Se2, symmetry: &Symmetry) -> bool {
    let (e, rows) = reduced_difference(a, b, symmetry);
    let theta = symmetry.rotation.period_rad().map(|_| e[e.len() - 1]);
    let position: f64 = e[..rows.len() - usize::from(theta.is_some())]
        .iter()
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt();
    position * 1e3 <= super::MODE_POSITION_MM
        && theta.is_none_or(|t| t.abs().to_degrees() <= super::MODE_THETA_DEG)
}

impl PosePosterior {
    /// Calibrate `evidence` (one entry per refined pose, any order, duplicates allowed) with `config`: poses within
    /// one mode of a better one are dropped, the rest weighted and given covariances (module docs).
    pub fn from_evidence(
        evidence: &[ModeEvidence],
        contact_px: usize,
        symmetry: &Symmetry,
        config: &PosteriorConfig,
    ) -> Self {
        let mut order: Vec<&ModeEvidence> =
            evidence.iter().filter(|e| e.nats.is_finite()).collect();
        order.sort_by(|a, b| a.nats.total_cmp(&b.nats));
        let mut kept: Vec<&ModeEvidence> = Vec::new();
        for e in order {
            if kept.len() < config.max_modes
                && !kept.iter().any(|k| same_pose(e.pose, k.pose, symmetry))
            {
                kept.push(e);
            }
        }
        let best = kept.first().map_or(0.0, |e| e.nats);
        let floor_scale =
            (config.floor_contact_px / (contact_px.max(10) as f64)).powf(config.floor_exponent);
        let raw: Vec<f64> = kept
            .iter()
            .map(|e| (-(e.nats - best) / config.temperature).exp())
            .collect();
        let total: f64 = raw.iter().sum();
        let mut modes: Vec<PosteriorMode> = kept
            .iter()
            .zip(&raw)
            .filter(|(_, &w)| w / total >= config.min_weight)
            .map(|(e, &w)| PosteriorMode {
                weight: w,
                mean: [e.pose.x, e.pose.y, wrap_angle(e.pose.theta)],
                cov: laplace_covariance(&e.hessian, floor_scale, config),
                nats: e.nats,
                hessian: e.hessian,
            })
            .collect();
        let kept_total: f64 = modes.iter().map(|m| m.weight).sum();
        modes.iter_mut().for_each(|m| m.weight /= kept_total);
        Self { modes, contact_px }
    }

    /// The same evidence calibrated again with `config` (e.g. one fitted to a user's own sensor).
    pub fn recalibrated(&self, symmetry: &Symmetry, config: &PosteriorConfig) -> Self {
        let evidence: Vec<ModeEvidence> = self
            .modes
            .iter()
            .map(|m| ModeEvidence {
                pose: m.pose(),
                nats: m.nats,
                hessian: m.hessian,
            })
            .collect();
        Self::from_evidence(&evidence, self.contact_px, symmetry, config)
    }

    /// The heaviest mode.
    pub fn top(&self) -> Option<&PosteriorMode> {
        self.modes.first()
    }

    /// The mode `pose` falls in (within one mode of its mean), if any.
    pub fn mode_of(&self, pose: Se2, symmetry: &Symmetry) -> Option<&PosteriorMode> {
        self.modes
            .iter()
            .find(|m| same_pose(pose, m.pose(), symmetry))
    }

    /// Log density of the mixture at `pose`, over the identifiable coordinates ([`reduced_difference`]); −∞
    /// without modes.
    pub fn log_density(&self, pose: Se2, symmetry: &Symmetry) -> f64 {
        let terms: Vec<f64> = self
            .modes
            .iter()
            .map(|m| {
                let (e, rows) = reduced_difference(pose, m.pose(), symmetry);
                m.weight.ln() + gaussian_log_density(&e, &project(&m.cov, &rows))
            })
            .collect();
        log_sum_exp(&terms)
    }

    /// The probability mass of the highest-density region whose boundary passes through `pose` (0: at the peak,
    /// near 1: far in the tails): `pose` lies inside the reported `p` region when this is ≤ p. Monte Carlo with
    /// `draws` draws from a fixed seed (a numerical integral, the same on every run). `None` without modes.
    pub fn region_mass(&self, pose: Se2, symmetry: &Symmetry, draws: usize) -> Option<f64> {
        if self.modes.is_empty() {
            return None;
        }
        let level = self.log_density(pose, symmetry);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5eed_9051);
        let chol: Vec<Option<Mat3>> = self.modes.iter().map(|m| cholesky3(&m.cov)).collect();
        let mut inside = 0usize;
        let n = draws.max(1);
        for _ in 0..n {
            let u: f64 = rand::Rng::random(&mut rng);
            let mut acc = 0.0;
            let k = self
                .modes
                .iter()
                .position(|m| {
                    acc += m.weight;
                    u < acc
                })
                .unwrap_or(self.modes.len() - 1);
            let z: [f64; 3] = [0; 3].map(|_| StandardNormal.sample(&mut rng));
            let m = &self.modes[k];
            let mut x = m.mean;
            if let Some(l) = &chol[k] {
                for (i, xi) in x.iter_mut().enumerate() {
                    *xi += (0..=i).map(|j| l[i][j] * z[j]).sum::<f64>();
                }
            }
            if self.log_density(Se2::new(x[0], x[1], x[2]), symmetry) >= level {
                inside += 1;
            }
        }
        Some(inside as f64 / n as f64)
    }
}

/// τ·H⁻¹ (module docs) with each flat direction capped, plus the floors times `floor_scale`.
fn laplace_covariance(hessian: &Mat3, floor_scale: f64, config: &PosteriorConfig) -> Mat3 {
    // In scaled coordinates (x, y, θ·lever) the eigenvalues share one unit and one cap.
    let s = [1.0, 1.0, config.lever_m];
    let mut h = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let v = 0.5 * (hessian[i][j] + hessian[j][i]) / (s[i] * s[j]);
            h[i][j] = if v.is_finite() { v } else { 0.0 };
        }
    }
    let (values, vectors) = symmetric_eigen3(&h);
    let floor = config.temperature / (config.max_sigma_m * config.max_sigma_m);
    let mut cov = [[0.0; 3]; 3];
    for k in 0..3 {
        let var = config.temperature / values[k].max(floor);
        for i in 0..3 {
            for j in 0..=i {
                cov[i][j] += var * vectors[i][k] * vectors[j][k] / (s[i] * s[j]);
            }
        }
    }
    // Exactly symmetric (the products above are not commutative in floating point).
    mirror_lower(&mut cov);
    let floors = [
        config.floor_position_m,
        config.floor_position_m,
        config.floor_theta_rad,
    ];
    for (i, f) in floors.iter().enumerate() {
        cov[i][i] += (f * floor_scale).powi(2);
    }
    cov
}

/// Copy the lower triangle of `m` onto its upper one: a symmetric matrix, exactly.
pub(crate) fn mirror_lower(m: &mut Mat3) {
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        m[i][j] = m[j][i];
    }
}

/// Eigenvalues and eigenvectors (columns) of a symmetric 3x3 matrix, by cyclic Jacobi rotations.
pub fn symmetric_eigen3(a: &Mat3) -> ([f64; 3], Mat3) {
    let mut a = *a;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let scale = (0..3).map(|i| a[i][i].powi(2)).sum::<f64>();
        if off <= 1e-30 * scale.max(1e-300) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * row_p[k] - s * row_q[k];
                a[q][k] = s * row_p[k] + c * row_q[k];
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}

/// Lower Cholesky factor of a symmetric positive definite 3x3 matrix; `None` when it is not.
fn cholesky3(a: &Mat3) -> Option<Mat3> {
    let mut l = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let s: f64 = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    Some(l)
}

/// `rows · cov · rowsᵀ`.
pub(crate) fn project(cov: &Mat3, rows: &[[f64; 3]]) -> Vec<Vec<f64>> {
    rows.iter()
        .map(|r| {
            rows.iter()
                .map(|q| {
                    (0..3)
                        .map(|i| (0..3).map(|j| r[i] * cov[i][j] * q[j]).sum::<f64>())
                        .sum()
                })
                .collect()
        })
        .collect()
}

/// log N(e; 0, c) for a k-dimensional `e` (k ≤ 3); −∞ when `c` is not positive definite.
pub(crate) fn gaussian_log_density(e: &[f64], c: &[Vec<f64>]) -> f64 {
    let k = e.len();
    let mut full = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for i in 0..k {
        for j in 0..k {
            full[i][j] = c[i][j];
        }
    }
    let Some(l) = cholesky3(&full) else {
        return f64::NEG_INFINITY;
    };
    // Solve L y = e; the quadratic form is |y|², log det = 2 Σ ln L_ii.
    let mut y = [0.0; 3];
    for i in 0..k {
        y[i] = (e[i] - (0..i).map(|j| l[i][j] * y[j]).sum::<f64>()) / l[i][i];
    }
    let quad: f64 = y[..k].iter().map(|v| v * v).sum();
    let log_det: f64 = (0..k).map(|i| 2.0 * l[i][i].ln()).sum();
    -0.5 * (quad + log_det + k as f64 * (std::f64::consts::TAU).ln())
}

pub(crate) fn log_sum_exp(terms: &[f64]) -> f64 {
    let max = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return max;
    }
    max + terms.iter().map(|t| (t - max).exp()).sum::<f64>().ln()
}

#[cfg(test)]
#[path = "posterior_tests.rs"]
mod tests;
