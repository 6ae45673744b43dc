//! **Estimate the pose** of one signature from its de-rendered samples (paper IV.C registration, V.D uncertainty):
//! a K-start registration of the first sample with contact (every hypothesis, best first), then the uncertainty
//! analysis from that start ([`crate::uncertainty::analysis`]): every sample and the threshold baseline registered,
//! the multi-sample estimate (the samples' consensus contact), errors against the true pose when it is known, KDEs.

use glam::DAffine3;

use super::{LoadedObject, PipelineError, Progress};
use crate::image::Image;
use crate::metrics::evaluate::EvalError;
use crate::objects::ObjectSet;
use crate::pose::camera_path::CameraPath;
use crate::pose::posterior::PosePosterior;
use crate::pose::signature_check::Rival;
use crate::pose::{threshold_contact, Hypothesis};
use crate::pose::{Estimator, ObjectModel, PoseConfig, PosePrior, SensorContext};
use crate::recon::is_valid_depth;
use crate::sensor::Se2;
use crate::sim::Simulator;
use crate::uncertainty::analysis::{analyse_with_progress, first_registration, Signature};
use crate::uncertainty::UncertaintyReport;
use crate::uncertainty::{same_pose, SampleError};

/// What the sensor saw, placed: the camera's pose and the [`Observation`] (its fields read through `input.samples`
/// and so on).
#[derive(Clone, Copy, Debug)]
pub struct PoseInput<'a> {
    /// `t_world_camera` of the sensor camera.
    pub t_world_camera: DAffine3,
    /// The samples, the imprint, the signature and the truth.
    pub observation: Observation<'a>,
}

impl<'a> std::ops::Deref for PoseInput<'a> {
    type Target = Observation<'a>;

    fn deref(&self) -> &Observation<'a> {
        &self.observation
    }
}

/// The pose of one signature, from one sample and from many.
#[derive(Clone, Debug)]
pub struct PoseEstimate {
    /// The object's name.
    pub object: String,
    /// The K-start registration of sample `registered_sample`: every hypothesis, best first.
    pub hypotheses: Vec<Hypothesis>,
    /// The sample whose K-start registration gave the start of the others.
    pub registered_sample: usize,
    /// The imprint's threshold contact registered from the same starts, best first: the proposals the signature
    /// check scored beside `hypotheses` ([`PoseConfig::imprint_proposals`]); empty when they were not made (no
    /// signature, the check or the proposals off).
    pub imprint_hypotheses: Vec<Hypothesis>,
    /// The single-sample estimate after the signature check ([`crate::pose::signature_check`]): the hypothesis
    /// that best explains the measured signature, refined; `None` without a signature or with the check off.
    pub checked: Option<Se2>,
    /// The signature check picked a hypothesis of the imprint's threshold contact over the sample's
    /// ([`PoseConfig::imprint_proposals`]).
    pub checked_from_imprint: bool,
    /// The signature check's best hypothesis that is another pose than its pick, reduced by the object's symmetry
    /// ([`crate::pose::signature_check::Rival`]); close to it the signature cannot tell the two apart
    /// ([`Self::signature_ambiguous`]).
    pub signature_rival: Option<Rival>,
    /// Indices of the samples with contact (the others cannot be registered).
    pub with_contact: Vec<usize>,
    /// Every sample's, the baseline's and the multi-sample estimate's pose and errors, with the KDEs.
    pub report: UncertaintyReport,
    /// What the signature supports ([`crate::pose::posterior`]): weighted modes with covariances, from the
    /// hypotheses the check refined; `None` without the check.
    pub posterior: Option<PosePosterior>,
    /// The probability mass of the posterior's smallest region holding the true pose, when it is known
    /// ([`PosePosterior::region_mass`]).
    pub truth_region: Option<f64>,
    /// Per sample, the depth shift that anchored its contact onto the signature before registration (metres;
    /// [`PoseConfig::anchor_to_signature`]); empty when the samples were registered as generated.
    pub anchor_shift_m: Vec<f64>,
}

impl PoseEstimate {
    /// The signature explains another pose (the rival) about as well as the estimate ([`Rival::ambiguous`]): a
    /// contact the object fits more than one way.
    pub fn signature_ambiguous(&self) -> bool {
        self.signature_rival.is_some_and(|r| r.ambiguous())
    }

    /// The single-sample estimate: the signature check's pick when it ran, else the best hypothesis of the K-start
    /// registration.
    pub fn best(&self) -> Option<Se2> {
        self.checked
            .or_else(|| self.hypotheses.first().map(|h| h.pose))
    }

    /// The contact points the single-sample estimate was fitted to: sample `registered_sample` of `input`
    /// back-projected, world frame, metres.
    /// Anchored onto the signature as registered ([`PoseEstimate::anchor_shift_m`]).
    pub fn contact_points(&self, sim: &Simulator, input: &PoseInput<'_>) -> Vec<glam::DVec3> {
        let Some(s) = input.samples.get(self.registered_sample) else {
            return Vec::new();
        };
        let shift = self.anchor_shift_m.get(self.registered_sample).copied();
        let s = crate::pose::from_depth::shift_contact(s, shift.unwrap_or(0.0));
        crate::recon::back_project(&s, sim.intrinsics(), &input.t_world_camera).p_world
    }
}

/// Where the sensor was when it took the imprint: a known camera pose (a simulation, a session's scene), or a press
/// to find over the object ([`super::press`]).
#[derive(Clone, Copy, Debug)]
pub enum Placement {
    /// `t_world_camera` of the sensor camera.
    Camera(DAffine3),
    /// Placed over the object at this press (fixed, or found from the samples and the signature).
    Press(super::press::PressChoice),
}

/// One imprint's samples as the pose use case takes them (metres, the model's resolution).
#[derive(Clone, Copy, Debug)]
pub struct Observation<'a> {
    /// X̂0 samples of the generator.
    pub samples: &'a [Image],
    /// Y, the imprint (for the threshold baseline).
    pub imprint: &'a Image,
    /// S, the signature (the check, the press search and the baseline need it).
    pub signature: Option<&'a Image>,
    /// The true pose `t_world_object`, when known (errors are then measured against it).
    pub truth: Option<Se2>,
    /// What earlier frames of the same contact said (a track's), `None` for an observation on its own: the
    /// registrations start from its poses and the press search stays near its press.
    pub prior: Option<&'a PosePrior>,
    /// The camera's native pixels when the frames reached the model's resolution by area resampling (a recording's
    /// frames, imported pairs): the signature check then predicts them the same way
    /// ([`crate::pose::camera_path`]). `None` for frames made at the model's resolution.
    pub camera_path: Option<&'a std::sync::Arc<CameraPath>>,
}

/// A pose estimate with the sensor placement it was made at.
#[derive(Clone, Debug)]
pub struct PlacedEstimate {
    /// The press the sensor was placed at, metres (`None` for a known camera pose).
    pub press_m: Option<f64>,
    /// `t_world_camera` the samples were registered from.
    pub t_world_camera: DAffine3,
    /// The estimate.
    pub estimate: PoseEstimate,
}

impl PlacedEstimate {
    /// The [`PoseInput`] the estimate was made from, for figures and geometry files.
    pub fn input<'a>(&self, observation: &Observation<'a>) -> PoseInput<'a> {
        PoseInput {
            t_world_camera: self.t_world_camera,
            observation: *observation,
        }
    }
}

/// **The pose use case** that `tnd pose`, `tnd recording track` and the workbench's Pose job share: place the sensor
/// over `object` ([`Placement`]; `prepared` is the same object prepared for rendering, built here when `None` and a
/// press is to be found), then [`estimate_pose`], both with `engine` (which keeps the object's prepared model for
/// the next call). [`PipelineError::NoContact`] when no sample has contact.
#[allow(clippy::too_many_arguments)]
pub fn place_and_estimate(
    object: &LoadedObject,
    prepared: Option<&crate::sim::PreparedObject>,
    sim: &Simulator,
    observation: &Observation<'_>,
    placement: Placement,
    engine: &Estimator,
    seed: u64,
    progress: Progress<'_>,
) -> Result<PlacedEstimate, PipelineError> {
    engine.config.validate()?;
    let (press_m, t_world_camera) = match placement {
        Placement::Camera(t) => (None, t),
        Placement::Press(choice) => {
            let built;
            let prepared = match prepared {
                Some(p) => p,
                None => {
                    built = crate::sim::PreparedObject::new(object.mesh.clone())?;
                    &built
                }
            };
            let placement = super::press::SensorPlacement {
                sim,
                object,
                prepared,
                engine,
                camera_path: observation.camera_path,
            };
            let press = placement
                .press(
                    choice,
                    observation.samples,
                    observation.signature,
                    observation.imprint,
                    observation.prior,
                    seed,
                )?
                .ok_or(PipelineError::NoContact)?;
            let sensor = sim.pressing_pose(prepared, 0.0, 0.0, 0.0, press);
            (Some(press), sim.t_world_camera(&sensor))
        }
    };
    let input = PoseInput {
        t_world_camera,
        observation: *observation,
    };
    let estimate = estimate_pose(object, sim, &input, engine, seed, progress)?;
    Ok(PlacedEstimate {
        press_m,
        t_world_camera,
        estimate,
    })
}

/// Register `input`'s samples to `object` seen by `sim`'s sensor (see the module docs). `progress` counts the
/// K-start registration, every sample, the baseline and the multi-sample estimate. With a prior
/// ([`Observation::prior`]) every registration starts from its poses (and a few random ones) instead of
/// [`PoseConfig::inits`] random starts.
pub fn estimate_pose(
    object: &LoadedObject,
    sim: &Simulator,
    input: &PoseInput<'_>,
    estimator: &Estimator,
    seed: u64,
    progress: Progress<'_>,
) -> Result<PoseEstimate, PipelineError> {
    let mut sensor = SensorContext::of_simulator(sim, ObjectSet::builtin());
    sensor.camera_path = input.camera_path.cloned();
    let model = estimator.object_from_mesh(&object.name, &object.mesh, object.symmetry)?;
    estimate_observation(
        estimator,
        &object.name,
        &model,
        &sensor,
        input,
        seed,
        progress,
    )
}

/// **The pose sequence**, written once for every front end (`tnd pose`, `tnd eval`, `tnd recording track`, `tnd
/// bench`, the workbench): the samples anchored onto the signature, the K-start registration of the first sample
/// that registers, the imprint's proposals, the signature check with its posterior (reweighed by a track's prior),
/// then the uncertainty analysis (every sample and the baseline from the estimate, the multi-sample estimate).
/// `sensor` is the sensor as calibrated; the frame's pixels without a return are taken out of its free space here.
/// `model` is `name`'s prepared model ([`Estimator::object_from_mesh`], [`Estimator::object`]).
pub fn estimate_observation(
    estimator: &Estimator,
    name: &str,
    model: &ObjectModel,
    sensor: &SensorContext,
    input: &PoseInput<'_>,
    seed: u64,
    progress: Progress<'_>,
) -> Result<PoseEstimate, PipelineError> {
    let config: &PoseConfig = &estimator.config;
    // Pixels without a return give no free-space evidence.
    let ctx = sensor.observing(input.signature);
    let ctx = ctx.as_ref();
    let strategy = estimator.starts(seed, input.prior);
    let (samples, anchor_shift_m) =
        estimator.anchor(input.samples, input.signature, input.imprint)?;
    let with_contact: Vec<usize> = input
        .samples
        .iter()
        .enumerate()
        .filter(|(_, s)| s.data.iter().any(|&d| is_valid_depth(d)))
        .map(|(i, _)| i)
        .collect();
    // The first sample with contact that registers gives the start; one that fails is skipped here (the analysis
    // records it with the others).
    let (registered_sample, hypotheses) = first_registration(
        estimator,
        model,
        ctx,
        &input.t_world_camera,
        &samples,
        &strategy,
        seed,
    )?
    .ok_or(PipelineError::NoContact)?;
    let baseline = input
        .signature
        .map(|s| threshold_contact(s, input.imprint, &config.baseline));
    let measured = input
        .signature
        .map(|s| (s, input.imprint))
        .filter(|_| config.check_signature);
    // The imprint's own contact proposes poses too; the check scores them beside the sample's.
    let imprint_hypotheses = match (measured, config.imprint_proposals, &baseline) {
        (Some(m), true, Some(b)) => estimator.pooled_hypotheses(
            model,
            std::slice::from_ref(b),
            ctx,
            &input.t_world_camera,
            Some(m),
            &strategy,
        )?,
        _ => Vec::new(),
    };
    let (checked, checked_from_imprint, mut posterior) = match measured {
        Some(m) => {
            let pool = [hypotheses.as_slice(), &imprint_hypotheses].concat();
            match estimator.check_with_posterior(
                model,
                &pool,
                ctx,
                &input.t_world_camera,
                Some(m),
                true,
            )? {
                Some((c, p)) => (Some(c), c.from >= hypotheses.len(), p),
                None => (None, false, None),
            }
        }
        None => (None, false, None),
    };
    // A track's previous frame reweighs the modes (the object has not moved): the pick is the fused posterior's top.
    let prior_posterior = input.prior.and_then(|p| p.posterior.as_ref());
    let fused_top = match (&posterior, prior_posterior) {
        (Some(p), Some(before)) => {
            let fused = crate::pose::fusion::fuse(
                p,
                before,
                &model.symmetry,
                config.posterior_for(ctx).fusion_weight,
            );
            let top = fused.top().map(|m| m.pose());
            posterior = Some(fused);
            top
        }
        _ => None,
    };
    let truth_region = posterior.as_ref().zip(input.truth).and_then(|(p, t)| {
        p.region_mass(t, &model.symmetry, crate::metrics::evaluate::REGION_DRAWS)
    });
    // A rival that is the pick turned by the object's symmetry is the same pose.
    let signature_rival = checked.and_then(|c| {
        c.rival
            .filter(|r| !same_pose(r.pose, c.pose, &model.symmetry))
    });
    let checked = checked.map(|c| match fused_top {
        Some(top) if !same_pose(top, c.pose, &model.symmetry) => top,
        _ => c.pose,
    });
    let n = input.samples.len();
    let total = pose_steps(n);
    if !progress(1, total) {
        return Err(PipelineError::Cancelled);
    }
    let sig = Signature {
        t_world_camera: input.t_world_camera,
        samples: &samples,
        baseline: baseline.as_ref(),
        truth: input.truth,
        // The samples are registered from the pose reported (the signature check's pick where there is one), so
        // their spread and modes describe the uncertainty around it, not around a hypothesis the check rejected.
        init: checked.or_else(|| hypotheses.first().map(|h| h.pose)),
        measured: input.signature.map(|s| (s, input.imprint)),
        prior: input.prior,
    };
    // The baseline's step is counted whether or not there is one (no signature), so that the steps keep the
    // numbers [`pose_stage`] names.
    let no_baseline = usize::from(sig.baseline.is_none());
    let mut report = analyse_with_progress(estimator, model, ctx, &sig, seed, &mut |done, _| {
        progress(1 + done + no_baseline * usize::from(done > n), total)
    })
    .map_err(|e| match e {
        EvalError::Cancelled => PipelineError::Cancelled,
        e => e.into(),
    })?;
    // The pose reported, beside the samples' in the report (and its figure).
    report.estimate = checked
        .or_else(|| hypotheses.first().map(|h| h.pose))
        .map(|pose| {
            let cost = hypotheses
                .iter()
                .find(|h| h.pose == pose)
                .map_or(f64::NAN, |h| h.cost);
            SampleError::new(pose, cost, report.reference, &model.symmetry)
        });
    Ok(PoseEstimate {
        object: name.to_string(),
        hypotheses,
        imprint_hypotheses,
        registered_sample,
        checked,
        checked_from_imprint,
        signature_rival,
        with_contact,
        report,
        posterior,
        truth_region,
        anchor_shift_m,
    })
}

/// The number of progress steps of [`estimate_pose`] for `samples` samples: the first registration (K starts and the
/// signature check), each sample, the baseline and, from two samples, the multi-sample estimate.
pub fn pose_steps(samples: usize) -> usize {
    2 + samples + usize::from(samples > 1)
}

/// What [`estimate_pose`] is doing once `done` of its [`pose_steps`] are done, for progress displays.
pub fn pose_stage(done: usize, samples: usize) -> String {
    match done {
        0 => "registering the first sample from random starts".into(),
        d if d <= samples => format!("registering sample {d} of {samples}"),
        d if d == samples + 1 => "registering the threshold baseline".into(),
        d if d == samples + 2 && samples > 1 => {
            "multi-sample estimate: registering the samples' consensus".into()
        }
        _ => "finishing".into(),
    }
}

/// One file written by [`write_pose_geometry`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GeometryFile {
    pub path: std::path::PathBuf,
    /// Points (or mesh vertices) in it.
    pub vertices: usize,
}

/// Write the geometry of `estimate` as PLY files in `dir`, world frame, metres: the registered sample's
/// back-projected contact (`contact_points.ply`) and its free-space evidence (`free_space_points.ply`), the samples'
/// consensus contact (`consensus_points.ply`, with two or more samples), and the object at the single-sample
/// estimate (`object_estimate.ply`), at the multi-sample estimate (`object_multi_sample.ply`) and at the true pose
/// (`object_truth.ply`) where those exist.
#[allow(clippy::too_many_arguments)]
pub fn write_pose_geometry(
    dir: &std::path::Path,
    object: &LoadedObject,
    sim: &Simulator,
    input: &PoseInput<'_>,
    estimate: &PoseEstimate,
    config: &PoseConfig,
    seed: u64,
    encoding: crate::io::ply::PlyEncoding,
) -> Result<Vec<GeometryFile>, PipelineError> {
    use crate::io::ply::write_points;
    use crate::mesh::ply::write_mesh;
    use crate::recon::{back_project, free_space_points};
    std::fs::create_dir_all(dir).map_err(|source| PipelineError::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut files = Vec::new();
    let mut done = |name: &str, vertices: usize, r: std::io::Result<()>| {
        let path = dir.join(name);
        r.map_err(|source| PipelineError::Write {
            path: path.clone(),
            source,
        })?;
        files.push(GeometryFile { path, vertices });
        Ok::<(), PipelineError>(())
    };
    let intrinsics = sim.intrinsics();
    let t_world_camera = &input.t_world_camera;
    let frame = "world frame, metres (tactile-derender)";
    if let Some(sample) = input.samples.get(estimate.registered_sample) {
        let contact = estimate.contact_points(sim, input);
        let name = "contact_points.ply";
        let comment = format!("contact of sample {}, {frame}", estimate.registered_sample);
        done(
            name,
            contact.len(),
            write_points(&dir.join(name), &contact, &comment, encoding),
        )?;
        let free = free_space_points(
            sample,
            sim.nominal_depth(),
            intrinsics,
            t_world_camera,
            &config.free_space,
            seed,
        );
        let name = "free_space_points.ply";
        let comment = format!("free space beside the contact, {frame}");
        done(
            name,
            free.len(),
            write_points(&dir.join(name), &free, &comment, encoding),
        )?;
    }
    if input.samples.len() > 1 {
        // Of the samples anchored onto the signature, as the multi-sample estimate registers them.
        let anchored: Vec<crate::image::Image> = input
            .samples
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let shift = estimate.anchor_shift_m.get(i).copied().unwrap_or(0.0);
                crate::pose::from_depth::shift_contact(s, shift)
            })
            .collect();
        let consensus =
            crate::pose::from_depth::consensus_depth(&anchored, config.consensus_probability)?;
        let points = back_project(&consensus, intrinsics, t_world_camera).p_world;
        let name = "consensus_points.ply";
        let comment = format!("the samples' consensus contact, {frame}");
        done(
            name,
            points.len(),
            write_points(&dir.join(name), &points, &comment, encoding),
        )?;
    }
    if let Some(posterior) = &estimate.posterior {
        // Each mode's 90 % position region on the table (z = 0), 64 points a ring; the modes themselves in words.
        let rings: Vec<glam::DVec3> = posterior
            .modes
            .iter()
            .flat_map(|m| m.ellipse_xy(0.9, 64))
            .map(|[x, y]| glam::DVec3::new(x, y, 0.0))
            .collect();
        let name = "posterior_region_points.ply";
        let comment = format!(
            "90 % position region of each pose-posterior mode (64 points each, in the order below) on the table \
             z = 0, {frame}\n{}",
            posterior_comment(posterior)
        );
        done(
            name,
            rings.len(),
            write_points(&dir.join(name), &rings, &comment, encoding),
        )?;
    }
    let poses = [
        (
            "object_estimate.ply",
            "single-sample estimate",
            estimate.best(),
        ),
        (
            "object_multi_sample.ply",
            "multi-sample estimate",
            estimate.report.multi_sample.map(|m| m.pose),
        ),
        ("object_truth.ply", "true pose", input.truth),
    ];
    for (name, what, pose) in poses {
        if let Some(p) = pose {
            let mut comment = format!(
                "{} at the {what} x={} y={} theta={}, {frame}",
                object.name, p.x, p.y, p.theta
            );
            if let (true, Some(posterior)) = (name == "object_estimate.ply", &estimate.posterior) {
                comment.push('\n');
                comment.push_str(&posterior_comment(posterior));
            }
            let r = write_mesh(
                &dir.join(name),
                &object.mesh,
                &p.to_affine(),
                &comment,
                encoding,
            );
            done(name, object.mesh.vertices().len(), r)?;
        }
    }
    Ok(files)
}

/// The pose posterior as PLY comment lines: one per mode, `posterior mode K weight W mean X Y THETA cov C00 C01 C02
/// C10 … C22` (metres, radians, the world frame; θ circular).
fn posterior_comment(posterior: &crate::pose::posterior::PosePosterior) -> String {
    let mut lines = vec![format!(
        "posterior modes {} (weight, mean x y theta, 3x3 covariance of core and tail row by row; metres, radians)",
        posterior.modes.len()
    )];
    for (k, m) in posterior.modes.iter().enumerate() {
        let cov: Vec<String> = m
            .spread_cov()
            .iter()
            .flatten()
            .map(|c| format!("{c:e}"))
            .collect();
        lines.push(format!(
            "posterior mode {k} weight {} mean {} {} {} cov {}",
            m.weight,
            m.mean[0],
            m.mean[1],
            m.mean[2],
            cov.join(" ")
        ));
    }
    lines.join("\n")
}

/// Write the SE(2) fit figure of `estimate` (`fit.svg`, `fit.png`: the object's top-view outline at the true pose and
/// at each estimate, with the registered sample's contact points) into `dir` at `figure`'s size; the KDE figure comes
/// with the report ([`UncertaintyReport::write_with`]).
pub fn write_fit_figure(
    dir: &std::path::Path,
    object: &LoadedObject,
    sim: &Simulator,
    input: &PoseInput<'_>,
    estimate: &PoseEstimate,
    figure: &crate::io::figure::FigureConfig,
) -> Result<[std::path::PathBuf; 2], PipelineError> {
    let outline = crate::pose::outline::outline(&object.mesh);
    let contacts: Vec<[f64; 2]> = estimate
        .contact_points(sim, input)
        .iter()
        .map(|p| [p.x, p.y])
        .collect();
    let samples: Vec<[f64; 2]> = estimate
        .report
        .samples
        .iter()
        .map(|s| [s.pose.x, s.pose.y])
        .collect();
    let fit = crate::pose::figure::FitFigure {
        object: &object.name,
        outline: &outline,
        contacts: &contacts,
        truth: input.truth,
        single: estimate.best(),
        multi: estimate.report.multi_sample.map(|m| m.pose),
        baseline: estimate.report.baseline.map(|b| b.pose),
        samples: &samples,
        posterior: estimate.posterior.as_ref(),
        symmetry: object.symmetry,
    };
    Ok(crate::io::figure::write_figure(dir, "fit", figure, &fit)?)
}
