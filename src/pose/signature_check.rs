//! **Signature check** (analysis by synthesis, after registration): a pose hypothesis for the object predicts the
//! whole tactile signature the sensor would have measured — the object depth D rendered at that pose, the contact
//! mask where D lies in front of the undeformed membrane E, and the synthetic signature with its tactile-shadow cloak
//! (paper V.A, [`crate::sim::shadows::tactile_signature`]). Comparing that prediction with the measured signature S
//! scores a hypothesis by what the sensor saw, not by how well one generated sample fits the mesh.
//!
//! The registration's hypotheses (from one sample, or from every sample) are scored this way, the best few are
//! refined by a pattern search on the same score, and the lowest wins ([`SignatureCheck::select`]). The cost is a
//! robust mean over the pixels where both S and E are measured: `mean ρ(S − Ŝ(q))` with a Cauchy ρ at scale
//! [`SignatureCheckConfig::scale_m`] (Gaussian in the bulk of the sensor noise, so a real sensor's unmodelled
//! artefacts do not dominate).

use glam::DAffine3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::camera_path::MembranePath;
use super::posterior::{same_pose, FrameNoise, Mat3, ModeEvidence, PosePosterior, PosteriorConfig};
use super::register::wrap_angle;
use super::sdf_register::RobustLoss;
use super::PoseError;
use super::{MODE_POSITION_MM, MODE_THETA_DEG};
use crate::image::Image;
use crate::mesh::RayCaster;
use crate::recording::process::median_of;
use crate::sensor::{Intrinsics, Se2};
use crate::sim::render::render_depth;
use crate::sim::shadows::tactile_signature;

/// Settings of the signature check. On the command line only `--check-refine` ([`Self::refine`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct SignatureCheckConfig {
    /// Robust (Cauchy) scale of the per-pixel residual S − Ŝ, metres (default 3 mm, about twice the synthetic
    /// noise σ = 1.38 mm).
    #[arg(skip = DEFAULT_SIGNATURE_CHECK.scale_m)]
    pub scale_m: f64,
    /// Hypotheses the signature check refines besides the registration's best (0: none).
    ///
    /// The lowest-scoring distinct ones; the default 20 is every hypothesis of a 10-start registration of the
    /// sample and of the imprint, and 0 picks among all as scored. On the real-mesh validation set refining 20 instead of 3 took the mean
    /// position error from 1.94 to 1.44 mm: the pose that explains the signature best often starts as a
    /// hypothesis the unrefined score ranks low.
    #[arg(long = "check-refine", default_value_t = DEFAULT_SIGNATURE_CHECK.refine)]
    pub refine: usize,
    /// How much better (natural log-likelihood under the sensor's Gaussian noise, [`SignatureModel::noise_std`])
    /// another hypothesis must explain the signature than the registration's best to replace it (default 0: the
    /// best explanation wins; 3 and 10 nats were no better on the real-mesh validation set).
    #[arg(skip = DEFAULT_SIGNATURE_CHECK.margin_nats)]
    pub margin_nats: f64,
    /// First translation step of the pattern search, metres (default 1 mm); rotation steps are this over
    /// `lever_m`.
    #[arg(skip = DEFAULT_SIGNATURE_CHECK.step_m)]
    pub step_m: f64,
    /// The search stops when the step falls below this, metres (default 0.05 mm).
    #[arg(skip = DEFAULT_SIGNATURE_CHECK.min_step_m)]
    pub min_step_m: f64,
    /// Lever arm converting rotation to length, metres (default 20 mm).
    #[arg(skip = DEFAULT_SIGNATURE_CHECK.lever_m)]
    pub lever_m: f64,
    /// Most cost evaluations per refined hypothesis (default 150).
    #[arg(skip = DEFAULT_SIGNATURE_CHECK.max_evaluations)]
    pub max_evaluations: usize,
    /// Take the membrane from the measurement's own reference frame (R = S + Y, averaged over a window of this
    /// radius, pixels) instead of the nominal membrane, so that a drifted inflation is predicted as measured; 0
    /// uses the nominal membrane (default 3).
    #[arg(skip = DEFAULT_SIGNATURE_CHECK.reference_radius_px)]
    pub reference_radius_px: usize,
    /// Predict a frame brought down from the camera's native pixels at those pixels, resampled as the frame was
    /// (`pose::camera_path`); false: one ray per model pixel for every frame (default true).
    #[arg(id = "check_native", long = "check-native", value_name = "BOOL", action = clap::ArgAction::Set,
          default_value_t = DEFAULT_SIGNATURE_CHECK.native)]
    pub native: bool,
}

/// The defaults (also the command line's).
const DEFAULT_SIGNATURE_CHECK: SignatureCheckConfig = SignatureCheckConfig {
    scale_m: 0.003,
    refine: 20,
    margin_nats: 0.0,
    step_m: 0.001,
    min_step_m: 5e-5,
    lever_m: 0.02,
    max_evaluations: 150,
    reference_radius_px: 3,
    native: true,
};

impl Default for SignatureCheckConfig {
    fn default() -> Self {
        DEFAULT_SIGNATURE_CHECK
    }
}

impl SignatureCheckConfig {
    pub(crate) fn validate(&self) -> Result<(), PoseError> {
        super::check_settings(
            "signature check: ",
            &[
                ("scale_m", self.scale_m),
                ("step_m", self.step_m),
                ("min_step_m", self.min_step_m),
                ("lever_m", self.lever_m),
            ],
            &[("margin_nats", self.margin_nats)],
        )
    }
}

/// How the sensor turns a contact into a signature: the tactile-shadow width, the pixel size it is measured in, and
/// the measurement noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignatureModel {
    /// Width of the shadow cloak, native sensor pixels ([`crate::sim::SignatureConfig::shadow_px`]).
    pub shadow_px: f64,
    /// Size of one image pixel in native sensor pixels ([`Intrinsics::pixel_size_in`]).
    pub spacing: (f64, f64),
    /// Standard deviation of the depth noise on S, metres ([`crate::sim::SignatureConfig::noise_std`]).
    pub noise_std: f64,
}

impl SignatureModel {
    /// The signature model of `sim`'s sensor.
    pub fn of_simulator(sim: &crate::sim::Simulator) -> Self {
        Self {
            shadow_px: sim.config().signature.shadow_px,
            spacing: sim.intrinsics().pixel_size_in(&sim.config().camera.native),
            noise_std: sim.config().signature.noise_std,
        }
    }

    /// Imprint guidance ([`crate::model::guidance`]) towards `imprint` Y on this sensor, whose undeformed membrane
    /// is `nominal`: on the membrane the measurement's own reference frame R = S + Y shows ([`measured_membrane`])
    /// when the signature S is known, else on `nominal`. `None` when `config` is off.
    pub fn guidance(
        &self,
        config: &crate::model::GuidanceConfig,
        nominal: &Image,
        imprint: &Image,
        signature: Option<&Image>,
    ) -> Result<Option<crate::model::ImprintGuidance>, PoseError> {
        if !config.active() {
            return Ok(None);
        }
        let membrane = match signature {
            Some(s) => measured_membrane(
                nominal,
                s,
                imprint,
                SignatureCheckConfig::default().reference_radius_px,
            )?,
            None => nominal.clone(),
        };
        let cloak = crate::model::Cloak {
            width_native_px: self.shadow_px,
            spacing: self.spacing,
        };
        let guidance = crate::model::ImprintGuidance::new(*config, imprint, &membrane, cloak)
            .map_err(|e| PoseError::Config(crate::error::render(&e)))?;
        // Where the frame has no return the imprint was filled in: no evidence there.
        Ok(Some(match signature {
            Some(s) => guidance.ignoring_missing(s),
            None => guidance,
        }))
    }
}

/// One signature to explain: the camera, the undeformed membrane and the measurement.
/// A refined pose and its check cost.
pub type Candidate = (Se2, f64);

pub struct SignatureCheck<'a> {
    /// The object's ray caster, object frame (resting pose).
    pub caster: &'a RayCaster,
    pub intrinsics: &'a Intrinsics,
    /// E: depth of the undeformed membrane, metres (0 where not seen).
    pub membrane: &'a Image,
    /// `t_world_camera` of the sensor camera.
    pub t_world_camera: DAffine3,
    /// S: the measured signature, metres (0 where not measured).
    pub signature: &'a Image,
    pub model: SignatureModel,
    pub config: &'a SignatureCheckConfig,
    /// Predict at the camera's native pixels and resample, as the measured frame was made
    /// ([`super::camera_path`]); `None`: one ray per pixel at this resolution (frames made at it).
    pub camera_path: Option<MembranePath<'a>>,
}

/// The outcome of [`SignatureCheck::select`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checked {
    /// The chosen pose `t_world_object`.
    pub pose: Se2,
    /// Its signature cost (robust mean, metres²).
    pub cost: f64,
    /// Index of the hypothesis it was refined from.
    pub from: usize,
    /// Cost evaluations used in all.
    pub evaluations: usize,
    /// The best refined hypothesis that is another pose (more than [`MODE_POSITION_MM`] or [`MODE_THETA_DEG`] from
    /// the pick, symmetry not reduced): how close the signature comes to explaining the contact another way.
    pub rival: Option<Rival>,
}

/// Another pose than the pick, with how much worse it explains the signature.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rival {
    /// The pose `t_world_object`.
    pub pose: Se2,
    /// Its cost above the pick's as Gaussian log-likelihood, nats (n·ΔC/σ² over the n measured pixels): about 0
    /// says the signature cannot tell the two apart, tens that it can.
    pub nats: f64,
}

/// Fewest measured pixels [`SignatureCheck::residual_noise`] estimates a frame's noise from.
pub const MIN_NOISE_PIXELS: usize = 64;

/// Fewest contact pixels [`SignatureCheck::contact_misfit`] measures a misfit over.
pub const MIN_MISFIT_PIXELS: usize = 5;

/// A rival explaining the signature within this many nats of the pick (a likelihood ratio under e⁴ ≈ 55) makes the
/// estimate ambiguous: which of the two it is, the sensor's noise decides.
pub const SIGNATURE_AMBIGUOUS_NATS: f64 = 4.0;

impl Rival {
    /// Within [`SIGNATURE_AMBIGUOUS_NATS`] of the pick.
    pub fn ambiguous(&self) -> bool {
        self.nats < SIGNATURE_AMBIGUOUS_NATS
    }

    /// "x 1.2 mm, y -3.4 mm, θ 172°, 1.3 nats worse" (millimetres and degrees, for people).
    pub fn describe(&self) -> String {
        format!(
            "x {:.1} mm, y {:.1} mm, θ {:.0}°, {:.1} nats worse",
            self.pose.x * 1e3,
            self.pose.y * 1e3,
            self.pose.theta.to_degrees(),
            self.nats
        )
    }
}

impl SignatureCheck<'_> {
    /// Check that the images agree in size with the camera.
    pub fn validate(&self) -> Result<(), PoseError> {
        self.config.validate()?;
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        for (what, img) in [("membrane", self.membrane), ("signature", self.signature)] {
            if (img.width, img.height) != (w, h) {
                return Err(PoseError::Config(format!(
                    "signature check: the {what} is {}x{} pixels, the camera {w}x{h}",
                    img.width, img.height
                )));
            }
        }
        Ok(())
    }

    /// The object's depth from the camera with the object at `pose` (metres; 0 where the ray misses it).
    fn object_depth(&self, pose: Se2) -> Image {
        let t_object_camera = pose.to_affine().inverse() * self.t_world_camera;
        render_depth(self.caster, self.intrinsics, &t_object_camera)
    }

    /// Ŝ(q): the noise-free signature the sensor would measure with the object at `pose` (metres).
    pub fn predict(&self, pose: Se2) -> Image {
        self.render(pose).1
    }

    /// The object's depth at `pose` ([`Self::object_depth`]) and the signature it predicts ([`Self::predict`]):
    /// one ray per pixel of this resolution, or at the camera's native pixels where it reaches the membrane
    /// ([`Self::camera_path`]).
    fn render(&self, pose: Se2) -> (Image, Image) {
        let depth = self.object_depth(pose);
        let predicted = match &self.camera_path {
            Some(path) => path.predict(
                self.caster,
                &self.t_world_camera,
                pose,
                &depth,
                self.model.shadow_px,
            ),
            None => {
                let mask =
                    depth.zip_map(self.membrane, |d, e| f32::from(u8::from(in_contact(d, e))));
                tactile_signature(
                    &depth,
                    self.membrane,
                    &mask,
                    self.model.shadow_px,
                    self.model.spacing,
                )
            }
        };
        (depth, predicted)
    }

    /// The robust mean residual between the measured signature and [`Self::predict`] (metres²; lower is better).
    pub fn cost(&self, pose: Se2) -> f64 {
        let predicted = self.predict(pose);
        let (mut sum, mut n) = (0.0, 0usize);
        for ((&s, &p), &e) in self
            .signature
            .data
            .iter()
            .zip(&predicted.data)
            .zip(&self.membrane.data)
        {
            if s > 0.0 && s.is_finite() && e > 0.0 {
                sum += RobustLoss::Cauchy
                    .eval(f64::from(s - p), self.config.scale_m)
                    .0;
                n += 1;
            }
        }
        if n == 0 {
            f64::INFINITY
        } else {
            sum / n as f64
        }
    }

    /// Pattern search on [`Self::cost`] from `start`: the six axis moves (x, y, θ at the lever arm), the step halved
    /// when none improves. Returns the pose, its cost and the evaluations used.
    pub fn refine(&self, start: Se2) -> (Se2, f64, usize) {
        let cfg = self.config;
        let mut best = (start, self.cost(start));
        let mut evaluations = 1;
        let mut step = cfg.step_m;
        while step >= cfg.min_step_m && evaluations < cfg.max_evaluations {
            let rot = step / cfg.lever_m;
            let moves = [
                (step, 0.0, 0.0),
                (-step, 0.0, 0.0),
                (0.0, step, 0.0),
                (0.0, -step, 0.0),
                (0.0, 0.0, rot),
                (0.0, 0.0, -rot),
            ];
            let mut improved = false;
            for (dx, dy, dt) in moves {
                let q = Se2::new(best.0.x + dx, best.0.y + dy, wrap_angle(best.0.theta + dt));
                let c = self.cost(q);
                evaluations += 1;
                if c < best.1 {
                    best = (q, c);
                    improved = true;
                }
                if evaluations >= cfg.max_evaluations {
                    break;
                }
            }
            if !improved {
                step *= 0.5;
            }
        }
        (best.0, best.1, evaluations)
    }

    /// Pixels the cost averages over (S and E both measured).
    pub fn measured_pixels(&self) -> usize {
        self.signature
            .data
            .iter()
            .zip(&self.membrane.data)
            .filter(|(&s, &e)| s > 0.0 && s.is_finite() && e > 0.0)
            .count()
    }

    /// Score every hypothesis pose, refine the registration's best (`poses[0]`) and the
    /// [`SignatureCheckConfig::refine`] lowest-scoring distinct others, and return the refined best unless another
    /// explains the signature better by more than [`SignatureCheckConfig::margin_nats`] of log-likelihood (the
    /// registration, which saw the de-rendered contact, keeps the say where the signature cannot tell the poses
    /// apart); `None` when `poses` is empty.
    pub fn select(&self, poses: &[Se2]) -> Result<Option<Checked>, PoseError> {
        Ok(self.select_all(poses)?.map(|(c, _)| c))
    }

    /// [`Self::select`], with every refined candidate (pose, cost) beside the pick, for [`Self::posterior`].
    pub fn select_all(
        &self,
        poses: &[Se2],
    ) -> Result<Option<(Checked, Vec<Candidate>)>, PoseError> {
        self.validate()?;
        let mut scored: Vec<(usize, Se2, f64)> = Vec::with_capacity(poses.len());
        for (i, &p) in poses.iter().enumerate() {
            let same = |q: &Se2| {
                (q.x - p.x).hypot(q.y - p.y)
                    + wrap_angle(q.theta - p.theta).abs() * self.config.lever_m
                    < self.config.min_step_m
            };
            if !scored.iter().any(|(_, q, _)| same(q)) {
                scored.push((i, p, self.cost(p)));
            }
        }
        let mut evaluations = scored.len();
        let Some(&first) = scored.first() else {
            return Ok(None);
        };
        scored.sort_by(|a, b| a.2.total_cmp(&b.2));
        // Without refinement every hypothesis competes as scored; with it, the refined ones (the lower-scoring
        // rest cannot beat them).
        let others = match self.config.refine {
            0 => usize::MAX,
            k => k,
        };
        let mut candidates = vec![first];
        candidates.extend(scored.iter().filter(|c| c.0 != first.0).take(others));
        // Each refinement is its own pattern search: in parallel, collected in order (the same pick on any
        // number of threads).
        let refined: Vec<Checked> = candidates
            .par_iter()
            .map(|&(from, p, c)| {
                let (pose, cost, evaluations) = if self.config.refine > 0 {
                    self.refine(p)
                } else {
                    (p, c, 0)
                };
                Checked {
                    pose,
                    cost,
                    from,
                    evaluations,
                    rival: None,
                }
            })
            .collect();
        evaluations += refined.iter().map(|c| c.evaluations).sum::<usize>();
        // A cost difference ΔC over n pixels is n·ΔC/σ² nats of Gaussian log-likelihood.
        let margin = self.config.margin_nats / self.nats_per_cost();
        let registered = refined[0];
        let best = refined
            .iter()
            .copied()
            .min_by(|a, b| a.cost.total_cmp(&b.cost))
            .filter(|b| b.cost < registered.cost - margin)
            .unwrap_or(registered);
        let nats_per_cost = self.nats_per_cost();
        let rival = refined
            .iter()
            .filter(|c| {
                let apart_mm = (c.pose.x - best.pose.x).hypot(c.pose.y - best.pose.y) * 1e3;
                let apart_deg = wrap_angle(c.pose.theta - best.pose.theta)
                    .abs()
                    .to_degrees();
                apart_mm > MODE_POSITION_MM || apart_deg > MODE_THETA_DEG
            })
            .min_by(|a, b| a.cost.total_cmp(&b.cost))
            .map(|c| Rival {
                pose: c.pose,
                nats: (c.cost - best.cost) * nats_per_cost,
            });
        let candidates = refined.iter().map(|c| (c.pose, c.cost)).collect();
        Ok(Some((
            Checked {
                evaluations,
                rival,
                ..best
            },
            candidates,
        )))
    }

    /// Nats of log-likelihood per unit of [`Self::cost`]: the measured pixels over the noise variance (the cost is a
    /// mean of ρ ≈ r²/2).
    pub fn nats_per_cost(&self) -> f64 {
        self.measured_pixels().max(1) as f64
            / (self.model.noise_std * self.model.noise_std).max(1e-30)
    }

    /// The pose posterior of refined `candidates` (pose, cost) from [`Self::select_all`] for an object with
    /// `symmetry` ([`super::posterior`]): distinct candidates (at most `config.max_modes`, the best first) with
    /// their Δ nats and the Hessian of the negative log-likelihood by central differences.
    pub fn posterior(
        &self,
        candidates: &[(Se2, f64)],
        symmetry: &crate::objects::Symmetry,
        config: &PosteriorConfig,
    ) -> Result<PosePosterior, PoseError> {
        config.validate()?;
        let scale = self.nats_per_cost();
        let mut order: Vec<(Se2, f64)> = candidates
            .iter()
            .copied()
            .filter(|c| c.1.is_finite())
            .collect();
        order.sort_by(|a, b| a.1.total_cmp(&b.1));
        let mut distinct: Vec<(Se2, f64)> = Vec::new();
        for c in order {
            if distinct.len() < config.max_modes
                && !distinct.iter().any(|d| same_pose(c.0, d.0, symmetry))
            {
                distinct.push(c);
            }
        }
        let best = distinct.first().map_or(0.0, |c| c.1);
        let evidence: Vec<ModeEvidence> = distinct
            .par_iter()
            .map(|&(pose, cost)| ModeEvidence {
                pose,
                nats: (cost - best) * scale,
                hessian: self.hessian(pose, cost, config.step_m, config.lever_m, scale),
            })
            .collect();
        let contact_px = self
            .signature
            .data
            .iter()
            .zip(&self.membrane.data)
            .filter(|(&s, &e)| {
                s > 0.0 && s.is_finite() && e > 0.0 && f64::from(e - s) > config.contact_threshold_m
            })
            .count();
        // The best pose's prediction, rendered once for its contact, the frame's noise and the contact's misfit.
        let best_fit = distinct.first().map(|&(pose, _)| self.render(pose));
        let predicted_contact_px = best_fit
            .as_ref()
            .map(|(depth, _)| self.contact_px_of(depth));
        let noise = best_fit.as_ref().and_then(|(depth, predicted)| {
            self.residual_noise_of(predicted)
                .map(|measured_m| FrameNoise {
                    assumed_m: self.model.noise_std,
                    measured_m,
                    contact_rms_m: self.contact_misfit_of(
                        depth,
                        predicted,
                        config.contact_threshold_m,
                    ),
                })
        });
        Ok(PosePosterior::from_evidence_with(
            &evidence,
            contact_px,
            predicted_contact_px,
            noise,
            symmetry,
            config,
        ))
    }

    /// The measured signature's noise about [`Self::predict`] at `pose`, metres: 1.4826 × the median absolute
    /// deviation of S − Ŝ over the measured pixels (robust to the pixels the prediction gets wrong, so it is the
    /// noise of the frame as the check sees it, not the contact's misfit); `None` with fewer than
    /// [`MIN_NOISE_PIXELS`] measured pixels.
    pub fn residual_noise(&self, pose: Se2) -> Option<f64> {
        self.residual_noise_of(&self.predict(pose))
    }

    /// [`Self::residual_noise`] about the prediction `predicted`.
    fn residual_noise_of(&self, predicted: &Image) -> Option<f64> {
        let mut r: Vec<f64> = self
            .signature
            .data
            .iter()
            .zip(&predicted.data)
            .zip(&self.membrane.data)
            .filter(|((&s, _), &e)| s > 0.0 && s.is_finite() && e > 0.0)
            .map(|((&s, &p), _)| f64::from(s - p))
            .collect();
        if r.len() < MIN_NOISE_PIXELS {
            return None;
        }
        let centre = median_of(&mut r);
        let mut deviation: Vec<f64> = r.iter().map(|v| (v - centre).abs()).collect();
        Some(1.4826 * median_of(&mut deviation))
    }

    /// RMS of the measured signature about [`Self::predict`] at `pose` over the contact, predicted or measured
    /// (where the object at `pose` reaches in front of the membrane, or the signature lies in front of it by more
    /// than `threshold_m`), metres: what the pose leaves unexplained where the object touches — the frame's noise
    /// for a pose that explains the contact, more for one that does not. `None` with fewer than
    /// [`MIN_MISFIT_PIXELS`] such pixels measured.
    pub fn contact_misfit(&self, pose: Se2, threshold_m: f64) -> Option<f64> {
        let (depth, predicted) = self.render(pose);
        self.contact_misfit_of(&depth, &predicted, threshold_m)
    }

    /// [`Self::contact_misfit`] with the object's `depth` and the signature `predicted` from it.
    fn contact_misfit_of(&self, depth: &Image, predicted: &Image, threshold_m: f64) -> Option<f64> {
        let (mut sum, mut n) = (0.0, 0usize);
        for (((&s, &p), &d), &e) in self
            .signature
            .data
            .iter()
            .zip(&predicted.data)
            .zip(&depth.data)
            .zip(&self.membrane.data)
        {
            let measured = s > 0.0 && s.is_finite() && e > 0.0;
            let touches = in_contact(d, e) || f64::from(e - s) > threshold_m;
            if measured && touches {
                sum += f64::from(s - p).powi(2);
                n += 1;
            }
        }
        (n >= MIN_MISFIT_PIXELS).then(|| (sum / n as f64).sqrt())
    }

    /// The contact pixels with the object at `pose`: where it reaches in front of the membrane (the contact mask
    /// [`Self::predict`] renders), free of the sensor's noise.
    pub fn contact_px_at(&self, pose: Se2) -> usize {
        self.contact_px_of(&self.object_depth(pose))
    }

    /// [`Self::contact_px_at`] of the object's `depth`.
    fn contact_px_of(&self, depth: &Image) -> usize {
        depth
            .data
            .iter()
            .zip(&self.membrane.data)
            .filter(|(&d, &e)| in_contact(d, e))
            .count()
    }

    /// Hessian of `scale · cost` at `pose` (whose cost is `at`) over (x m, y m, θ rad): central differences with
    /// step `step_m` in x and y and `step_m / lever_m` in θ.
    fn hessian(&self, pose: Se2, at: f64, step_m: f64, lever_m: f64, scale: f64) -> Mat3 {
        let h = [step_m, step_m, step_m / lever_m];
        let f = |d: [f64; 3]| self.cost(Se2::new(pose.x + d[0], pose.y + d[1], pose.theta + d[2]));
        let unit = |i: usize, s: f64| {
            let mut d = [0.0; 3];
            d[i] = s * h[i];
            d
        };
        let mut m = [[0.0; 3]; 3];
        for i in 0..3 {
            m[i][i] = (f(unit(i, 1.0)) - 2.0 * at + f(unit(i, -1.0))) / (h[i] * h[i]) * scale;
            for j in 0..i {
                let both = |si: f64, sj: f64| {
                    let mut d = unit(i, si);
                    d[j] = sj * h[j];
                    f(d)
                };
                let v = (both(1.0, 1.0) - both(1.0, -1.0) - both(-1.0, 1.0) + both(-1.0, -1.0))
                    / (4.0 * h[i] * h[j])
                    * scale;
                m[i][j] = v;
                m[j][i] = v;
            }
        }
        m
    }
}

/// The object's depth `d` lies in front of the membrane's `e` (both seen): the contact mask [`SignatureCheck::predict`]
/// renders.
fn in_contact(d: f32, e: f32) -> bool {
    d > 0.0 && e > 0.0 && d < e
}

/// The membrane as this measurement's reference frame R = S + Y shows it: the nominal E plus the measured offset
/// R − E averaged over a (2·`radius_px` + 1)² window (the sensor noise averaged out, a drifted inflation kept),
/// where E is seen; elsewhere E (metres).
pub fn measured_membrane(
    nominal: &Image,
    signature: &Image,
    imprint: &Image,
    radius_px: usize,
) -> Result<Image, PoseError> {
    let (w, h) = (nominal.width, nominal.height);
    for (what, img) in [("signature", signature), ("imprint", imprint)] {
        if (img.width, img.height) != (w, h) {
            return Err(PoseError::Config(format!(
                "signature check: the {what} is {}x{} pixels, the membrane {w}x{h}",
                img.width, img.height
            )));
        }
    }
    let offset: Vec<Option<f64>> = (0..w * h)
        .map(|i| {
            let (e, s, y) = (nominal.data[i], signature.data[i], imprint.data[i]);
            (e > 0.0 && s > 0.0 && (s + y).is_finite() && s + y > 0.0)
                .then(|| f64::from(s + y) - f64::from(e))
        })
        .collect();
    let mut out = nominal.clone();
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            if nominal.data[i] <= 0.0 {
                continue;
            }
            let (mut sum, mut n) = (0.0, 0usize);
            for vv in v.saturating_sub(radius_px)..(v + radius_px + 1).min(h) {
                for uu in u.saturating_sub(radius_px)..(u + radius_px + 1).min(w) {
                    if let Some(d) = offset[vv * w + uu] {
                        sum += d;
                        n += 1;
                    }
                }
            }
            if n > 0 {
                out.data[i] = (f64::from(nominal.data[i]) + sum / n as f64) as f32;
            }
        }
    }
    Ok(out)
}
