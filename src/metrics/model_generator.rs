//! The conditional diffusion model (paper IV.B) as an evaluation [`Generator`]: X̂0 samples for a pair's imprint,
//! guided towards the imprint ([`crate::model::guidance`]) where the source knows its sensor's cloak.

use super::evaluate::{EvalError, EvalPair, Generator};
use crate::image::Image;
use crate::model::{DiffusionModel, GuidanceConfig, ImprintGuidance, SamplerKind};
use crate::pose::SensorContext;

/// A loaded model and the sampler to run it with.
pub struct ModelGenerator {
    pub model: DiffusionModel,
    pub sampler: SamplerKind,
    /// Imprint guidance; applied where the source's context has a signature model (the cloak).
    pub guidance: GuidanceConfig,
}

impl ModelGenerator {
    /// The guidance for `pair`: towards its imprint, on the membrane its own reference frame shows; `None` when
    /// off or when the sensor's cloak is unknown.
    pub fn guidance_for(
        &self,
        pair: &EvalPair,
        ctx: &SensorContext,
    ) -> Result<Option<ImprintGuidance>, EvalError> {
        let Some(model) = ctx.signature_model.as_ref() else {
            return Ok(None);
        };
        model
            .guidance(
                &self.guidance,
                &ctx.membrane,
                &pair.imprint,
                Some(&pair.signature),
            )
            .map_err(|e| EvalError::Generator(crate::error::render(&e)))
    }
}

impl Generator for ModelGenerator {
    fn name(&self) -> String {
        let sampler = match self.sampler {
            SamplerKind::Ddpm => "ddpm".to_string(),
            SamplerKind::Ddim {
                steps,
                eta,
                spacing,
            } => format!("ddim {steps} steps, eta {eta}, {spacing} spacing"),
        };
        let guided = if self.guidance.active() {
            ", imprint-guided"
        } else {
            ""
        };
        format!(
            "model {} ({sampler}{guided})",
            self.model.source().display()
        )
    }

    fn generate(
        &self,
        pair: &EvalPair,
        ctx: &SensorContext,
        n: usize,
        seed: u64,
    ) -> Result<Vec<Image>, EvalError> {
        let guidance = self.guidance_for(pair, ctx)?;
        self.model
            .sample_guided(
                &pair.imprint,
                guidance.as_ref(),
                n,
                self.sampler,
                seed,
                &mut |_, _| true,
            )
            .map_err(|source| EvalError::Model {
                model: self.model.source().to_path_buf(),
                source: Box::new(source),
            })
    }
}
