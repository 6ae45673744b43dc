//! A batch as two half-batches side by side (paper IV.B, speed on the CPU): data parallelism on top of the ops'
//! own parallelism.
//!
//! Measured first (`perf`, default model, batch-16 training step): about a third of the step's wall time ran on
//! one thread while the other core idled. Our convolution and GroupNorm ops split their work over the rayon pool,
//! but candle runs its elementwise ops and the whole backward walk on the calling thread: the gradient
//! accumulation (`zeros_like` + `add` for every graph edge), residual adds, concatenations, Adam. Running the two
//! halves of the batch as two independent graphs with `rayon::join` lets one half's serial stretches overlap with
//! the other half's parallel ops, on the same two threads. Every op computes each sample independently (GroupNorm
//! is per sample) and in a fixed order, so the halves give the same values as the whole batch; the training loss
//! is the sample-count-weighted sum of the halves' mean losses, and the gradients are summed (first half + second),
//! which equals the whole batch's gradient up to f32 rounding and is deterministic.

use std::ops::Range;

use candle_core::backprop::GradStore;
use candle_core::{Result, Tensor};

/// Batches smaller than this run as one graph.
pub const MIN_SPLIT: usize = 2;

/// The sample ranges of the halves of a batch of `n` (`n` itself when it is not split).
pub fn halves(n: usize) -> Vec<Range<usize>> {
    if n < MIN_SPLIT || rayon::current_num_threads() < 2 {
        std::iter::once(0..n).collect()
    } else {
        vec![0..n / 2, n / 2..n]
    }
}

/// `f` on the halves of a batch of `n` samples at the same time (one graph each), the results in order.
pub fn map_halves<T: Send>(
    n: usize,
    f: impl Fn(Range<usize>) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    let parts = halves(n);
    match parts.as_slice() {
        [a, b] => {
            let (x, y) = rayon::join(|| f(a.clone()), || f(b.clone()));
            Ok(vec![x?, y?])
        }
        _ => Ok(vec![f(0..n)?]),
    }
}

/// The mean loss of a batch of `n` and its gradients: `mean_loss(range)` is the mean loss of the samples in `range`
/// (a scalar); each half's is weighted by its share of the batch, back-propagated on its own, and the gradients are
/// summed.
pub fn loss_and_grads(
    n: usize,
    mean_loss: impl Fn(Range<usize>) -> Result<Tensor> + Sync,
) -> Result<(f32, GradStore)> {
    let parts = map_halves(n, |r| {
        let share = r.len() as f64 / n.max(1) as f64;
        let loss = mean_loss(r)?;
        let value = loss.to_scalar::<f32>()?;
        let grads = if share == 1.0 {
            loss.backward()?
        } else {
            (loss * share)?.backward()?
        };
        Ok((value as f64 * share, grads))
    })?;
    let mut parts = parts.into_iter();
    let Some((mut total, mut grads)) = parts.next() else {
        candle_core::bail!("loss of an empty batch")
    };
    for (value, more) in parts {
        total += value;
        grads.extend(more)?;
    }
    Ok((total as f32, grads))
}

/// `forward(x[range], range)` on the halves of `x` `[B, …]` at the same time, concatenated along the batch.
pub fn forward_halves(
    x: &Tensor,
    forward: impl Fn(&Tensor, Range<usize>) -> Result<Tensor> + Sync,
) -> Result<Tensor> {
    let n = x.dim(0)?;
    let mut outs = map_halves(n, |r| forward(&x.narrow(0, r.start, r.len())?, r))?;
    if outs.len() == 1 {
        return Ok(outs.remove(0));
    }
    Tensor::cat(&outs, 0)
}
