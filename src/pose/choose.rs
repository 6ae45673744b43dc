//! **Choosing the pose** from registration hypotheses (paper IV.C, extended): the hypotheses of one or several
//! in-contact depth estimates pooled, and the pick — the registration's best, or the hypothesis that best explains
//! the measured signature ([`super::signature_check`]), refined.

use glam::DAffine3;

use super::estimator::{Estimator, ObjectModel, SensorContext};
use super::posterior::PosePosterior;
use super::signature_check::{measured_membrane, Checked, SignatureCheck};
use super::{Hypothesis, PoseError};
use crate::image::Image;
use crate::sensor::Se2;

impl Estimator {
    /// The pose from a registration's `hypotheses`: the first one (the best of a single registration), or, with
    /// [`super::PoseConfig::check_signature`], a `measured` (signature, imprint) and the sensor's signature model, the one the
    /// signature check picks and refines ([`SignatureCheck::select`]), with the index in `hypotheses` of the one it came
    /// from (0 without the check). `None` without hypotheses.
    pub fn choose(
        &self,
        object: &ObjectModel,
        hypotheses: &[Hypothesis],
        ctx: &SensorContext,
        t_world_camera: &DAffine3,
        measured: Option<(&Image, &Image)>,
    ) -> Result<Option<(Se2, usize)>, PoseError> {
        Ok(self
            .choose_scored(object, hypotheses, ctx, t_world_camera, measured)?
            .map(|(pose, from, _)| (pose, from)))
    }

    /// [`Self::choose`], with the signature cost of the pick (robust mean, metres²) when the check ran: a score of
    /// how well the pose, seen from `t_world_camera`, explains the signature.
    pub fn choose_scored(
        &self,
        object: &ObjectModel,
        hypotheses: &[Hypothesis],
        ctx: &SensorContext,
        t_world_camera: &DAffine3,
        measured: Option<(&Image, &Image)>,
    ) -> Result<Option<(Se2, usize, Option<f64>)>, PoseError> {
        let best = hypotheses.first().map(|h| (h.pose, 0, None));
        Ok(self
            .check(object, hypotheses, ctx, t_world_camera, measured)?
            .map(|c| (c.pose, c.from, Some(c.cost)))
            .or(best))
    }

    /// [`Self::choose`] with the posterior of the check (`None` where the check does not run).
    pub fn choose_with_posterior(
        &self,
        object: &ObjectModel,
        hypotheses: &[Hypothesis],
        ctx: &SensorContext,
        t_world_camera: &DAffine3,
        measured: Option<(&Image, &Image)>,
    ) -> Result<Option<(Se2, Option<PosePosterior>)>, PoseError> {
        let best = hypotheses.first().map(|h| (h.pose, None));
        Ok(self
            .check_with_posterior(object, hypotheses, ctx, t_world_camera, measured, true)?
            .map(|(c, p)| (c.pose, p))
            .or(best))
    }

    /// The signature check's pick among `hypotheses` with its cost and its rival ([`Checked`]); `None` when the
    /// check does not run (no signature, no signature model, the check off) or there are no hypotheses.
    pub fn check(
        &self,
        object: &ObjectModel,
        hypotheses: &[Hypothesis],
        ctx: &SensorContext,
        t_world_camera: &DAffine3,
        measured: Option<(&Image, &Image)>,
    ) -> Result<Option<Checked>, PoseError> {
        Ok(self
            .check_with_posterior(object, hypotheses, ctx, t_world_camera, measured, false)?
            .map(|(c, _)| c))
    }

    /// [`Self::check`] with the pose posterior of the check's refined candidates
    /// ([`SignatureCheck::posterior`] with [`super::PoseConfig::posterior`]) when `posterior` is asked for.
    pub fn check_with_posterior(
        &self,
        object: &ObjectModel,
        hypotheses: &[Hypothesis],
        ctx: &SensorContext,
        t_world_camera: &DAffine3,
        measured: Option<(&Image, &Image)>,
        posterior: bool,
    ) -> Result<Option<(Checked, Option<PosePosterior>)>, PoseError> {
        let measured = measured.filter(|_| self.config.check_signature);
        let (Some(model), Some((signature, imprint))) = (ctx.signature_model, measured) else {
            return Ok(None);
        };
        let cfg = &self.config.signature_check;
        let membrane = if cfg.reference_radius_px > 0 {
            measured_membrane(&ctx.membrane, signature, imprint, cfg.reference_radius_px)?
        } else {
            ctx.membrane.clone()
        };
        let check = SignatureCheck {
            caster: &object.caster,
            intrinsics: &ctx.intrinsics,
            membrane: &membrane,
            t_world_camera: *t_world_camera,
            signature,
            model,
            config: &self.config.signature_check,
            camera_path: ctx
                .camera_path
                .as_deref()
                .filter(|_| cfg.native)
                .and_then(|path| path.for_membrane(&membrane)),
        };
        let poses: Vec<Se2> = hypotheses.iter().map(|h| h.pose).collect();
        let Some((checked, candidates)) = check.select_all(&poses)? else {
            return Ok(None);
        };
        let posterior = posterior
            .then(|| {
                check.posterior(
                    &candidates,
                    &object.symmetry,
                    self.config.posterior_for(ctx),
                )
            })
            .transpose()?;
        Ok(Some((checked, posterior)))
    }
}
