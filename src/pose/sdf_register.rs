//! CHSEL-inspired **SE(2) registration** (paper IV.C; Zhong et al., "CHSEL", RSS 2023): the object pose q = (x, y, θ)
//! minimises a robust cost with two terms, both read from the object's signed distance φ in the object frame:
//!
//! * surface: every contact point should lie on the surface, residual `φ(p_obj)`;
//! * free space: every free-space point must be outside the object, residual `min(0, φ(p_obj))`,
//!
//! with `p_obj = R(θ)ᵀ (p_world − (x, y, 0))` and the cost
//! `C(q) = (Σ_surface ρ(r) + w_free Σ_free ρ(r)) / N_surface` for a robust ρ with scale `c`
//! ([`RobustLoss`]). Each start is refined by Levenberg–Marquardt on iteratively reweighted Gauss–Newton normal
//! equations (analytic Jacobian from the SDF gradient), first on the cached [`SdfGrid`] with the scale annealed from
//! `initial_scale_m` down to `scale_m` (wide basin first, outlier rejection last), then polished on the
//! [`ExactSdf`]. Every hypothesis's final cost is evaluated on the exact SDF at scale `scale_m`.

use std::sync::Arc;

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::register::{wrap_angle, Hypothesis, Registration, RegistrationProblem};
use super::sdf::{ExactSdf, ObjectSdf};
use super::sdf_grid::{ExactOnGrid, SdfGrid, SdfGridConfig};
use super::PoseError;
use crate::mesh::Mesh;
use crate::sensor::Se2;

/// Grid optima closer than this (translation plus rotation at the lever arm, metres) are one optimum: polished once.
const DUPLICATE_M: f64 = 2e-5;

/// Free-space points whose grid distance exceeds this (metres) are certainly outside the object (the grid's error
/// is below 0.3 spacing) and are skipped on the exact SDF.
const FREE_SKIP_M: f64 = 0.002;

/// Relative cost decrease below which a Levenberg–Marquardt run has converged.
const REL_DECREASE: f64 = 1e-7;

/// Which signed distance a solver pass reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Field {
    Grid,
    Exact,
}

/// The robust loss ρ(r) with scale c.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RobustLoss {
    /// ρ = r²/2 (not robust).
    L2,
    /// ρ = r²/2 for |r| ≤ c, c(|r| − c/2) beyond.
    Huber,
    /// ρ = c²/2 · ln(1 + (r/c)²): outliers far beyond c barely count.
    Cauchy,
}

impl RobustLoss {
    /// `(ρ(r), w(r))` with the IRLS weight `w = ρ'(r) / r`.
    #[inline]
    pub fn eval(self, r: f64, c: f64) -> (f64, f64) {
        match self {
            RobustLoss::L2 => (0.5 * r * r, 1.0),
            RobustLoss::Huber => {
                let a = r.abs();
                if a <= c {
                    (0.5 * r * r, 1.0)
                } else {
                    (c * (a - 0.5 * c), c / a)
                }
            }
            RobustLoss::Cauchy => {
                let s = (r / c) * (r / c);
                (0.5 * c * c * s.ln_1p(), 1.0 / (1.0 + s))
            }
        }
    }
}

/// Settings of [`SdfRegistration`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SdfRegistrationConfig {
    /// Robust loss (default Cauchy).
    pub loss: RobustLoss,
    /// Final robust scale c, metres (default 1 mm: residuals well beyond it are treated as outliers).
    pub scale_m: f64,
    /// Starting robust scale, metres, halved every iteration down to `scale_m` (default 8 mm).
    pub initial_scale_m: f64,
    /// Weight of one free-space point relative to one surface point (default 1).
    pub free_weight: f64,
    /// Levenberg–Marquardt iterations on the grid (default 40).
    pub max_iterations: usize,
    /// Levenberg–Marquardt iterations on the exact SDF after the grid (default 4).
    pub exact_iterations: usize,
    /// Polish on the exact SDF only the hypotheses whose grid cost is at most this multiple of the best one
    /// (default 3); the others keep their grid optimum.
    pub refine_cost_ratio: f64,
    /// Stop when a step moves less than this, metres (rotation measured as the arc at `lever_m`) (default 0.1 µm on
    /// the exact SDF; 10x that on the grid).
    pub step_tolerance_m: f64,
    /// Lever arm converting rotation steps to lengths for the tolerance and step limits, metres (default 20 mm).
    pub lever_m: f64,
    /// Largest step per iteration, metres (default 5 mm; rotation at most `max_step_m / lever_m` rad).
    pub max_step_m: f64,
    /// The cached SDF grid.
    pub grid: SdfGridConfig,
    /// Refine the starts in parallel (rayon).
    pub parallel: bool,
}

impl Default for SdfRegistrationConfig {
    fn default() -> Self {
        Self {
            loss: RobustLoss::Cauchy,
            scale_m: 0.001,
            initial_scale_m: 0.008,
            free_weight: 1.0,
            max_iterations: 40,
            exact_iterations: 4,
            refine_cost_ratio: 3.0,
            step_tolerance_m: 1e-7,
            lever_m: 0.02,
            max_step_m: 0.005,
            grid: SdfGridConfig::default(),
            parallel: true,
        }
    }
}

impl SdfRegistrationConfig {
    pub(crate) fn validate(&self) -> Result<(), PoseError> {
        let positive = [
            ("scale_m", self.scale_m),
            ("initial_scale_m", self.initial_scale_m),
            ("lever_m", self.lever_m),
            ("max_step_m", self.max_step_m),
            ("step_tolerance_m", self.step_tolerance_m),
        ];
        super::check_settings(
            "registration: ",
            &positive,
            &[("free_weight", self.free_weight)],
        )
    }
}

/// The CHSEL-inspired registration of one object mesh (SDF grid built once; reuse it for many problems).
pub struct SdfRegistration {
    exact: Arc<ExactSdf>,
    grid: SdfGrid,
    config: SdfRegistrationConfig,
    /// Object z range (object frame = world z for SE(2) poses): free points outside it can never be inside.
    z_range: (f64, f64),
}

/// Sums of one linearisation: cost, JᵀWJ and JᵀWr.
struct Normal {
    cost: f64,
    h: DMat3,
    g: DVec3,
}

impl SdfRegistration {
    /// Prepare an object mesh (object frame, resting pose; any triangle soup): exact SDF and its grid.
    pub fn new(mesh: &Mesh, config: SdfRegistrationConfig) -> Result<Self, PoseError> {
        config.validate()?;
        let exact = Arc::new(ExactSdf::new(mesh)?);
        let grid = SdfGrid::build(exact.clone(), &config.grid)?;
        let (lo, hi) = exact.aabb();
        Ok(Self {
            exact,
            grid,
            config,
            z_range: (lo.z, hi.z),
        })
    }

    /// The settings.
    pub fn config(&self) -> &SdfRegistrationConfig {
        &self.config
    }

    /// The exact object SDF.
    pub fn exact_sdf(&self) -> &ExactSdf {
        &self.exact
    }

    /// The cached grid.
    pub fn grid(&self) -> &SdfGrid {
        &self.grid
    }

    /// The cost C(q) on the exact SDF at the final scale (what hypotheses report).
    pub fn cost(&self, problem: &RegistrationProblem<'_>, pose: Se2) -> f64 {
        let free = self.relevant_free(problem.free);
        self.linearise(
            Field::Exact,
            problem.surface,
            &free,
            pose,
            self.config.scale_m,
            false,
        )
        .cost
    }

    fn relevant_free(&self, free: &[DVec3]) -> Vec<DVec3> {
        free.iter()
            .copied()
            .filter(|p| p.z >= self.z_range.0 && p.z <= self.z_range.1)
            .collect()
    }

    /// Cost and (optionally) the weighted normal equations at `pose`.
    fn linearise(
        &self,
        field: Field,
        surface: &[DVec3],
        free: &[DVec3],
        pose: Se2,
        scale: f64,
        jacobian: bool,
    ) -> Normal {
        let exact = ExactOnGrid(&self.grid);
        let sdf: &dyn ObjectSdf = match field {
            Field::Grid => &self.grid,
            Field::Exact => &exact,
        };
        let (s, c) = pose.theta.sin_cos();
        let mut n = Normal {
            cost: 0.0,
            h: DMat3::ZERO,
            g: DVec3::ZERO,
        };
        let loss = self.config.loss;
        let mut add = |p: DVec3, free_point: bool, weight: f64| {
            let (dx, dy) = (p.x - pose.x, p.y - pose.y);
            let p_obj = DVec3::new(c * dx + s * dy, -s * dx + c * dy, p.z);
            if free_point && field == Field::Exact && self.grid.value(p_obj) > FREE_SKIP_M {
                return;
            }
            let (phi, grad) = if jacobian {
                sdf.value_grad(p_obj)
            } else {
                (sdf.value(p_obj), DVec3::ZERO)
            };
            let r = if free_point { phi.min(0.0) } else { phi };
            if free_point && r == 0.0 {
                return;
            }
            let (rho, w) = loss.eval(r, scale);
            n.cost += weight * rho;
            if jacobian {
                // d p_obj / d(x, y, theta) = (-c, s), (-s, -c), (y_obj, -x_obj).
                let j = DVec3::new(
                    -grad.x * c + grad.y * s,
                    -grad.x * s - grad.y * c,
                    grad.x * p_obj.y - grad.y * p_obj.x,
                );
                let wj = j * (weight * w);
                n.h += DMat3::from_cols(wj * j.x, wj * j.y, wj * j.z);
                n.g += wj * r;
            }
        };
        for &p in surface {
            add(p, false, 1.0);
        }
        if self.config.free_weight > 0.0 {
            for &p in free {
                add(p, true, self.config.free_weight);
            }
        }
        let norm = 1.0 / surface.len().max(1) as f64;
        n.cost *= norm;
        n.h *= norm;
        n.g *= norm;
        n
    }

    /// Levenberg–Marquardt from `pose` on `sdf`; `anneal` halves the robust scale each iteration from
    /// `initial_scale_m` to `scale_m`. Returns the pose and the iterations used.
    fn solve(
        &self,
        field: Field,
        surface: &[DVec3],
        free: &[DVec3],
        mut pose: Se2,
        iterations: usize,
        anneal: bool,
    ) -> (Se2, usize) {
        let cfg = &self.config;
        let mut scale = if anneal {
            cfg.initial_scale_m.max(cfg.scale_m)
        } else {
            cfg.scale_m
        };
        // The grid pass only has to land in the exact optimum's basin: a 10x looser tolerance.
        let tolerance = if field == Field::Grid {
            10.0 * cfg.step_tolerance_m
        } else {
            cfg.step_tolerance_m
        };
        let mut mu = 1e-3;
        let max_rot = cfg.max_step_m / cfg.lever_m;
        let mut used = 0;
        for it in 0..iterations {
            used = it + 1;
            let n = self.linearise(field, surface, free, pose, scale, true);
            let mut moved = None;
            for _ in 0..12 {
                let diag = DVec3::new(n.h.x_axis.x, n.h.y_axis.y, n.h.z_axis.z);
                let damp = diag * mu + DVec3::splat(1e-12 * (diag.x + diag.y + diag.z) + 1e-18);
                let a = n.h + DMat3::from_diagonal(damp);
                if a.determinant().abs() < f64::MIN_POSITIVE {
                    mu *= 10.0;
                    continue;
                }
                let mut step = -(a.inverse() * n.g);
                // Limit the step (translation and rotation separately).
                let t = (step.x * step.x + step.y * step.y).sqrt();
                if t > cfg.max_step_m {
                    step.x *= cfg.max_step_m / t;
                    step.y *= cfg.max_step_m / t;
                }
                step.z = step.z.clamp(-max_rot, max_rot);
                let candidate = Se2::new(pose.x + step.x, pose.y + step.y, pose.theta + step.z);
                let cost = self
                    .linearise(field, surface, free, candidate, scale, false)
                    .cost;
                if cost <= n.cost {
                    mu = (mu / 3.0).max(1e-9);
                    moved = Some((candidate, step, n.cost - cost));
                    break;
                }
                mu *= 4.0;
            }
            let shrinking = scale > cfg.scale_m;
            scale = (scale * 0.5).max(cfg.scale_m);
            match moved {
                Some((candidate, step, decrease)) => {
                    pose = candidate;
                    let size =
                        (step.x * step.x + step.y * step.y).sqrt() + step.z.abs() * cfg.lever_m;
                    // Converged: a tiny step, or (noisy data, slow IRLS tail) a negligible relative decrease.
                    if !shrinking && (size < tolerance || decrease <= REL_DECREASE * n.cost) {
                        break;
                    }
                }
                None if !shrinking => break,
                None => {}
            }
        }
        pose.theta = wrap_angle(pose.theta);
        (pose, used)
    }
}

impl Registration for SdfRegistration {
    fn name(&self) -> &'static str {
        "sdf-lm"
    }

    fn refine(
        &self,
        problem: &RegistrationProblem<'_>,
        inits: &[Se2],
    ) -> Result<Vec<Hypothesis>, PoseError> {
        problem.validate()?;
        let free = self.relevant_free(problem.free);
        let surface = problem.surface;
        let coarse = |&init: &Se2| {
            let (pose, iterations) = self.solve(
                Field::Grid,
                surface,
                &free,
                init,
                self.config.max_iterations,
                true,
            );
            let cost = self
                .linearise(
                    Field::Grid,
                    surface,
                    &free,
                    pose,
                    self.config.scale_m,
                    false,
                )
                .cost;
            (init, pose, iterations, cost)
        };
        let coarse: Vec<_> = if self.config.parallel {
            inits.par_iter().map(coarse).collect()
        } else {
            inits.iter().map(coarse).collect()
        };
        let best = coarse.iter().map(|c| c.3).fold(f64::INFINITY, f64::min);
        let limit = best * self.config.refine_cost_ratio + 1e-15;
        // Starts that reached the same grid optimum (within DUPLICATE_M) share one polish on the exact SDF.
        let mut groups: Vec<(Se2, Vec<usize>)> = Vec::new();
        for (i, c) in coarse.iter().enumerate() {
            let same = |g: &Se2| {
                let d = (g.x - c.1.x).hypot(g.y - c.1.y)
                    + wrap_angle(g.theta - c.1.theta).abs() * self.config.lever_m;
                d < DUPLICATE_M
            };
            match groups.iter_mut().find(|(g, _)| same(g)) {
                Some((_, members)) => members.push(i),
                None => groups.push((c.1, vec![i])),
            }
        }
        let fine = |(pose, members): &(Se2, Vec<usize>)| {
            let (pose, more) = if members.iter().any(|&i| coarse[i].3 <= limit) {
                self.solve(
                    Field::Exact,
                    surface,
                    &free,
                    *pose,
                    self.config.exact_iterations,
                    false,
                )
            } else {
                (*pose, 0)
            };
            let cost = self
                .linearise(
                    Field::Exact,
                    surface,
                    &free,
                    pose,
                    self.config.scale_m,
                    false,
                )
                .cost;
            (pose, more, cost)
        };
        let polished: Vec<(Se2, usize, f64)> = if self.config.parallel {
            groups.par_iter().map(fine).collect()
        } else {
            groups.iter().map(fine).collect()
        };
        let mut out: Vec<Option<Hypothesis>> = vec![None; coarse.len()];
        for ((_, members), &(pose, more, cost)) in groups.iter().zip(&polished) {
            for &i in members {
                let (init, _, iterations, _) = coarse[i];
                out[i] = Some(Hypothesis {
                    init,
                    pose,
                    cost,
                    iterations: iterations + more,
                });
            }
        }
        Ok(out.into_iter().flatten().collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_losses_and_weights() {
        for loss in [RobustLoss::L2, RobustLoss::Huber, RobustLoss::Cauchy] {
            // Near zero every loss is r²/2 with weight 1.
            let (rho, w) = loss.eval(1e-6, 1e-3);
            assert!((rho - 0.5e-12).abs() < 1e-16 && (w - 1.0).abs() < 1e-5);
            // The weight is rho'(r)/r (central difference).
            let (r, c, h) = (2.5e-3, 1e-3, 1e-9);
            let d = (loss.eval(r + h, c).0 - loss.eval(r - h, c).0) / (2.0 * h);
            assert!((d / r - loss.eval(r, c).1).abs() < 1e-6, "{loss:?}");
        }
        assert!(RobustLoss::Cauchy.eval(0.1, 1e-3).0 < RobustLoss::Huber.eval(0.1, 1e-3).0);
    }
}
