//! Bringing real depth frames to the model resolution with **the simulator's camera model**: the crop of
//! [`CameraConfig`] (rows/columns of the native image), then area resampling, where each output pixel covers exactly
//! the block of input pixels whose image-plane area it replaces — the same mapping as
//! [`crate::sensor::Intrinsics::resized`], so an output pixel's centre ray is the simulator's ray for that pixel.

use super::CameraConfig;
use crate::image::Image;

/// A depth pixel of the output is valid when at least this fraction of its area is covered by valid (non-zero)
/// input pixels; its value is the area-weighted mean of those.
pub const MIN_VALID_COVERAGE: f64 = 0.5;

/// Which stage of the camera model an input image is at, judged by its size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputSize {
    /// The sensor's native frame (e.g. 224 x 171): crop, then resample.
    Native,
    /// Already cropped (e.g. 175 x 140): resample.
    Cropped,
    /// Already at the model resolution: used as is.
    Model,
}

/// Classify a `width x height` frame against the camera, or say which sizes are accepted.
pub fn classify(
    camera: &CameraConfig,
    width: usize,
    height: usize,
) -> Result<InputSize, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("depth image size", || {
        let crop = camera.crop();
        if (width, height) == camera.resolution {
            Ok(InputSize::Model)
        } else if (width, height) == (camera.native.width, camera.native.height) {
            Ok(InputSize::Native)
        } else if (width, height) == (crop.width, crop.height) {
            Ok(InputSize::Cropped)
        } else {
            Err(format!(
            "image is {width}x{height}; expected the native {}x{}, the crop {}x{} or the model resolution {}x{}",
            camera.native.width,
            camera.native.height,
            crop.width,
            crop.height,
            camera.resolution.0,
            camera.resolution.1
        ))
        }
    })
}

/// Crop rows `rows.0..rows.1`, columns `cols.0..cols.1`.
pub fn crop(image: &Image, rows: (usize, usize), cols: (usize, usize)) -> Image {
    let (w, h) = (cols.1 - cols.0, rows.1 - rows.0);
    let mut data = Vec::with_capacity(w * h);
    for v in rows.0..rows.1 {
        let start = v * image.width + cols.0;
        data.extend_from_slice(&image.data[start..start + w]);
    }
    Image {
        width: w,
        height: h,
        data,
    }
}

/// Whether a pixel of a frame on its way to the model resolution holds a value: not 0, finite and within
/// [`crate::image::MAX_DEPTH_M`] (a depth, or an imprint, which may be negative); the others are missing.
#[inline]
fn has_value(d: f32) -> bool {
    d != 0.0 && d.is_finite() && d.abs() <= crate::image::MAX_DEPTH_M
}

/// Area-resample a depth image (0, NaN, ±inf or out of range = missing) to `width x height`.
pub fn resample_depth(image: &Image, width: usize, height: usize) -> Image {
    let mut out = Image::filled(width, height, 0.0);
    let all = |x: usize, y: usize| image.get(x, y);
    for v in 0..height {
        for u in 0..width {
            *out.get_mut(u, v) =
                resampled_pixel(&all, (image.width, image.height), (width, height), u, v);
        }
    }
    out
}

/// Pixel `(u, v)` of [`resample_depth`]'s `out.0 x out.1` output for a `size.0 x size.1` image whose pixel `(x, y)`
/// is `get(x, y)`: for resampling only the part of an image that changed, without assembling it. 0 where less than
/// [`MIN_VALID_COVERAGE`] of the pixel's area holds values.
pub fn resampled_pixel(
    get: &impl Fn(usize, usize) -> f32,
    size: (usize, usize),
    out: (usize, usize),
    u: usize,
    v: usize,
) -> f32 {
    let sx = size.0 as f64 / out.0 as f64;
    let sy = size.1 as f64 / out.1 as f64;
    let (y0, y1) = (v as f64 * sy, (v + 1) as f64 * sy);
    let (x0, x1) = (u as f64 * sx, (u + 1) as f64 * sx);
    let (mut sum, mut valid, mut area) = (0.0f64, 0.0f64, 0.0f64);
    for iy in (y0.floor() as usize)..(y1.ceil() as usize).min(size.1) {
        let wy = (y1.min(iy as f64 + 1.0) - y0.max(iy as f64)).max(0.0);
        for ix in (x0.floor() as usize)..(x1.ceil() as usize).min(size.0) {
            let wx = (x1.min(ix as f64 + 1.0) - x0.max(ix as f64)).max(0.0);
            let a = wx * wy;
            area += a;
            let d = get(ix, iy);
            if has_value(d) {
                sum += a * f64::from(d);
                valid += a;
            }
        }
    }
    if area > 0.0 && valid / area >= MIN_VALID_COVERAGE {
        (sum / valid) as f32
    } else {
        0.0
    }
}

/// Whether a `width` x `height` frame of `camera` reaches the model resolution by area resampling (a native or
/// cropped frame), which averages several camera pixels into one model pixel: such inputs are quieter than frames
/// at the model resolution (`--model auto` picks its model by this).
pub fn is_resampled(camera: &CameraConfig, width: usize, height: usize) -> bool {
    matches!(
        classify(camera, width, height),
        Ok(InputSize::Native | InputSize::Cropped)
    )
}

/// Bring a depth frame to the model resolution: crop if native, resample if not at the model size. Pixels without a
/// value come out as 0 (missing) whatever way the frame marked them.
pub fn to_model(camera: &CameraConfig, image: &Image) -> Result<Image, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("depth image size", || {
        let (w, h) = camera.resolution;
        match classify(camera, image.width, image.height)? {
            InputSize::Model => Ok(Image {
                width: image.width,
                height: image.height,
                data: image
                    .data
                    .iter()
                    .map(|&d| if has_value(d) { d } else { 0.0 })
                    .collect(),
            }),
            InputSize::Cropped => Ok(resample_depth(image, w, h)),
            InputSize::Native => Ok(resample_depth(
                &crop(image, camera.crop_rows, camera.crop_cols),
                w,
                h,
            )),
        }
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn native_and_cropped_frames_are_resampled_model_sized_ones_not() {
        let camera = CameraConfig::default();
        let (w, h) = camera.resolution;
        assert!(!is_resampled(&camera, w, h));
        assert!(is_resampled(&camera, 224, 171));
        let (r, c) = (camera.crop_rows, camera.crop_cols);
        assert!(is_resampled(&camera, c.1 - c.0, r.1 - r.0));
        assert!(
            !is_resampled(&camera, 13, 7),
            "a size no stage has is not resampled"
        );
    }

    #[test]
    fn block_average_and_coverage_rule() {
        // 4x4 -> 2x2: each output pixel is the mean of a 2x2 block (depths of 10..160 mm).
        let img = Image::from_vec(4, 4, (1..=16).map(|x| x as f32 * 0.01).collect()).unwrap();
        let out = resample_depth(&img, 2, 2);
        let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
        assert!(
            close(&out.data, &[0.035, 0.055, 0.115, 0.135]),
            "{:?}",
            out.data
        );
        // A block with one valid pixel of four (25 % < 50 %) is missing; two of four (50 %) is their mean.
        let mut img = Image::filled(4, 2, 0.0);
        *img.get_mut(0, 0) = 0.01;
        *img.get_mut(2, 0) = 0.02;
        *img.get_mut(3, 1) = 0.04;
        let out = resample_depth(&img, 2, 1);
        assert!(close(&out.data, &[0.0, 0.03]), "{:?}", out.data);
        // NaN, ±inf and out-of-range values (a 65 535 mm sentinel) are missing like 0.
        let mut img = Image::filled(2, 2, 0.05);
        *img.get_mut(0, 0) = f32::NAN;
        *img.get_mut(1, 0) = 65.535;
        *img.get_mut(0, 1) = f32::INFINITY;
        assert_eq!(resample_depth(&img, 1, 1).data, vec![0.0]);
        *img.get_mut(0, 1) = 0.07;
        assert!(close(&resample_depth(&img, 1, 1).data, &[0.06]));
    }

    #[test]
    fn fractional_ratio_conserves_mass_and_preserves_a_constant() {
        // 175 -> 64 columns: non-integer blocks. Area resampling conserves the integral (sum of value x block width
        // equals the input sum), each output lies within half a pixel of the ramp at its block centre, and a constant
        // stays constant.
        // A ramp of 5 .. 1745 mm, 10 mm a pixel.
        let img =
            Image::from_vec(175, 1, (0..175).map(|x| (x as f32 + 0.5) * 0.01).collect()).unwrap();
        let out = resample_depth(&img, 64, 1);
        let input: f64 = img.data.iter().map(|&x| f64::from(x)).sum();
        let output: f64 = out.data.iter().map(|&x| f64::from(x) * 175.0 / 64.0).sum();
        assert!((input - output).abs() < 1e-3 * input, "{input} vs {output}");
        for u in 0..64 {
            let centre = (u as f64 + 0.5) * 175.0 / 64.0 * 0.01;
            assert!(
                (f64::from(out.get(u, 0)) - centre).abs() <= 0.005 + 1e-6,
                "{u}"
            );
        }
        let c = resample_depth(&Image::filled(175, 140, 0.09), 64, 64);
        assert!(c.data.iter().all(|&x| (x - 0.09).abs() < 1e-7));
    }

    #[test]
    fn classify_and_crop() {
        let cam = CameraConfig::default();
        assert_eq!(classify(&cam, 224, 171), Ok(InputSize::Native));
        assert_eq!(classify(&cam, 175, 140), Ok(InputSize::Cropped));
        assert_eq!(classify(&cam, 64, 64), Ok(InputSize::Model));
        assert!(classify(&cam, 100, 100)
            .unwrap_err()
            .message
            .contains("224x171"));
        let img = Image::from_vec(4, 3, (0..12).map(|x| x as f32).collect()).unwrap();
        assert_eq!(crop(&img, (1, 3), (1, 3)).data, vec![5.0, 6.0, 9.0, 10.0]);
    }
}
