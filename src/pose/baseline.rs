//! The **threshold baseline** (paper V.D): instead of de-rendering with the model, keep the measured signature S where
//! the imprint Y = R − S exceeds a threshold (default 3 mm) as the in-contact depth, then back-project and register
//! exactly like the model's output.

use serde::{Deserialize, Serialize};

use crate::image::Image;

/// Settings of the threshold baseline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BaselineConfig {
    /// Imprint above which a pixel counts as in contact, metres (default 3 mm).
    pub threshold_m: f64,
}

impl Default for BaselineConfig {
    fn default() -> Self {
        Self { threshold_m: 0.003 }
    }
}

/// The baseline's in-contact depth: `S` where `Y > threshold_m` (and S is a valid depth), 0 elsewhere.
pub fn threshold_contact(signature: &Image, imprint: &Image, config: &BaselineConfig) -> Image {
    let t = config.threshold_m as f32;
    signature.zip_map(imprint, |s, y| {
        if y > t && s.is_finite() && s > 0.0 {
            s
        } else {
            0.0
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_signature_where_the_imprint_exceeds_the_threshold() {
        let s = Image::from_vec(4, 1, vec![0.07, 0.071, 0.072, f32::NAN]).unwrap();
        let y = Image::from_vec(4, 1, vec![0.001, 0.0031, 0.003, 0.01]).unwrap();
        let x = threshold_contact(&s, &y, &BaselineConfig::default());
        assert_eq!(x.data, vec![0.0, 0.071, 0.0, 0.0]);
    }
}
