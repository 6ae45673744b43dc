//! Depth images from ROS messages: `sensor_msgs/Image` in `16UC1`/`mono16` (millimetres) or `32FC1` (metres), either
//! byte order and any row padding, and `sensor_msgs/PointCloud2` projected through the camera's pinhole model.
//! Pixels without a measurement (0, NaN, infinite, negative or beyond [`crate::image::MAX_DEPTH_M`], e.g. 65 535 mm)
//! are 0, missing.

use super::ros::{ImageMsg, PointCloudMsg};
use crate::image::Image;
use crate::sensor::Intrinsics;

/// Largest frame accepted, pixels (a 4096 x 4096 depth camera).
const MAX_PIXELS: usize = 4096 * 4096;

/// The depth image of an `Image` message, metres.
pub fn image_depth(m: &ImageMsg) -> Result<Image, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("depth image message", || {
        let (w, h) = (m.width as usize, m.height as usize);
        if w == 0 || h == 0 || w.saturating_mul(h) > MAX_PIXELS {
            return Err(format!("image is {w}x{h}"));
        }
        let (bytes_per_px, scale, float) = match m.encoding.as_str() {
        "16UC1" | "mono16" => (2, 0.001f32, false),
        "32FC1" => (4, 1.0f32, true),
        other => {
            return Err(format!(
                "image encoding '{other}' is not a depth encoding (16UC1 or mono16 in millimetres, 32FC1 in metres)"
            ))
        }
    };
        let step = m.step as usize;
        if step < w * bytes_per_px {
            return Err(format!(
                "row step {step} bytes is shorter than {w} pixels of {bytes_per_px} bytes"
            ));
        }
        let needed = step * (h - 1) + w * bytes_per_px;
        if m.data.len() < needed {
            return Err(format!(
                "image data is {} bytes; {w}x{h} with step {step} needs {needed}",
                m.data.len()
            ));
        }
        let mut data = Vec::with_capacity(w * h);
        for v in 0..h {
            let row = &m.data[v * step..v * step + w * bytes_per_px];
            for px in row.chunks_exact(bytes_per_px) {
                let d = if float {
                    let b = [px[0], px[1], px[2], px[3]];
                    if m.is_bigendian {
                        f32::from_be_bytes(b)
                    } else {
                        f32::from_le_bytes(b)
                    }
                } else {
                    let b = [px[0], px[1]];
                    let raw = if m.is_bigendian {
                        u16::from_be_bytes(b)
                    } else {
                        u16::from_le_bytes(b)
                    };
                    raw as f32
                } * scale;
                data.push(if crate::image::is_measured_depth(d) {
                    d
                } else {
                    0.0
                });
            }
        }
        Image::from_vec(w, h, data).ok_or_else(|| "image size".to_string())
    })
}

/// The depth image of a point cloud seen by a camera with intrinsics `k` (points in its optical frame); the nearest
/// point wins where several fall into one pixel.
pub fn cloud_depth(m: &PointCloudMsg, k: &Intrinsics) -> Result<Image, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("point cloud message", || {
        let field = |name: &str| {
            m.fields
                .iter()
                .find(|f| f.name == name)
                .ok_or_else(|| format!("point cloud has no '{name}' field"))
        };
        let (fx, fy, fz) = (field("x")?, field("y")?, field("z")?);
        let size = |datatype: u8| match datatype {
            7 => Ok(4usize),
            8 => Ok(8usize),
            t => Err(format!(
                "point field datatype {t} is not a float (7 float32, 8 float64)"
            )),
        };
        let step = m.point_step as usize;
        let n = (m.width as usize).saturating_mul(m.height as usize);
        for f in [fx, fy, fz] {
            if f.offset as usize + size(f.datatype)? > step {
                return Err(format!(
                    "field '{}' at offset {} does not fit in a {step}-byte point",
                    f.name, f.offset
                ));
            }
        }
        let row_step = (m.row_step as usize).max(step * m.width as usize);
        let rows_needed = (m.height as usize)
            .saturating_sub(1)
            .saturating_mul(row_step);
        if n > 0 && m.data.len() < rows_needed.saturating_add(step.saturating_mul(m.width as usize))
        {
            return Err(format!(
                "point data is {} bytes, too short for {}x{} points of {step} bytes",
                m.data.len(),
                m.width,
                m.height
            ));
        }
        let read = |p: &[u8], f: &super::ros::PointField| -> f64 {
            let o = f.offset as usize;
            if f.datatype == 8 {
                let b: [u8; 8] = [
                    p[o],
                    p[o + 1],
                    p[o + 2],
                    p[o + 3],
                    p[o + 4],
                    p[o + 5],
                    p[o + 6],
                    p[o + 7],
                ];
                if m.is_bigendian {
                    f64::from_be_bytes(b)
                } else {
                    f64::from_le_bytes(b)
                }
            } else {
                let b = [p[o], p[o + 1], p[o + 2], p[o + 3]];
                (if m.is_bigendian {
                    f32::from_be_bytes(b)
                } else {
                    f32::from_le_bytes(b)
                }) as f64
            }
        };
        let mut image = Image::filled(k.width, k.height, 0.0);
        for v in 0..m.height as usize {
            for u in 0..m.width as usize {
                let start = v * row_step + u * step;
                let p = &m.data[start..start + step];
                let p_cam = glam::DVec3::new(read(p, fx), read(p, fy), read(p, fz));
                if !p_cam.is_finite() {
                    continue;
                }
                let Some((pu, pv, z)) = k.project(p_cam) else {
                    continue;
                };
                let (iu, iv) = (pu.round(), pv.round());
                if iu < 0.0 || iv < 0.0 || iu >= k.width as f64 || iv >= k.height as f64 {
                    continue;
                }
                let px = image.get_mut(iu as usize, iv as usize);
                let z = z as f32;
                if *px == 0.0 || z < *px {
                    *px = z;
                }
            }
        }
        Ok(image)
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::recording::ros::PointField;

    #[test]
    fn depth_encodings_give_metres() {
        // 2 x 2, 16UC1 little-endian with a 2-byte row pad; 0 stays "no measurement".
        let mut data = Vec::new();
        for (row, vals) in [[85u16, 0], [90, 65535]].iter().enumerate() {
            for v in vals {
                data.extend(v.to_le_bytes());
            }
            data.extend([row as u8, 0xff]); // padding, ignored
        }
        let m = ImageMsg {
            stamp_ns: 0,
            height: 2,
            width: 2,
            encoding: "16UC1".into(),
            is_bigendian: false,
            step: 6,
            data,
        };
        let d = image_depth(&m).unwrap();
        // 65 535 mm, the 16-bit drivers' no-return sentinel, is beyond any tactile camera's range: missing.
        assert_eq!(d.data, vec![0.085, 0.0, 0.09, 0.0]);
        let be = ImageMsg {
            encoding: "32FC1".into(),
            is_bigendian: true,
            width: 2,
            height: 1,
            step: 8,
            data: [0.08f32.to_be_bytes(), f32::NAN.to_be_bytes()].concat(),
            stamp_ns: 0,
        };
        assert_eq!(image_depth(&be).unwrap().data, vec![0.08, 0.0]);
        let rgb = ImageMsg {
            encoding: "rgb8".into(),
            ..be.clone()
        };
        assert!(image_depth(&rgb).unwrap_err().message.contains("rgb8"));
        let short = ImageMsg {
            data: vec![0; 7],
            ..be
        };
        assert!(image_depth(&short).is_err());
    }

    #[test]
    fn cloud_projects_to_the_pixel_of_its_ray() {
        let k = Intrinsics::pico_flexx();
        // Points on the rays of pixels (10, 20) and (100, 50) at 80 and 90 mm, plus a farther point on the first ray.
        let pts = [
            k.back_project(10.0, 20.0, 0.08),
            k.back_project(100.0, 50.0, 0.09),
            k.back_project(10.0, 20.0, 0.1),
        ];
        let mut data = Vec::new();
        for p in pts {
            for c in [p.x, p.y, p.z] {
                data.extend((c as f32).to_le_bytes());
            }
            data.extend([0u8; 4]); // padding field
        }
        let fields = ["x", "y", "z"]
            .iter()
            .enumerate()
            .map(|(i, n)| PointField {
                name: n.to_string(),
                offset: 4 * i as u32,
                datatype: 7,
                count: 1,
            })
            .collect();
        let m = PointCloudMsg {
            stamp_ns: 0,
            height: 1,
            width: 3,
            fields,
            is_bigendian: false,
            point_step: 16,
            row_step: 48,
            data,
        };
        let d = cloud_depth(&m, &k).unwrap();
        assert!((d.get(10, 20) - 0.08).abs() < 1e-6);
        assert!((d.get(100, 50) - 0.09).abs() < 1e-6);
        assert_eq!(d.count_nonzero(), 2);
    }
}
