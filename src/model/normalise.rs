//! Normalisation of the imprint Y and the in-contact depth X0 (paper IV.B) between metres and the model's range.
//! DDPM clips its x0 estimate to [-1, 1], so the target must map into that interval; the mapping is saved in the
//! model config (`tactile_derender.imprint` / `.target`) so that a checkpoint carries its own units. A sensor whose
//! contact lies elsewhere gets a mapping fitted to it ([`super::config::TactileConfig::fitted_to_contact_range`]).

use serde::{Deserialize, Serialize};

use super::ModelError;

/// Affine map `model = (metres - offset_m) / scale_m`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
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

impl super::config::TactileConfig {
    /// Why in-contact depths in `[lo_m, hi_m]` (metres, e.g. a dataset's) do not fit this model's target mapping, or
    /// `None` when they do: the shallowest must lie beyond the contact cut (else its samples decode as no contact)
    /// and the deepest inside the model's range (else it is clipped).
    pub fn contact_range_problem(&self, lo_m: f32, hi_m: f32) -> Option<String> {
        let (cut, top) = (self.contact_min_depth_m, self.target.inverse(1.0));
        let mm = |m: f32| format!("{:.1} mm", m * 1e3);
        if lo_m <= cut {
            Some(format!(
                "in-contact depths {:.1}–{} reach below the model's contact cut {} \
                 (tactile_derender.contact_min_depth_m): such contact decodes as no contact",
                lo_m * 1e3,
                mm(hi_m),
                mm(cut)
            ))
        } else if hi_m > top {
            Some(format!(
                "in-contact depths {:.1}–{} reach beyond the deepest depth the model represents, {} \
                 (tactile_derender.target offset_m + scale_m): deeper contact is clipped",
                lo_m * 1e3,
                mm(hi_m),
                mm(top)
            ))
        } else {
            None
        }
    }

    /// This config with its target mapping fitted to in-contact depths in `[lo_m, hi_m]` (metres), as the default
    /// is to the default sensor: no contact (0 m) maps to −1, 1.2 × the deepest to +1, and the contact cut sits in
    /// the middle (model 0) or, when that would come within a quarter of the shallowest depth, at 3/4 of it.
    pub fn fitted_to_contact_range(&self, lo_m: f32, hi_m: f32) -> Self {
        let half = 0.6 * hi_m;
        Self {
            target: Normalisation {
                offset_m: half,
                scale_m: half,
            },
            contact_min_depth_m: half.min(0.75 * lo_m),
            ..self.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fitted_mapping_holds_the_contact_the_default_cannot() {
        let default = super::super::config::TactileConfig::default();
        // The default sensor's contact (76–90 mm) fits the default; a shallow sensor's (34–40 mm) does not, nor does
        // a deep one's (80–130 mm).
        assert_eq!(default.contact_range_problem(0.076, 0.090), None);
        let shallow = default.contact_range_problem(0.034, 0.040).unwrap();
        assert!(
            shallow.contains("34.0–40.0 mm") && shallow.contains("cut 50.0 mm"),
            "{shallow}"
        );
        assert!(default
            .contact_range_problem(0.080, 0.130)
            .unwrap()
            .contains("clipped"));
        for (lo, hi) in [(0.034, 0.040), (0.080, 0.130), (0.010, 0.090)] {
            let fit = default.fitted_to_contact_range(lo, hi);
            assert_eq!(fit.contact_range_problem(lo, hi), None, "{lo}–{hi}");
            assert_eq!(fit.target.forward(0.0), -1.0);
            assert!(fit.target.forward(hi) < 0.9);
            assert_eq!(fit.prediction_type, default.prediction_type);
        }
        // The default sensor's range gives back the default's own cut position: model 0.
        let fit = default.fitted_to_contact_range(0.076, 0.090);
        assert_eq!(fit.target.forward(fit.contact_min_depth_m), 0.0);
    }

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
