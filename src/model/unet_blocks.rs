//! The levels of Ho et al.'s U-Net (paper IV.B): diffusers `DownBlock2D` / `AttnDownBlock2D`, `UNetMidBlock2D` and
//! `UpBlock2D` / `AttnUpBlock2D` (`diffusers/models/unets/unet_2d_blocks.py`). A block "with attention" runs an
//! `Attention` after each ResNet.

use candle_core::{Module, Result, Tensor};
use candle_nn::VarBuilder;

use super::attention::Attention;
use super::resnet::{Downsample2D, ResnetBlock2D, ResnetCfg, Upsample2D};

/// Attention settings of a block.
#[derive(Clone, Copy, Debug)]
pub struct AttnCfg {
    pub head_dim: Option<usize>,
    pub groups: usize,
}

/// `DownBlock2D` (no `attentions`) or `AttnDownBlock2D`: keys `resnets.j`, `attentions.j`, `downsamplers.0.conv`.
#[derive(Clone, Debug)]
pub struct DownBlock2D {
    pub resnets: Vec<ResnetBlock2D>,
    pub attentions: Vec<Attention>,
    pub downsamplers: Option<Downsample2D>,
}

impl DownBlock2D {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        vb: VarBuilder,
        c_in: usize,
        c_out: usize,
        layers: usize,
        rcfg: ResnetCfg,
        attn: Option<AttnCfg>,
        add_downsample: bool,
        downsample_padding: usize,
    ) -> Result<Self> {
        let mut resnets = Vec::with_capacity(layers);
        let mut attentions = Vec::new();
        for j in 0..layers {
            let cin = if j == 0 { c_in } else { c_out };
            resnets.push(ResnetBlock2D::new(
                vb.pp("resnets").pp(j),
                cin,
                c_out,
                rcfg,
            )?);
            if let Some(a) = attn {
                attentions.push(Attention::new(
                    vb.pp("attentions").pp(j),
                    c_out,
                    a.head_dim,
                    a.groups,
                    rcfg.eps,
                    rcfg.output_scale_factor,
                )?);
            }
        }
        let downsamplers = if add_downsample {
            Some(Downsample2D::new(
                vb.pp("downsamplers").pp("0"),
                c_out,
                downsample_padding,
            )?)
        } else {
            None
        };
        Ok(Self {
            resnets,
            attentions,
            downsamplers,
        })
    }

    /// Returns the output and the skip states (after each ResNet/attention pair, then after the down-sampler).
    pub fn forward(&self, x: &Tensor, temb: &Tensor, train: bool) -> Result<(Tensor, Vec<Tensor>)> {
        let mut h = x.clone();
        let mut states = Vec::with_capacity(self.resnets.len() + 1);
        for (j, resnet) in self.resnets.iter().enumerate() {
            h = resnet.forward(&h, temb, train)?;
            if let Some(a) = self.attentions.get(j) {
                h = a.forward(&h)?;
            }
            states.push(h.clone());
        }
        if let Some(d) = &self.downsamplers {
            h = d.forward(&h)?;
            states.push(h.clone());
        }
        Ok((h, states))
    }
}

/// `UNetMidBlock2D`: `resnets.0`, then for each layer `attentions.i` (when `add_attention`) and `resnets.i+1`.
#[derive(Clone, Debug)]
pub struct UNetMidBlock2D {
    pub resnets: Vec<ResnetBlock2D>,
    pub attentions: Vec<Attention>,
}

impl UNetMidBlock2D {
    pub fn new(
        vb: VarBuilder,
        channels: usize,
        rcfg: ResnetCfg,
        attn: Option<AttnCfg>,
    ) -> Result<Self> {
        let resnets = vec![
            ResnetBlock2D::new(vb.pp("resnets").pp("0"), channels, channels, rcfg)?,
            ResnetBlock2D::new(vb.pp("resnets").pp("1"), channels, channels, rcfg)?,
        ];
        let attentions = match attn {
            Some(a) => vec![Attention::new(
                vb.pp("attentions").pp("0"),
                channels,
                a.head_dim,
                a.groups,
                rcfg.eps,
                rcfg.output_scale_factor,
            )?],
            None => Vec::new(),
        };
        Ok(Self {
            resnets,
            attentions,
        })
    }

    pub fn forward(&self, x: &Tensor, temb: &Tensor, train: bool) -> Result<Tensor> {
        let mut h = self.resnets[0].forward(x, temb, train)?;
        for (i, resnet) in self.resnets.iter().enumerate().skip(1) {
            if let Some(a) = self.attentions.get(i - 1) {
                h = a.forward(&h)?;
            }
            h = resnet.forward(&h, temb, train)?;
        }
        Ok(h)
    }
}

/// `UpBlock2D` (no `attentions`) or `AttnUpBlock2D`: keys `resnets.j`, `attentions.j`, `upsamplers.0.conv`. ResNet
/// `j` takes `cat([h, skip], channels)` with the skips taken from the end of the down path.
#[derive(Clone, Debug)]
pub struct UpBlock2D {
    pub resnets: Vec<ResnetBlock2D>,
    pub attentions: Vec<Attention>,
    pub upsamplers: Option<Upsample2D>,
}

impl UpBlock2D {
    /// `c_in`: channels of the deepest skip this block consumes; `prev_out`: channels of the incoming `h`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        vb: VarBuilder,
        c_in: usize,
        prev_out: usize,
        c_out: usize,
        layers: usize,
        rcfg: ResnetCfg,
        attn: Option<AttnCfg>,
        add_upsample: bool,
    ) -> Result<Self> {
        let mut resnets = Vec::with_capacity(layers);
        let mut attentions = Vec::new();
        for j in 0..layers {
            let skip = if j == layers - 1 { c_in } else { c_out };
            let hin = if j == 0 { prev_out } else { c_out };
            resnets.push(ResnetBlock2D::new(
                vb.pp("resnets").pp(j),
                hin + skip,
                c_out,
                rcfg,
            )?);
            if let Some(a) = attn {
                attentions.push(Attention::new(
                    vb.pp("attentions").pp(j),
                    c_out,
                    a.head_dim,
                    a.groups,
                    rcfg.eps,
                    rcfg.output_scale_factor,
                )?);
            }
        }
        let upsamplers = if add_upsample {
            Some(Upsample2D::new(vb.pp("upsamplers").pp("0"), c_out)?)
        } else {
            None
        };
        Ok(Self {
            resnets,
            attentions,
            upsamplers,
        })
    }

    /// `skips` holds this block's skip states in down-path order; they are consumed from the last.
    pub fn forward(
        &self,
        x: &Tensor,
        skips: &[Tensor],
        temb: &Tensor,
        train: bool,
    ) -> Result<Tensor> {
        let mut h = x.clone();
        for (j, (resnet, skip)) in self.resnets.iter().zip(skips.iter().rev()).enumerate() {
            h = Tensor::cat(&[&h, skip], 1)?;
            h = resnet.forward(&h, temb, train)?;
            if let Some(a) = self.attentions.get(j) {
                h = a.forward(&h)?;
            }
        }
        if let Some(u) = &self.upsamplers {
            h = u.forward(&h)?;
        }
        Ok(h)
    }
}
