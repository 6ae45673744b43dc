//! **Registration** of the object mesh to the reconstructed contact (paper IV.C, "pose estimation"): the
//! [`Registration`] trait (one implementation per file, e.g. [`super::sdf_register`]), the problem it solves, its
//! hypotheses, and the initialisation strategies (K random starts, the paper's 10, or one fixed start for the
//! uncertainty analysis of V.D).

use glam::DVec3;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use super::PoseError;
use crate::sensor::Se2;

/// What a registration sees, in the world frame (metres): points on the object's surface (back-projected contact)
/// and points known to be outside the object (free space: the undeformed membrane away from contact and the camera
/// rays in front of what is seen).
#[derive(Clone, Copy, Debug)]
pub struct RegistrationProblem<'a> {
    /// Contact points, `p_world`.
    pub surface: &'a [DVec3],
    /// Free-space points, `p_world`.
    pub free: &'a [DVec3],
}

impl RegistrationProblem<'_> {
    /// Reject empty contact and non-finite points.
    pub fn validate(&self) -> Result<(), PoseError> {
        if self.surface.is_empty() {
            return Err(PoseError::NoContact);
        }
        if let Some(index) = self.surface.iter().position(|p| !p.is_finite()) {
            return Err(PoseError::NonFinite {
                what: "surface points",
                index,
            });
        }
        if let Some(index) = self.free.iter().position(|p| !p.is_finite()) {
            return Err(PoseError::NonFinite {
                what: "free-space points",
                index,
            });
        }
        Ok(())
    }

    /// Mean of the surface points.
    pub fn surface_centroid(&self) -> DVec3 {
        self.surface.iter().copied().sum::<DVec3>() / self.surface.len().max(1) as f64
    }
}

/// One local optimum: where it started, where it ended and at what cost.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hypothesis {
    /// Starting pose `t_world_object`.
    pub init: Se2,
    /// Estimated pose `t_world_object` (theta wrapped to (-pi, pi]).
    pub pose: Se2,
    /// Final cost (method-specific, lower is better; comparable between hypotheses of one call).
    #[serde(deserialize_with = "crate::io::null_as_nan")]
    pub cost: f64,
    /// Local-solver iterations used.
    pub iterations: usize,
}

/// A registration method: refine each starting pose to a local optimum of its cost.
pub trait Registration: Send + Sync {
    /// Short name for reports.
    fn name(&self) -> &'static str;
    /// One hypothesis per starting pose, in the order of `inits`.
    fn refine(
        &self,
        problem: &RegistrationProblem<'_>,
        inits: &[Se2],
    ) -> Result<Vec<Hypothesis>, PoseError>;
}

/// How starting poses are chosen.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitStrategy {
    /// `count` starts: yaw uniform in [0, 2pi), position the surface centroid's (x, y) plus a uniform offset in
    /// [-radius_m, radius_m] on each axis (the paper uses 10 starts).
    Random {
        count: usize,
        radius_m: f64,
        seed: u64,
    },
    /// One given start (the uncertainty analysis registers every sample from the same pose).
    Fixed(Se2),
    /// Given starts (what an earlier frame of the same contact found), then `random` random ones drawn as
    /// [`InitStrategy::Random`] does, so that a pose the earlier frames missed can still be found.
    Carried {
        starts: Vec<Se2>,
        random: usize,
        radius_m: f64,
        seed: u64,
    },
}

impl Default for InitStrategy {
    fn default() -> Self {
        InitStrategy::Random {
            count: 10,
            radius_m: 0.010,
            seed: 0,
        }
    }
}

/// The starting poses of `strategy` for `problem`.
pub fn initial_poses(
    strategy: &InitStrategy,
    problem: &RegistrationProblem<'_>,
) -> Result<Vec<Se2>, PoseError> {
    match *strategy {
        InitStrategy::Fixed(pose) => Ok(vec![pose]),
        InitStrategy::Carried {
            ref starts,
            random,
            radius_m,
            seed,
        } => {
            let mut poses = starts.clone();
            if random > 0 {
                poses.extend(initial_poses(
                    &InitStrategy::Random {
                        count: random,
                        radius_m,
                        seed,
                    },
                    problem,
                )?);
            }
            if poses.is_empty() {
                return Err(PoseError::Config(
                    "carried initialisation needs at least one start".into(),
                ));
            }
            Ok(poses)
        }
        InitStrategy::Random {
            count,
            radius_m,
            seed,
        } => {
            if count == 0 || !(radius_m.is_finite() && radius_m >= 0.0) {
                return Err(PoseError::Config(format!(
                    "random initialisation needs count >= 1 (got {count}) and a radius >= 0 m (got {radius_m})"
                )));
            }
            let c = problem.surface_centroid();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            Ok((0..count)
                .map(|_| {
                    let theta = rng.random_range(0.0..std::f64::consts::TAU);
                    let dx = rng.random_range(-1.0..=1.0) * radius_m;
                    let dy = rng.random_range(-1.0..=1.0) * radius_m;
                    Se2::new(c.x + dx, c.y + dy, wrap_angle(theta))
                })
                .collect())
        }
    }
}

/// Register: validate, choose the starts, refine each, and return every hypothesis sorted by cost (best first).
pub fn register(
    method: &dyn Registration,
    problem: &RegistrationProblem<'_>,
    strategy: &InitStrategy,
) -> Result<Vec<Hypothesis>, PoseError> {
    problem.validate()?;
    let inits = initial_poses(strategy, problem)?;
    let mut hypotheses = method.refine(problem, &inits)?;
    hypotheses.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    Ok(hypotheses)
}

/// `angle` wrapped to (-pi, pi].
pub fn wrap_angle(angle: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let a = angle.rem_euclid(TAU);
    if a > PI {
        a - TAU
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn carried_starts_come_first_then_the_random_ones_random_would_draw() {
        let surface = [DVec3::new(0.01, 0.02, 0.0), DVec3::new(0.03, 0.0, 0.0)];
        let problem = RegistrationProblem {
            surface: &surface,
            free: &[],
        };
        let given = vec![Se2::new(0.001, 0.002, 0.3), Se2::new(-0.001, 0.0, 2.0)];
        let carried = InitStrategy::Carried {
            starts: given.clone(),
            random: 3,
            radius_m: 0.005,
            seed: 9,
        };
        let random = InitStrategy::Random {
            count: 3,
            radius_m: 0.005,
            seed: 9,
        };
        let poses = initial_poses(&carried, &problem).unwrap();
        assert_eq!(poses[..2], given[..]);
        assert_eq!(poses[2..], initial_poses(&random, &problem).unwrap()[..]);
        // Without random starts the given ones alone; with neither, an error naming the strategy.
        let only = InitStrategy::Carried {
            starts: given.clone(),
            random: 0,
            radius_m: 0.0,
            seed: 0,
        };
        assert_eq!(initial_poses(&only, &problem).unwrap(), given);
        let none = InitStrategy::Carried {
            starts: vec![],
            random: 0,
            radius_m: 0.0,
            seed: 0,
        };
        assert!(initial_poses(&none, &problem)
            .unwrap_err()
            .to_string()
            .contains("carried"));
    }

    #[test]
    fn random_starts_are_seeded_and_around_the_centroid() {
        let surface = [DVec3::new(0.01, 0.02, 0.0), DVec3::new(0.03, 0.0, 0.0)];
        let problem = RegistrationProblem {
            surface: &surface,
            free: &[],
        };
        let s = InitStrategy::Random {
            count: 10,
            radius_m: 0.005,
            seed: 4,
        };
        let a = initial_poses(&s, &problem).unwrap();
        assert_eq!(a.len(), 10);
        assert_eq!(a, initial_poses(&s, &problem).unwrap());
        assert!(a
            .iter()
            .all(|p| (p.x - 0.02).abs() <= 0.005 && (p.y - 0.01).abs() <= 0.005));
        assert!(a
            .iter()
            .all(|p| p.theta > -std::f64::consts::PI && p.theta <= std::f64::consts::PI));
        let fixed = Se2::new(1.0, 2.0, 0.5);
        assert_eq!(
            initial_poses(&InitStrategy::Fixed(fixed), &problem).unwrap(),
            vec![fixed]
        );
        let empty = RegistrationProblem {
            surface: &[],
            free: &[],
        };
        assert!(matches!(empty.validate(), Err(PoseError::NoContact)));
    }

    #[test]
    fn wrap_angle_range() {
        use std::f64::consts::PI;
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-12);
        assert!((wrap_angle(7.0) - (7.0 - 2.0 * PI)).abs() < 1e-12);
    }
}
