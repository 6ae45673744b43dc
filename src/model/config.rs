//! Model configuration (paper IV.B): the diffusers `UNet2DModel` config, mirrored field by field so that a
//! `config.json` written by `UNet2DModel.save_pretrained` loads here and ours loads there, plus our own section
//! (`tactile_derender`: normalisation of imprint and target, diffusion schedule) that diffusers ignores.

use serde::{Deserialize, Serialize};

use super::normalise::Normalisation;
use super::ModelError;

/// Largest image side a config may ask for, pixels.
pub const MAX_SAMPLE_SIZE: usize = 4096;
/// Most input or output channels.
pub const MAX_IO_CHANNELS: usize = 64;
/// Widest level, channels.
pub const MAX_CHANNELS: usize = 4096;
/// Most ResNet blocks per level.
pub const MAX_LAYERS_PER_BLOCK: usize = 16;
/// Most resolution levels.
pub const MAX_LEVELS: usize = 8;
/// Most diffusion steps of a training schedule.
pub const MAX_TIMESTEPS: usize = 100_000;
/// Most parameters (estimated by [`UNet2DConfig::parameter_estimate`]): 2 GB of f32, far above any U-Net trained
/// for this task (the bundled default has 2.7 M).
pub const MAX_PARAMETERS: u128 = 500_000_000;

/// diffusers `UNet2DModel` configuration (`diffusers/models/unets/unet_2d.py`). Field names and meanings are
/// diffusers'; values we do not implement are rejected by [`UNet2DConfig::validate`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct UNet2DConfig {
    /// Image side length in pixels (square images; the model itself accepts any multiple of 2^(levels-1)).
    pub sample_size: usize,
    /// Input channels: the noisy target x_t and the imprint condition (2).
    pub in_channels: usize,
    /// Output channels: the predicted noise ε (1).
    pub out_channels: usize,
    /// diffusers: map the input from [0, 1] to [-1, 1] first (`2x - 1`).
    pub center_input_sample: bool,
    /// Only `"positional"` (sinusoidal) is supported.
    pub time_embedding_type: String,
    /// Width of the time embedding; `None` = 4 × `block_out_channels[0]`.
    pub time_embedding_dim: Option<usize>,
    /// `downscale_freq_shift` of the sinusoidal embedding (diffusers default 0).
    pub freq_shift: f64,
    /// Put cosines before sines in the sinusoidal embedding (diffusers default true).
    pub flip_sin_to_cos: bool,
    /// `"DownBlock2D"` or `"AttnDownBlock2D"` per level, finest first.
    pub down_block_types: Vec<String>,
    /// `"UNetMidBlock2D"` (with attention when `add_attention`) or `None` for no middle block.
    pub mid_block_type: Option<String>,
    /// `"UpBlock2D"` or `"AttnUpBlock2D"` per level, coarsest first.
    pub up_block_types: Vec<String>,
    /// Channels of each level, finest first.
    pub block_out_channels: Vec<usize>,
    /// ResNet blocks per down level (up levels have one more).
    pub layers_per_block: usize,
    /// `output_scale_factor` of the middle block's ResNets and attention.
    pub mid_block_scale_factor: f64,
    /// Padding of the stride-2 down-sampling convolutions (1; 0 pads one pixel right/bottom like diffusers).
    pub downsample_padding: usize,
    /// Only `"conv"` is supported.
    pub downsample_type: String,
    /// Only `"conv"` is supported.
    pub upsample_type: String,
    /// Dropout probability (used in training only; 0 in the paper's setting).
    pub dropout: f64,
    /// Only `"silu"` is supported.
    pub act_fn: String,
    /// Channels per attention head; `None` = one head over all channels.
    pub attention_head_dim: Option<usize>,
    /// Groups of every GroupNorm.
    pub norm_num_groups: usize,
    /// Groups of the middle block's attention GroupNorm; `None` = `norm_num_groups`.
    pub attn_norm_num_groups: Option<usize>,
    /// ε of every GroupNorm.
    pub norm_eps: f64,
    /// Only `"default"` (additive time embedding) is supported.
    pub resnet_time_scale_shift: String,
    /// Attention in the middle block.
    pub add_attention: bool,
    /// Class conditioning is not supported (must be `None`).
    pub class_embed_type: Option<String>,
    /// Class conditioning is not supported (must be `None`).
    pub num_class_embeds: Option<usize>,
    /// Informational (diffusers keeps it in the config); our schedule is in [`TactileConfig`].
    pub num_train_timesteps: Option<usize>,
    /// Our section: normalisation and schedule. Absent in a plain diffusers config (then defaults apply).
    pub tactile_derender: TactileConfig,
}

impl Default for UNet2DConfig {
    /// The architecture of the bundled `small` model (the bundled default, which `tnd train` starts from, is the same
    /// network with levels 32/64/96/96, 2.7 M parameters; `assets/models/README.md`): 64 × 64, four levels 16/32/64/64, one ResNet per level, attention at the coarsest level (8 × 8) and in the middle block —
    /// the peer script's "smaller U-Net" (1.09 M parameters), so that PyTorch figures exist for it.
    fn default() -> Self {
        Self {
            sample_size: 64,
            in_channels: 2,
            out_channels: 1,
            center_input_sample: false,
            time_embedding_type: "positional".into(),
            time_embedding_dim: None,
            freq_shift: 0.0,
            flip_sin_to_cos: true,
            down_block_types: vec![
                "DownBlock2D".into(),
                "DownBlock2D".into(),
                "DownBlock2D".into(),
                "AttnDownBlock2D".into(),
            ],
            mid_block_type: Some("UNetMidBlock2D".into()),
            up_block_types: vec![
                "AttnUpBlock2D".into(),
                "UpBlock2D".into(),
                "UpBlock2D".into(),
                "UpBlock2D".into(),
            ],
            block_out_channels: vec![16, 32, 64, 64],
            layers_per_block: 1,
            mid_block_scale_factor: 1.0,
            downsample_padding: 1,
            downsample_type: "conv".into(),
            upsample_type: "conv".into(),
            dropout: 0.0,
            act_fn: "silu".into(),
            attention_head_dim: Some(8),
            norm_num_groups: 8,
            attn_norm_num_groups: None,
            norm_eps: 1e-5,
            resnet_time_scale_shift: "default".into(),
            add_attention: true,
            class_embed_type: None,
            num_class_embeds: None,
            num_train_timesteps: None,
            tactile_derender: TactileConfig::default(),
        }
    }
}

/// Our part of the config: how images in metres map to the model's range, and the diffusion schedule.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TactileConfig {
    /// Imprint (input condition) normalisation.
    pub imprint: Normalisation,
    /// Target (in-contact depth X0) normalisation.
    pub target: Normalisation,
    /// Decoded sample pixels shallower than this are "no contact" (0 m), metres. The model never outputs the
    /// no-contact code (0 m, −1 with the default normalisation) exactly, and a background pixel decoded to, say,
    /// 7 mm would back-project to a point just in front of the camera. The default, 0.05 m, is the middle of the
    /// default target range (model value 0): in-contact depths of the default sensor are 0.076–0.090 m (model
    /// 0.52–0.80), so the cut has a wide margin on both sides.
    pub contact_min_depth_m: f32,
    /// Diffusion steps T of the training schedule (the paper: 250).
    pub num_train_timesteps: usize,
    /// diffusers `beta_schedule`; only `"squaredcos_cap_v2"` (Nichol & Dhariwal's cosine schedule) is supported.
    pub beta_schedule: String,
    /// What the network predicts (diffusers' scheduler `prediction_type`): the noise ε (the paper, Ho et al.) or the
    /// velocity v = √ᾱ·ε − √(1−ᾱ)·x0 (Salimans & Ho). Checkpoints without the entry are ε-prediction models.
    pub prediction_type: PredictionType,
}

/// The network's regression target (diffusers' `prediction_type`).
///
/// With ε-prediction the sampler recovers x0 = (x_t − √(1−ᾱ)·ε̂)/√ᾱ, which divides the network's error by √ᾱ: at the
/// first steps of the cosine schedule (ᾱ = 0.003 at t = 240 of 250, ~1e-6 at t = 249) x0 is mostly the clipped
/// amplification of that error, and the sampler commits to contact regions the imprint does not support. With
/// v-prediction x0 = √ᾱ·x_t − √(1−ᾱ)·v̂ stays as accurate as v̂ at every noise level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum PredictionType {
    /// ε, the added noise (Ho et al.; the paper).
    #[default]
    #[value(name = "eps", alias = "epsilon")]
    Epsilon,
    /// v = √ᾱ·ε − √(1−ᾱ)·x0.
    #[value(name = "v", alias = "v_prediction")]
    VPrediction,
}

impl PredictionType {
    /// `(x0, ε)` from a network output `out` at a pixel with value `x_t`, where `sa = √ᾱ_t` and `sb = √(1 − ᾱ_t)`;
    /// x0 unclipped (diffusers' `pred_original_sample`, `pred_epsilon`).
    #[inline]
    pub fn x0_eps(self, out: f32, x_t: f32, sa: f32, sb: f32) -> (f32, f32) {
        match self {
            Self::Epsilon => ((x_t - sb * out) / sa, out),
            Self::VPrediction => (sa * x_t - sb * out, sa * out + sb * x_t),
        }
    }
}

impl Default for TactileConfig {
    fn default() -> Self {
        Self {
            imprint: Normalisation::default_imprint(),
            target: Normalisation::default_target(),
            contact_min_depth_m: 0.05,
            num_train_timesteps: 250,
            beta_schedule: "squaredcos_cap_v2".into(),
            prediction_type: PredictionType::Epsilon,
        }
    }
}

impl UNet2DConfig {
    /// Parse a config JSON (ours or diffusers'); `source` names the file in errors. A key that is neither a
    /// `UNet2DModel` argument nor diffusers metadata (`_class_name`, `_diffusers_version`, …) is refused, so a setting
    /// in the wrong place (`prediction_type` beside `block_out_channels` instead of under `tactile_derender`) cannot
    /// silently fall back to its default.
    pub fn from_json(text: &str, source: &str) -> Result<Self, ModelError> {
        let bad = |message: String| ModelError::Config {
            source_name: source.into(),
            message,
        };
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| bad(format!("not a valid UNet2DModel config: {e}")))?;
        let object = value
            .as_object()
            .ok_or_else(|| bad("not a valid UNet2DModel config: not a JSON object".into()))?;
        let known = serde_json::to_value(Self::default()).map_err(|e| bad(e.to_string()))?;
        let ours =
            serde_json::to_value(TactileConfig::default()).map_err(|e| bad(e.to_string()))?;
        for key in object.keys() {
            if key.starts_with('_') || known.get(key).is_some() {
                continue;
            }
            return Err(bad(if ours.get(key).is_some() {
                format!(
                    "unknown key \"{key}\" at the top level; it belongs under \"tactile_derender\""
                )
            } else {
                format!("unknown key \"{key}\" (not a UNet2DModel setting)")
            }));
        }
        let cfg: Self = serde_json::from_value(value)
            .map_err(|e| bad(format!("not a valid UNet2DModel config: {e}")))?;
        cfg.validate(source)?;
        Ok(cfg)
    }

    /// The config as diffusers-compatible JSON (with `_class_name` so `UNet2DModel.from_pretrained` accepts it).
    pub fn to_json(&self) -> Result<String, ModelError> {
        let mut v = serde_json::to_value(self).map_err(|e| ModelError::Config {
            source_name: "config".into(),
            message: e.to_string(),
        })?;
        if let Some(o) = v.as_object_mut() {
            o.insert("_class_name".into(), "UNet2DModel".into());
        }
        serde_json::to_string_pretty(&v).map_err(|e| ModelError::Config {
            source_name: "config".into(),
            message: e.to_string(),
        })
    }

    /// An upper estimate of the parameter count from the channel widths (3x3 convolutions of every ResNet, down and
    /// up, and the middle block), cheap to compute before anything is allocated.
    pub fn parameter_estimate(&self) -> u128 {
        let layers = self.layers_per_block as u128;
        let channels: Vec<u128> = self.block_out_channels.iter().map(|&c| c as u128).collect();
        let mut total = 0u128;
        for (i, &c) in channels.iter().enumerate() {
            let wider = channels.get(i + 1).copied().unwrap_or(c).max(c);
            // Down: `layers` ResNets of two convolutions; up: `layers + 1` of them at up to twice the width in.
            total += 9 * 2 * layers * c * c + 9 * 2 * (layers + 1) * 2 * wider * wider;
        }
        let last = channels.last().copied().unwrap_or(0);
        total + 9 * 4 * last * last
    }

    /// Width of the time embedding.
    pub fn time_embed_dim(&self) -> usize {
        self.time_embedding_dim
            .unwrap_or(4 * self.block_out_channels.first().copied().unwrap_or(0))
    }

    /// Reject settings we do not implement, with the field named.
    pub fn validate(&self, source: &str) -> Result<(), ModelError> {
        let bad = |message: String| ModelError::Config {
            source_name: source.into(),
            message,
        };
        self.check_sizes().map_err(bad)?;
        self.check_numbers().map_err(bad)?;
        self.check_block_types().map_err(bad)?;
        self.check_fixed_choices().map_err(bad)?;
        self.check_divisibility().map_err(bad)?;
        self.tactile_derender.imprint.validate("imprint", source)?;
        self.tactile_derender.target.validate("target", source)?;
        let cut = self.tactile_derender.contact_min_depth_m;
        if !(cut.is_finite() && cut >= 0.0) {
            return Err(bad(format!(
                "tactile_derender.contact_min_depth_m must be finite and not negative (found {cut})"
            )));
        }
        Ok(())
    }

    /// Sizes bounded before anything is allocated: an absurd value in a config or a checkpoint's metadata is
    /// refused naming the field, instead of aborting in a multi-terabyte allocation ([`Self::validate`]'s first
    /// step).
    fn check_sizes(&self) -> Result<(), String> {
        let n = self.block_out_channels.len();
        for (field, value, max) in [
            ("sample_size", self.sample_size, MAX_SAMPLE_SIZE),
            ("in_channels", self.in_channels, MAX_IO_CHANNELS),
            ("out_channels", self.out_channels, MAX_IO_CHANNELS),
            (
                "layers_per_block",
                self.layers_per_block,
                MAX_LAYERS_PER_BLOCK,
            ),
            ("block_out_channels (levels)", n, MAX_LEVELS),
            ("norm_num_groups", self.norm_num_groups, MAX_CHANNELS),
            (
                "time_embedding_dim",
                self.time_embedding_dim.unwrap_or(1),
                4 * MAX_CHANNELS,
            ),
            (
                "attention_head_dim",
                self.attention_head_dim.unwrap_or(1),
                MAX_CHANNELS,
            ),
            (
                "num_train_timesteps",
                self.num_train_timesteps.unwrap_or(1),
                MAX_TIMESTEPS,
            ),
            (
                "tactile_derender.num_train_timesteps",
                self.tactile_derender.num_train_timesteps,
                MAX_TIMESTEPS,
            ),
        ] {
            if value > max {
                return Err(format!("{field} {value} is out of range (at most {max})"));
            }
        }
        if self.time_embedding_dim == Some(0) {
            return Err("time_embedding_dim must be at least 1".into());
        }
        for &c in &self.block_out_channels {
            if c == 0 || c > MAX_CHANNELS {
                return Err(format!(
                    "block_out_channels {c} is out of range (1 to {MAX_CHANNELS})"
                ));
            }
        }
        let parameters = self.parameter_estimate();
        if parameters > MAX_PARAMETERS {
            return Err(format!(
                "block_out_channels {:?} with layers_per_block {} make about {:.1e} parameters, more than the {:.0e} \
                 a model here may have",
                self.block_out_channels, self.layers_per_block, parameters as f64, MAX_PARAMETERS as f64
            ));
        }
        Ok(())
    }

    /// The dropout is a probability below 1 and the other real-valued settings are finite.
    fn check_numbers(&self) -> Result<(), String> {
        if !(self.dropout.is_finite() && (0.0..1.0).contains(&self.dropout)) {
            return Err(format!("dropout {} must be in [0, 1)", self.dropout));
        }
        for (field, value) in [
            ("norm_eps", self.norm_eps),
            ("mid_block_scale_factor", self.mid_block_scale_factor),
            ("freq_shift", self.freq_shift),
        ] {
            if !value.is_finite() {
                return Err(format!("{field} {value} must be finite"));
            }
        }
        Ok(())
    }

    /// One down and one up block per level, of the block types implemented here, and the one middle block.
    fn check_block_types(&self) -> Result<(), String> {
        let n = self.block_out_channels.len();
        if n == 0 || self.down_block_types.len() != n || self.up_block_types.len() != n {
            return Err(format!(
                "block_out_channels, down_block_types and up_block_types must have the same non-zero length \
                 (found {n}, {}, {})",
                self.down_block_types.len(),
                self.up_block_types.len()
            ));
        }
        for t in &self.down_block_types {
            if t != "DownBlock2D" && t != "AttnDownBlock2D" {
                return Err(format!(
                    "down block type '{t}' is not supported (DownBlock2D, AttnDownBlock2D)"
                ));
            }
        }
        for t in &self.up_block_types {
            if t != "UpBlock2D" && t != "AttnUpBlock2D" {
                return Err(format!(
                    "up block type '{t}' is not supported (UpBlock2D, AttnUpBlock2D)"
                ));
            }
        }
        if let Some(m) = &self.mid_block_type {
            if m != "UNetMidBlock2D" {
                return Err(format!(
                    "mid_block_type '{m}' is not supported (UNetMidBlock2D or null)"
                ));
            }
        }
        Ok(())
    }

    /// The settings that have one implemented value (embedding, resampling, activation, no class conditioning, the
    /// noise schedule) and the simple bounds on the others.
    fn check_fixed_choices(&self) -> Result<(), String> {
        let checks = [
            (
                self.time_embedding_type == "positional",
                "time_embedding_type must be \"positional\"",
            ),
            (
                self.downsample_type == "conv",
                "downsample_type must be \"conv\"",
            ),
            (
                self.upsample_type == "conv",
                "upsample_type must be \"conv\"",
            ),
            (self.act_fn == "silu", "act_fn must be \"silu\""),
            (
                self.resnet_time_scale_shift == "default",
                "resnet_time_scale_shift must be \"default\"",
            ),
            (
                self.class_embed_type.is_none() && self.num_class_embeds.is_none(),
                "class conditioning is not supported",
            ),
            (
                self.downsample_padding <= 1,
                "downsample_padding must be 0 or 1",
            ),
            (
                self.layers_per_block > 0,
                "layers_per_block must be at least 1",
            ),
            (self.norm_eps > 0.0, "norm_eps must be positive"),
            (
                self.in_channels > self.out_channels,
                "in_channels must exceed out_channels (the imprint is a channel)",
            ),
            (
                self.tactile_derender.beta_schedule == "squaredcos_cap_v2",
                "tactile_derender.beta_schedule must be \"squaredcos_cap_v2\"",
            ),
            (
                self.tactile_derender.num_train_timesteps >= 2,
                "tactile_derender.num_train_timesteps must be at least 2",
            ),
        ];
        for (ok, msg) in checks {
            if !ok {
                return Err(msg.into());
            }
        }
        Ok(())
    }

    /// Every level's channels split into the norm groups and attention heads, and the sample size halves at every
    /// level but the last. After [`Self::check_block_types`] (at least one level).
    fn check_divisibility(&self) -> Result<(), String> {
        let n = self.block_out_channels.len();
        let g = self.norm_num_groups;
        for &c in &self.block_out_channels {
            if g == 0 || c % g != 0 {
                return Err(format!(
                    "block_out_channels {c} is not divisible by norm_num_groups {g}"
                ));
            }
            if let Some(h) = self.attention_head_dim {
                if h == 0 || c % h != 0 {
                    return Err(format!(
                        "block_out_channels {c} is not divisible by attention_head_dim {h}"
                    ));
                }
            }
        }
        let factor = 1usize << (n - 1);
        if self.sample_size == 0 || !self.sample_size.is_multiple_of(factor) {
            return Err(format!(
                "sample_size {} must be a positive multiple of {factor} (2^(levels-1))",
                self.sample_size
            ));
        }
        Ok(())
    }
}
