//! Seeded parameter initialisation for training from scratch (paper IV.B): PyTorch's defaults as diffusers gets
//! them — `nn.Conv2d`/`nn.Linear` weights and biases uniform in ±1/√fan_in, GroupNorm scale 1 and shift 0 — drawn
//! from ChaCha8 so that a seed reproduces the model.

use candle_core::{Tensor, Var};
use candle_nn::VarMap;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::checkpoint::named_vars;
use super::ModelError;

/// Initialise every parameter of `varmap` from `seed` (names visited in sorted order).
pub fn init_params(varmap: &VarMap, seed: u64) -> Result<(), ModelError> {
    let vars = named_vars(varmap);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for (name, var) in &vars {
        let (stem, leaf) = name.rsplit_once('.').unwrap_or(("", name.as_str()));
        let weight_dims = vars
            .get(&format!("{stem}.weight"))
            .map(|w| w.dims().to_vec());
        let values = match weight_dims {
            Some(wd) if wd.len() >= 2 => {
                let fan_in: usize = wd[1..].iter().product();
                let bound = 1.0 / (fan_in.max(1) as f32).sqrt();
                (0..var.elem_count())
                    .map(|_| rng.random_range(-bound..=bound))
                    .collect()
            }
            // GroupNorm: scale 1, shift 0.
            _ if leaf == "weight" => vec![1f32; var.elem_count()],
            _ => vec![0f32; var.elem_count()],
        };
        set(var, values)?;
    }
    Ok(())
}

fn set(var: &Var, values: Vec<f32>) -> Result<(), ModelError> {
    let t = Tensor::from_vec(values, var.dims(), var.device())?;
    var.set(&t)?;
    Ok(())
}
