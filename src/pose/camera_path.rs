//! The **camera path** of the signature check's forward model: for frames that reached the model's resolution by
//! area resampling (a recording's native or cropped frames, imported), the predicted signature is rendered the way
//! the frame was made — at the camera's native pixels over the crop, with the shadow cloak in native pixels — and
//! area-resampled as `tnd dataset import` resamples ([`crate::sensor::resample::resample_depth`]).
//!
//! Rendered at the model's resolution instead, one ray per model pixel, the prediction is sharper than the measured
//! frame at every edge of the contact and its shadow; on imported validation recordings that model error was larger
//! than what tells two near-symmetric poses apart, and the check preferred a wrong pose to the true one in most
//! pairs it got wrong (docs/experiments/2026-11-30-camera-path-check.md).

use std::sync::Arc;

use glam::DAffine3;

use crate::image::Image;
use crate::mesh::RayCaster;
use crate::sensor::resample::{crop, resample_depth, resampled_pixel};
use crate::sensor::{Intrinsics, Se2};
use crate::sim::render::render_depth_where;
use crate::sim::shadows::tactile_signature;
use crate::sim::{SimConfig, SimError, Simulator};

/// A sensor's camera at native resolution over its crop, for predictions of resampled frames.
#[derive(Clone, Debug)]
pub struct CameraPath {
    /// The native camera over the crop (native pixel size).
    crop: Intrinsics,
    /// The undeformed membrane's depth over the crop, native pixels (metres, 0 where not seen).
    membrane: Image,
    /// The model's resolution (width, height).
    resolution: (usize, usize),
}

impl CameraPath {
    /// The camera path of `config`'s sensor (renders its membrane at native resolution once).
    pub fn new(config: &SimConfig) -> Result<Self, SimError> {
        let native = Simulator::native(config.clone())?;
        let camera = &config.camera;
        Ok(Self {
            crop: camera.crop(),
            membrane: crop(native.nominal_depth(), camera.crop_rows, camera.crop_cols),
            resolution: camera.resolution,
        })
    }

    /// The path shared by an observation's frames: [`Self::new`] where they were `resampled` from the camera's
    /// native pixels, `None` for frames made at the model's resolution.
    pub fn for_frames(config: &SimConfig, resampled: bool) -> Result<Option<Arc<Self>>, SimError> {
        resampled
            .then(|| Self::new(config).map(Arc::new))
            .transpose()
    }

    /// The path for one measurement whose membrane at the model's resolution is `membrane` (the nominal one, or the
    /// measured one of [`super::signature_check::measured_membrane`]): the native membrane moved by the same offset
    /// from nominal, so that a drifted inflation is predicted at native resolution too. `None` when `membrane` is not
    /// at this path's resolution.
    pub fn for_membrane<'a>(&'a self, membrane: &'a Image) -> Option<MembranePath<'a>> {
        let (w, h) = self.resolution;
        if (membrane.width, membrane.height) != (w, h) {
            return None;
        }
        let nominal = resample_depth(&self.membrane, w, h);
        let (cw, ch) = (self.membrane.width, self.membrane.height);
        let mut native = self.membrane.clone();
        for y in 0..ch {
            let v = (y * h / ch).min(h - 1);
            for x in 0..cw {
                let u = (x * w / cw).min(w - 1);
                let (e, n) = (membrane.get(u, v), nominal.get(u, v));
                let px = native.get_mut(x, y);
                if *px > 0.0 && e > 0.0 && n > 0.0 {
                    *px += e - n;
                }
            }
        }
        let resampled = resample_depth(&native, w, h);
        Some(MembranePath {
            path: self,
            membrane,
            native,
            resampled,
        })
    }
}

/// [`CameraPath`] for one measurement's membrane.
pub struct MembranePath<'a> {
    path: &'a CameraPath,
    /// The membrane at the model's resolution the path was made for (metres).
    membrane: &'a Image,
    /// The membrane at native resolution over the crop (metres).
    native: Image,
    /// `native` area-resampled to the model's resolution.
    resampled: Image,
}

impl MembranePath<'_> {
    /// The noise-free signature at the model's resolution with the object (ray caster in its own frame) at `pose`,
    /// seen from `t_world_camera`: rendered over the crop at native pixels, the contact where the object lies in
    /// front of the membrane, the cloak of `shadow_px` native pixels, area-resampled; then placed on the membrane
    /// this path was made for as the resampled deformation. 0 where that membrane is 0.
    ///
    /// Only where the signature can differ from the membrane is any of that done: rays are cast at the native
    /// pixels of the model pixels within [`REACH_PX`] of one where the object's depth at the model's resolution,
    /// `coarse` (one ray per pixel, which the check renders anyway), comes within [`NEAR_M`] of the membrane; the
    /// cloak is computed in that region's box grown by the cloak, and only the model pixels that box touches are
    /// resampled again. Elsewhere the signature is the membrane.
    pub fn predict(
        &self,
        caster: &RayCaster,
        t_world_camera: &DAffine3,
        pose: Se2,
        coarse: &Image,
        shadow_px: f64,
    ) -> Image {
        let t_object_camera = pose.to_affine().inverse() * *t_world_camera;
        let (w, h) = self.path.resolution;
        let membrane = self.membrane;
        let near: Vec<bool> = coarse
            .data
            .iter()
            .zip(&membrane.data)
            .map(|(&d, &e)| d > 0.0 && e > 0.0 && d < e + NEAR_M)
            .collect();
        let reach = dilate(&near, w, h, REACH_PX);
        let mut reached: Option<(usize, usize, usize, usize)> = None;
        for (i, _) in reach.iter().enumerate().filter(|(_, &r)| r) {
            let (u, v) = (i % w, i / w);
            reached = Some(reached.map_or((u, u, v, v), |(u0, u1, v0, v1)| {
                (u0.min(u), u1.max(u), v0.min(v), v1.max(v))
            }));
        }
        let Some((u0, u1, v0, v1)) = reached else {
            return membrane.clone();
        };
        let (cw, ch) = (self.native.width, self.native.height);
        let (sx, sy) = (cw as f64 / w as f64, ch as f64 / h as f64);
        // The native pixels of the reached model pixels' box, grown by the cloak.
        let cloak = shadow_px.max(0.0).ceil() as usize;
        let span = |lo: usize, hi: usize, s: f64, n: usize| {
            let a = ((lo as f64 * s).floor() as usize).saturating_sub(cloak);
            let b = ((((hi + 1) as f64 * s).ceil() as usize) + cloak).min(n);
            (a.min(b), b)
        };
        let (cols, rows) = (span(u0, u1, sx, cw), span(v0, v1, sy, ch));
        let window = self.path.crop.cropped(rows, cols);
        let model_pixel = |x: usize, s: f64, n: usize| (((x as f64 + 0.5) / s) as usize).min(n - 1);
        let depth = render_depth_where(caster, &window, &t_object_camera, |x, y| {
            reach[model_pixel(rows.0 + y, sy, h) * w + model_pixel(cols.0 + x, sx, w)]
        });
        let membrane_window = crop(&self.native, rows, cols);
        let mask = depth.zip_map(&membrane_window, |d, e| {
            f32::from(u8::from(d > 0.0 && e > 0.0 && d < e))
        });
        let cloaked = tactile_signature(&depth, &membrane_window, &mask, shadow_px, (1.0, 1.0));
        let signature = |x: usize, y: usize| {
            if (cols.0..cols.1).contains(&x) && (rows.0..rows.1).contains(&y) {
                cloaked.get(x - cols.0, y - rows.0)
            } else {
                self.native.get(x, y)
            }
        };
        // Model pixels whose area meets the window; the others resample the membrane, as before.
        let touched = |(a, b): (usize, usize), s: f64, n: usize| {
            (
                (a as f64 / s).floor() as usize,
                ((b as f64 / s).ceil() as usize).min(n),
            )
        };
        let (us, vs) = (touched(cols, sx, w), touched(rows, sy, h));
        let mut out = membrane.clone();
        for v in vs.0..vs.1 {
            for u in us.0..us.1 {
                let s = resampled_pixel(&signature, (cw, ch), (w, h), u, v);
                let e = self.resampled.get(u, v);
                let p = out.get_mut(u, v);
                if *p > 0.0 && s > 0.0 && e > 0.0 {
                    *p -= e - s;
                }
            }
        }
        out
    }
}

/// `mask` grown by `radius` pixels in every direction (a square structuring element).
fn dilate(mask: &[bool], width: usize, height: usize, radius: usize) -> Vec<bool> {
    let mut rows = vec![false; mask.len()];
    for y in 0..height {
        for x in 0..width {
            let lo = x.saturating_sub(radius);
            let hi = (x + radius).min(width - 1);
            rows[y * width + x] = mask[y * width + lo..=y * width + hi].iter().any(|&m| m);
        }
    }
    let mut out = vec![false; mask.len()];
    for y in 0..height {
        let (lo, hi) = (y.saturating_sub(radius), (y + radius).min(height - 1));
        for x in 0..width {
            out[y * width + x] = (lo..=hi).any(|yy| rows[yy * width + x]);
        }
    }
    out
}

/// How many model pixels beyond those whose centre ray comes near the membrane ([`NEAR_M`]) the object may reach it
/// between rays: their native pixels are rendered too.
pub const REACH_PX: usize = 2;

/// How far behind the membrane (metres) the object's depth at a model pixel's centre ray may lie for
/// [`MembranePath::predict`] to render that pixel's surroundings natively: between the model's rays it may reach the
/// membrane.
pub const NEAR_M: f32 = 0.002;
