//! The conditional diffusion model (paper IV.B) as an evaluation [`Generator`]: X̂0 samples for a pair's imprint.

use super::evaluate::{EvalError, EvalPair, Generator};
use crate::image::Image;
use crate::model::{DiffusionModel, SamplerKind};

/// A loaded model and the sampler to run it with.
pub struct ModelGenerator {
    pub model: DiffusionModel,
    pub sampler: SamplerKind,
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
        format!("model {} ({sampler})", self.model.source().display())
    }

    fn generate(&self, pair: &EvalPair, n: usize, seed: u64) -> Result<Vec<Image>, EvalError> {
        self.model
            .sample(&pair.imprint, n, self.sampler, seed, &mut |_, _| true)
            .map_err(|source| EvalError::Model {
                model: self.model.source().to_path_buf(),
                source: Box::new(source),
            })
    }
}
