//! U-Net parity with diffusers `UNet2DModel` (fixtures made by `../shared/peers/unet_torch.py`, see
//! `tests/fixtures/README.md`), our convolution vs candle's, and checkpoint error handling.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use candle_core::{Device, Tensor, Var};
use tactile_derender::model::checkpoint::{read_tensors, save_model};
use tactile_derender::model::conv::{conv2d, ConvBackend, ConvGeom};
use tactile_derender::model::{DiffusionModel, ModelError};

fn parity(dir: &str) -> f32 {
    let model =
        DiffusionModel::load(&Path::new(dir).join("unet_ref.safetensors")).expect("load fixture");
    let io = read_tensors(&Path::new(dir).join("unet_ref_io.safetensors")).expect("io");
    let input = &io.tensors["input"];
    let t: Vec<f32> = io.tensors["timesteps"]
        .to_vec1::<i64>()
        .unwrap()
        .iter()
        .map(|&t| t as f32)
        .collect();
    let out = model.unet().forward(input, &t).unwrap();
    let diff = (out - &io.tensors["output"]).unwrap().abs().unwrap();
    let d = diff
        .flatten_all()
        .unwrap()
        .max(0)
        .unwrap()
        .to_scalar::<f32>()
        .unwrap();
    eprintln!("{dir}: max |Δ| = {d:e}");
    d
}

#[test]
fn unet_matches_diffusers_small() {
    let d = parity("tests/fixtures/unet_small");
    assert!(d <= 1e-4, "max |Δ| = {d}");
}

#[test]
fn unet_matches_diffusers_variant() {
    // downsample_padding 0, freq_shift 1, flip_sin_to_cos false, one head per block, mid_block_scale_factor 2,
    // time_embedding_dim 10, 2 layers per block, attention at the finest level.
    let d = parity("tests/fixtures/unet_variant");
    assert!(d <= 1e-4, "max |Δ| = {d}");
}

fn rand_t(shape: &[usize], seed: u64) -> Tensor {
    // Deterministic pseudo-random values (LCG) so the test does not depend on candle's RNG.
    let n: usize = shape.iter().product();
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let v: Vec<f32> = (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 33) as f32 / (1u64 << 31) as f32) - 0.5
        })
        .collect();
    Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
}

fn max_abs(a: &Tensor, b: &Tensor) -> f32 {
    (a - b)
        .unwrap()
        .abs()
        .unwrap()
        .flatten_all()
        .unwrap()
        .max(0)
        .unwrap()
        .to_scalar()
        .unwrap()
}

#[test]
fn im2col_conv_matches_candle_forward_and_backward() {
    let cases = [
        // (b, c_in, c_out, h, w, geom)
        (
            2,
            3,
            5,
            9,
            7,
            ConvGeom {
                kernel: 3,
                stride: 1,
                pad_begin: 1,
                pad_end: 1,
            },
        ),
        (
            3,
            4,
            2,
            8,
            8,
            ConvGeom {
                kernel: 3,
                stride: 2,
                pad_begin: 1,
                pad_end: 1,
            },
        ),
        (
            2,
            4,
            3,
            8,
            6,
            ConvGeom {
                kernel: 3,
                stride: 2,
                pad_begin: 0,
                pad_end: 1,
            },
        ),
        (
            1,
            6,
            4,
            5,
            5,
            ConvGeom {
                kernel: 1,
                stride: 1,
                pad_begin: 0,
                pad_end: 0,
            },
        ),
        // The direct path's edge cases: one output channel (the GEMM's portable loop), two input channels,
        // one sample, non-square; and a 5 × 5 kernel (padding 2).
        (
            1,
            2,
            1,
            7,
            5,
            ConvGeom {
                kernel: 3,
                stride: 1,
                pad_begin: 1,
                pad_end: 1,
            },
        ),
        (
            2,
            9,
            10,
            6,
            11,
            ConvGeom {
                kernel: 5,
                stride: 1,
                pad_begin: 2,
                pad_end: 2,
            },
        ),
        // Large enough for the tiled path's GEMM register blocks: K = 576 (5 K blocks of the AVX-512 kernel),
        // 400 output pixels in 2 tiles of 227 (dW accumulated across tiles), Cout = 24 (a partial 8-row block
        // and a masked 24-wide column strip).
        (
            2,
            64,
            24,
            20,
            20,
            ConvGeom {
                kernel: 3,
                stride: 1,
                pad_begin: 1,
                pad_end: 1,
            },
        ),
    ];
    for (i, &(b, ci, co, h, w, geom)) in cases.iter().enumerate() {
        let x = Var::from_tensor(&rand_t(&[b, ci, h, w], i as u64)).unwrap();
        let k =
            Var::from_tensor(&rand_t(&[co, ci, geom.kernel, geom.kernel], 100 + i as u64)).unwrap();
        let bias = Var::from_tensor(&rand_t(&[co], 200 + i as u64)).unwrap();
        let mut outs = Vec::new();
        for backend in [
            ConvBackend::Candle,
            ConvBackend::Im2colGemm,
            ConvBackend::Tiled,
            ConvBackend::Direct,
        ] {
            let y = conv2d(
                x.as_tensor(),
                k.as_tensor(),
                Some(bias.as_tensor()),
                geom,
                backend,
                None,
            )
            .unwrap();
            // A non-uniform upstream gradient: loss = sum(y * r).
            let r = rand_t(y.dims(), 300 + i as u64);
            let g = (&y * &r).unwrap().sum_all().unwrap().backward().unwrap();
            outs.push((
                y,
                g.get(&x).unwrap().clone(),
                g.get(&k).unwrap().clone(),
                g.get(&bias).unwrap().clone(),
            ));
        }
        let a = &outs[0];
        for (n, b2) in outs.iter().enumerate().skip(1) {
            assert_eq!(a.0.dims(), b2.0.dims(), "case {i}");
            // f32 rounding of sums of up to 800 terms: 1e-5 relative to the largest value (at least 1e-5).
            for (what, x, y) in [
                ("forward", &a.0, &b2.0),
                ("grad x", &a.1, &b2.1),
                ("grad w", &a.2, &b2.2),
                ("grad b", &a.3, &b2.3),
            ] {
                let scale = max_abs(x, &x.zeros_like().unwrap()).max(1.0);
                let err = max_abs(x, y);
                assert!(
                    err < 1e-5 * scale,
                    "{what} case {i} backend {n}: {err} (scale {scale})"
                );
            }
        }
    }
}

#[test]
fn checkpoint_round_trip_and_errors() {
    let dir = tempfile::tempdir().unwrap();
    let model =
        DiffusionModel::load(Path::new("tests/fixtures/unet_small/unet_ref.safetensors")).unwrap();
    // Save in our format, reload, same output.
    let ours = dir.path().join("m.safetensors");
    save_model(
        &ours,
        &model.vars().varmap,
        model.config(),
        Default::default(),
    )
    .unwrap();
    let again = DiffusionModel::load(&ours).unwrap();
    assert_eq!(again.config(), model.config());
    let x = rand_t(&[1, 2, 8, 8], 5);
    let d = max_abs(
        &model.unet().forward(&x, &[17.0]).unwrap(),
        &again.unet().forward(&x, &[17.0]).unwrap(),
    );
    assert_eq!(d, 0.0);

    // Missing file.
    let e = DiffusionModel::load(&dir.path().join("nope.safetensors"))
        .err()
        .unwrap();
    assert!(matches!(e, ModelError::MissingWeights { .. }), "{e}");
    assert!(e.to_string().contains("nope.safetensors"));
    // Truncated file.
    let bytes = std::fs::read(&ours).unwrap();
    let cut = dir.path().join("cut.safetensors");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = DiffusionModel::load(&cut).err().unwrap();
    assert!(matches!(e, ModelError::BadFile { .. }), "{e}");
    // Config that does not match the weights: more channels -> a shape error naming the key.
    let mut cfg = model.config().clone();
    cfg.block_out_channels = vec![8, 8, 8];
    cfg.norm_num_groups = 2;
    let wrong = dir.path().join("wrong.safetensors");
    let file = read_tensors(&ours).unwrap();
    let mut meta = file.metadata.clone();
    meta.insert("config".into(), cfg.to_json().unwrap());
    let tensors = file
        .tensors
        .iter()
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    tactile_derender::model::checkpoint::write_tensors(&wrong, &tensors, meta).unwrap();
    let e = DiffusionModel::load(&wrong).err().unwrap();
    match &e {
        ModelError::Shape { key, .. } => assert!(!key.is_empty()),
        other => panic!("expected a shape error, got {other}"),
    }
    assert!(e.to_string().contains("wrong.safetensors"));
}

#[test]
fn fused_group_norm_silu_matches_candle_nn() {
    use tactile_derender::model::group_norm::GroupNorm;
    // Small planes (scalar tails only) and 2 × 9 × 19 = 342 values per group (vector lanes, blocks and tails).
    for (shape, groups) in [([3, 6, 5, 4], 3), ([2, 8, 9, 19], 4)] {
        let c = shape[1];
        let x = Var::from_tensor(&((rand_t(&shape, 1) * 3.0).unwrap() + 0.5).unwrap()).unwrap();
        let w = Var::from_tensor(&(rand_t(&[c], 2) + 1.0).unwrap()).unwrap();
        let b = Var::from_tensor(&rand_t(&[c], 3)).unwrap();
        for silu in [false, true] {
            let ours = GroupNorm {
                weight: w.as_tensor().clone(),
                bias: b.as_tensor().clone(),
                groups,
                eps: 1e-5,
                portable: false,
            };
            let theirs = candle_nn::GroupNorm::new(
                w.as_tensor().clone(),
                b.as_tensor().clone(),
                c,
                groups,
                1e-5,
            )
            .unwrap();
            let y1 = if silu {
                ours.forward_silu(x.as_tensor())
            } else {
                ours.forward(x.as_tensor())
            }
            .unwrap();
            let y2 = candle_core::Module::forward(&theirs, x.as_tensor()).unwrap();
            let y2 = if silu { y2.silu().unwrap() } else { y2 };
            assert!(max_abs(&y1, &y2) < 1e-5, "forward silu={silu}");
            let r = rand_t(y1.dims(), 9);
            let g1 = (&y1 * &r).unwrap().sum_all().unwrap().backward().unwrap();
            let g2 = (&y2 * &r).unwrap().sum_all().unwrap().backward().unwrap();
            for v in [&x, &w, &b] {
                let d = max_abs(g1.get(v).unwrap(), g2.get(v).unwrap());
                assert!(d < 1e-4, "gradient silu={silu} {shape:?}: {d}");
            }
        }
    }
}

#[test]
fn group_norm_with_time_shift_matches_broadcast_add() {
    // silu(GroupNorm(x + t[:, :, None, None])) fused vs candle: broadcast_add, candle-nn GroupNorm, silu.
    use tactile_derender::model::group_norm::GroupNorm;
    let shape = [3, 8, 7, 13];
    let x = Var::from_tensor(&(rand_t(&shape, 11) * 2.0).unwrap()).unwrap();
    let t = Var::from_tensor(&(rand_t(&[3, 8], 12) * 3.0).unwrap()).unwrap();
    let w = Var::from_tensor(&(rand_t(&[8], 13) + 1.0).unwrap()).unwrap();
    let b = Var::from_tensor(&rand_t(&[8], 14)).unwrap();
    let ours = GroupNorm {
        weight: w.as_tensor().clone(),
        bias: b.as_tensor().clone(),
        groups: 4,
        eps: 1e-5,
        portable: false,
    };
    let theirs =
        candle_nn::GroupNorm::new(w.as_tensor().clone(), b.as_tensor().clone(), 8, 4, 1e-5)
            .unwrap();
    let y1 = ours
        .forward_shift_silu(x.as_tensor(), t.as_tensor())
        .unwrap();
    let xt = x
        .as_tensor()
        .broadcast_add(&t.as_tensor().unsqueeze(2).unwrap().unsqueeze(3).unwrap())
        .unwrap();
    let y2 = candle_core::Module::forward(&theirs, &xt)
        .unwrap()
        .silu()
        .unwrap();
    assert!(max_abs(&y1, &y2) < 1e-5);
    let r = rand_t(y1.dims(), 15);
    let g1 = (&y1 * &r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = (&y2 * &r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [&x, &t, &w, &b] {
        let d = max_abs(g1.get(v).unwrap(), g2.get(v).unwrap());
        assert!(d < 1e-4, "gradient {:?}: {d}", v.dims());
    }
    assert!(ours
        .forward_shift_silu(x.as_tensor(), &rand_t(&[3, 7], 1))
        .is_err());
}

#[test]
fn upsample_op_matches_broadcast_reshape() {
    // Reference: nearest × 2 as candle broadcast + reshape (its backward sums the 2 × 2 cells) and candle's own
    // upsample_nearest2d for the values.
    use tactile_derender::model::resnet::upsample_nearest_x2;
    let x = Var::from_tensor(&rand_t(&[2, 3, 5, 7], 21)).unwrap();
    let y1 = upsample_nearest_x2(x.as_tensor()).unwrap();
    let y2 = x
        .as_tensor()
        .reshape((2, 3, 5, 1, 7, 1))
        .unwrap()
        .broadcast_as((2, 3, 5, 2, 7, 2))
        .unwrap()
        .reshape((2, 3, 10, 14))
        .unwrap();
    assert_eq!(y1.dims(), &[2, 3, 10, 14]);
    assert_eq!(max_abs(&y1, &y2), 0.0);
    let y3 = x.as_tensor().upsample_nearest2d(10, 14).unwrap();
    assert_eq!(max_abs(&y1, &y3), 0.0);
    let r = rand_t(y1.dims(), 22);
    let g1 = (&y1 * &r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = (&y2 * &r).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(max_abs(g1.get(&x).unwrap(), g2.get(&x).unwrap()) < 1e-6);
}

#[test]
fn fused_attention_matches_candle_ops() {
    use tactile_derender::model::kernels::attention::fused_attention;
    // Reference: the heads split out of the channel-major [B, 3C, N] input, softmax(q kᵀ · scale) v with candle's
    // matmul and softmax, heads merged back channel-major [B, C, N].
    let reference = |qkv: &Tensor, heads: usize, scale: f32| -> Tensor {
        let (b, c3, n) = qkv.dims3().unwrap();
        let (c, d) = (c3 / 3, c3 / 3 / heads);
        let part = |i: usize| {
            qkv.narrow(1, i * c, c)
                .unwrap()
                .reshape((b, heads, d, n))
                .unwrap()
                .transpose(2, 3)
                .unwrap()
                .contiguous()
                .unwrap() // [B, heads, N, d]
        };
        let (q, k, v) = (part(0), part(1), part(2));
        let s = (q.matmul(&k.t().unwrap()).unwrap() * f64::from(scale)).unwrap();
        let p = candle_nn::ops::softmax(&s, candle_core::D::Minus1).unwrap();
        p.matmul(&v)
            .unwrap()
            .transpose(2, 3)
            .unwrap()
            .reshape((b, c, n))
            .unwrap()
    };
    // (batch, tokens, heads, head width): rows of 37 (two 16-lane blocks and a tail), one head over all channels,
    // the peer config's 16 heads of 8 at 16 × 16, and a 3-token edge case.
    for (b, n, heads, d) in [(2, 37, 3, 5), (1, 64, 1, 12), (2, 256, 16, 8), (3, 3, 2, 4)] {
        let c = heads * d;
        let qkv = Var::from_tensor(&(rand_t(&[b, 3 * c, n], 41) * 3.0).unwrap()).unwrap();
        let scale = 1.0 / (d as f32).sqrt();
        let y1 = fused_attention(qkv.as_tensor(), heads, scale).unwrap();
        let y2 = reference(qkv.as_tensor(), heads, scale);
        assert_eq!(y1.dims(), &[b, c, n]);
        let scale_y = max_abs(&y2, &y2.zeros_like().unwrap());
        assert!(
            max_abs(&y1, &y2) < 1e-5 * scale_y.max(1.0),
            "{b} {n} {heads} {d}"
        );
        let r = rand_t(y1.dims(), 42);
        let g1 = (&y1 * &r).unwrap().sum_all().unwrap().backward().unwrap();
        let g2 = (&y2 * &r).unwrap().sum_all().unwrap().backward().unwrap();
        let (g1, g2) = (g1.get(&qkv).unwrap(), g2.get(&qkv).unwrap());
        let scale_g = max_abs(g2, &g2.zeros_like().unwrap());
        assert!(scale_g > 1e-3, "the gradient must not vanish");
        let err = max_abs(g1, g2);
        assert!(
            err < 1e-5 * scale_g.max(1.0),
            "{b} {n} {heads} {d}: {err} (scale {scale_g})"
        );
    }
    // Channels that do not split into q, k, v of equal heads are refused.
    let bad = rand_t(&[1, 3 * 10, 4], 43);
    assert!(fused_attention(&bad, 3, 1.0).is_err());
    let empty = Tensor::zeros(
        (2, 12, 0),
        candle_core::DType::F32,
        &candle_core::Device::Cpu,
    )
    .unwrap();
    assert!(fused_attention(&empty, 2, 1.0).is_err());
}

#[test]
fn loads_a_diffusers_save_pretrained_directory() {
    // `UNet2DModel.save_pretrained` layout: config.json + diffusion_pytorch_model.safetensors without our metadata.
    let dir = tempfile::tempdir().unwrap();
    let src = read_tensors(Path::new("tests/fixtures/unet_small/unet_ref.safetensors")).unwrap();
    let tensors = src
        .tensors
        .iter()
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    tactile_derender::model::checkpoint::write_tensors(
        &dir.path().join("diffusion_pytorch_model.safetensors"),
        &tensors,
        Default::default(),
    )
    .unwrap();
    std::fs::copy(
        "tests/fixtures/unet_small/unet_ref_config.json",
        dir.path().join("config.json"),
    )
    .unwrap();
    let model = DiffusionModel::load(dir.path()).unwrap();
    let io = read_tensors(Path::new(
        "tests/fixtures/unet_small/unet_ref_io.safetensors",
    ))
    .unwrap();
    let t: Vec<f32> = io.tensors["timesteps"]
        .to_vec1::<i64>()
        .unwrap()
        .iter()
        .map(|&t| t as f32)
        .collect();
    let out = model.unet().forward(&io.tensors["input"], &t).unwrap();
    assert!(max_abs(&out, &io.tensors["output"]) <= 1e-4);
    // Without any config: a config error naming the file.
    std::fs::remove_file(dir.path().join("config.json")).unwrap();
    let e = DiffusionModel::load(dir.path()).err().unwrap();
    assert!(matches!(e, ModelError::Config { .. }), "{e}");
    assert!(e
        .to_string()
        .contains("diffusion_pytorch_model.safetensors"));
}

/// The two half-batches run side by side give the whole batch's output, loss and gradients (invariant: every op
/// treats samples independently), and a timestep count that fits neither is an error.
#[test]
fn half_batches_match_the_whole_batch() {
    use tactile_derender::model::kernels::parallel_batch::{halves, loss_and_grads};
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    pool.install(|| {
        assert_eq!(halves(5), vec![0..2, 2..5]);
        let model =
            DiffusionModel::load(Path::new("tests/fixtures/unet_small/unet_ref.safetensors"))
                .unwrap();
        let unet = model.unet();
        let x = rand_t(&[5, 2, 8, 8], 11);
        let target = rand_t(&[5, 1, 8, 8], 12);
        let t = [3.0, 50.0, 100.0, 200.0, 249.0];
        let whole = unet.forward_t(&x, &t, false).unwrap();
        let split = unet.forward(&x, &t).unwrap();
        assert!(max_abs(&whole, &split) < 1e-6);
        assert!(unet.forward(&x, &t[..3]).is_err());

        let loss = (unet.forward_t(&x, &t, true).unwrap() - &target)
            .unwrap()
            .sqr()
            .unwrap()
            .mean_all()
            .unwrap();
        let want = loss.backward().unwrap();
        let (value, got) = loss_and_grads(5, |r| {
            let pred = unet.forward_t(&x.narrow(0, r.start, r.len())?, &t[r.clone()], true)?;
            (pred - target.narrow(0, r.start, r.len())?)?
                .sqr()?
                .mean_all()
        })
        .unwrap();
        let whole_value = loss.to_scalar::<f32>().unwrap();
        assert!((value - whole_value).abs() < 1e-6 * whole_value.abs().max(1.0));
        let vars = model.vars().varmap.all_vars();
        assert!(!vars.is_empty());
        for v in &vars {
            let (a, b) = (want.get(v).unwrap(), got.get(v).unwrap());
            let scale = max_abs(a, &a.zeros_like().unwrap()).max(1e-3);
            assert!(max_abs(a, b) < 1e-5 * scale.max(1.0), "{:?}", v.dims());
        }
    });
}

/// A model written as a diffusers folder reads back bit-identically (weights, config, outputs), and the folder holds
/// what `from_pretrained` looks for (diffusers itself opens it in CI: tests/python/diffusers_export_check.py).
#[test]
fn diffusers_folder_export_round_trips() {
    use tactile_derender::model::diffusers_folder;
    let dir = tempfile::tempdir().unwrap();
    let model =
        DiffusionModel::load(Path::new("tests/fixtures/unet_small/unet_ref.safetensors")).unwrap();
    let folder = dir.path().join("exported");
    let files = diffusers_folder::export(&model, &folder).unwrap();
    assert!(files.iter().all(|f| f.is_file()), "{files:?}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("config.json")).unwrap())
            .unwrap();
    assert_eq!(config["_class_name"], "UNet2DModel");
    assert_eq!(config["in_channels"], 2);
    let sched: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(folder.join("scheduler_config.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(sched["_class_name"], "DDPMScheduler");
    assert_eq!(sched["beta_schedule"], "squaredcos_cap_v2");
    assert_eq!(sched["num_train_timesteps"], 250);
    let again = DiffusionModel::load(&folder).unwrap();
    assert_eq!(again.config(), model.config());
    let x = rand_t(&[2, 2, 8, 8], 21);
    let t = [4.0, 230.0];
    let d = max_abs(
        &model.unet().forward(&x, &t).unwrap(),
        &again.unet().forward(&x, &t).unwrap(),
    );
    assert_eq!(d, 0.0);
    // A folder missing its weights names the file.
    std::fs::remove_file(folder.join("diffusion_pytorch_model.safetensors")).unwrap();
    let err = match DiffusionModel::load(&folder) {
        Ok(_) => panic!("a folder without weights loaded"),
        Err(e) => e.to_string(),
    };
    assert!(err.contains("diffusion_pytorch_model.safetensors"), "{err}");
}

/// candle's own tensor ops (what a GPU runs: `Kernels::Portable`) give the fast CPU kernels' output within 1e-5
/// relative, forward and gradients, on both reference configurations (attention, odd padding, every block type).
#[test]
fn portable_candle_ops_match_the_fast_kernels() {
    use tactile_derender::model::kernels::Kernels;
    for fixture in ["unet_small", "unet_variant"] {
        let path = format!("tests/fixtures/{fixture}/unet_ref.safetensors");
        let fast = DiffusionModel::load(Path::new(&path)).unwrap();
        let mut portable = fast.unet().clone();
        portable.set_kernels(Kernels::Portable);
        let cfg = fast.config();
        let x = rand_t(&[3, cfg.in_channels, cfg.sample_size, cfg.sample_size], 31);
        let t = [0.0, 117.0, 249.0];
        let a = fast.unet().forward_t(&x, &t, false).unwrap();
        let b = portable.forward_t(&x, &t, false).unwrap();
        let scale = max_abs(&a, &a.zeros_like().unwrap()).max(1e-3);
        let err = max_abs(&a, &b);
        assert!(
            err <= 1e-5 * scale,
            "{fixture} forward: {err} (scale {scale})"
        );
        // Gradients of a loss through both (the parameters are shared: the clone holds the same Vars).
        let target = rand_t(&[3, cfg.out_channels, cfg.sample_size, cfg.sample_size], 32);
        let loss = |y: Tensor| (y - &target).unwrap().sqr().unwrap().mean_all().unwrap();
        let ga = loss(fast.unet().forward_t(&x, &t, true).unwrap())
            .backward()
            .unwrap();
        let gb = loss(portable.forward_t(&x, &t, true).unwrap())
            .backward()
            .unwrap();
        let vars = fast.vars().varmap.all_vars();
        assert!(!vars.is_empty());
        for v in &vars {
            let (ga, gb) = (ga.get(v).unwrap(), gb.get(v).unwrap());
            let scale = max_abs(ga, &ga.zeros_like().unwrap()).max(1e-4);
            let err = max_abs(ga, gb);
            assert!(
                err <= 1e-5 * scale.max(1.0),
                "{fixture} grad {:?}: {err} (scale {scale})",
                v.dims()
            );
        }
    }
}

/// A loaded model packs its convolution weights once (`UNet2DModel::freeze`); its output is bit-identical to the
/// same model packing per call, on both reference configurations and at batch 1 (channel ranges) and 3.
#[test]
fn frozen_weights_give_the_per_call_output() {
    for fixture in ["unet_small", "unet_variant"] {
        let path = format!("tests/fixtures/{fixture}/unet_ref.safetensors");
        let model = DiffusionModel::load(Path::new(&path)).unwrap();
        assert!(
            model.unet().is_frozen(),
            "{fixture}: a loaded model is frozen"
        );
        let mut per_call = model.unet().clone();
        per_call.thaw();
        assert!(!per_call.is_frozen());
        let cfg = model.config();
        for (b, seed) in [(1, 41), (3, 42)] {
            let x = rand_t(
                &[b, cfg.in_channels, cfg.sample_size, cfg.sample_size],
                seed,
            );
            let t: Vec<f32> = (0..b).map(|i| 10.0 + 90.0 * i as f32).collect();
            let flat = |y: Tensor| y.flatten_all().unwrap().to_vec1::<f32>().unwrap();
            let a = flat(model.unet().forward(&x, &t).unwrap());
            let c = flat(per_call.forward(&x, &t).unwrap());
            assert_eq!(a, c, "{fixture} batch {b}");
        }
    }
}
