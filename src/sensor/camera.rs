//! Pinhole model of the Soft Bubble's depth camera (PMD Pico Flexx), its usual crop, and rendering directly at the
//! model resolution by scaling the crop's intrinsics (paper IV.A, step 2 "depth projection to 3D").
//!
//! Convention (OpenCV): pixel `(u, v)` (column, row) has its centre at image coordinates `(u, v)`, and the ray through
//! it is `((u - cx) / fx, (v - cy) / fy, 1)` in the camera frame, so a hit at ray parameter `t` has z-depth `t`.

use crate::error::InvalidSetting;
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels (pixel centres at integer coordinates).
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

impl Intrinsics {
    /// The PMD Pico Flexx of the Soft Bubble: 224 x 171, fx = fy = 216.42569, cx = 118.77025, cy = 87.25412.
    pub fn pico_flexx() -> Self {
        Self {
            width: 224,
            height: 171,
            fx: 216.42569,
            fy: 216.42569,
            cx: 118.77025,
            cy: 87.25412,
        }
    }

    /// The sub-image of rows `rows.0..rows.1` and columns `cols.0..cols.1`.
    pub fn cropped(&self, rows: (usize, usize), cols: (usize, usize)) -> Self {
        Self {
            width: cols.1 - cols.0,
            height: rows.1 - rows.0,
            cx: self.cx - cols.0 as f64,
            cy: self.cy - rows.0 as f64,
            ..*self
        }
    }

    /// The same field of view sampled on a `width x height` grid: each new pixel covers the same area of the image
    /// plane as the block of old pixels it replaces (area resampling), so its centre ray is the block's centre ray.
    pub fn resized(&self, width: usize, height: usize) -> Self {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        Self {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
        }
    }

    /// Ray direction through pixel `(u, v)` in the camera frame, with unit z component.
    #[inline]
    pub fn ray_dir(&self, u: f64, v: f64) -> DVec3 {
        DVec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    /// Back-project pixel `(u, v)` with z-depth `depth` (metres) to a point in the camera frame, `p_cam`.
    #[inline]
    pub fn back_project(&self, u: f64, v: f64, depth: f64) -> DVec3 {
        self.ray_dir(u, v) * depth
    }

    /// Project a camera-frame point to pixel coordinates `(u, v)` and its z-depth; `None` behind the camera.
    #[inline]
    pub fn project(&self, p_cam: DVec3) -> Option<(f64, f64, f64)> {
        (p_cam.z > 0.0).then(|| {
            (
                self.fx * p_cam.x / p_cam.z + self.cx,
                self.fy * p_cam.y / p_cam.z + self.cy,
                p_cam.z,
            )
        })
    }

    /// Pixel size relative to another sampling of the same field of view: `(sx, sy)` = this pixel's width and height
    /// measured in `native` pixels.
    pub fn pixel_size_in(&self, native: &Intrinsics) -> (f64, f64) {
        (native.fx / self.fx, native.fy / self.fy)
    }
}

/// The camera as configured by the user: the sensor's native intrinsics, the crop, and the model resolution.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CameraConfig {
    /// Native intrinsics of the depth camera.
    pub native: Intrinsics,
    /// Rows kept by the crop, `[start, end)` in native pixels (default 20..160).
    pub crop_rows: (usize, usize),
    /// Columns kept by the crop, `[start, end)` in native pixels (default 25..200).
    pub crop_cols: (usize, usize),
    /// Rendered (model) resolution `(width, height)` in pixels; multiples of 8 (default 64 x 64).
    pub resolution: (usize, usize),
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            native: Intrinsics::pico_flexx(),
            crop_rows: (20, 160),
            crop_cols: (25, 200),
            resolution: (64, 64),
        }
    }
}

/// Largest model (rendered) resolution, pixels a side.
pub const MAX_RESOLUTION: usize = 1024;

impl CameraConfig {
    /// The crop of the native image in native pixels.
    pub fn crop(&self) -> Intrinsics {
        self.native.cropped(self.crop_rows, self.crop_cols)
    }

    /// Intrinsics of the rendered images: the crop rescaled to `resolution`.
    pub fn intrinsics(&self) -> Intrinsics {
        self.crop().resized(self.resolution.0, self.resolution.1)
    }

    /// Check the configuration, with a message saying what to change.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        let (w, h) = self.resolution;
        if w == 0 || h == 0 || w % 8 != 0 || h % 8 != 0 {
            return Err(InvalidSetting::new(
                "camera.resolution",
                format!("resolution {w}x{h} must be a positive multiple of 8 in both directions"),
            ));
        }
        // The model's resolution (a 1024 x 1024 simulation takes ~1 GB and seconds a contact; larger ones hours).
        if w > MAX_RESOLUTION || h > MAX_RESOLUTION {
            return Err(InvalidSetting::new(
                "camera.resolution",
                format!("resolution {w}x{h} is larger than {MAX_RESOLUTION} pixels"),
            ));
        }
        let n = &self.native;
        if n.width == 0 || n.height == 0 || n.width > 4096 || n.height > 4096 {
            return Err(InvalidSetting::new(
                "camera.native",
                format!(
                    "the native image {}x{} must be 1 to 4096 pixels a side",
                    n.width, n.height
                ),
            ));
        }
        // A depth camera's focal length in pixels: its field of view between ~1° and ~170° across the image.
        let widest = n.width.max(n.height) as f64;
        let focal_ok = |f: f64| f.is_finite() && f >= 0.04 * widest && f <= 60.0 * widest;
        if !(focal_ok(n.fx) && focal_ok(n.fy) && n.cx.is_finite() && n.cy.is_finite()) {
            return Err(InvalidSetting::new(
                "camera.native",
                format!(
                    "focal lengths {} and {} px must be between {} and {} px for a {}x{} image (fields of view of ~1 to ~170 degrees), the principal point finite",
                    n.fx,
                    n.fy,
                    0.04 * widest,
                    60.0 * widest,
                    n.width,
                    n.height
                ),
            ));
        }
        let (r0, r1) = self.crop_rows;
        let (c0, c1) = self.crop_cols;
        if r0 >= r1 || c0 >= c1 || r1 > n.height || c1 > n.width {
            return Err(InvalidSetting::new(
                "camera.crop",
                format!(
                    "crop rows {r0}..{r1}, cols {c0}..{c1} must be non-empty and inside the {}x{} native image",
                    n.width, n.height
                ),
            ));
        }
        Ok(())
    }
}

/// Parse `"WxH"` (e.g. `64x64`).
pub fn parse_resolution(s: &str) -> Result<(usize, usize), InvalidSetting> {
    let bad = || {
        InvalidSetting::new(
            "resolution",
            format!("resolution '{s}' must look like 64x64"),
        )
    };
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    // Any image here is at most 16384 pixels a side (the model's at most MAX_RESOLUTION, a figure's more): larger
    // numbers would overflow a pixel count.
    let parse = |t: &str| {
        t.trim()
            .parse::<usize>()
            .ok()
            .filter(|&v| v <= 16_384)
            .ok_or_else(bad)
    };
    Ok((parse(w)?, parse(h)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn back_projection_round_trip() {
        let k = CameraConfig::default().intrinsics();
        for &(u, v, d) in &[(0.0, 0.0, 0.05), (31.5, 17.25, 0.1), (63.0, 63.0, 0.149)] {
            let p = k.back_project(u, v, d);
            let (u2, v2, d2) = k.project(p).unwrap();
            assert!((u - u2).abs() < 1e-9 && (v - v2).abs() < 1e-9 && (d - d2).abs() < 1e-12);
        }
        assert!(k.project(DVec3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn resizing_preserves_the_field_of_view_edges() {
        // The left edge of pixel 0 (u = -0.5) and the right edge of the last pixel (u = W - 0.5) must map to the
        // same rays before and after resampling.
        let crop = Intrinsics::pico_flexx().cropped((20, 160), (25, 200));
        let small = crop.resized(64, 64);
        let edge = |k: &Intrinsics, u: f64, v: f64| k.ray_dir(u, v);
        let a = edge(&crop, -0.5, -0.5);
        let b = edge(&small, -0.5, -0.5);
        assert!((a - b).length() < 1e-12);
        let a = edge(&crop, 174.5, 139.5);
        let b = edge(&small, 63.5, 63.5);
        assert!((a - b).length() < 1e-12);
        // A 175 -> 175 resize is the identity.
        assert_eq!(crop.resized(175, 140), crop);
    }

    #[test]
    fn validation_messages() {
        let mut c = CameraConfig::default();
        assert!(c.validate().is_ok());
        c.resolution = (60, 64);
        assert!(c.validate().unwrap_err().message.contains("multiple of 8"));
        c.resolution = (64, 64);
        c.crop_rows = (20, 400);
        assert!(c.validate().unwrap_err().message.contains("inside"));
        assert_eq!(parse_resolution("128x96"), Ok((128, 96)));
        assert!(parse_resolution("128").is_err());
    }
}
