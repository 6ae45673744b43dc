//! The built-in object catalogue (paper V.A object set, re-created procedurally): seven families in four sizes each,
//! sized for a Soft Bubble whose camera sees about a 70 x 55 mm patch. One size per family is held out as unseen.

use std::collections::BTreeMap;

use glam::Vec2;

use super::{shapes, Family, ObjectEntry, ObjectError, Split};
use crate::mesh::Mesh;

/// Sides of lying cylinders' cross-sections.
const CYLINDER_SEGMENTS: u32 = 64;
/// Icosphere subdivisions of spheres (1280 triangles).
const SPHERE_SUBDIVISIONS: u32 = 3;
/// Sides of bullets around their axis.
const BULLET_SEGMENTS: u32 = 48;
/// Segments of each semicircular arm end of round crosses.
const ROUND_END_SEGMENTS: u32 = 16;
/// Length of lying cylinders and prisms, metres (longer than the sensor's view: position along x is ambiguous).
const LYING_LENGTH: f64 = 0.09;
/// Thickness of crosses, metres.
const CROSS_HEIGHT: f64 = 0.02;

/// Parameters of one built-in object, all in metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum ShapeSpec {
    Cylinder {
        radius: f64,
        length: f64,
    },
    TriangularPrism {
        base: f64,
        height: f64,
        length: f64,
    },
    TrapezoidalPrism {
        base: f64,
        top: f64,
        height: f64,
        length: f64,
    },
    /// `height` is the total height, body plus hemispherical cap.
    Bullet {
        radius: f64,
        height: f64,
    },
    Sphere {
        radius: f64,
    },
    Cross {
        arm_width: f64,
        span: f64,
        height: f64,
    },
    RoundCross {
        arm_width: f64,
        span: f64,
        height: f64,
    },
}

/// Millimetres as an integer, for names.
fn mm(metres: f64) -> i64 {
    (metres * 1000.0).round() as i64
}

impl ShapeSpec {
    pub(crate) fn family(&self) -> Family {
        match self {
            ShapeSpec::Cylinder { .. } => Family::Cylinder,
            ShapeSpec::TriangularPrism { .. } => Family::TriangularPrism,
            ShapeSpec::TrapezoidalPrism { .. } => Family::TrapezoidalPrism,
            ShapeSpec::Bullet { .. } => Family::Bullet,
            ShapeSpec::Sphere { .. } => Family::Sphere,
            ShapeSpec::Cross { .. } => Family::Cross,
            ShapeSpec::RoundCross { .. } => Family::RoundCross,
        }
    }

    /// Name with dimensions in millimetres, e.g. `cylinder_r15`, `cross_w12_s50`.
    pub(crate) fn name(&self) -> String {
        match *self {
            ShapeSpec::Cylinder { radius, .. } => format!("cylinder_r{}", mm(radius)),
            ShapeSpec::TriangularPrism { base, height, .. } => {
                format!("triangular_prism_b{}_h{}", mm(base), mm(height))
            }
            ShapeSpec::TrapezoidalPrism {
                base, top, height, ..
            } => {
                format!(
                    "trapezoidal_prism_b{}_t{}_h{}",
                    mm(base),
                    mm(top),
                    mm(height)
                )
            }
            ShapeSpec::Bullet { radius, height } => {
                format!("bullet_r{}_h{}", mm(radius), mm(height))
            }
            ShapeSpec::Sphere { radius } => format!("sphere_r{}", mm(radius)),
            ShapeSpec::Cross {
                arm_width, span, ..
            } => format!("cross_w{}_s{}", mm(arm_width), mm(span)),
            ShapeSpec::RoundCross {
                arm_width, span, ..
            } => {
                format!("round_cross_w{}_s{}", mm(arm_width), mm(span))
            }
        }
    }

    /// Named dimensions in metres, as stored in the manifest.
    pub(crate) fn dimensions(&self) -> BTreeMap<String, f64> {
        let pairs: Vec<(&str, f64)> = match *self {
            ShapeSpec::Cylinder { radius, length } => vec![("radius", radius), ("length", length)],
            ShapeSpec::TriangularPrism {
                base,
                height,
                length,
            } => {
                vec![("base_width", base), ("height", height), ("length", length)]
            }
            ShapeSpec::TrapezoidalPrism {
                base,
                top,
                height,
                length,
            } => vec![
                ("base_width", base),
                ("top_width", top),
                ("height", height),
                ("length", length),
            ],
            ShapeSpec::Bullet { radius, height } => {
                vec![
                    ("radius", radius),
                    ("body_length", height - radius),
                    ("height", height),
                ]
            }
            ShapeSpec::Sphere { radius } => vec![("radius", radius)],
            ShapeSpec::Cross {
                arm_width,
                span,
                height,
            }
            | ShapeSpec::RoundCross {
                arm_width,
                span,
                height,
            } => {
                vec![("arm_width", arm_width), ("span", span), ("height", height)]
            }
        };
        pairs.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
    }

    /// The mesh, resting on the table.
    pub(crate) fn build(&self) -> Result<Mesh, ObjectError> {
        match *self {
            ShapeSpec::Cylinder { radius, length } => {
                shapes::cylinder_lying(radius, length, CYLINDER_SEGMENTS)
            }
            ShapeSpec::TriangularPrism {
                base,
                height,
                length,
            } => shapes::prism_lying(
                &profile(&[(-base / 2.0, 0.0), (base / 2.0, 0.0), (0.0, height)]),
                length,
            ),
            ShapeSpec::TrapezoidalPrism {
                base,
                top,
                height,
                length,
            } => shapes::prism_lying(
                &profile(&[
                    (-base / 2.0, 0.0),
                    (base / 2.0, 0.0),
                    (top / 2.0, height),
                    (-top / 2.0, height),
                ]),
                length,
            ),
            ShapeSpec::Bullet { radius, height } => {
                shapes::bullet(radius, height - radius, BULLET_SEGMENTS)
            }
            ShapeSpec::Sphere { radius } => shapes::sphere(radius, SPHERE_SUBDIVISIONS),
            ShapeSpec::Cross {
                arm_width,
                span,
                height,
            } => shapes::cross(arm_width, span, height),
            ShapeSpec::RoundCross {
                arm_width,
                span,
                height,
            } => shapes::round_cross(arm_width, span, height, ROUND_END_SEGMENTS),
        }
    }

    /// Volume of the ideal (untessellated) shape, m³.
    #[cfg(test)]
    pub(crate) fn analytic_volume_m3(&self) -> f64 {
        use std::f64::consts::PI;
        match *self {
            ShapeSpec::Cylinder { radius, length } => PI * radius * radius * length,
            ShapeSpec::TriangularPrism {
                base,
                height,
                length,
            } => 0.5 * base * height * length,
            ShapeSpec::TrapezoidalPrism {
                base,
                top,
                height,
                length,
            } => 0.5 * (base + top) * height * length,
            ShapeSpec::Bullet { radius, height } => {
                PI * radius * radius * (height - radius) + 2.0 / 3.0 * PI * radius.powi(3)
            }
            ShapeSpec::Sphere { radius } => 4.0 / 3.0 * PI * radius.powi(3),
            ShapeSpec::Cross {
                arm_width: w,
                span: s,
                height,
            } => (2.0 * w * s - w * w) * height,
            ShapeSpec::RoundCross {
                arm_width: w,
                span: s,
                height,
            } => {
                let a = w / 2.0;
                (4.0 * a * a + 8.0 * a * (s / 2.0 - 2.0 * a) + 2.0 * PI * a * a) * height
            }
        }
    }

    /// The manifest record of this object (mesh file `<name>.obj` in metres, as written by `ObjectSet::export`).
    pub(crate) fn entry(&self, split: Split) -> ObjectEntry {
        let name = self.name();
        ObjectEntry {
            mesh: format!("{name}.obj"),
            name,
            family: Some(self.family()),
            scale_to_m: 1.0,
            rotation: None,
            split,
            symmetry: self.family().symmetry(),
            dimensions: self.dimensions(),
            weight: 1.0,
        }
    }
}

fn profile(points: &[(f64, f64)]) -> Vec<Vec2> {
    points
        .iter()
        .map(|&(y, z)| Vec2::new(y as f32, z as f32))
        .collect()
}

/// The catalogue, in millimetres converted to metres: four sizes per family, `(spec, split)`.
pub(crate) fn catalogue() -> Vec<(ShapeSpec, Split)> {
    let m = |v: f64| v / 1000.0;
    let length = LYING_LENGTH;
    let mut out = Vec::new();
    // Each family lists four sizes; the index in `unseen` is held out.
    let mut family = |specs: Vec<ShapeSpec>, unseen: usize| {
        for (i, spec) in specs.into_iter().enumerate() {
            out.push((
                spec,
                if i == unseen {
                    Split::Unseen
                } else {
                    Split::Seen
                },
            ));
        }
    };
    family(
        [8.0, 12.0, 15.0, 20.0]
            .map(|r| ShapeSpec::Cylinder {
                radius: m(r),
                length,
            })
            .to_vec(),
        2,
    );
    family(
        [(20.0, 15.0), (25.0, 20.0), (30.0, 20.0), (35.0, 25.0)]
            .map(|(b, h)| ShapeSpec::TriangularPrism {
                base: m(b),
                height: m(h),
                length,
            })
            .to_vec(),
        1,
    );
    family(
        [
            (25.0, 12.0, 15.0),
            (30.0, 15.0, 20.0),
            (35.0, 20.0, 20.0),
            (40.0, 25.0, 25.0),
        ]
        .map(|(b, t, h)| ShapeSpec::TrapezoidalPrism {
            base: m(b),
            top: m(t),
            height: m(h),
            length,
        })
        .to_vec(),
        2,
    );
    family(
        [(8.0, 25.0), (10.0, 30.0), (12.0, 35.0), (15.0, 40.0)]
            .map(|(r, h)| ShapeSpec::Bullet {
                radius: m(r),
                height: m(h),
            })
            .to_vec(),
        2,
    );
    family(
        [10.0, 15.0, 20.0, 25.0]
            .map(|r| ShapeSpec::Sphere { radius: m(r) })
            .to_vec(),
        1,
    );
    let crosses = [(10.0, 40.0), (12.0, 50.0), (15.0, 60.0), (20.0, 70.0)];
    family(
        crosses
            .map(|(w, s)| ShapeSpec::Cross {
                arm_width: m(w),
                span: m(s),
                height: CROSS_HEIGHT,
            })
            .to_vec(),
        2,
    );
    family(
        crosses
            .map(|(w, s)| ShapeSpec::RoundCross {
                arm_width: m(w),
                span: m(s),
                height: CROSS_HEIGHT,
            })
            .to_vec(),
        1,
    );
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn every_builtin_mesh_is_closed_rests_and_matches_analytic_volume() {
        for (spec, _) in catalogue() {
            let mesh = spec.build().unwrap();
            let report = mesh.report();
            assert!(report.closed, "{}: {report:?}", spec.name());
            // Inscribed tessellations lose volume: 64-gon cylinders 0.16 %, 1280-face icospheres ~1.3 %,
            // 48-side bullets ~0.5 %, 16-segment round ends < 0.3 %; prisms and square crosses are exact.
            let tolerance = match spec.family() {
                Family::Sphere => 0.02,
                Family::Bullet => 0.01,
                _ => 0.005,
            };
            let expected = spec.analytic_volume_m3();
            let rel = (report.volume_m3 - expected) / expected;
            assert!(
                rel.abs() < tolerance && report.volume_m3 > 0.0,
                "{}: rel volume error {rel}",
                spec.name()
            );
            let (lo, hi) = mesh.aabb();
            assert!(lo.z.abs() < 1e-6, "{}: lowest z {}", spec.name(), lo.z);
            assert!(
                (lo.x + hi.x).abs() < 1e-6 && (lo.y + hi.y).abs() < 1e-6,
                "{}",
                spec.name()
            );
            assert!(
                report.triangles <= 3000,
                "{}: {} triangles",
                spec.name(),
                report.triangles
            );
        }
    }

    #[test]
    fn names_encode_dimensions() {
        let names: Vec<String> = catalogue().iter().map(|(s, _)| s.name()).collect();
        for expected in [
            "cylinder_r15",
            "sphere_r20",
            "cross_w12_s50",
            "round_cross_w12_s50",
            "bullet_r10_h30",
        ] {
            assert!(
                names.iter().any(|n| n == expected),
                "{expected} missing from {names:?}"
            );
        }
    }
}
