//! Single-channel float images (row-major, metres or 0/1 masks) shared by every pipeline stage.

use serde::{Deserialize, Serialize};

/// A row-major `height x width` image of `f32`. Depth images are z-depths in metres with `0.0` meaning "no value"
/// (ray miss or outside the contact region); masks hold `0.0`/`1.0`.
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
