//! Ho et al.'s U-Net as diffusers `UNet2DModel` (`diffusers/models/unets/unet_2d.py`), the ε-predictor of the
//! conditional DDPM (paper IV.B): input `cat([x_t, imprint])`, output ε. Field and `vb.pp` names are the diffusers
//! state-dict keys, so diffusers checkpoints load unchanged.

use candle_core::{Module, Result, Tensor};
use candle_nn::VarBuilder;

use super::config::UNet2DConfig;
use super::conv::Conv2d;
use super::embeddings::{timestep_embedding, TimestepEmbedding};
use super::group_norm::{group_norm, GroupNorm};
use super::kernels::Kernels;
use super::resnet::ResnetCfg;
use super::unet_blocks::{AttnCfg, DownBlock2D, UNetMidBlock2D, UpBlock2D};

/// diffusers `UNet2DModel` with `time_embedding_type="positional"`.
#[derive(Clone, Debug)]
pub struct UNet2DModel {
    pub conv_in: Conv2d,
    pub time_embedding: TimestepEmbedding,
    pub down_blocks: Vec<DownBlock2D>,
    pub mid_block: Option<UNetMidBlock2D>,
    pub up_blocks: Vec<UpBlock2D>,
    pub conv_norm_out: GroupNorm,
    pub conv_out: Conv2d,
    pub config: UNet2DConfig,
}

impl UNet2DModel {
    /// Run the network on our fused CPU kernels ([`Kernels::Fast`], the default) or on candle's own tensor ops
    /// ([`Kernels::Portable`]: what every device other than the CPU runs; on the CPU, to check one against the other).
    pub fn set_kernels(&mut self, kernels: Kernels) {
        let portable = kernels == Kernels::Portable;
        self.set_conv_backend(if portable {
            super::conv::ConvBackend::Candle
        } else {
            super::conv::ConvBackend::default()
        });
        for a in self.attentions_mut() {
            a.portable = portable;
            a.group_norm.portable = portable;
        }
        let mut norms = vec![&mut self.conv_norm_out];
        for b in &mut self.down_blocks {
            norms.extend(b.resnets.iter_mut().flat_map(|r| r.norms_mut()));
        }
        if let Some(m) = &mut self.mid_block {
            norms.extend(m.resnets.iter_mut().flat_map(|r| r.norms_mut()));
        }
        for b in &mut self.up_blocks {
            norms.extend(b.resnets.iter_mut().flat_map(|r| r.norms_mut()));
            if let Some(u) = &mut b.upsamplers {
                u.portable = portable;
            }
        }
        for n in norms {
            n.portable = portable;
        }
    }

    /// Run every convolution with `backend` (benchmarks compare them; the default is the fastest).
    pub fn set_conv_backend(&mut self, backend: super::conv::ConvBackend) {
        for c in self.convs_mut() {
            c.backend = backend;
        }
    }

    /// Packs every convolution's weight once for inference ([`Conv2d::freeze`]): for a model whose weights are
    /// final (a loaded checkpoint); changes to them afterwards are not seen by the convolutions until
    /// [`UNet2DModel::thaw`]. Only our CPU convolutions use it.
    pub fn freeze(&mut self) -> Result<()> {
        self.convs_mut().into_iter().try_for_each(Conv2d::freeze)?;
        self.attentions_mut()
            .into_iter()
            .try_for_each(super::attention::Attention::freeze)
    }

    /// Undoes [`UNet2DModel::freeze`] (before training a frozen model).
    pub fn thaw(&mut self) {
        self.convs_mut().into_iter().for_each(Conv2d::thaw);
        self.attentions_mut()
            .into_iter()
            .for_each(super::attention::Attention::thaw);
    }

    fn attentions_mut(&mut self) -> Vec<&mut super::attention::Attention> {
        let mut attentions = Vec::new();
        for b in &mut self.down_blocks {
            attentions.extend(b.attentions.iter_mut());
        }
        if let Some(m) = &mut self.mid_block {
            attentions.extend(m.attentions.iter_mut());
        }
        for b in &mut self.up_blocks {
            attentions.extend(b.attentions.iter_mut());
        }
        attentions
    }

    /// Whether [`UNet2DModel::freeze`] holds packed weights.
    pub fn is_frozen(&self) -> bool {
        self.conv_in.frozen.is_some()
    }

    fn convs_mut(&mut self) -> Vec<&mut Conv2d> {
        let mut convs: Vec<&mut Conv2d> = vec![&mut self.conv_in, &mut self.conv_out];
        for b in &mut self.down_blocks {
            convs.extend(b.resnets.iter_mut().flat_map(|r| r.convs_mut()));
            convs.extend(b.downsamplers.as_mut().map(|d| &mut d.conv));
        }
        if let Some(m) = &mut self.mid_block {
            convs.extend(m.resnets.iter_mut().flat_map(|r| r.convs_mut()));
        }
        for b in &mut self.up_blocks {
            convs.extend(b.resnets.iter_mut().flat_map(|r| r.convs_mut()));
            convs.extend(b.upsamplers.as_mut().map(|u| &mut u.conv));
        }
        convs
    }

    /// Build from `vb` (names as in diffusers); `config` must have passed [`UNet2DConfig::validate`].
    pub fn new(vb: VarBuilder, config: &UNet2DConfig) -> Result<Self> {
        let ch = &config.block_out_channels;
        let n = ch.len();
        let temb = config.time_embed_dim();
        let rcfg = ResnetCfg {
            temb_channels: temb,
            groups: config.norm_num_groups,
            eps: config.norm_eps,
            output_scale_factor: 1.0,
            dropout: config.dropout as f32,
        };
        let attn = |ty: &str| {
            ty.starts_with("Attn").then_some(AttnCfg {
                head_dim: config.attention_head_dim,
                groups: config.norm_num_groups,
            })
        };
        let conv_in = Conv2d::new(vb.pp("conv_in"), config.in_channels, ch[0], 3, 1, 1, true)?;
        let time_embedding = TimestepEmbedding::new(vb.pp("time_embedding"), ch[0], temb)?;
        let mut down_blocks = Vec::with_capacity(n);
        let mut c_out = ch[0];
        for (i, ty) in config.down_block_types.iter().enumerate() {
            let c_in = c_out;
            c_out = ch[i];
            down_blocks.push(DownBlock2D::new(
                vb.pp("down_blocks").pp(i),
                c_in,
                c_out,
                config.layers_per_block,
                rcfg,
                attn(ty),
                i + 1 < n,
                config.downsample_padding,
            )?);
        }
        let mid_block = match &config.mid_block_type {
            Some(_) => {
                let mcfg = ResnetCfg {
                    output_scale_factor: config.mid_block_scale_factor,
                    ..rcfg
                };
                let a = config.add_attention.then_some(AttnCfg {
                    head_dim: config.attention_head_dim,
                    groups: config
                        .attn_norm_num_groups
                        .unwrap_or(config.norm_num_groups),
                });
                Some(UNetMidBlock2D::new(vb.pp("mid_block"), ch[n - 1], mcfg, a)?)
            }
            None => None,
        };
        let rev: Vec<usize> = ch.iter().rev().copied().collect();
        let mut up_blocks = Vec::with_capacity(n);
        let mut c_out = rev[0];
        for (i, ty) in config.up_block_types.iter().enumerate() {
            let prev = c_out;
            c_out = rev[i];
            let c_in = rev[(i + 1).min(n - 1)];
            up_blocks.push(UpBlock2D::new(
                vb.pp("up_blocks").pp(i),
                c_in,
                prev,
                c_out,
                config.layers_per_block + 1,
                rcfg,
                attn(ty),
                i + 1 < n,
            )?);
        }
        Ok(Self {
            conv_in,
            time_embedding,
            down_blocks,
            mid_block,
            up_blocks,
            conv_norm_out: group_norm(
                config.norm_num_groups,
                ch[0],
                config.norm_eps,
                vb.pp("conv_norm_out"),
            )?,
            conv_out: Conv2d::new(vb.pp("conv_out"), ch[0], config.out_channels, 3, 1, 1, true)?,
            config: config.clone(),
        })
    }

    /// ε prediction for `x` `[B, in_channels, H, W]` at diffusion `timesteps` (one per sample, or one for all).
    /// Batches of two or more run as two half-batches side by side ([`super::parallel_batch`]).
    pub fn forward(&self, x: &Tensor, timesteps: &[f32]) -> Result<Tensor> {
        let b = x.dim(0)?;
        if timesteps.len() != 1 && timesteps.len() != b {
            candle_core::bail!("{} timesteps for a batch of {b}", timesteps.len());
        }
        super::kernels::parallel_batch::forward_halves(x, |xh, r| {
            let t = if timesteps.len() == 1 {
                timesteps
            } else {
                &timesteps[r]
            };
            self.forward_t(xh, t, false)
        })
    }

    /// Like [`Self::forward`]; `train` enables dropout.
    pub fn forward_t(&self, x: &Tensor, timesteps: &[f32], train: bool) -> Result<Tensor> {
        let b = x.dim(0)?;
        let t: Vec<f32> = match timesteps.len() {
            1 => vec![timesteps[0]; b],
            n if n == b => timesteps.to_vec(),
            n => candle_core::bail!("{n} timesteps for a batch of {b}"),
        };
        let cfg = &self.config;
        let t_emb = timestep_embedding(
            &t,
            cfg.block_out_channels[0],
            cfg.flip_sin_to_cos,
            cfg.freq_shift,
            x.device(),
        )?;
        let emb = self.time_embedding.forward(&t_emb)?;
        let x = if cfg.center_input_sample {
            x.affine(2.0, -1.0)?
        } else {
            x.clone()
        };
        let mut h = self.conv_in.forward(&x)?;
        let mut skips = vec![h.clone()];
        for block in &self.down_blocks {
            let (out, states) = block.forward(&h, &emb, train)?;
            h = out;
            skips.extend(states);
        }
        if let Some(mid) = &self.mid_block {
            h = mid.forward(&h, &emb, train)?;
        }
        for block in &self.up_blocks {
            let k = block.resnets.len();
            if skips.len() < k {
                candle_core::bail!("U-Net skip stack exhausted");
            }
            let these = skips.split_off(skips.len() - k);
            h = block.forward(&h, &these, &emb, train)?;
        }
        let h = self.conv_norm_out.forward_silu(&h)?;
        self.conv_out.forward(&h)
    }

    /// Multiply-add FLOPs (2 per MAC) of one forward pass of one `sample_size`² sample: convolutions, linear layers
    /// and attention products (normalisations and activations are not counted).
    pub fn flops_per_sample(&self) -> f64 {
        let conv = |c: &Conv2d, out_px: usize| 2.0 * c.weight.elem_count() as f64 * out_px as f64;
        let resnet = |r: &super::resnet::ResnetBlock2D, px: usize| {
            conv(&r.conv1, px)
                + conv(&r.conv2, px)
                + r.conv_shortcut.as_ref().map_or(0.0, |c| conv(c, px))
        };
        let attn = |a: &super::attention::Attention, px: usize| {
            let c = a.group_norm.weight.elem_count() as f64;
            let n = px as f64;
            8.0 * n * c * c + 4.0 * n * n * c
        };
        let s = self.config.sample_size;
        let mut f = conv(&self.conv_in, s * s) + conv(&self.conv_out, s * s);
        let mut px = s * s;
        for b in &self.down_blocks {
            f += b.resnets.iter().map(|r| resnet(r, px)).sum::<f64>();
            f += b.attentions.iter().map(|a| attn(a, px)).sum::<f64>();
            if let Some(d) = &b.downsamplers {
                px /= 4;
                f += conv(&d.conv, px);
            }
        }
        if let Some(m) = &self.mid_block {
            f += m.resnets.iter().map(|r| resnet(r, px)).sum::<f64>();
            f += m.attentions.iter().map(|a| attn(a, px)).sum::<f64>();
        }
        for b in &self.up_blocks {
            f += b.resnets.iter().map(|r| resnet(r, px)).sum::<f64>();
            f += b.attentions.iter().map(|a| attn(a, px)).sum::<f64>();
            if let Some(u) = &b.upsamplers {
                px *= 4;
                f += conv(&u.conv, px);
            }
        }
        f
    }
}
