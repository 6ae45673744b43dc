//! Normalisation of the imprint Y and the in-contact depth X0 (paper IV.B) between metres and the model's range.
//! DDPM clips its x0 estimate to [-1, 1], so the target must map into that interval; the mapping is saved in the
//! model config (`tactile_derender.imprint` / `.target`) so that a checkpoint carries its own units.

use serde::{Deserialize, Serialize};

use super::ModelError;

/// Affine map `model = (metres - offset_m) / scale_m`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Normalisation {
    /// Value in metres that maps to 0, metres.
    pub offset_m: f32,
    /// Metres per model unit (> 0), metres.
    pub scale_m: f32,
}

impl Default for Normalisation {
    fn default() -> Self {
        Self::default_target()
    }
}

impl Normalisation {
    /// Target X0: 0 (no contact) maps to -1, 0.10 m to +1 (the default camera sits 6 cm behind the membrane base and
    /// the dome is 3 cm high, so in-contact depths lie in about 0.06–0.09 m).
    pub fn default_target() -> Self {
        Self {
            offset_m: 0.05,
            scale_m: 0.05,
        }
    }

    /// Imprint Y = R − S: 0 maps to 0, 20 mm of membrane deformation to 1.
    pub fn default_imprint() -> Self {
        Self {
            offset_m: 0.0,
            scale_m: 0.02,
        }
    }

    /// Metres to model units.
    #[inline]
    pub fn forward(&self, metres: f32) -> f32 {
        (metres - self.offset_m) / self.scale_m
    }

    /// Model units to metres.
    #[inline]
    pub fn inverse(&self, model: f32) -> f32 {
        model * self.scale_m + self.offset_m
    }

    pub(crate) fn validate(&self, what: &str, source: &str) -> Result<(), ModelError> {
        if !(self.scale_m.is_finite() && self.scale_m > 0.0 && self.offset_m.is_finite()) {
            return Err(ModelError::Config {
                source_name: source.into(),
                message: format!(
                    "tactile_derender.{what}: scale_m must be positive and finite, offset_m finite (found {:?})",
                    self
                ),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_target_range() {
        let n = Normalisation::default_target();
        assert_eq!(n.forward(0.0), -1.0);
        assert!((n.forward(0.1) - 1.0).abs() < 1e-6);
        for x in [0.0f32, 0.061, 0.0875] {
            assert!((n.inverse(n.forward(x)) - x).abs() < 1e-7);
        }
    }
}
