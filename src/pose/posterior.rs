//! **Pose posterior**: what the measured signature says about the pose, as weighted Gaussian modes in (x, y, θ).
//!
//! The signature check ([`super::signature_check`]) refines the registration's hypotheses to the poses that explain
//! the measured signature best; distinct ones are distinct explanations. Each becomes a mode:
//!
//! * **weight** ∝ exp(−Δ / τ): Δ is how much worse (nats, the sensor's Gaussian noise with independent pixels) the
//!   mode explains the signature than the best one, τ the [`PosteriorConfig::temperature`]. Neighbouring pixels of a
//!   tactile signature are far from independent (the shadow cloak, the membrane, the model's own errors), so the
//!   raw likelihood is overconfident by orders of magnitude; τ tempers it and is fitted on validation data. With
//!   [`PosteriorConfig::frame_noise`] the nats (and Hessians) are first rescaled from the sensor model's noise σ₀ to
//!   the frame's own, σ₀² / (σ_f² + σ_floor²): a frame averaged down from a native image is several times less
//!   noisy than one simulated at the model's size, and its signature says more.
//! * **covariance** of its *core*: the Laplace approximation τ_c·H⁻¹ with H the Hessian of the negative
//!   log-likelihood at the mode (central differences of the check's cost), τ_c the
//!   [`PosteriorConfig::covariance_temperature`], its flat directions capped at [`PosteriorConfig::max_sigma_m`], plus
//!   a small floor ([`PosteriorConfig::floor_position_m`], [`PosteriorConfig::floor_theta_rad`]) scaled by the contact.
//! * **heavy tails** as explicit components instead of a wider core: errors are mostly small with a few far off, and
//!   one Gaussian wide enough for the few is far too wide for the many. A share ε_tail of the mode's weight is a
//!   *tail* (the core scaled by [`PosteriorConfig::tail_core_scale`] and widened by
//!   [`PosteriorConfig::tail_position_m`] and [`PosteriorConfig::tail_theta_rad`], scaled by the contact: a contact
//!   the sample got somewhat wrong), a share ε_far is *far* (position spread
//!   [`PosteriorConfig::far_position_m`], any θ: a pose no hypothesis came near). Both shares are logistic in the
//!   contact's evidence, ε = logistic(logit + slope · ln(pixels / [`PosteriorConfig::floor_contact_px`]) + …): a
//!   small contact says less; a contact with **rival explanations** (n distinct refined poses within
//!   [`PosteriorConfig::rival_window_nats`] of the best: the likelihood is rough there) is more often wrong
//!   ([`PosteriorConfig::tail_rivals`], [`PosteriorConfig::far_rivals`], per unit of ln n); so is one the best pose
//!   leaves **unexplained**, its signature's misfit over the contact several times the frame's noise
//!   ([`FrameNoise::ln_misfit`]; [`PosteriorConfig::tail_misfit`], [`PosteriorConfig::far_misfit`]); the far share
//!   also follows the modes' disagreement ([`PosteriorConfig::far_ambiguity`]). A quiet, well-explained contact
//!   with no rival keeps most of its weight in the sharp core.
//!
//! The parameters are fitted by the mean negative log density of the truth on labelled pairs
//! ([`crate::metrics::coverage::fit_posterior`]): a proper score, so a fit is calibrated at every level where the
//! family can be.
//!
//! Poses are `t_world_object` (metres, radians); θ is circular and taken modulo the object's symmetry period, the
//! position along a translation axis is not identifiable and left out of region tests ([`reduced_difference`]).
//! [`PosePosterior::region_mass`] gives the probability mass of the highest-density region that just reaches a
//! pose: the truth lies inside the reported p region when it is ≤ p.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

pub use super::posterior_config::PosteriorConfig;
use super::register::wrap_angle;
use crate::objects::Symmetry;
use crate::sensor::Se2;

pub(crate) use super::mat3::{cholesky3, gaussian_log_density, log_sum_exp, mirror_lower, project};
pub use super::mat3::{symmetric_eigen3, Mat3};

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
    /// Its heavy tails (module docs); `mean` and `cov` are the core's.
    #[serde(default)]
    pub tails: ModeTails,
}

/// A mode's heavy tails (module docs): the shares of its weight outside the core and their spreads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModeTails {
    /// Share of the mode's weight in its tail, 0–1.
    pub tail: f64,
    /// Covariance of the tail (the core's widened), as `cov`.
    pub tail_cov: Mat3,
    /// Share of the mode's weight in its far component, 0–1.
    pub far: f64,
    /// Standard deviation of the far component's x and y about the mean, metres; its θ is uniform.
    pub far_position_m: f64,
}

/// One Gaussian component of a [`PosePosterior`]'s mixture.
#[derive(Clone, Copy, Debug)]
struct Component {
    weight: f64,
    mean: [f64; 3],
    cov: Mat3,
    /// θ uniform over the symmetry period instead of Gaussian (`cov`'s θ row is then unused).
    uniform_theta: bool,
}

impl PosteriorMode {
    /// The mean as a pose.
    pub fn pose(&self) -> Se2 {
        Se2::new(self.mean[0], self.mean[1], self.mean[2])
    }

    /// The covariance of the mode's core and tail together (moment-matched; the far component, a pose no
    /// hypothesis came near, is its own share `tails.far`): the spread to act on, m², m·rad, rad².
    pub fn spread_cov(&self) -> Mat3 {
        let t = &self.tails;
        let near = 1.0 - t.far;
        if t.tail <= 0.0 || near <= 0.0 {
            return self.cov;
        }
        let core = (near - t.tail) / near;
        let tail = t.tail / near;
        let mut cov = [[0.0; 3]; 3];
        for (i, row) in cov.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = core * self.cov[i][j] + tail * t.tail_cov[i][j];
            }
        }
        cov
    }

    /// Standard deviations of x and y (metres) and θ (radians) of [`Self::spread_cov`].
    pub fn sigmas(&self) -> [f64; 3] {
        let cov = self.spread_cov();
        [0, 1, 2].map(|i| cov[i][i].max(0.0).sqrt())
    }

    /// Half-widths of the central intervals about the mean of x, y (metres) and θ (radians) that hold `p` of this
    /// mode's weight — its core, tail and far component, the far θ uniform over `symmetry`'s period (a full turn
    /// without one; [`theta_period`]). With heavy tails the standard deviation ([`Self::sigmas`]) is set by the few
    /// contacts far off; this is the spread read the way a Gaussian's is: at `p` = [`ONE_SIGMA`] it is ±σ for a
    /// Gaussian mode, and the truth lies within it `p` of the time for a calibrated one.
    pub fn half_widths(&self, p: f64, symmetry: &Symmetry) -> [f64; 3] {
        let theta_period = theta_period(symmetry);
        let t = &self.tails;
        let (core, tail, far) = (
            (1.0 - t.tail - t.far).max(0.0),
            t.tail.max(0.0),
            t.far.max(0.0),
        );
        let total = (core + tail + far).max(f64::MIN_POSITIVE);
        let sd = |cov: &Mat3, i: usize| cov[i][i].max(0.0).sqrt();
        [0, 1, 2].map(|i| {
            let gaussians = [(core, sd(&self.cov, i)), (tail, sd(&t.tail_cov, i))];
            // Mass within ±h of the mean, as a share of the mode.
            let mass = |h: f64| {
                let gauss: f64 = gaussians.iter().map(|&(w, s)| w * central_mass(h, s)).sum();
                let far_mass = if i == 2 {
                    (2.0 * h / theta_period).min(1.0)
                } else {
                    central_mass(h, t.far_position_m)
                };
                (gauss + far * far_mass) / total
            };
            let widest = gaussians
                .iter()
                .map(|g| g.1)
                .fold(t.far_position_m, f64::max);
            let mut hi = if i == 2 {
                theta_period / 2.0
            } else {
                10.0 * widest
            };
            if mass(hi) <= p {
                return hi;
            }
            let mut lo = 0.0;
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if mass(mid) < p {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            0.5 * (lo + hi)
        })
    }

    /// The `p` ellipse of the position marginal of [`Self::spread_cov`], `n` points (x, y in metres): the contour
    /// holding probability `p` of a Gaussian with this mode's spread.
    pub fn ellipse_xy(&self, p: f64, n: usize) -> Vec<[f64; 2]> {
        let r = (-2.0 * (1.0 - p.clamp(0.0, 1.0 - 1e-12)).ln()).sqrt();
        let [[a, b, _], [_, d, _], _] = self.spread_cov();
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
    /// The measured signature's contact pixels (in front of the membrane by more than
    /// [`PosteriorConfig::contact_threshold_m`]); the floors and tails scale by these unless
    /// [`PosteriorConfig::contact_from_prediction`].
    #[serde(default)]
    pub contact_px: usize,
    /// The contact pixels the best mode predicts (the object rendered at its pose in front of the membrane): free of
    /// the sensor's noise, which puts hundreds of pixels past the threshold on a noisy frame. `None` in records
    /// from before it was kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predicted_contact_px: Option<usize>,
    /// The noise the modes' nats and Hessians assume and the frame's own ([`PosteriorConfig::frame_noise`]); `None`
    /// in records from before it was measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<FrameNoise>,
    /// Δ nats (as computed, before any rescaling) of every distinct pose the check refined to, the best's 0 first,
    /// also those too light to be a mode: the rival explanations [`PosteriorConfig::rival_window_nats`] counts.
    /// Empty in records from before it was kept (the modes' own nats stand in).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub distinct_nats: Vec<f64>,
}

/// The depth noise of one measured signature, at the resolution the check compares it in (metres).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameNoise {
    /// σ the modes' nats and Hessians were computed with (the sensor model's noise, one pixel).
    pub assumed_m: f64,
    /// σ of the measured signature about the best mode's prediction, robust (1.4826 × the median absolute
    /// deviation): the sensor's noise as this frame shows it, with what the model does not explain.
    pub measured_m: f64,
    /// RMS of the signature about that prediction over the contact, predicted or measured
    /// ([`super::signature_check::SignatureCheck::contact_misfit`]): near `measured_m` when the pose explains the
    /// contact. `None` in records from before it was measured, or with too few contact pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_rms_m: Option<f64>,
}

impl FrameNoise {
    /// ln(`contact_rms_m` / `measured_m`): how many times the frame's noise the pose leaves unexplained on the
    /// contact, as a log; 0 where either is unknown.
    pub fn ln_misfit(&self) -> f64 {
        self.contact_rms_m
            .map(|c| (c / self.measured_m).ln())
            .filter(|v| v.is_finite())
            .unwrap_or(0.0)
    }
}

/// What a posterior is calibrated from besides its modes' evidence ([`PosePosterior`]'s fields of the same names).
struct Context {
    contact_px: usize,
    predicted_contact_px: Option<usize>,
    noise: Option<FrameNoise>,
    distinct_nats: Vec<f64>,
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
        Self::from_evidence_with(evidence, contact_px, None, None, symmetry, config)
    }

    /// [`Self::from_evidence`] with the contact the best mode predicts beside the measured one (see
    /// [`Self::predicted_contact_px`]; `config` chooses which the floors and tails scale by) and the frame's noise
    /// (which [`PosteriorConfig::frame_noise`] weighs the evidence by).
    pub fn from_evidence_with(
        evidence: &[ModeEvidence],
        contact_px: usize,
        predicted_contact_px: Option<usize>,
        noise: Option<FrameNoise>,
        symmetry: &Symmetry,
        config: &PosteriorConfig,
    ) -> Self {
        Self::calibrate(
            evidence,
            Context {
                contact_px,
                predicted_contact_px,
                noise,
                distinct_nats: Vec::new(),
            },
            symmetry,
            config,
        )
    }

    /// [`Self::from_evidence_with`] with `context`'s rival nats (empty: those of the distinct `evidence`).
    fn calibrate(
        evidence: &[ModeEvidence],
        context: Context,
        symmetry: &Symmetry,
        config: &PosteriorConfig,
    ) -> Self {
        let Context {
            contact_px,
            predicted_contact_px,
            noise,
            distinct_nats,
        } = context;
        let k = config.evidence_scale(noise.as_ref());
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
        let distinct_nats = if distinct_nats.is_empty() {
            kept.iter().map(|e| e.nats - best).collect()
        } else {
            distinct_nats
        };
        // ln n, n the distinct poses within the window of the best (itself included).
        let ln_rivals = (distinct_nats
            .iter()
            .filter(|&&d| d <= config.rival_window_nats)
            .count()
            .max(1) as f64)
            .ln();
        let ln_misfit = noise.as_ref().map_or(0.0, FrameNoise::ln_misfit);
        let used = match predicted_contact_px {
            Some(p) if config.contact_from_prediction => p,
            _ => contact_px,
        };
        let contact = used.max(10) as f64;
        let floor_scale = (config.floor_contact_px / contact).powf(config.floor_exponent);
        let ln_contact = (contact / config.floor_contact_px).ln();
        let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
        let tail = logistic(
            config.tail_logit
                + config.tail_contact_slope * ln_contact
                + config.tail_rivals * ln_rivals
                + config.tail_misfit * ln_misfit,
        );
        let far_scale = (config.floor_contact_px / contact).powf(config.far_exponent);
        let raw: Vec<f64> = kept
            .iter()
            .map(|e| (-k * (e.nats - best) / config.temperature).exp())
            .collect();
        let total: f64 = raw.iter().sum();
        let top_weight = raw.first().map_or(1.0, |w| w / total);
        let far = logistic(
            config.far_logit
                + config.far_contact_slope * ln_contact
                + config.far_ambiguity * (1.0 - top_weight)
                + config.far_rivals * ln_rivals
                + config.far_misfit * ln_misfit,
        );
        let tail_scale = (config.floor_contact_px / contact).powf(config.tail_exponent);
        let tails = |core: &Mat3| {
            let k2 = config.tail_core_scale * config.tail_core_scale;
            let mut tail_cov = core.map(|row| row.map(|v| v * k2));
            widen(
                &mut tail_cov,
                config.tail_position_m,
                config.tail_theta_rad,
                tail_scale,
            );
            ModeTails {
                tail: (1.0 - far) * tail,
                tail_cov,
                far,
                far_position_m: config.far_position_m * far_scale,
            }
        };
        let mut modes: Vec<PosteriorMode> = kept
            .iter()
            .zip(&raw)
            .filter(|(_, &w)| w / total >= config.min_weight)
            .map(|(e, &w)| {
                let cov =
                    laplace_covariance(&e.hessian.map(|r| r.map(|v| k * v)), floor_scale, config);
                PosteriorMode {
                    weight: w,
                    mean: [e.pose.x, e.pose.y, wrap_angle(e.pose.theta)],
                    cov,
                    nats: e.nats,
                    hessian: e.hessian,
                    tails: tails(&cov),
                }
            })
            .collect();
        let kept_total: f64 = modes.iter().map(|m| m.weight).sum();
        modes.iter_mut().for_each(|m| m.weight /= kept_total);
        Self {
            modes,
            contact_px,
            predicted_contact_px,
            noise,
            distinct_nats,
        }
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
        Self::calibrate(
            &evidence,
            Context {
                contact_px: self.contact_px,
                predicted_contact_px: self.predicted_contact_px,
                noise: self.noise,
                distinct_nats: self.distinct_nats.clone(),
            },
            symmetry,
            config,
        )
    }

    /// [`PosteriorMode::half_widths`] at [`ONE_SIGMA`] of the mode `estimate` falls in (the heaviest where it falls
    /// in none): the estimate's ±σ read as a Gaussian's; `None` without modes.
    pub fn estimate_half_widths(&self, estimate: Se2, symmetry: &Symmetry) -> Option<[f64; 3]> {
        self.mode_of(estimate, symmetry)
            .or(self.top())
            .map(|m| m.half_widths(ONE_SIGMA, symmetry))
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

    /// The mixture's Gaussian components: each mode's core, tail and far component, by weight.
    fn components(&self) -> Vec<Component> {
        let mut out = Vec::with_capacity(3 * self.modes.len());
        for m in &self.modes {
            let t = &m.tails;
            let core = m.weight * (1.0 - t.tail - t.far);
            let far_var = t.far_position_m * t.far_position_m;
            for (weight, cov, uniform_theta) in [
                (core, m.cov, false),
                (m.weight * t.tail, t.tail_cov, false),
                (
                    m.weight * t.far,
                    [[far_var, 0.0, 0.0], [0.0, far_var, 0.0], [0.0, 0.0, 1.0]],
                    true,
                ),
            ] {
                if weight > 0.0 {
                    out.push(Component {
                        weight,
                        mean: m.mean,
                        cov,
                        uniform_theta,
                    });
                }
            }
        }
        out
    }

    /// Log density of the mixture at `pose`, over the identifiable coordinates ([`reduced_difference`]); −∞
    /// without modes.
    pub fn log_density(&self, pose: Se2, symmetry: &Symmetry) -> f64 {
        log_density_of(&self.components(), pose, symmetry)
    }

    /// Log of ∫ N(x; `pose`, `spread`) p(x) dx for this mixture p: how well it predicts a pose known only to within
    /// the Gaussian `spread` (over x, y, θ; m², m·rad, rad²), over the identifiable coordinates. −∞ without modes.
    pub fn predictive_log_density(&self, pose: Se2, spread: &Mat3, symmetry: &Symmetry) -> f64 {
        let widened: Vec<Component> = self
            .components()
            .into_iter()
            .map(|mut c| {
                for (row, add) in c.cov.iter_mut().zip(spread) {
                    for (v, a) in row.iter_mut().zip(add) {
                        *v += a;
                    }
                }
                c
            })
            .collect();
        log_density_of(&widened, pose, symmetry)
    }

    /// The probability mass of the highest-density region whose boundary passes through `pose` (0: at the peak,
    /// near 1: far in the tails): `pose` lies inside the reported `p` region when this is ≤ p. Monte Carlo with
    /// `draws` draws from a fixed seed (a numerical integral, the same on every run). `None` without modes.
    pub fn region_mass(&self, pose: Se2, symmetry: &Symmetry, draws: usize) -> Option<f64> {
        let components = self.components();
        if components.is_empty() {
            return None;
        }
        let level = log_density_of(&components, pose, symmetry);
        let total: f64 = components.iter().map(|c| c.weight).sum();
        let period = theta_period(symmetry);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5eed_9051);
        let chol: Vec<Option<Mat3>> = components.iter().map(|c| cholesky3(&c.cov)).collect();
        let mut inside = 0usize;
        let n = draws.max(1);
        for _ in 0..n {
            let u: f64 = rand::Rng::random::<f64>(&mut rng) * total;
            let mut acc = 0.0;
            let k = components
                .iter()
                .position(|c| {
                    acc += c.weight;
                    u < acc
                })
                .unwrap_or(components.len() - 1);
            let z: [f64; 3] = [0; 3].map(|_| StandardNormal.sample(&mut rng));
            let c = &components[k];
            let mut x = c.mean;
            if let Some(l) = &chol[k] {
                for (i, xi) in x.iter_mut().enumerate() {
                    *xi += (0..=i).map(|j| l[i][j] * z[j]).sum::<f64>();
                }
            }
            if c.uniform_theta {
                let v: f64 = rand::Rng::random(&mut rng);
                x[2] = c.mean[2] + (v - 0.5) * period;
            }
            if log_density_of(&components, Se2::new(x[0], x[1], x[2]), symmetry) >= level {
                inside += 1;
            }
        }
        Some(inside as f64 / n as f64)
    }
}

/// The period over which a far component's θ is uniform: the symmetry's, a full turn without one (and where θ is
/// free, whose θ no density reads).
fn theta_period(symmetry: &Symmetry) -> f64 {
    symmetry
        .rotation
        .period_rad()
        .unwrap_or(std::f64::consts::TAU)
}

/// The central probability of ±1σ of a Gaussian: erf(1/√2).
pub const ONE_SIGMA: f64 = 0.682_689_492_137_085_9;

/// Mass of a zero-mean Gaussian of standard deviation `sd` within ±`h` (a point mass at 0 when `sd` is 0).
fn central_mass(h: f64, sd: f64) -> f64 {
    if sd <= 0.0 {
        return 1.0;
    }
    libm::erf(h / (sd * std::f64::consts::SQRT_2))
}

/// Log density of a mixture of `components` at `pose` (see [`PosePosterior::log_density`]).
fn log_density_of(components: &[Component], pose: Se2, symmetry: &Symmetry) -> f64 {
    let terms: Vec<f64> = components
        .iter()
        .map(|c| {
            let mean = Se2::new(c.mean[0], c.mean[1], c.mean[2]);
            let (mut e, mut rows) = reduced_difference(pose, mean, symmetry);
            let mut uniform = 0.0;
            if c.uniform_theta {
                if let Some(period) = symmetry.rotation.period_rad() {
                    e.pop();
                    rows.pop();
                    uniform = -period.ln();
                }
            }
            c.weight.ln() + gaussian_log_density(&e, &project(&c.cov, &rows)) + uniform
        })
        .collect();
    log_sum_exp(&terms)
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
    let tau = config.covariance_temperature;
    let floor = tau / (config.max_sigma_m * config.max_sigma_m);
    let mut cov = [[0.0; 3]; 3];
    for k in 0..3 {
        let var = tau / values[k].max(floor);
        for i in 0..3 {
            for j in 0..=i {
                cov[i][j] += var * vectors[i][k] * vectors[j][k] / (s[i] * s[j]);
            }
        }
    }
    // Exactly symmetric (the products above are not commutative in floating point).
    mirror_lower(&mut cov);
    widen(
        &mut cov,
        config.floor_position_m,
        config.floor_theta_rad,
        floor_scale,
    );
    cov
}

/// Add independent spreads (x and y: `position_m`, θ: `theta_rad`, each times `scale`) to `cov`'s diagonal.
fn widen(cov: &mut Mat3, position_m: f64, theta_rad: f64, scale: f64) {
    for (i, s) in [position_m, position_m, theta_rad].iter().enumerate() {
        cov[i][i] += (s * scale).powi(2);
    }
}

#[cfg(test)]
#[path = "posterior_tests.rs"]
mod tests;
