//! NumPy `.npy` files (format 1.0/2.0/3.0): float32 images are written little-endian, C order; reading accepts what
//! numpy writes every day — float16/32/64, bool, signed and unsigned 8- to 64-bit integers, either byte order, C or
//! Fortran order — and converts to `f32` in C order, so users can hand us arrays from numpy without our code.
//! Complex, string, object and structured dtypes are refused by name.

use std::path::{Path, PathBuf};

use crate::image::Image;

/// Errors reading or writing `.npy` files; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a valid .npy file: {message}")]
    Format { path: PathBuf, message: String },
    #[error(
        "{path}: unsupported dtype '{descr}' (numeric arrays only: float16/32/64, bool, int8..int64, uint8..uint64)"
    )]
    Dtype { path: PathBuf, descr: String },
    #[error("{path}: expected a 2-D array (H, W) or (1, H, W), found shape {shape:?}")]
    Shape { path: PathBuf, shape: Vec<usize> },
    #[error("{path}: {message}")]
    Units { path: PathBuf, message: String },
}

/// An n-dimensional array read from a `.npy` file, converted to `f32`, C order.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
    /// The file's dtype as numpy wrote it (e.g. `<f4`, `<u2`).
    pub descr: String,
}

/// Largest magnitude, metres, that a depth or imprint image of a hand-sized sensor plausibly holds; larger values
/// are taken for millimetres.
pub const PLAUSIBLE_METRES: f32 = 2.0;

/// A `.npy` (format 1.0) header for a C-order array of dtype `descr` (e.g. `<f4`), padded with spaces and a final
/// `\n` so that magic(6) + version(2) + length(2) + header is a multiple of 64 bytes (the data start aligned).
pub fn header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let shape_str = match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_str}, }}");
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out
}

/// Encode a float32 array of the given shape as `.npy` bytes.
pub fn encode_f32(shape: &[usize], data: &[f32]) -> Vec<u8> {
    let mut out = header("<f4", shape);
    out.reserve(data.len() * 4);
    for x in data {
        out.extend_from_slice(&x.to_le_bytes());
    }
    out
}

/// Write an image as a float32 `(H, W)` `.npy` file, atomically.
pub fn write_image(path: &Path, image: &Image) -> Result<(), NpyError> {
    let bytes = encode_f32(&[image.height, image.width], &image.data);
    crate::io::write_atomic(path, &bytes).map_err(|source| NpyError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Read any numeric `.npy` file as `f32`.
pub fn read(path: &Path) -> Result<NpyArray, NpyError> {
    let bytes =
        super::input::read_capped(path, super::input::MAX_ARRAY_BYTES).map_err(|source| {
            NpyError::Io {
                path: path.to_path_buf(),
                source,
            }
        })?;
    decode(&bytes).map_err(|e| e.with_path(path))
}

/// Read a 2-D (or `(1, H, W)`) `.npy` depth or imprint image in **metres** (float32 or float64): integer arrays
/// (sensor millimetres, say) and arrays whose typical value is beyond [`PLAUSIBLE_METRES`] are refused with the
/// conversion to make, rather than read as silently wrong depths. Pixels without a value — NaN, ±inf (how ROS
/// drivers and numpy dumps mark a pixel without a return) or a single value beyond [`PLAUSIBLE_METRES`] — are 0,
/// the value every stage reads as missing.
pub fn read_metres_image(path: &Path) -> Result<Image, NpyError> {
    let a = read(path)?;
    let units = |message: String| NpyError::Units {
        path: path.to_path_buf(),
        message,
    };
    if !is_float(&a.descr) {
        return Err(units(format!(
            "integer array ({}); images here are float metres — if it holds millimetres, save np.asarray(a, np.float32) / 1000",
            a.descr
        )));
    }
    // The typical magnitude decides the units (a few out-of-range pixels are pixels without a return).
    if let Some(typical) =
        crate::image::typical_magnitude(&a.data).filter(|&t| t > PLAUSIBLE_METRES)
    {
        return Err(units(crate::image::implausible_depth_units(
            typical,
            "images here are metres: divide by 1000",
        )));
    }
    let mut img = image_of(path, a)?;
    for v in &mut img.data {
        if v.abs() > PLAUSIBLE_METRES {
            *v = 0.0;
        }
    }
    Ok(img)
}

/// Read a 2-D (or `(1, H, W)`) `.npy` file of any numeric dtype as an image (the caller applies units; see
/// [`read_metres_image`] for metre images from users). NaN and ±inf values, a pixel without a return, are 0 (missing).
pub fn read_image(path: &Path) -> Result<Image, NpyError> {
    image_of(path, read(path)?)
}

fn image_of(path: &Path, mut a: NpyArray) -> Result<Image, NpyError> {
    let (h, w) = match a.shape.as_slice() {
        [h, w] => (*h, *w),
        [1, h, w] => (*h, *w),
        _ => {
            return Err(NpyError::Shape {
                path: path.to_path_buf(),
                shape: a.shape,
            })
        }
    };
    for x in &mut a.data {
        if !x.is_finite() {
            *x = 0.0;
        }
    }
    Image::from_vec(w, h, a.data).ok_or_else(|| NpyError::Format {
        path: path.to_path_buf(),
        message: "data length does not match shape".into(),
    })
}

impl NpyError {
    fn with_path(self, path: &Path) -> Self {
        let path = path.to_path_buf();
        match self {
            Self::Format { message, .. } => Self::Format { path, message },
            Self::Dtype { descr, .. } => Self::Dtype { path, descr },
            Self::Shape { shape, .. } => Self::Shape { path, shape },
            other => other,
        }
    }
}

/// Decode `.npy` bytes (the path in errors is empty; [`read`] fills it in).
pub fn decode(bytes: &[u8]) -> Result<NpyArray, NpyError> {
    let fmt = |m: &str| NpyError::Format {
        path: PathBuf::new(),
        message: m.to_string(),
    };
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(fmt("missing \\x93NUMPY magic"));
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(fmt(&format!("unsupported format version {v}"))),
    };
    let header = bytes
        .get(start..start + header_len)
        .ok_or_else(|| fmt("truncated header"))?;
    let header = std::str::from_utf8(header).map_err(|_| fmt("header is not text"))?;
    let descr = dict_value(header, "descr").ok_or_else(|| fmt("header has no 'descr'"))?;
    let descr = descr.trim_matches(|c| c == '\'' || c == '"').to_string();
    let fortran = dict_value(header, "fortran_order").is_some_and(|v| v.starts_with("True"));
    let shape_s = dict_value(header, "shape").ok_or_else(|| fmt("header has no 'shape'"))?;
    let shape: Vec<usize> = shape_s
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| fmt("bad shape")))
        .collect::<Result<_, _>>()?;
    // Checked: a header may claim 2^62 elements (refused below by the data length, without allocating).
    let count = shape
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| {
            fmt(&format!(
                "shape {shape:?} has more elements than memory can hold"
            ))
        })?;
    let body = &bytes[start + header_len..];
    let (size, conv) = converter(&descr).ok_or_else(|| NpyError::Dtype {
        path: PathBuf::new(),
        descr: descr.clone(),
    })?;
    let needed = count.checked_mul(size);
    if needed != Some(body.len()) {
        let hint = match needed {
            Some(n) if n > body.len() => "truncated file?",
            Some(_) => "more data than the shape holds: a wrong shape in the header?",
            None => "a wrong shape in the header?",
        };
        return Err(fmt(&format!(
            "data holds {} bytes, shape {:?} of {descr} needs {} ({hint})",
            body.len(),
            shape,
            needed.map_or_else(
                || "more than memory can hold".to_string(),
                |n| n.to_string()
            )
        )));
    }
    let data: Vec<f32> = body.chunks_exact(size).map(conv).collect();
    let data = if fortran && shape.len() > 1 {
        fortran_to_c(&shape, &data)
    } else {
        data
    };
    Ok(NpyArray { shape, data, descr })
}

/// Reads one element from its bytes.
type ElementToF32 = fn(&[u8]) -> f32;

/// Whether a dtype holds floating-point values (metres may be stored in any of them).
fn is_float(descr: &str) -> bool {
    matches!(descr.get(1..), Some("f2" | "f4" | "f8"))
}

/// Element size and conversion to `f32` of a numpy dtype string (`<f4`, `>i8`, `|b1`, …); `None` if not numeric.
fn converter(descr: &str) -> Option<(usize, ElementToF32)> {
    fn arr<const N: usize>(b: &[u8], big: bool) -> [u8; N] {
        let mut a = [0u8; N];
        a.copy_from_slice(&b[..N]);
        if big {
            a.reverse();
        }
        a
    }
    // `get`, not slicing: a malformed header may start the dtype with a multi-byte character.
    let (order, kind) = (descr.get(..1)?, descr.get(1..)?);
    let big = match order {
        "<" | "|" | "=" => false,
        ">" => true,
        _ => return None,
    };
    Some(match (kind, big) {
        ("b1", _) => (1, |b| f32::from(u8::from(b[0] != 0))),
        ("u1", _) => (1, |b| f32::from(b[0])),
        ("i1", _) => (1, |b| f32::from(b[0] as i8)),
        ("f2", false) => (2, |b| f16_to_f32(u16::from_le_bytes(arr(b, false)))),
        ("f2", true) => (2, |b| f16_to_f32(u16::from_le_bytes(arr(b, true)))),
        ("u2", false) => (2, |b| f32::from(u16::from_le_bytes(arr(b, false)))),
        ("u2", true) => (2, |b| f32::from(u16::from_le_bytes(arr(b, true)))),
        ("i2", false) => (2, |b| f32::from(i16::from_le_bytes(arr(b, false)))),
        ("i2", true) => (2, |b| f32::from(i16::from_le_bytes(arr(b, true)))),
        ("f4", false) => (4, |b| f32::from_le_bytes(arr(b, false))),
        ("f4", true) => (4, |b| f32::from_le_bytes(arr(b, true))),
        ("u4", false) => (4, |b| u32::from_le_bytes(arr(b, false)) as f32),
        ("u4", true) => (4, |b| u32::from_le_bytes(arr(b, true)) as f32),
        ("i4", false) => (4, |b| i32::from_le_bytes(arr(b, false)) as f32),
        ("i4", true) => (4, |b| i32::from_le_bytes(arr(b, true)) as f32),
        ("f8", false) => (8, |b| f64::from_le_bytes(arr(b, false)) as f32),
        ("f8", true) => (8, |b| f64::from_le_bytes(arr(b, true)) as f32),
        ("u8", false) => (8, |b| u64::from_le_bytes(arr(b, false)) as f32),
        ("u8", true) => (8, |b| u64::from_le_bytes(arr(b, true)) as f32),
        ("i8", false) => (8, |b| i64::from_le_bytes(arr(b, false)) as f32),
        ("i8", true) => (8, |b| i64::from_le_bytes(arr(b, true)) as f32),
        _ => return None,
    })
}

/// IEEE 754 half precision to single (exact: every half is a single).
fn f16_to_f32(h: u16) -> f32 {
    let sign = u32::from(h >> 15) << 31;
    let exp = u32::from((h >> 10) & 0x1f);
    let frac = u32::from(h & 0x3ff);
    let bits = match (exp, frac) {
        (0, 0) => sign,
        (0, f) => {
            // Subnormal: f · 2^-24.
            let v = f as f32 * f32::from_bits(0x3380_0000);
            return if sign != 0 { -v } else { v };
        }
        (0x1f, 0) => sign | 0x7f80_0000,
        (0x1f, f) => sign | 0x7fc0_0000 | (f << 13),
        (e, f) => sign | ((e + 127 - 15) << 23) | (f << 13),
    };
    f32::from_bits(bits)
}

/// Reorder a Fortran-order (first index fastest) array of `shape` to C order (last index fastest).
fn fortran_to_c(shape: &[usize], data: &[f32]) -> Vec<f32> {
    let mut f_stride = vec![1usize; shape.len()];
    for k in 1..shape.len() {
        f_stride[k] = f_stride[k - 1] * shape[k - 1];
    }
    let mut index = vec![0usize; shape.len()];
    let mut out = Vec::with_capacity(data.len());
    for _ in 0..data.len() {
        let src: usize = index.iter().zip(&f_stride).map(|(i, s)| i * s).sum();
        out.push(data[src]);
        for k in (0..shape.len()).rev() {
            index[k] += 1;
            if index[k] < shape[k] {
                break;
            }
            index[k] = 0;
        }
    }
    out
}

/// The text after `'key':` in a numpy header dict, up to the next top-level comma.
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let pat_single = format!("'{key}':");
    let pat_double = format!("\"{key}\":");
    let pos = header
        .find(&pat_single)
        .map(|p| p + pat_single.len())
        .or_else(|| header.find(&pat_double).map(|p| p + pat_double.len()))?;
    let rest = header[pos..].trim_start();
    let mut depth = 0i32;
    for (i, c) in rest.char_indices() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            ',' | '}' if depth == 0 => return Some(rest[..i].trim()),
            _ => {}
        }
    }
    Some(rest.trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_alignment() {
        let bytes = encode_f32(&[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, -6.5]);
        let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0);
        let a = decode(&bytes).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, -6.5]);
    }

    #[test]
    fn reads_numpy_written_float64_and_uint16() {
        // Headers exactly as numpy 1.26 writes them (np.save of np.arange(3, dtype=...)).
        let mut f8 =
            b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_order': False, 'shape': (3,), }"
                .to_vec();
        f8.resize(10 + 0x76 - 1, b' ');
        f8.push(b'\n');
        for x in [0.0f64, 1.0, 2.0] {
            f8.extend_from_slice(&x.to_le_bytes());
        }
        assert_eq!(decode(&f8).unwrap().data, vec![0.0, 1.0, 2.0]);
        let mut u2 =
            b"\x93NUMPY\x01\x00v\x00{'descr': '<u2', 'fortran_order': False, 'shape': (1, 2), }"
                .to_vec();
        u2.resize(10 + 0x76 - 1, b' ');
        u2.push(b'\n');
        for x in [7u16, 65535] {
            u2.extend_from_slice(&x.to_le_bytes());
        }
        let a = decode(&u2).unwrap();
        assert_eq!((a.shape, a.data), (vec![1, 2], vec![7.0, 65535.0]));
    }

    fn with_header(descr: &str, header_shape: &str, fortran: bool, body: &[u8]) -> Vec<u8> {
        let dict = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {header_shape}, }}",
            if fortran { "True" } else { "False" }
        );
        let mut h = dict.into_bytes();
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(b' ');
        }
        h.push(b'\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(h.len() as u16).to_le_bytes());
        out.extend_from_slice(&h);
        out.extend_from_slice(body);
        out
    }

    #[test]
    fn reads_what_numpy_writes_every_day() {
        // np.asfortranarray([[1, 2, 3], [4, 5, 6]], '<f4'): memory holds the columns, 1 4 2 5 3 6.
        let body: Vec<u8> = [1.0f32, 4.0, 2.0, 5.0, 3.0, 6.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let a = decode(&with_header("<f4", "(2, 3)", true, &body)).unwrap();
        assert_eq!(a.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        // A 3-D Fortran array (2, 2, 2): element [i, j, k] sits at i + 2j + 4k.
        let body: Vec<u8> = (0..8u8).collect();
        let a = decode(&with_header("|u1", "(2, 2, 2)", true, &body)).unwrap();
        assert_eq!(a.data, vec![0.0, 4.0, 2.0, 6.0, 1.0, 5.0, 3.0, 7.0]);
        // float16 bit patterns (IEEE 754): 1, -2, 65504 (largest), 2^-24 (smallest subnormal), 1/3 rounded, -0.
        let halves = [0x3c00u16, 0xc000, 0x7bff, 0x0001, 0x3555, 0x8000];
        let body: Vec<u8> = halves.iter().flat_map(|h| h.to_le_bytes()).collect();
        let a = decode(&with_header("<f2", "(6,)", false, &body)).unwrap();
        let want = [1.0f32, -2.0, 65504.0, 2f32.powi(-24), 0.333_251_95, -0.0];
        assert_eq!(a.data, want);
        assert!(a.data[5].is_sign_negative());
        let inf = decode(&with_header("<f2", "(1,)", false, &0x7c00u16.to_le_bytes())).unwrap();
        assert_eq!(inf.data, vec![f32::INFINITY]);
        // bool, int64 and big-endian float64.
        let a = decode(&with_header("|b1", "(3,)", false, &[0, 1, 0])).unwrap();
        assert_eq!(a.data, vec![0.0, 1.0, 0.0]);
        let body: Vec<u8> = [-3i64, 1 << 40]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let a = decode(&with_header("<i8", "(2,)", false, &body)).unwrap();
        assert_eq!(a.data, vec![-3.0, (1u64 << 40) as f32]);
        let a = decode(&with_header(">f8", "(1,)", false, &0.25f64.to_be_bytes())).unwrap();
        assert_eq!(a.data, vec![0.25]);
        // Complex and strings are refused by name.
        let err = decode(&with_header("<c8", "(1,)", false, &[0; 8])).unwrap_err();
        assert!(err.to_string().contains("'<c8'"), "{err}");
        assert!(decode(&with_header("<U4", "(1,)", false, &[0; 16])).is_err());
    }

    #[test]
    fn metre_images_take_any_float_width() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("imprint.npy");
        // 0.01 m in float16 is 0x211F (0.010002136…, numpy).
        std::fs::write(
            &p,
            with_header("<f2", "(1, 1)", false, &0x211fu16.to_le_bytes()),
        )
        .unwrap();
        let img = read_metres_image(&p).unwrap();
        assert!((img.data[0] - 0.01).abs() < 1e-5, "{:?}", img.data);
    }

    #[test]
    fn truncated_and_bad_dtype_are_errors() {
        let bytes = encode_f32(&[4, 4], &[0.0; 16]);
        let err = decode(&bytes[..bytes.len() - 3]).unwrap_err();
        assert!(err.to_string().contains("truncated"), "{err}");
        let mut bad = bytes.clone();
        let at = bad.windows(3).position(|w| w == b"<f4").unwrap();
        bad[at..at + 3].copy_from_slice(b"<c8");
        assert!(matches!(decode(&bad), Err(NpyError::Dtype { .. })));
        assert!(decode(b"hello").is_err());
    }

    #[test]
    fn read_image_reads_nan_as_missing_and_names_bad_shapes() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("depth.npy");
        // NaN and ±inf: a pixel without a return, 0 (missing), not a refused file.
        std::fs::write(
            &p,
            encode_f32(&[1, 3], &[0.08, f32::NAN, f32::NEG_INFINITY]),
        )
        .unwrap();
        assert_eq!(read_image(&p).unwrap().data, vec![0.08, 0.0, 0.0]);
        assert_eq!(read_metres_image(&p).unwrap().data, vec![0.08, 0.0, 0.0]);
        std::fs::write(&p, encode_f32(&[2, 2, 2], &[0.0; 8])).unwrap();
        assert!(matches!(read_image(&p), Err(NpyError::Shape { .. })));
    }

    #[test]
    fn metre_images_refuse_integers_and_millimetres() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("imprint.npy");
        let mut u2 = header("<u2", &[1, 2]);
        for x in [7u16, 1200] {
            u2.extend_from_slice(&x.to_le_bytes());
        }
        std::fs::write(&p, &u2).unwrap();
        let err = read_metres_image(&p).unwrap_err().to_string();
        assert!(
            err.contains("imprint.npy") && err.contains("integer") && err.contains("/ 1000"),
            "{err}"
        );
        // The same values as float millimetres.
        std::fs::write(&p, encode_f32(&[1, 2], &[7.0, 12.0])).unwrap();
        let err = read_metres_image(&p).unwrap_err().to_string();
        assert!(err.contains("millimetres"), "{err}");
        // Values no unit makes depths are said to be none (not "around 1000000000000000000000000000000 m").
        std::fs::write(&p, encode_f32(&[1, 2], &[1e30, 1e30])).unwrap();
        let err = read_metres_image(&p).unwrap_err().to_string();
        assert!(
            err.contains("1e30") && err.contains("no depth camera"),
            "{err}"
        );
        // Metres are read as they are.
        std::fs::write(&p, encode_f32(&[1, 2], &[0.007, -0.012])).unwrap();
        assert_eq!(read_metres_image(&p).unwrap().data, vec![0.007, -0.012]);
        // The generic reader still converts integers (for imports that apply their own scale).
        std::fs::write(&p, &u2).unwrap();
        assert_eq!(read_image(&p).unwrap().data, vec![7.0, 1200.0]);
    }
}
