//! File formats and safe writing: atomic writes, `.npy` arrays, PLY point clouds and meshes, and PNG previews with a
//! JET colour map.

pub mod atomic;
pub mod depth_file;
pub mod figure;
pub mod lock;
pub mod npy;
pub mod ply;
pub mod preview;
pub mod settings;

pub use atomic::write_atomic;
