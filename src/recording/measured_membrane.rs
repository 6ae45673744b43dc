//! A **measured membrane**: where the parametric dome cannot explain a sensor's no-contact frames (a sagging or
//! dented membrane, a tilted camera), the membrane the simulator uses can be the measurement itself. The calibrated
//! dome plus the measured residual, smoothed over 5 x 5 pixels (what is left of the noise of the frames' mean is
//! averaged away; sag and dents are wider), is back-projected into the sensor frame, one vertex per pixel, and closed
//! into a solid — the measured surface on top, walls down to the membrane base at z = 0, the base as its floor — so
//! that the simulator renders it, tests contact against it (inside or outside) and finds its apex, as for any
//! membrane mesh (`elastomer.mesh_file`). It covers the camera's view, which is all the sensor can see or touch.

use glam::{DVec3, Vec3};

use super::calibrate::{CalibrationImages, SensorCalibration};
use crate::image::Image;
use crate::mesh::Mesh;

/// The measured membrane of a calibration (module docs), in the sensor frame, metres.
pub fn measured_membrane(
    cal: &SensorCalibration,
    images: &CalibrationImages,
) -> Result<Mesh, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("reference frames", || {
        let sensor = &cal.sensor;
        let (w, h) = (images.measured.width, images.measured.height);
        let (intrinsics, _) = super::calibrate::frame_intrinsics(sensor, w, h)?;
        if w < 2 || h < 2 {
            return Err(format!("a {w}x{h} reference is too small for a membrane"));
        }
        // The residual where both are measured, smoothed; the fitted dome where the camera measured nothing.
        let residual =
            images.measured.zip_map(
                &images.fitted,
                |m, f| {
                    if m > 0.0 && f > 0.0 {
                        m - f
                    } else {
                        0.0
                    }
                },
            );
        let valid =
            images.measured.zip_map(
                &images.fitted,
                |m, f| {
                    if m > 0.0 && f > 0.0 {
                        1.0
                    } else {
                        0.0
                    }
                },
            );
        let sum = super::process::box_means(&residual, 2);
        let count = super::process::box_means(&valid, 2);
        let depth = Image {
            width: w,
            height: h,
            data: images
                .fitted
                .data
                .iter()
                .enumerate()
                .map(|(i, &f)| {
                    if count[i] > 0.0 {
                        f + (sum[i] / count[i]) as f32
                    } else {
                        f
                    }
                })
                .collect(),
        };
        if depth.data.iter().any(|&d| !(d > 0.0 && d.is_finite())) {
            return Err("the calibrated membrane does not cover the camera's view".into());
        }
        let t_sensor_camera = sensor.mount.t_sensor_camera();
        // The vertices sit a quarter pixel off the pixel centres, with a pixel of margin all round (depths interpolated
        // bilinearly, clamped at the border), so that every pixel's ray meets the top inside a triangle — a ray through
        // a vertex or along an edge can slip between the triangles that share it.
        let (pw, ph) = (w, h);
        let (w, h) = (w + 2, h + 2);
        let bilinear = |x: f64, y: f64| -> f64 {
            let (x, y) = (x.clamp(0.0, (pw - 1) as f64), y.clamp(0.0, (ph - 1) as f64));
            let (x0, y0) = (x.floor() as usize, y.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(pw - 1), (y0 + 1).min(ph - 1));
            let (fx, fy) = (x - x0 as f64, y - y0 as f64);
            let at = |u: usize, v: usize| f64::from(depth.get(u, v));
            (1.0 - fy) * ((1.0 - fx) * at(x0, y0) + fx * at(x1, y0))
                + fy * ((1.0 - fx) * at(x0, y1) + fx * at(x1, y1))
        };
        let mut vertices: Vec<Vec3> = Vec::with_capacity(2 * w * h);
        for v in 0..h {
            for u in 0..w {
                let (x, y) = (u as f64 - 1.75, v as f64 - 1.75);
                let p_cam = intrinsics.back_project(x, y, bilinear(x, y));
                let p: DVec3 = t_sensor_camera.transform_point3(p_cam);
                if p.z <= 0.0 {
                    return Err(format!(
                        "pixel ({u}, {v}) of the membrane lies below its base (z = {:.1} mm)",
                        p.z * 1e3
                    ));
                }
                vertices.push(p.as_vec3());
            }
        }
        let top = |u: usize, v: usize| (v * w + u) as u32;
        let mut triangles = Vec::with_capacity(4 * w * h);
        // The measured surface, facing up (+z, away from the camera: the solid lies below it).
        for v in 0..h - 1 {
            for u in 0..w - 1 {
                let (a, b, c, d) = (top(u, v), top(u + 1, v), top(u, v + 1), top(u + 1, v + 1));
                triangles.push([a, c, b]);
                triangles.push([b, c, d]);
            }
        }
        // The border, walked around once, dropped to the base plane: walls, and the base as a fan from its centre.
        let mut ring: Vec<(usize, usize)> = (0..w).map(|u| (u, 0)).collect();
        ring.extend((1..h).map(|v| (w - 1, v)));
        ring.extend((0..w - 1).rev().map(|u| (u, h - 1)));
        ring.extend((1..h - 1).rev().map(|v| (0, v)));
        let base_start = vertices.len() as u32;
        for &(u, v) in &ring {
            let p = vertices[top(u, v) as usize];
            vertices.push(Vec3::new(p.x, p.y, 0.0));
        }
        let centre = vertices.len() as u32;
        let mean = ring
            .iter()
            .map(|&(u, v)| vertices[top(u, v) as usize])
            .fold(Vec3::ZERO, |s, p| s + p)
            / ring.len() as f32;
        vertices.push(Vec3::new(mean.x, mean.y, 0.0));
        let n = ring.len() as u32;
        for k in 0..n {
            let (p, q) = (k, (k + 1) % n);
            let (tp, tq) = (
                top(ring[p as usize].0, ring[p as usize].1),
                top(ring[q as usize].0, ring[q as usize].1),
            );
            let (bp, bq) = (base_start + p, base_start + q);
            triangles.push([tp, tq, bq]);
            triangles.push([tp, bq, bp]);
            triangles.push([centre, bp, bq]);
        }
        let mesh =
            Mesh::from_raw(vertices, triangles, "measured membrane").map_err(|e| e.to_string())?;
        // The winding above is one choice of two; make the solid face outwards whichever way the camera looks.
        Ok(if mesh.report().volume_m3 < 0.0 {
            mesh.flipped()
        } else {
            mesh
        })
    })
}
