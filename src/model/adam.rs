//! Adam (Kingma & Ba), the paper's optimiser (IV.B, learning rate 1e-4), with its moments exposed so that a
//! training checkpoint can hold them and a resumed run continues exactly. Same update as `torch.optim.Adam`
//! (no weight decay, no AMSGrad): `p -= lr / (1 − β1^t) · m / (√v / √(1 − β2^t) + ε)`.

use candle_core::{backprop::GradStore, Tensor, Var};

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
        })
    }

    /// One update from `grads`; parameters without a gradient are left alone (their moments too).
    pub fn step(&mut self, grads: &GradStore) -> Result<(), ModelError> {
        self.t += 1;
        let bc1 = 1.0 - self.beta1.powi(self.t as i32);
        let bc2 = 1.0 - self.beta2.powi(self.t as i32);
        for (i, (_, var)) in self.vars.iter().enumerate() {
            let Some(g) = grads.get(var) else { continue };
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
}
