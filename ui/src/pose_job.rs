//! Pose estimation of a de-rendering run (paper IV.C, V.D) on a worker thread: the core's use case
//! [`tactile_derender::pipeline::place_and_estimate`] (the same as `tnd pose`: a K-start registration of the first sample
//! with contact, then every sample, the threshold baseline and the multi-sample estimate registered from that start,
//! errors against the true pose, KDE curves), plus what the Pose tab draws (the object's outline, contact points).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;

use anyhow::{Context, Result};
use tactile_derender::image::Image;
use tactile_derender::pipeline::press::PressChoice;
use tactile_derender::pipeline::{self, Observation, Placement};
use tactile_derender::pose::camera_path::CameraPath;
use tactile_derender::pose::PoseConfig;
use tactile_derender::sim::Simulator;

use crate::derender::PoseContext;
use crate::pose_view::{outline, PoseAnalysis};
use crate::worker::{JobKind, WorkerMsg};

/// One requested pose analysis.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseRequest {
    pub generation: u64,
    pub context: PoseContext,
    /// Y, for the threshold baseline, metres.
    pub imprint: Image,
    /// The run's X̂0 samples, metres.
    pub samples: Vec<Image>,
    pub seed: u64,
    /// The pose engine's settings (the session's): the job and the exports of its result run with these.
    pub config: PoseConfig,
}

/// Register the samples and the baseline ([`pipeline::place_and_estimate`], as `tnd pose` does), reporting
/// `progress(done, total)` after each registration; `cancel` stops it at the next one.
pub fn run(
    req: &PoseRequest,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<PoseAnalysis> {
    let sim = Simulator::new(req.context.sim.clone()).context("sensor configuration")?;
    let object = req.context.object.spec().load()?;
    // Where the press is not known, the sensor goes where the samples and the signature say (as `tnd pose`).
    let c = &req.context;
    let placement = if c.find_press {
        Placement::Press(PressChoice::Auto)
    } else {
        Placement::Camera(c.t_world_camera)
    };
    // A frame brought down from the camera's native pixels is predicted the same way by the signature check.
    let camera_path =
        CameraPath::for_frames(&c.sim, c.resampled).context("sensor configuration")?;
    let observation = Observation {
        samples: &req.samples,
        imprint: &req.imprint,
        signature: Some(&c.signature),
        truth: c.truth,
        prior: None,
        camera_path: camera_path.as_ref(),
    };
    let placed = pipeline::place_and_estimate(
        &object,
        None,
        &sim,
        &observation,
        placement,
        &tactile_derender::pose::Estimator::new(req.config.clone()),
        req.seed,
        &mut |done, total| {
            progress(done, total);
            !cancel.load(Ordering::Relaxed)
        },
    )?;
    let (press_found_m, placed_camera) = (placed.press_m, placed.t_world_camera);
    let input = placed.input(&observation);
    let estimate = placed.estimate;
    let contacts = estimate
        .contact_points(&sim, &input)
        .iter()
        .map(|p| [p.x, p.y])
        .collect();
    Ok(PoseAnalysis {
        object: estimate.object,
        outline: outline(&object.mesh),
        truth: c.truth,
        registered_sample: estimate.registered_sample,
        checked: estimate.checked,
        checked_from_imprint: estimate.checked_from_imprint,
        signature_rival: estimate.signature_rival,
        posterior: estimate.posterior,
        symmetry: object.symmetry,
        truth_region: estimate.truth_region,
        hypotheses: estimate.hypotheses,
        imprint_hypotheses: estimate.imprint_hypotheses,
        contacts,
        report: estimate.report,
        sample_index: estimate.with_contact,
        anchor_shift_m: estimate.anchor_shift_m,
        // The request as registered: at the camera the press search placed it, when it searched.
        inputs: Some(Box::new({
            let mut req = req.clone();
            req.context.t_world_camera = placed_camera;
            req
        })),
        press_found_m,
    })
}

/// Run `req` on its own thread, reporting progress and the result through `tx`; setting `cancel` stops it.
pub fn spawn(
    req: PoseRequest,
    cancel: Arc<AtomicBool>,
    tx: Sender<WorkerMsg>,
    ctx: egui::Context,
) -> Result<()> {
    let generation = req.generation;
    crate::worker::spawn_job(JobKind::Pose, generation, tx, ctx, move |progress| {
        Ok(WorkerMsg::Posed {
            generation,
            analysis: Box::new(run(&req, &cancel, progress)?),
        })
    })
}
