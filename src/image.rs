//! Single-channel float images (row-major, metres or 0/1 masks) shared by every pipeline stage.

use serde::{Deserialize, Serialize};

/// A row-major `height x width` image of `f32`. Depth images are z-depths in metres with `0.0` meaning "no value"
/// (ray miss, outside the contact region, or a pixel without a return: [`Image::missing_as_zero`]); masks hold
/// `0.0`/`1.0`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl Image {
    /// An image filled with `value`.
    pub fn filled(width: usize, height: usize, value: f32) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }

    /// An image from row-major data; `None` if the length does not match.
    pub fn from_vec(width: usize, height: usize, data: Vec<f32>) -> Option<Self> {
        (data.len() == width * height).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// Value at column `u`, row `v`.
    #[inline]
    pub fn get(&self, u: usize, v: usize) -> f32 {
        self.data[v * self.width + u]
    }

    /// Mutable value at column `u`, row `v`.
    #[inline]
    pub fn get_mut(&mut self, u: usize, v: usize) -> &mut f32 {
        &mut self.data[v * self.width + u]
    }

    /// `(min, max)` over the pixels where `valid` holds; `None` if there are none.
    pub fn range_where(&self, valid: impl Fn(f32) -> bool) -> Option<(f32, f32)> {
        self.data
            .iter()
            .copied()
            .filter(|&x| valid(x))
            .fold(None, |acc, x| match acc {
                None => Some((x, x)),
                Some((lo, hi)) => Some((lo.min(x), hi.max(x))),
            })
    }

    /// Number of pixels with a value other than zero.
    pub fn count_nonzero(&self) -> usize {
        self.data.iter().filter(|&&x| x != 0.0).count()
    }

    /// Element-wise combination of two images of the same size.
    pub fn zip_map(&self, other: &Image, f: impl Fn(f32, f32) -> f32) -> Image {
        debug_assert_eq!((self.width, self.height), (other.width, other.height));
        Image {
            width: self.width,
            height: self.height,
            data: self
                .data
                .iter()
                .zip(&other.data)
                .map(|(&a, &b)| f(a, b))
                .collect(),
        }
    }
}

/// Farthest depth, metres, a tactile sensor's camera can report: a value beyond it (a 16-bit driver's 65 535 mm
/// sentinel, say) is a pixel without a return, not a depth.
pub const MAX_DEPTH_M: f32 = 2.0;

/// Whether `d` is a measured depth (metres): finite, positive and within [`MAX_DEPTH_M`]. NaN, ±inf, 0, negative
/// and out-of-range values are how depth cameras and their drivers mark a pixel without a return (REP 118: NaN in
/// 32FC1, 0 in 16UC1).
#[inline]
pub fn is_measured_depth(d: f32) -> bool {
    d.is_finite() && d > 0.0 && d <= MAX_DEPTH_M
}

/// What to tell of depths whose typical magnitude is `typical` (beyond [`MAX_DEPTH_M`]), with `fix` the way to
/// read millimetres: millimetres when they could be (a tactile sensor's depths are up to ~0.2 m: 200 mm), and
/// otherwise that they are no depths at all (1e30 is not "around 1000000000000000000000000000000 m: millimetres?").
pub fn implausible_depth_units(typical: f32, fix: &str) -> String {
    if typical <= 2000.0 {
        format!("depths around {typical} m: millimetres? {fix}")
    } else {
        format!("depths around {typical:e}: no depth camera's depths in metres or millimetres")
    }
}

/// The median magnitude of the finite, non-zero `values` (`None` without any): the scale a frame is in, which a
/// few out-of-range pixels (a driver's no-return sentinel) do not move.
pub fn typical_magnitude(values: &[f32]) -> Option<f32> {
    let mut m: Vec<f32> = values
        .iter()
        .filter(|v| v.is_finite() && **v != 0.0)
        .map(|v| v.abs())
        .collect();
    if m.is_empty() {
        return None;
    }
    let mid = m.len() / 2;
    let (_, &mut typical, _) = m.select_nth_unstable_by(mid, f32::total_cmp);
    Some(typical)
}

impl Image {
    /// A depth frame with every pixel without a return ([`is_measured_depth`] false) set to 0, the value every
    /// stage reads as missing, and how many there were.
    pub fn missing_as_zero(mut self) -> (Image, usize) {
        let mut missing = 0;
        for d in &mut self.data {
            if !is_measured_depth(*d) {
                if *d != 0.0 {
                    *d = 0.0;
                }
                missing += 1;
            }
        }
        (self, missing)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn every_no_return_convention_becomes_zero() {
        let frame = Image::from_vec(
            7,
            1,
            vec![
                0.08,
                f32::NAN,
                f32::INFINITY,
                f32::NEG_INFINITY,
                0.0,
                -0.01,
                65.535,
            ],
        )
        .unwrap();
        let (clean, missing) = frame.missing_as_zero();
        assert_eq!(clean.data, vec![0.08, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(missing, 6);
        assert!(is_measured_depth(MAX_DEPTH_M) && !is_measured_depth(MAX_DEPTH_M * 1.001));
    }
}
