//! Depth images as users keep them: `.npy` arrays, one array of an `.npz`, or 16-bit grayscale PNGs, read into an
//! [`Image`] in metres with the scale each format was written at (a pair table's images, a folder of frames). A
//! pixel without a return (NaN, ±inf; 0 in a PNG) is read as 0, the value every stage takes for missing.

use std::io::Read;
use std::path::{Path, PathBuf};

use super::npy;
use crate::image::Image;

/// A depth image file that could not be read: the file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", path.display())]
pub struct DepthFileError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

/// Read one depth image in metres; `rel` is relative to `from` (`file.npz:name` picks an array of an npz). `.npy` and
/// `.npz` values are multiplied by `npy_scale`, 16-bit PNG values by `png_scale` (metres per unit).
pub fn read(
    from: &Path,
    rel: &str,
    npy_scale: f64,
    png_scale: f64,
) -> Result<Image, DepthFileError> {
    let (file, member) = match rel.rsplit_once(':') {
        Some((f, m)) if f.to_ascii_lowercase().ends_with(".npz") => (f, Some(m)),
        _ => (rel, None),
    };
    let path = from.join(file);
    let bad = |message: String| DepthFileError {
        path: path.clone(),
        message,
    };
    if !path.is_file() {
        return Err(bad(
            "file not found (paths in the pair table are relative to its directory)".into(),
        ));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let (img, scale) = match ext.as_str() {
        "npy" => (
            // The .npy error names the file already; the message is what follows it.
            npy::read_image(&path).map_err(|e| {
                let e = e.to_string();
                let named = format!("{}: ", path.display());
                bad(e
                    .strip_prefix(&named)
                    .map_or_else(|| e.clone(), str::to_owned))
            })?,
            npy_scale,
        ),
        "npz" => (read_npz_image(&path, member)?, npy_scale),
        "png" => {
            let dynamic = image::open(&path).map_err(|e| bad(format!("cannot read PNG: {e}")))?;
            if !matches!(dynamic, image::DynamicImage::ImageLuma16(_)) {
                return Err(bad(format!(
                    "PNG is {:?}; depth PNGs must be 16-bit grayscale",
                    dynamic.color()
                )));
            }
            let g = dynamic.to_luma16();
            let (w, h) = (g.width() as usize, g.height() as usize);
            let data = g.into_raw().into_iter().map(f32::from).collect();
            (
                Image::from_vec(w, h, data).ok_or_else(|| bad("PNG size".into()))?,
                png_scale,
            )
        }
        _ => {
            return Err(bad(
                "unsupported image file (use .npy, .npz or 16-bit .png)".into(),
            ))
        }
    };
    let scale = scale as f32;
    Ok(Image {
        data: img.data.iter().map(|&x| x * scale).collect(),
        ..img
    })
}

/// One array of an `.npz` (any compression numpy writes): `member`, or the only array.
fn read_npz_image(path: &Path, member: Option<&str>) -> Result<Image, DepthFileError> {
    let bad = |message: String| DepthFileError {
        path: path.to_path_buf(),
        message,
    };
    let file = std::fs::File::open(path).map_err(|e| bad(e.to_string()))?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| bad(format!("not an npz: {e}")))?;
    let names: Vec<String> = zip
        .file_names()
        .filter_map(|n| n.ok()?.strip_suffix(".npy").map(str::to_string))
        .collect();
    let name = match member {
        Some(m) => m.to_string(),
        None if names.len() == 1 => names[0].clone(),
        None => {
            return Err(bad(format!(
                "holds {} arrays ({}); name one as file.npz:name",
                names.len(),
                names.join(", ")
            )))
        }
    };
    let mut bytes = Vec::new();
    zip.by_name(&format!("{name}.npy"))
        .map_err(|_| bad(format!("no array '{name}' (has {})", names.join(", "))))?
        .read_to_end(&mut bytes)
        .map_err(|e| bad(format!("array '{name}': {e}")))?;
    let a = npy::decode(&bytes).map_err(|e| bad(format!("array '{name}': {e}")))?;
    let (h, w) = match a.shape.as_slice() {
        [h, w] | [1, h, w] => (*h, *w),
        s => {
            return Err(bad(format!(
                "array '{name}' has shape {s:?}; expected (H, W)"
            )))
        }
    };
    // NaN and ±inf mark pixels without a return: missing (0), as in a .npy.
    let data = a
        .data
        .into_iter()
        .map(|x| if x.is_finite() { x } else { 0.0 })
        .collect();
    Image::from_vec(w, h, data).ok_or_else(|| bad(format!("array '{name}': size mismatch")))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    #[test]
    fn a_damaged_npy_frame_is_named_once() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("frame.npy"), b"\x93NUMPY\x01\x00").unwrap();
        let e = super::read(dir.path(), "frame.npy", 1.0, 0.001)
            .unwrap_err()
            .to_string();
        assert_eq!(e.matches("frame.npy").count(), 1, "{e}");
        assert!(e.contains("not a valid .npy file"), "{e}");
    }
}
