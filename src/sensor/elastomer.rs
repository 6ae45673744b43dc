//! The elastomer: the Soft Bubble's inflated membrane, as a closed mesh in the sensor frame (base at z = 0, dome
//! towards +z). Parametric (an elliptical footprint and a half-ellipsoid dome whose height is the inflation) or loaded
//! from a mesh file. Inflation is the parameter users calibrate against measured imprints.

use std::f64::consts::{FRAC_PI_2, TAU};
use std::path::PathBuf;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::mesh::{self, LoadOptions, Mesh, MeshError, Units};

/// Errors building the elastomer mesh.
#[derive(Debug, thiserror::Error)]
pub enum ElastomerError {
    #[error("elastomer: {0}")]
    Config(String),
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

/// Elastomer (membrane) geometry in the sensor frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ElastomerConfig {
    /// Footprint length along sensor x, metres (default 0.120).
    pub footprint_x: f64,
    /// Footprint width along sensor y, metres (default 0.080).
    pub footprint_y: f64,
    /// Inflation height of the dome apex above the base, metres (default 0.030).
    pub inflation: f64,
    /// Tessellation: number of latitude rings from apex to rim (default 24).
    pub rings: usize,
    /// Tessellation: number of segments around the rim (default 96).
    pub segments: usize,
    /// A mesh file (OBJ, STL, PLY, glTF/GLB) replacing the parametric membrane, already in the sensor frame.
    pub mesh_file: Option<PathBuf>,
    /// Units of `mesh_file`.
    pub mesh_units: Units,
}

impl Default for ElastomerConfig {
    fn default() -> Self {
        Self {
            footprint_x: 0.120,
            footprint_y: 0.080,
            inflation: 0.030,
            rings: 24,
            segments: 96,
            mesh_file: None,
            mesh_units: Units::M,
        }
    }
}

impl ElastomerConfig {
    /// Check the parameters, with a message saying what to change.
    pub fn validate(&self) -> Result<(), ElastomerError> {
        if self.mesh_file.is_some() {
            return Ok(());
        }
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(ElastomerError::Config(format!(
                    "{name} must be a positive length in metres, got {v}"
                )))
            }
        };
        positive("footprint_x", self.footprint_x)?;
        positive("footprint_y", self.footprint_y)?;
        positive("inflation", self.inflation)?;
        if self.rings < 2 || self.segments < 8 || self.rings * self.segments > 1_000_000 {
            return Err(ElastomerError::Config(format!(
                "tessellation rings={} segments={} must satisfy rings >= 2, segments >= 8, rings*segments <= 1e6",
                self.rings, self.segments
            )));
        }
        Ok(())
    }

    /// The apex (highest point of the dome) in the sensor frame, metres.
    pub fn apex_height(&self, mesh: &Mesh) -> f64 {
        if self.mesh_file.is_some() {
            f64::from(mesh.aabb().1.z)
        } else {
            self.inflation
        }
    }

    /// Build the closed membrane mesh in the sensor frame.
    pub fn build(&self) -> Result<Mesh, ElastomerError> {
        self.validate()?;
        if let Some(path) = &self.mesh_file {
            let options = LoadOptions {
                units: self.mesh_units,
                fit_to_size: None,
            };
            return Ok(mesh::load(path, &options)?);
        }
        Ok(dome(
            self.footprint_x / 2.0,
            self.footprint_y / 2.0,
            self.inflation,
            self.rings,
            self.segments,
        )?)
    }
}

/// Half-ellipsoid with semi-axes `a`, `b` (footprint) and `h` (height) closed by a flat base at z = 0.
fn dome(a: f64, b: f64, h: f64, rings: usize, segments: usize) -> Result<Mesh, MeshError> {
    let mut vertices = vec![Vec3::new(0.0, 0.0, h as f32)];
    for i in 1..=rings {
        let phi = FRAC_PI_2 * i as f64 / rings as f64;
        let (s, c) = phi.sin_cos();
        let z = if i == rings { 0.0 } else { h * c };
        for j in 0..segments {
            let psi = TAU * j as f64 / segments as f64;
            vertices.push(Vec3::new(
                (a * s * psi.cos()) as f32,
                (b * s * psi.sin()) as f32,
                z as f32,
            ));
        }
    }
    let ring = |i: usize, j: usize| (1 + (i - 1) * segments + j % segments) as u32;
    let mut triangles = Vec::with_capacity(2 * rings * segments);
    for j in 0..segments {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
    }
    for i in 1..rings {
        for j in 0..segments {
            let (u0, u1, l0, l1) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            triangles.push([u0, l0, l1]);
            triangles.push([u0, l1, u1]);
        }
    }
    let centre = vertices.len() as u32;
    vertices.push(Vec3::ZERO);
    for j in 0..segments {
        triangles.push([centre, ring(rings, j + 1), ring(rings, j)]);
    }
    Mesh::from_raw(vertices, triangles, "parametric elastomer")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parametric_membrane_is_closed_with_half_ellipsoid_volume() {
        let cfg = ElastomerConfig {
            rings: 64,
            segments: 256,
            ..Default::default()
        };
        let m = cfg.build().unwrap();
        let r = m.report();
        assert!(r.closed, "{r:?}");
        let exact = 2.0 / 3.0 * std::f64::consts::PI * 0.06 * 0.04 * 0.03;
        // Inscribed tessellation: volume slightly below the analytic one.
        assert!(
            r.volume_m3 < exact && r.volume_m3 > 0.995 * exact,
            "{} vs {exact}",
            r.volume_m3
        );
        let (lo, hi) = m.aabb();
        assert!((hi.z - 0.03).abs() < 1e-7 && lo.z.abs() < 1e-7);
        assert!((hi.x - 0.06).abs() < 1e-6 && (hi.y - 0.04).abs() < 1e-6);
    }

    #[test]
    fn bad_parameters_are_reported() {
        let cfg = ElastomerConfig {
            inflation: -0.01,
            ..Default::default()
        };
        assert!(cfg.build().unwrap_err().to_string().contains("inflation"));
        let cfg = ElastomerConfig {
            mesh_file: Some("/nonexistent/bubble.obj".into()),
            ..Default::default()
        };
        assert!(cfg.build().unwrap_err().to_string().contains("bubble.obj"));
    }
}
