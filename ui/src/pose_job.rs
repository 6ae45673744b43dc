//! Pose estimation of a de-rendering run (paper IV.C, V.D) on a worker thread: the core's use case
//! [`tactile_derender::pipeline::estimate_pose`] (the same as `tnd pose`: a K-start registration of the first sample
//! with contact, then every sample, the threshold baseline and the multi-sample estimate registered from that start,
//! errors against the true pose, KDE curves), plus what the Pose tab draws (the object's outline, contact points).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;

use anyhow::{Context, Result};
use tactile_derender::image::Image;
use tactile_derender::metrics::evaluate::EvalConfig;
use tactile_derender::pipeline::press::{PressChoice, SensorPlacement};
use tactile_derender::pipeline::{self, PoseInput};
use tactile_derender::sim::{PreparedObject, Simulator};

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
    /// Judge the registration's hypotheses by the signature each predicts (the signature check).
    pub check_signature: bool,
    /// Pool the imprint's threshold-contact hypotheses with the sample's before the check.
    pub imprint_proposals: bool,
}

/// Register the samples and the baseline ([`pipeline::estimate_pose`], as `tnd pose` does), reporting
/// `progress(done, total)` after each registration; `cancel` stops it at the next one.
pub fn run(
    req: &PoseRequest,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<PoseAnalysis> {
    let sim = Simulator::new(req.context.sim.clone()).context("sensor configuration")?;
    let object = req.context.object.spec().load()?;
    let eval = EvalConfig {
        check_signature: req.check_signature,
        imprint_proposals: req.imprint_proposals,
        ..EvalConfig::default()
    };
    // Where the press is not known, the sensor goes where the samples and the signature say (as `tnd pose`).
    let mut req = req.clone();
    let mut press_found_m = None;
    if req.context.find_press {
        let prepared = PreparedObject::new(object.mesh.clone())?;
        let placement = SensorPlacement {
            sim: &sim,
            object: &object,
            prepared: &prepared,
            eval: &eval,
        };
        let c = &req.context;
        press_found_m = placement.press(
            PressChoice::Auto,
            &req.samples,
            Some(&c.signature),
            &req.imprint,
            req.seed,
        )?;
        if let Some(p) = press_found_m {
            req.context.t_world_camera =
                sim.t_world_camera(&sim.pressing_pose(&prepared, 0.0, 0.0, 0.0, p));
        }
    }
    let c = &req.context;
    let input = PoseInput {
        t_world_camera: c.t_world_camera,
        samples: &req.samples,
        imprint: &req.imprint,
        signature: Some(&c.signature),
        truth: c.truth,
    };
    let estimate = pipeline::estimate_pose(
        &object,
        &sim,
        &input,
        &eval,
        req.seed,
        &mut |done, total| {
            progress(done, total);
            !cancel.load(Ordering::Relaxed)
        },
    )?;
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
        hypotheses: estimate.hypotheses,
        contacts,
        report: estimate.report,
        sample_index: estimate.with_contact,
        anchor_shift_m: estimate.anchor_shift_m,
        inputs: Some(Box::new(req.clone())),
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
