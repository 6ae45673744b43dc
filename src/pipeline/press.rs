//! # Placing the sensor: how far it is pressed into the object
//!
//! A Soft Bubble does not measure how deep it is pressed into the object, and the registration works in the world
//! frame, so the sensor has to be placed over the object before the samples are registered. [`PressChoice::Fixed`]
//! takes one press (a simulation's `--press`); [`PressChoice::Auto`] finds it from the data
//! ([`SensorPlacement::press`]): the least press is the one that puts the samples' highest contact point on the
//! object's top ([`press_from_samples`]: the object lies on the table and the sensor comes down on it, so the part
//! pressed first is its top); with a signature the press is then searched around it ([`PRESS_SEARCH_M`]: the
//! contact may be on a lower part than the top), each press judged by how well the pose registered there explains
//! the signature (the signature check's cost), and refined on a parabola through the best three. With a prior (a
//! track's previous frame, [`PosePrior`]) the search is a narrower one around its press, registered from its poses
//! only ([`CARRIED_PRESS_SEARCH_M`]): the object has not moved and the press changes little from frame to frame.

use std::fmt;
use std::str::FromStr;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{LoadedObject, PipelineError};
use crate::dataset::import_recording::DEFAULT_MAX_PRESS_M;
use crate::image::Image;
use crate::objects::ObjectSet;
use crate::pose::InitStrategy;
use crate::pose::{Estimator, PosePrior, SensorContext};
use crate::sim::{PreparedObject, Simulator};

/// Deepest press a [`PressChoice::Fixed`] takes, metres: the whole sensor is about 90 mm deep.
pub const DEEPEST_PRESS_M: f64 = 0.1;

/// How far the sensor is pressed into the object, for placing it over the object.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PressChoice {
    /// Per frame, from the samples: their highest contact point on the object's top.
    #[default]
    Auto,
    /// The same press for every frame, metres.
    Fixed(f64),
}

impl FromStr for PressChoice {
    type Err = crate::error::InvalidSetting;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        crate::error::InvalidSetting::wrap("press", || {
            if s == "auto" {
                return Ok(PressChoice::Auto);
            }
            match s.parse::<f64>() {
                Ok(p) if p.is_finite() && (0.0..=DEEPEST_PRESS_M).contains(&p) => {
                    Ok(PressChoice::Fixed(p))
                }
                Ok(p) if p > DEEPEST_PRESS_M => Err(format!(
                "press {p} m is deeper than the whole sensor; presses are in metres (6 mm is 0.006)"
            )),
                Ok(p) => Err(format!("press {p} m: a press is a depth of 0 m or more")),
                Err(_) => Err(format!("'{s}' is neither \"auto\" nor a press in metres")),
            }
        })
    }
}

impl fmt::Display for PressChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PressChoice::Auto => write!(f, "auto"),
            PressChoice::Fixed(p) => write!(f, "{p}"),
        }
    }
}

/// What placing the sensor over an object needs.
pub struct SensorPlacement<'a> {
    pub sim: &'a Simulator,
    pub object: &'a LoadedObject,
    /// The same object, prepared for rendering (its top and ray caster).
    pub prepared: &'a PreparedObject,
    /// The pose engine (its settings and prepared object models).
    pub engine: &'a Estimator,
    /// The camera's native pixels for resampled frames ([`super::Observation::camera_path`]).
    pub camera_path: Option<&'a std::sync::Arc<crate::pose::camera_path::CameraPath>>,
}

impl SensorPlacement<'_> {
    /// The press for `samples` of one imprint (module docs): `choice`'s own for [`PressChoice::Fixed`]; for
    /// [`PressChoice::Auto`] found from the samples, and searched with the `signature` when there is one (near the
    /// `prior`'s press when it has one). `None`: no sample has contact. `seed` draws the registration's starts.
    pub fn press(
        &self,
        choice: PressChoice,
        samples: &[Image],
        signature: Option<&Image>,
        imprint: &Image,
        prior: Option<&PosePrior>,
        seed: u64,
    ) -> Result<Option<f64>, PipelineError> {
        let least = match choice {
            PressChoice::Fixed(p) => return Ok(Some(p)),
            PressChoice::Auto => press_from_samples(
                self.sim,
                self.prepared,
                samples,
                signature,
                imprint,
                self.engine,
                DEFAULT_MAX_PRESS_M,
            )?,
        };
        // The previous frame's estimate alone: another press moves the pose little.
        let carried = prior
            .filter(|p| !p.poses.is_empty())
            .and_then(|p| p.press_m.map(|press| (press, &p.poses[..1])));
        match (least, signature, carried) {
            (Some(_), Some(signature), Some((press, starts))) => {
                search_carried_press(self, samples, signature, imprint, press, starts).map(Some)
            }
            (Some(least), Some(signature), None) => {
                search_press(self, samples, signature, imprint, least, seed).map(Some)
            }
            (least, _, _) => Ok(least),
        }
    }
}

/// The press that puts the highest contact point of `samples` (as the registration sees them: anchored onto the
/// signature, when there is one) on `object`'s top, clamped to `0..=max_press` metres; `None` when no sample has contact.
pub fn press_from_samples(
    sim: &Simulator,
    object: &PreparedObject,
    samples: &[Image],
    signature: Option<&Image>,
    imprint: &Image,
    engine: &Estimator,
    max_press: f64,
) -> Result<Option<f64>, PipelineError> {
    // At press 0 the sensor's apex is on the object's top; pressing p deeper moves every back-projected point p down.
    let t_world_camera = sim.t_world_camera(&sim.pressing_pose(object, 0.0, 0.0, 0.0, 0.0));
    let (anchored, _) = engine.anchor(samples, signature, imprint)?;
    let mut presses: Vec<f64> = anchored
        .iter()
        .filter_map(|s| {
            crate::recon::back_project(&interior(s), sim.intrinsics(), &t_world_camera)
                .p_world
                .iter()
                .map(|p| p.z)
                .fold(None, |m: Option<f64>, z| Some(m.map_or(z, |m| m.max(z))))
        })
        .map(|z_top| z_top - object.top_z)
        .collect();
    if presses.is_empty() {
        return Ok(None);
    }
    // The lower median: with two samples, the one that says less.
    presses.sort_by(f64::total_cmp);
    Ok(Some(presses[(presses.len() - 1) / 2].clamp(0.0, max_press)))
}

/// Presses tried around the least one [`press_from_samples`] gives, metres: mostly deeper (the contact may be on a
/// lower part than the object's top), a little shallower (the samples' own error).
pub const PRESS_SEARCH_M: [f64; 11] = [
    -0.001, -0.0005, 0.0, 0.0005, 0.001, 0.0015, 0.002, 0.003, 0.004, 0.005, 0.006,
];

/// Starts of the registrations at the searched presses: the pick at the least press and its next-best poses.
const SEARCH_STARTS: usize = 3;

/// The first sample with contact, the sensor as the frame sees it, the object's model.
type SearchInputs<'s> = (
    &'s Image,
    SensorContext,
    std::sync::Arc<crate::pose::ObjectModel>,
);

/// What a press search registers: the first of `samples` with contact, the sensor as a frame with `signature` sees
/// it (no free space where it has no return) and the object's model; `None` when no sample has contact.
fn search_inputs<'s>(
    at: &SensorPlacement<'_>,
    samples: &'s [Image],
    signature: &Image,
) -> Result<Option<SearchInputs<'s>>, PipelineError> {
    let Some(first) = samples
        .iter()
        .find(|s| s.data.iter().any(|&d| crate::recon::is_valid_depth(d)))
    else {
        return Ok(None);
    };
    let mut sensor = SensorContext::of_simulator(at.sim, ObjectSet::builtin());
    sensor.camera_path = at.camera_path.cloned();
    let seen = sensor.observing(Some(signature)).into_owned();
    let model = at
        .engine
        .object_from_mesh(&at.object.name, &at.object.mesh, at.object.symmetry)?;
    Ok(Some((first, seen, model)))
}

/// The press of [`PRESS_SEARCH_M`] around `least` whose pose (the first sample with contact registered from
/// the evaluation's random starts, then the signature check) best explains the signature.
fn search_press(
    at: &SensorPlacement<'_>,
    samples: &[Image],
    signature: &Image,
    imprint: &Image,
    least: f64,
    seed: u64,
) -> Result<f64, PipelineError> {
    let estimator = at.engine;
    let Some((first, ectx, model)) = search_inputs(at, samples, signature)? else {
        return Ok(least);
    };
    let measured = Some((signature, imprint));
    let place = |press: f64| {
        at.sim
            .t_world_camera(&at.sim.pressing_pose(at.prepared, 0.0, 0.0, 0.0, press))
    };
    let register = |t: &glam::DAffine3, strategy: &InitStrategy| {
        estimator.pooled_hypotheses(
            &model,
            std::slice::from_ref(first),
            &ectx,
            t,
            measured,
            strategy,
        )
    };
    // At the least press from the evaluation's random starts; at the others from its pick and best poses (another
    // press moves the pose little), a third of the work.
    let t = place(least);
    let hypotheses = register(&t, &estimator.random_starts(seed))?;
    let Some((pick, _, cost)) =
        estimator.choose_scored(&model, &hypotheses, &ectx, &t, measured)?
    else {
        return Ok(least);
    };
    let mut scores: Vec<(f64, f64)> = cost.map(|c| (least, c)).into_iter().collect();
    let mut starts = vec![pick];
    starts.extend(
        hypotheses
            .iter()
            .map(|h| h.pose)
            .filter(|p| *p != pick)
            .take(SEARCH_STARTS - 1),
    );
    for dp in PRESS_SEARCH_M {
        let press = least + dp;
        if dp == 0.0 || press < 0.0 {
            continue;
        }
        if press > DEFAULT_MAX_PRESS_M {
            break;
        }
        let t = place(press);
        let found: Result<Vec<_>, _> = starts
            .par_iter()
            .map(|&s| register(&t, &InitStrategy::Fixed(s)))
            .collect();
        let mut hypotheses: Vec<_> = found?.into_iter().flatten().collect();
        hypotheses.sort_by(|a, b| a.cost.total_cmp(&b.cost));
        if let Some((_, _, Some(cost))) =
            estimator.choose_scored(&model, &hypotheses, &ectx, &t, measured)?
        {
            scores.push((press, cost));
        }
    }
    scores.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(parabola_minimum(&scores).unwrap_or(least))
}

/// Presses tried around a track's previous press, metres: the sensor moves a little between frames, either way
/// (the parabola through the best three refines it; a 30 fps recording of a 1 s press moves ~0.5 mm a frame).
pub const CARRIED_PRESS_SEARCH_M: [f64; 7] = [-0.0015, -0.001, -0.0005, 0.0, 0.0005, 0.001, 0.0015];

/// The press of [`CARRIED_PRESS_SEARCH_M`] around `previous` whose pose, registered from `starts` (the previous
/// frame's estimate) alone, best explains the signature; the presses are registered in parallel.
fn search_carried_press(
    at: &SensorPlacement<'_>,
    samples: &[Image],
    signature: &Image,
    imprint: &Image,
    previous: f64,
    starts: &[crate::sensor::Se2],
) -> Result<f64, PipelineError> {
    let estimator = at.engine;
    let Some((first, ectx, model)) = search_inputs(at, samples, signature)? else {
        return Ok(previous);
    };
    let measured = Some((signature, imprint));
    let strategy = InitStrategy::Carried {
        starts: starts.to_vec(),
        random: 0,
        radius_m: 0.0,
        seed: 0,
    };
    let presses: Vec<f64> = CARRIED_PRESS_SEARCH_M
        .iter()
        .map(|dp| previous + dp)
        .filter(|p| (0.0..=DEFAULT_MAX_PRESS_M).contains(p))
        .collect();
    let scored: Result<Vec<Option<(f64, f64)>>, PipelineError> = presses
        .par_iter()
        .map(|&press| {
            let t = at
                .sim
                .t_world_camera(&at.sim.pressing_pose(at.prepared, 0.0, 0.0, 0.0, press));
            let hypotheses = estimator.pooled_hypotheses(
                &model,
                std::slice::from_ref(first),
                &ectx,
                &t,
                measured,
                &strategy,
            )?;
            Ok(estimator
                .choose_scored(&model, &hypotheses, &ectx, &t, measured)?
                .and_then(|(_, _, cost)| cost.map(|c| (press, c))))
        })
        .collect();
    let mut scores: Vec<(f64, f64)> = scored?.into_iter().flatten().collect();
    scores.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(parabola_minimum(&scores).unwrap_or(previous))
}

/// The lowest of the `(x, cost)` points (in increasing x), moved to the minimum of the parabola through it and
/// its two neighbours when it has both and they rise on either side; `None` when empty.
pub fn parabola_minimum(points: &[(f64, f64)]) -> Option<f64> {
    let k = (0..points.len()).min_by(|&a, &b| points[a].1.total_cmp(&points[b].1))?;
    if k == 0 || k + 1 == points.len() {
        return Some(points[k].0);
    }
    let ((x0, y0), (x1, y1), (x2, y2)) = (points[k - 1], points[k], points[k + 1]);
    // Vertex of the parabola through three points (any spacing).
    let num = (x1 - x0).powi(2) * (y1 - y2) - (x1 - x2).powi(2) * (y1 - y0);
    let den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0);
    if den.abs() < f64::EPSILON * y1.abs().max(1e-300) || !den.is_finite() {
        return Some(x1);
    }
    Some((x1 - 0.5 * num / den).clamp(x0, x2))
}

/// The contact pixels of `x` whose four neighbours are in contact too (a stray pixel of a sample cannot set the
/// press); all of them when none is.
fn interior(x: &Image) -> Image {
    let (w, h) = (x.width, x.height);
    let contact = |i: usize, j: usize| crate::recon::is_valid_depth(x.data[j * w + i]);
    let mut out = x.clone();
    let mut any = false;
    for j in 0..h {
        for i in 0..w {
            let inside = contact(i, j)
                && i > 0
                && j > 0
                && i + 1 < w
                && j + 1 < h
                && contact(i - 1, j)
                && contact(i + 1, j)
                && contact(i, j - 1)
                && contact(i, j + 1);
            if inside {
                any = true;
            } else {
                out.data[j * w + i] = 0.0;
            }
        }
    }
    if any {
        out
    } else {
        x.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn press_choice_parses_auto_and_metres_and_refuses_millimetres() {
        assert_eq!("auto".parse::<PressChoice>(), Ok(PressChoice::Auto));
        assert_eq!(
            "0.006".parse::<PressChoice>(),
            Ok(PressChoice::Fixed(0.006))
        );
        assert!("6"
            .parse::<PressChoice>()
            .unwrap_err()
            .message
            .contains("6 mm is 0.006"));
        assert!("deep".parse::<PressChoice>().is_err());
        assert_eq!(
            PressChoice::Fixed(0.006).to_string().parse(),
            Ok(PressChoice::Fixed(0.006))
        );
    }

    #[test]
    fn parabola_minimum_finds_the_vertex_of_a_sampled_parabola() {
        // Independent truth: the vertex of (x − 0.0042)² + 1, sampled on an uneven grid.
        let f = |x: f64| (x - 0.0042_f64).powi(2) + 1.0;
        let xs = [0.002, 0.0025, 0.003, 0.004, 0.005, 0.0065];
        let points: Vec<(f64, f64)> = xs.iter().map(|&x| (x, f(x))).collect();
        let v = parabola_minimum(&points).unwrap();
        assert!((v - 0.0042).abs() < 1e-12, "{v}");
        // At the ends there is no bracket: the lowest point itself.
        assert_eq!(parabola_minimum(&points[..3]), Some(0.003));
        assert_eq!(parabola_minimum(&[]), None);
    }
}
