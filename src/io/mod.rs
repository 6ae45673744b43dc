//! File formats and safe writing: atomic writes, `.npy` arrays and PNG previews with a JET colour map.

pub mod atomic;
pub mod npy;
pub mod preview;

pub use atomic::write_atomic;
