//! The patched gradient accumulation of the vendored candle-core (vendor/candle-core/PATCHED.md): gradients
//! against analytic derivatives, for tensors with one consumer (the first gradient is stored as it is) and with
//! several (the later ones are added), through views (transpose, narrow) and our custom ops' callers.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use candle_core::{Device, Tensor, Var};

fn values(t: &Tensor) -> Vec<f32> {
    t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
}

#[test]
fn gradients_with_and_without_fan_in_match_the_analytic_ones() {
    let dev = Device::Cpu;
    let x = Var::from_vec(vec![1.0f32, -2.0, 3.0, 0.5, -1.5, 2.5], (2, 3), &dev).unwrap();
    let a = Tensor::from_vec(vec![0.5f32, 1.0, -1.0, 2.0, 0.25, -0.5], (2, 3), &dev).unwrap();
    // loss = sum(x·a) + sum(x²) + sum(3·x) + sum(xᵀ·(x reused)) : x feeds four consumers.
    let y1 = (x.as_tensor() * &a).unwrap().sum_all().unwrap();
    let y2 = x.sqr().unwrap().sum_all().unwrap();
    let y3 = x.affine(3.0, 0.0).unwrap().sum_all().unwrap();
    let y4 = x.t().unwrap().narrow(0, 1, 2).unwrap().sum_all().unwrap();
    let loss = (((y1 + y2).unwrap() + y3).unwrap() + y4).unwrap();
    let g = loss.backward().unwrap();
    let got = values(g.get(&x).unwrap());
    let xv = values(x.as_tensor());
    let av = values(&a);
    // d/dx: a + 2x + 3 + (1 where the column index is 1 or 2).
    for (i, gi) in got.iter().enumerate() {
        let col = i % 3;
        let want = av[i] + 2.0 * xv[i] + 3.0 + if col >= 1 { 1.0 } else { 0.0 };
        assert!((gi - want).abs() < 1e-6, "element {i}: {gi} vs {want}");
    }

    // A chain with one consumer per tensor: d/dx sum(exp(2x)) = 2 exp(2x), the gradient contiguous.
    let z = x
        .affine(2.0, 0.0)
        .unwrap()
        .exp()
        .unwrap()
        .sum_all()
        .unwrap();
    let g = z.backward().unwrap();
    let gx = g.get(&x).unwrap();
    assert!(gx.is_contiguous());
    for (gi, xi) in values(gx).iter().zip(&xv) {
        let want = 2.0 * (2.0 * xi).exp();
        assert!(
            (gi - want).abs() < 1e-4 * want.abs().max(1.0),
            "{gi} vs {want}"
        );
    }

    // x + x: both operands are the same tensor (stored, then added): gradient 2.
    let w = (x.as_tensor() + x.as_tensor()).unwrap().sum_all().unwrap();
    let g = w.backward().unwrap();
    assert!(values(g.get(&x).unwrap()).iter().all(|&v| v == 2.0));
}
