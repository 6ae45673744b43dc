//! Pose estimation of a de-rendering run (paper IV.C, V.D) on a worker thread, with the evaluation stage: the object
//! prepared for registration, a K-start registration of the first sample with contact (every hypothesis with its
//! cost), then the uncertainty analysis ([`tactile_derender::uncertainty::analysis::analyse`]): every sample and the
//! threshold baseline registered from that start, errors against the true pose, KDE curves.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;

use anyhow::{anyhow, Context, Result};
use tactile_derender::image::Image;
use tactile_derender::metrics::evaluate::{EvalConfig, EvalContext, EvalError, Evaluator};
use tactile_derender::objects::{ObjectSet, Symmetry};
use tactile_derender::pose::{threshold_contact, InitStrategy};
use tactile_derender::recon::{back_project, is_valid_depth};
use tactile_derender::sim::Simulator;
use tactile_derender::uncertainty::analysis::{analyse_with_progress, Signature};

use crate::derender::PoseContext;
use crate::pose_view::{outline, PoseAnalysis};
use crate::state::ObjectSource;
use crate::worker::{JobKind, WorkerMsg};

/// One requested pose analysis.
pub struct PoseRequest {
    pub generation: u64,
    pub context: PoseContext,
    /// Y, for the threshold baseline, metres.
    pub imprint: Image,
    /// The run's X̂0 samples, metres.
    pub samples: Vec<Image>,
    pub seed: u64,
}

/// Register the samples and the baseline (see the module docs), reporting `progress(done, total)` after each
/// registration; `cancel` stops it at the next one.
pub fn run(
    req: &PoseRequest,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<PoseAnalysis> {
    let c = &req.context;
    let sim = Simulator::new(c.sim.clone()).context("sensor configuration")?;
    let (name, objects, mesh, symmetry) = match &c.object {
        ObjectSource::Library { set, name } => {
            let objects = ObjectSet::open(set)?;
            let mesh = objects.mesh(name)?;
            let symmetry = objects.find(name).map(|e| e.symmetry).unwrap_or_default();
            (name.clone(), objects, mesh, symmetry)
        }
        // A mesh file has no symmetry entry; the context's object set is not used for it.
        source @ ObjectSource::File { .. } => {
            let object = crate::worker::load_object(source)?;
            (
                source.display_name(),
                ObjectSet::builtin(),
                object.mesh,
                Symmetry::default(),
            )
        }
    };
    let ctx = EvalContext {
        intrinsics: *sim.intrinsics(),
        membrane: sim.nominal_depth().clone(),
        objects,
    };
    let evaluator = Evaluator::new(EvalConfig::default());
    let object = evaluator.object_from_mesh(&name, &mesh, symmetry)?;
    let with_contact: Vec<usize> = req
        .samples
        .iter()
        .enumerate()
        .filter(|(_, s)| s.data.iter().any(|&d| is_valid_depth(d)))
        .map(|(i, _)| i)
        .collect();
    let first = *with_contact
        .first()
        .ok_or_else(|| anyhow!("no sample has any contact; nothing to register"))?;
    let strategy = InitStrategy::Random {
        count: evaluator.config.inits,
        radius_m: evaluator.config.init_radius_m,
        seed: req.seed,
    };
    let hypotheses = evaluator
        .register_depth(
            &object,
            &req.samples[first],
            &ctx,
            &c.t_world_camera,
            &strategy,
            req.seed,
        )
        .with_context(|| format!("registering sample {first}"))?
        .unwrap_or_default();
    // Step 1 of 1 + samples + baseline (+ the multi-sample estimate): the K-start search above; `analyse` reports
    // the rest.
    let total = 2 + req.samples.len() + usize::from(req.samples.len() > 1);
    progress(1, total);
    if cancel.load(Ordering::Relaxed) {
        return Err(anyhow!("cancelled"));
    }
    let baseline = threshold_contact(&c.signature, &req.imprint, &evaluator.config.baseline);
    let sig = Signature {
        t_world_camera: c.t_world_camera,
        samples: &req.samples,
        baseline: Some(&baseline),
        truth: Some(c.truth),
        init: hypotheses.first().map(|h| h.pose),
    };
    let report =
        analyse_with_progress(&evaluator, &object, &ctx, &sig, req.seed, &mut |done, _| {
            progress(1 + done, total);
            !cancel.load(Ordering::Relaxed)
        })
        .map_err(|e| match e {
            EvalError::Cancelled => anyhow!("cancelled"),
            e => anyhow!(e),
        })?;
    let contacts = back_project(&req.samples[first], &ctx.intrinsics, &c.t_world_camera)
        .p_world
        .iter()
        .map(|p| [p.x, p.y])
        .collect();
    Ok(PoseAnalysis {
        object: name,
        outline: outline(&mesh),
        truth: Some(c.truth),
        registered_sample: first,
        hypotheses,
        contacts,
        report,
        sample_index: with_contact,
    })
}

/// Run `req` on its own thread, reporting progress and the result through `tx`; setting `cancel` stops it.
pub fn spawn(
    req: PoseRequest,
    cancel: Arc<AtomicBool>,
    tx: Sender<WorkerMsg>,
    ctx: egui::Context,
) -> Result<()> {
    std::thread::Builder::new()
        .name("tnd-pose".into())
        .spawn(move || {
            let generation = req.generation;
            let mut progress =
                crate::worker::throttled_progress(JobKind::Pose, tx.clone(), ctx.clone());
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                run(&req, &cancel, &mut progress)
            }));
            let msg = match result {
                Ok(Ok(a)) => WorkerMsg::Posed {
                    generation,
                    analysis: Box::new(a),
                },
                Ok(Err(e)) => WorkerMsg::Error {
                    job: JobKind::Pose,
                    generation,
                    message: format!("pose: {}", tactile_derender::error::render_anyhow(&e)),
                },
                Err(_) => WorkerMsg::Error {
                    job: JobKind::Pose,
                    generation,
                    message: "pose: internal error (registration panicked); please report it"
                        .into(),
                },
            };
            let _ = tx.send(msg);
            ctx.request_repaint();
        })
        .map(|_| ())
        .map_err(|e| anyhow!("cannot start the pose thread: {e}"))
}
