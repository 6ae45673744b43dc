//! Adam (Kingma & Ba), the paper's optimiser (IV.B, learning rate 1e-4), with its moments exposed so that a
//! training checkpoint can hold them and a resumed run continues exactly. Same update as `torch.optim.Adam`
//! (no weight decay, no AMSGrad): `p -= lr / (1 − β1^t) · m / (√v / √(1 − β2^t) + ε)`.

use candle_core::{backprop::GradStore, DType, Tensor, Var};
use rayon::prelude::*;

use super::ModelError;

/// Optimiser state for a fixed, ordered list of parameters.
pub struct Adam {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    /// Number of updates applied so far.
    pub t: u64,
    pub vars: Vec<(String, Var)>,
    /// First moments, one per parameter.
    pub m: Vec<Tensor>,
    /// Second moments, one per parameter.
    pub v: Vec<Tensor>,
    /// Update f32 parameters on the CPU in one fused parallel pass (default) instead of candle ops (what other
    /// devices run); both give the same bits.
    pub fused: bool,
}

impl Adam {
    /// Fresh state (zero moments) with PyTorch's defaults β = (0.9, 0.999), ε = 1e-8.
    pub fn new(vars: Vec<(String, Var)>, lr: f64) -> Result<Self, ModelError> {
        let m = vars
            .iter()
            .map(|(_, v)| v.as_tensor().zeros_like())
            .collect::<Result<Vec<_>, _>>()?;
        let v = m.clone();
        Ok(Self {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            t: 0,
            vars,
            m,
            v,
            fused: true,
        })
    }

    /// One update from `grads`; parameters without a gradient are left alone (their moments too).
    pub fn step(&mut self, grads: &GradStore) -> Result<(), ModelError> {
        self.t += 1;
        let bc1 = 1.0 - self.beta1.powi(self.t as i32);
        let bc2 = 1.0 - self.beta2.powi(self.t as i32);
        for (i, (_, var)) in self.vars.iter().enumerate() {
            let Some(g) = grads.get(var) else { continue };
            if self.fused && var.device().is_cpu() && var.dtype() == DType::F32 {
                let (m, v) = fused_step(self, var, g, &self.m[i], &self.v[i], bc1, bc2)?;
                self.m[i] = m;
                self.v[i] = v;
                continue;
            }
            let m = ((&self.m[i] * self.beta1)? + (g * (1.0 - self.beta1))?)?;
            let v = ((&self.v[i] * self.beta2)? + (g.sqr()? * (1.0 - self.beta2))?)?;
            let denom = ((v.sqrt()? / bc2.sqrt())? + self.eps)?;
            let update = ((&m / denom)? * (self.lr / bc1))?;
            var.set(&(var.as_tensor() - update)?)?;
            // Plain values: the moments must not carry an op graph from one step into the next.
            self.m[i] = m.detach();
            self.v[i] = v.detach();
        }
        Ok(())
    }
}

/// One parameter's update on the CPU in one parallel pass (the candle-op version above makes ~12 full-size passes
/// and temporaries, 29 ms per step for 6.3 M parameters on 2 threads). The arithmetic is the candle path's,
/// operation for operation in f32 (its scalar multiplies and adds are `affine`s with f32 constants), so both give the
/// same bits. Returns the new moments.
fn fused_step(
    adam: &Adam,
    var: &Var,
    g: &Tensor,
    m: &Tensor,
    v: &Tensor,
    bc1: f64,
    bc2: f64,
) -> Result<(Tensor, Tensor), ModelError> {
    let flat = |t: &Tensor| t.flatten_all()?.to_vec1::<f32>();
    let (mut p, g, mut m, mut v) = (flat(var.as_tensor())?, flat(g)?, flat(m)?, flat(v)?);
    if g.len() != p.len() || m.len() != p.len() || v.len() != p.len() {
        return Err(ModelError::Input(format!(
            "adam: gradient/moments of {} values for a parameter of {}",
            g.len(),
            p.len()
        )));
    }
    let (b1, c1) = (adam.beta1 as f32, (1.0 - adam.beta1) as f32);
    let (b2, c2) = (adam.beta2 as f32, (1.0 - adam.beta2) as f32);
    let (inv_sbc2, eps, lr_bc1) = (
        (1.0 / bc2.sqrt()) as f32,
        adam.eps as f32,
        (adam.lr / bc1) as f32,
    );
    const CHUNK: usize = 1 << 14;
    p.par_chunks_mut(CHUNK)
        .zip(m.par_chunks_mut(CHUNK))
        .zip(v.par_chunks_mut(CHUNK))
        .zip(g.par_chunks(CHUNK))
        .for_each(|(((p, m), v), g)| {
            for (((p, m), v), &g) in p.iter_mut().zip(m).zip(v).zip(g) {
                *m = *m * b1 + g * c1;
                *v = *v * b2 + (g * g) * c2;
                let denom = v.sqrt() * inv_sbc2 * 1.0 + eps;
                *p -= (*m / denom) * lr_bc1;
            }
        });
    let shape = var.shape().clone();
    let dev = var.device();
    var.set(&Tensor::from_vec(p, shape.clone(), dev)?)?;
    Ok((
        Tensor::from_vec(m, shape.clone(), dev)?,
        Tensor::from_vec(v, shape, dev)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn first_step_moves_each_weight_by_lr_against_its_gradient_and_keeps_plain_moments() {
        let w = Var::from_slice(&[1.0f32, -2.0], 2, &Device::Cpu).unwrap();
        let mut adam = Adam::new(vec![("w".into(), w.clone())], 0.1).unwrap();
        for _ in 0..2 {
            // f = Σ w², ∇f = 2w.
            let grads = w
                .as_tensor()
                .sqr()
                .unwrap()
                .sum_all()
                .unwrap()
                .backward()
                .unwrap();
            adam.step(&grads).unwrap();
        }
        // Step 1: m̂ = g, v̂ = g², so w moves by lr·g/(|g| + ε) = ±0.1. Step 2 (same sign) moves another ~0.1.
        let got = w.as_tensor().to_vec1::<f32>().unwrap();
        assert!(
            (got[0] - 0.8).abs() < 1e-3 && (got[1] + 1.8).abs() < 1e-3,
            "{got:?}"
        );
        assert!(adam.m.iter().chain(&adam.v).all(|t| !t.track_op()));
    }

    /// The fused CPU update gives the candle-op update's bits: parameters and moments over several steps.
    #[test]
    fn fused_update_matches_the_candle_ops_bit_for_bit() {
        let n = 40_000; // several parallel chunks and a partial one
        let vals = |seed: u32| -> Vec<f32> {
            (0..n)
                .map(|i| ((i as u32).wrapping_mul(2_654_435_761).wrapping_add(seed) >> 8) as f32)
                .map(|x| x / (1u32 << 24) as f32 - 0.5)
                .collect()
        };
        let start = Tensor::from_vec(vals(1), (200, 200), &Device::Cpu).unwrap();
        let (wa, wb) = (
            Var::from_tensor(&start).unwrap(),
            Var::from_tensor(&start).unwrap(),
        );
        let mut fused = Adam::new(vec![("w".into(), wa.clone())], 1e-3).unwrap();
        let mut candle = Adam::new(vec![("w".into(), wb.clone())], 1e-3).unwrap();
        candle.fused = false;
        for step in 0..3u32 {
            let target = Tensor::from_vec(vals(7 + step), (200, 200), &Device::Cpu).unwrap();
            for (adam, w) in [(&mut fused, &wa), (&mut candle, &wb)] {
                // f = Σ (w − target)² · w: gradients of every sign and size.
                let grads = ((w.as_tensor() - &target).unwrap().sqr().unwrap() * w.as_tensor())
                    .unwrap()
                    .sum_all()
                    .unwrap()
                    .backward()
                    .unwrap();
                adam.step(&grads).unwrap();
            }
        }
        let bits = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(bits(wa.as_tensor()), bits(wb.as_tensor()));
        assert_ne!(
            bits(wa.as_tensor()),
            bits(&start),
            "the update moved the weights"
        );
        assert_eq!(bits(&fused.m[0]), bits(&candle.m[0]));
        assert_eq!(bits(&fused.v[0]), bits(&candle.v[0]));
    }
}
