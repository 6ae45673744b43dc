//! File formats and safe writing: atomic writes, `.npy` arrays, PLY point clouds and meshes, and PNG previews with a
//! JET colour map.

pub mod atomic;
pub mod depth_file;
pub mod figure;
pub mod input;
pub mod lock;
pub mod npy;
pub mod output;
pub mod paths;
pub mod ply;
pub mod preview;
pub mod settings;

/// A number JSON wrote as `null` (serde_json writes NaN so: a cost a refined pose has none of) read back as NaN,
/// for `#[serde(deserialize_with = ...)]`.
pub fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

pub use atomic::write_atomic;
