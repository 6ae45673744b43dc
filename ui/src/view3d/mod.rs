//! The 3D view of the scene (object, membrane, camera frustum, contact points): [`geometry`] builds it, [`camera`]
//! orbits around it, [`gpu`] draws it with a wgpu paint callback and [`cpu`] is the fallback without wgpu.

pub mod camera;
pub mod cpu;
pub mod geometry;
pub mod gpu;

use crate::state::MembraneStyle;

/// What to draw besides the object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrawFlags {
    pub membrane: MembraneStyle,
    pub frustum: bool,
    pub contacts: bool,
}
