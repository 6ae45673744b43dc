//! **Physical bounds of a sensor**: what a Soft Bubble-like sensor can be, checked wherever a sensor comes from
//! (flags, sensor files, calibration, datasets), so that an impossible one (a camera inside the membrane, a 10 m
//! inflation, a 100 000-pixel shadow) is refused with one line naming the setting and the limit instead of giving
//! silent nonsense or exhausting memory.
//!
//! [`check_settings`] needs only the numbers; [`check_membrane`], run after it, the membrane mesh and the camera's
//! view of it (the simulator runs both when it is built).

use glam::DVec3;

use super::SimConfig;
use crate::error::InvalidSetting;
use crate::mesh::Mesh;

/// The least distance, metres, at which the depth camera measures (time-of-flight cameras of this size: ~1–10 cm):
/// the membrane must be farther than this from the camera.
pub const MIN_RANGE_M: f64 = 0.01;
/// Plausible membrane footprint (each side), metres.
pub const FOOTPRINT_RANGE_M: (f64, f64) = (0.01, 0.5);
/// Plausible membrane inflation (apex above the base), metres.
pub const INFLATION_RANGE_M: (f64, f64) = (0.001, 0.2);
/// Largest signature noise, metres: a depth camera's noise is millimetres.
pub const MAX_NOISE_STD_M: f64 = 0.01;
/// The least share of the camera's pixels that must see the membrane.
pub const MIN_MEMBRANE_SHARE: f64 = 0.25;

/// A length for a message: millimetres for a sensor's sizes, scientific notation in metres for absurd ones (1e308 is
/// not 309 digits).
fn mm(m: f64) -> String {
    if m.is_finite() && m != 0.0 && !(1e-6..1e3).contains(&m.abs()) {
        format!("{m:e} m")
    } else {
        format!("{:.1} mm", m * 1e3)
    }
}

/// The bounds that need no mesh: membrane size, camera distance, noise and shadow width.
pub fn check_settings(config: &SimConfig) -> Result<(), InvalidSetting> {
    // Finite, non-negative noise and shadow (the camera is checked where a sensor is read: its native frames
    // render at a resolution that is no model's).
    config.signature.validate()?;
    let e = &config.elastomer;
    if e.mesh_file.is_none() {
        let (lo, hi) = FOOTPRINT_RANGE_M;
        for (name, v) in [
            ("elastomer.footprint_x", e.footprint_x),
            ("elastomer.footprint_y", e.footprint_y),
        ] {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return Err(InvalidSetting::new(
                    name,
                    format!("{} is outside {lo}..{hi} m", mm(v)),
                ));
            }
        }
        let (lo, hi) = INFLATION_RANGE_M;
        if !(e.inflation.is_finite() && (lo..=hi).contains(&e.inflation)) {
            return Err(InvalidSetting::new(
                "elastomer.inflation",
                format!(
                    "inflation {} is outside {}..{}: not an inflated membrane of this kind",
                    mm(e.inflation),
                    mm(lo),
                    mm(hi)
                ),
            ));
        }
    }
    let p = config.mount.position;
    if !p.iter().all(|v| v.is_finite()) {
        return Err(InvalidSetting::new(
            "mount.position",
            "the camera position must be finite",
        ));
    }
    let far = f64::from(crate::image::MAX_DEPTH_M);
    if DVec3::from_array(p).length() > far {
        return Err(InvalidSetting::new(
            "mount.position",
            format!(
                "the camera is {:.2} m from the membrane's base, beyond the {far} m a depth camera measures",
                DVec3::from_array(p).length()
            ),
        ));
    }
    let s = &config.signature;
    if s.noise_std > MAX_NOISE_STD_M {
        return Err(InvalidSetting::new(
            "signature.noise_std",
            format!(
                "noise_std {} is above {}: a depth camera's noise is millimetres",
                mm(s.noise_std),
                mm(MAX_NOISE_STD_M)
            ),
        ));
    }
    let n = &config.camera.native;
    let widest = n.width.max(n.height) as f64;
    if s.shadow_px > widest {
        return Err(InvalidSetting::new(
            "signature.shadow_px",
            format!(
                "shadow_px {} is wider than the {}x{} native image",
                s.shadow_px, n.width, n.height
            ),
        ));
    }
    Ok(())
}

/// The bounds of the camera against the membrane (after [`check_settings`]): behind its base, within its footprint, farther than
/// [`MIN_RANGE_M`] from what it sees of it; a membrane mesh closed; the camera seeing the membrane (`nominal`: the
/// rendered membrane depth, metres, 0 where a pixel misses it).
pub fn check_membrane(
    config: &SimConfig,
    membrane: &Mesh,
    nominal: &crate::image::Image,
) -> Result<(), InvalidSetting> {
    let (lo, hi) = membrane.aabb();
    let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
    if config.elastomer.mesh_file.is_some() && !membrane.report().closed {
        return Err(InvalidSetting::new(
            "elastomer.mesh_file",
            "the membrane mesh is not closed (it must enclose the membrane's inside for the contact test)",
        ));
    }
    let camera = DVec3::from_array(config.mount.position);
    if camera.z > lo.z {
        return Err(InvalidSetting::new(
            "mount.position",
            format!(
                "the camera (z {}) must be behind the membrane's base (z {}): it is inside or in front of the membrane",
                mm(camera.z),
                mm(lo.z)
            ),
        ));
    }
    let centre = 0.5 * (lo + hi);
    let half = 0.5 * (hi - lo);
    let (u, v) = (
        (camera.x - centre.x) / half.x.max(1e-9),
        (camera.y - centre.y) / half.y.max(1e-9),
    );
    if u * u + v * v > 1.0 {
        return Err(InvalidSetting::new(
            "mount.position",
            format!(
                "the camera (x {}, y {}) is outside the membrane's footprint",
                mm(camera.x),
                mm(camera.y)
            ),
        ));
    }
    // The nearest membrane depth the camera sees.
    let nearest = nominal
        .data
        .iter()
        .filter(|&&d| d > 0.0)
        .fold(f64::INFINITY, |m, &d| m.min(f64::from(d)));
    if nearest < MIN_RANGE_M {
        return Err(InvalidSetting::new(
            "mount.position",
            format!(
                "the camera is {} from the membrane, closer than the {} a depth camera measures",
                mm(nearest),
                mm(MIN_RANGE_M)
            ),
        ));
    }
    let seen = nominal.data.iter().filter(|&&d| d > 0.0).count() as f64;
    let share = seen / nominal.data.len().max(1) as f64;
    if share < MIN_MEMBRANE_SHARE {
        return Err(InvalidSetting::new(
            "mount.rotation",
            format!(
                "the camera sees the membrane in {:.0} % of its pixels (at least {:.0} % expected): it does not look at it",
                share * 100.0,
                MIN_MEMBRANE_SHARE * 100.0
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::sim::Simulator;

    fn refused(edit: impl FnOnce(&mut SimConfig)) -> String {
        let mut c = SimConfig::default();
        edit(&mut c);
        match Simulator::new(c.clone()) {
            Ok(_) => panic!("accepted: {:?} {:?}", c.mount, c.signature),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn the_nominal_sensor_passes_and_impossible_ones_are_named() {
        assert!(Simulator::new(SimConfig::default()).is_ok());
        let e = refused(|c| c.mount.position = [0.0, 0.0, 0.01]);
        assert!(e.contains("mount.position") && e.contains("behind"), "{e}");
        let e = refused(|c| c.elastomer.inflation = 10.0);
        assert!(e.contains("inflation") && e.contains("200.0 mm"), "{e}");
        // Absurd sizes in scientific notation, not hundreds of digits.
        let e = refused(|c| c.elastomer.footprint_x = 1e308);
        assert!(e.contains("footprint_x") && e.contains("1e308 m"), "{e}");
        let e = refused(|c| c.elastomer.inflation = 2.3e-9);
        assert!(e.contains("inflation"), "{e}");
        let e = refused(|c| c.mount.position = [0.0, 0.0, -100.0]);
        assert!(e.contains("beyond"), "{e}");
        let e = refused(|c| c.mount.position = [0.2, 0.0, -0.06]);
        assert!(e.contains("footprint"), "{e}");
        let e = refused(|c| {
            c.elastomer.inflation = 0.004;
            c.mount.position = [0.0, 0.0, -0.001];
        });
        assert!(e.contains("closer than"), "{e}");
        let e = refused(|c| c.signature.noise_std = 10.0);
        assert!(e.contains("noise_std"), "{e}");
        let e = refused(|c| c.signature.shadow_px = 100_000.0);
        assert!(e.contains("shadow_px") && e.contains("224x171"), "{e}");
        let e = refused(|c| c.mount.rotation = [std::f64::consts::PI, 0.0, 0.0]);
        assert!(e.contains("does not look at it"), "{e}");
    }
}
