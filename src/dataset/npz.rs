//! The shard format: an **uncompressed `.npz`** (a zip archive of `.npy` members, what `numpy.savez` writes), so
//! `numpy.load("train-00000.npz")` opens it without our code. Members are stored (no compression) with a fixed
//! timestamp, so the same arrays always give the same bytes; because they are stored, the reader can seek straight
//! to one pair's image inside a member (random access without reading the shard).

use std::io::{Cursor, Read, Seek, SeekFrom, Write};
use std::path::Path;

use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipArchive, ZipWriter};

use super::DatasetError;

/// The numpy dtypes used in shards (little-endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// `<f4`: images in metres, masks.
    F32,
    /// `<f8`: poses and press depths.
    F64,
    /// `<u8`: seeds and pair indices.
    U64,
    /// `<i4`: object indices and pixel counts.
    I32,
}

impl Dtype {
    /// The numpy `descr` string.
    pub fn descr(self) -> &'static str {
        match self {
            Dtype::F32 => "<f4",
            Dtype::F64 => "<f8",
            Dtype::U64 => "<u8",
            Dtype::I32 => "<i4",
        }
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            Dtype::F32 | Dtype::I32 => 4,
            Dtype::F64 | Dtype::U64 => 8,
        }
    }
}

/// One array to store: name (without `.npy`), dtype, shape and little-endian bytes (C order).
pub struct ArrayData {
    pub name: &'static str,
    pub dtype: Dtype,
    pub shape: Vec<usize>,
    pub bytes: Vec<u8>,
}

impl ArrayData {
    pub fn f32(name: &'static str, shape: Vec<usize>, data: impl IntoIterator<Item = f32>) -> Self {
        Self::from_le(name, Dtype::F32, shape, data, f32::to_le_bytes)
    }
    pub fn f64(name: &'static str, shape: Vec<usize>, data: impl IntoIterator<Item = f64>) -> Self {
        Self::from_le(name, Dtype::F64, shape, data, f64::to_le_bytes)
    }
    pub fn u64(name: &'static str, shape: Vec<usize>, data: impl IntoIterator<Item = u64>) -> Self {
        Self::from_le(name, Dtype::U64, shape, data, u64::to_le_bytes)
    }
    pub fn i32(name: &'static str, shape: Vec<usize>, data: impl IntoIterator<Item = i32>) -> Self {
        Self::from_le(name, Dtype::I32, shape, data, i32::to_le_bytes)
    }

    fn from_le<T, const N: usize>(
        name: &'static str,
        dtype: Dtype,
        shape: Vec<usize>,
        data: impl IntoIterator<Item = T>,
        to_le: fn(T) -> [u8; N],
    ) -> Self {
        let mut bytes = Vec::with_capacity(shape.iter().product::<usize>() * N);
        for x in data {
            bytes.extend_from_slice(&to_le(x));
        }
        Self {
            name,
            dtype,
            shape,
            bytes,
        }
    }
}

/// Encode arrays as uncompressed `.npz` bytes (members `<name>.npy` in the given order, fixed 1980-01-01 timestamp).
pub fn encode(arrays: &[ArrayData]) -> Result<Vec<u8>, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("npz", || {
        let mut zip = ZipWriter::new(Cursor::new(Vec::new()));
        let options = SimpleFileOptions::default()
            .compression_method(CompressionMethod::Stored)
            .last_modified_time(DateTime::default())
            .unix_permissions(0o644)
            .large_file(false);
        for a in arrays {
            let count: usize = a.shape.iter().product();
            if count * a.dtype.size() != a.bytes.len() {
                return Err(format!(
                    "array '{}': {} bytes do not match shape {:?} of {}",
                    a.name,
                    a.bytes.len(),
                    a.shape,
                    a.dtype.descr()
                ));
            }
            zip.start_file(format!("{}.npy", a.name), options)
                .map_err(|e| e.to_string())?;
            zip.write_all(&crate::io::npy::header(a.dtype.descr(), &a.shape))
                .map_err(|e| e.to_string())?;
            zip.write_all(&a.bytes).map_err(|e| e.to_string())?;
        }
        Ok(zip.finish().map_err(|e| e.to_string())?.into_inner())
    })
}

/// Where one stored `.npy` member's data lies in the shard file.
#[derive(Clone, Debug, PartialEq)]
pub struct MemberInfo {
    /// numpy `descr`, e.g. `<f4`.
    pub descr: String,
    pub shape: Vec<usize>,
    /// Absolute file offset of the first data byte.
    pub data_offset: u64,
    /// Data length in bytes.
    pub data_len: u64,
}

/// The member table of a stored `.npz`: array name (without `.npy`) -> where its data is.
#[derive(Clone, Debug, Default)]
pub struct NpzIndex {
    pub members: Vec<(String, MemberInfo)>,
}

impl NpzIndex {
    /// Read the zip directory and every member's `.npy` header. Members must be stored (uncompressed) `.npy` files.
    pub fn read<R: Read + Seek>(reader: R, path: &Path) -> Result<Self, DatasetError> {
        let npz = |message: String| DatasetError::Npz {
            path: path.to_path_buf(),
            message,
        };
        let mut archive = ZipArchive::new(reader).map_err(|e| npz(format!("zip: {e}")))?;
        let mut raw = Vec::with_capacity(archive.len());
        for i in 0..archive.len() {
            let f = archive
                .by_index_raw(i)
                .map_err(|e| npz(format!("member {i}: {e}")))?;
            let name = f.name().map_err(|e| npz(e.to_string()))?.to_string();
            raw.push((name, f.compression(), f.data_start(), f.size()));
        }
        let mut r = archive.into_inner();
        let mut members = Vec::with_capacity(raw.len());
        for (name, compression, data_start, size) in raw {
            let Some(stem) = name.strip_suffix(".npy") else {
                continue;
            };
            if compression != CompressionMethod::Stored {
                return Err(npz(format!(
                    "member '{name}' is compressed ({compression}); shards must be stored uncompressed (numpy.savez, not savez_compressed)"
                )));
            }
            let data_start =
                data_start.ok_or_else(|| npz(format!("member '{name}': no data offset")))?;
            let (descr, shape, header_len) = read_npy_header(&mut r, data_start)
                .map_err(|m| npz(format!("member '{name}': {m}")))?;
            let data_len = size
                .checked_sub(header_len)
                .ok_or_else(|| npz(format!("member '{name}': shorter than its header")))?;
            members.push((
                stem.to_string(),
                MemberInfo {
                    descr,
                    shape,
                    data_offset: data_start + header_len,
                    data_len,
                },
            ));
        }
        Ok(Self { members })
    }

    /// The member called `name`.
    pub fn get(&self, name: &str) -> Option<&MemberInfo> {
        self.members.iter().find(|(n, _)| n == name).map(|(_, m)| m)
    }
}

/// Parse a `.npy` header at `offset`: `(descr, shape, header length in bytes)`.
fn read_npy_header<R: Read + Seek>(
    r: &mut R,
    offset: u64,
) -> Result<(String, Vec<usize>, u64), String> {
    let mut head = [0u8; 12];
    r.seek(SeekFrom::Start(offset)).map_err(|e| e.to_string())?;
    r.read_exact(&mut head).map_err(|e| e.to_string())?;
    if &head[..6] != b"\x93NUMPY" {
        return Err("missing \\x93NUMPY magic".into());
    }
    let (len, start) = match head[6] {
        1 => (u64::from(u16::from_le_bytes([head[8], head[9]])), 10u64),
        2 | 3 => (
            u64::from(u32::from_le_bytes([head[8], head[9], head[10], head[11]])),
            12,
        ),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    if len > 1 << 20 {
        return Err(format!("implausible header length {len}"));
    }
    let mut text = vec![0u8; len as usize];
    r.seek(SeekFrom::Start(offset + start))
        .map_err(|e| e.to_string())?;
    r.read_exact(&mut text).map_err(|e| e.to_string())?;
    let text = String::from_utf8(text).map_err(|_| "header is not text".to_string())?;
    let (descr, shape) = parse_header_dict(&text)?;
    Ok((descr, shape, start + len))
}

/// `(descr, shape)` from a numpy header dict; Fortran order is rejected.
pub fn parse_header_dict(text: &str) -> Result<(String, Vec<usize>), crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("npy header", || {
        let value = |key: &str| -> Option<&str> {
            let pos = text.find(&format!("'{key}':"))? + key.len() + 3;
            let rest = text[pos..].trim_start();
            let mut depth = 0i32;
            for (i, c) in rest.char_indices() {
                match c {
                    '(' => depth += 1,
                    ')' => depth -= 1,
                    ',' | '}' if depth == 0 => return Some(rest[..i].trim()),
                    _ => {}
                }
            }
            None
        };
        let descr = value("descr")
            .ok_or("header has no 'descr'")?
            .trim_matches(|c| c == '\'' || c == '"')
            .to_string();
        if value("fortran_order").is_some_and(|v| v.starts_with("True")) {
            return Err("Fortran-order arrays are not supported".into());
        }
        let shape = value("shape")
            .ok_or("header has no 'shape'")?
            .trim_matches(|c| c == '(' || c == ')')
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<usize>()
                    .map_err(|_| format!("bad shape entry '{s}'"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok((descr, shape))
    })
}

/// Read `len` bytes at `offset` of `path`'s open file.
pub fn read_at<R: Read + Seek>(r: &mut R, offset: u64, len: usize) -> std::io::Result<Vec<u8>> {
    let mut buf = vec![0u8; len];
    r.seek(SeekFrom::Start(offset))?;
    r.read_exact(&mut buf)?;
    Ok(buf)
}

/// Decode little-endian elements of a stored member, checking its dtype and shape against the expectation.
pub fn check_member(
    index: &NpzIndex,
    path: &Path,
    name: &str,
    dtype: Dtype,
    shape: &[usize],
) -> Result<MemberInfo, DatasetError> {
    let m = index.get(name).ok_or_else(|| DatasetError::Npz {
        path: path.to_path_buf(),
        message: format!("array '{name}' is missing"),
    })?;
    if m.descr != dtype.descr() {
        return Err(DatasetError::Dtype {
            path: path.to_path_buf(),
            array: name.to_string(),
            found: m.descr.clone(),
            expected: dtype.descr().to_string(),
        });
    }
    if m.shape != shape {
        return Err(DatasetError::Shape {
            path: path.to_path_buf(),
            array: name.to_string(),
            found: m.shape.clone(),
            expected: shape.to_vec(),
        });
    }
    let need = shape.iter().product::<usize>() as u64 * dtype.size() as u64;
    if m.data_len != need {
        return Err(DatasetError::Npz {
            path: path.to_path_buf(),
            message: format!(
                "array '{name}' holds {} bytes, shape {shape:?} needs {need}",
                m.data_len
            ),
        });
    }
    Ok(m.clone())
}

/// Little-endian bytes to values.
pub fn decode_f32(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}
pub fn decode_f64(bytes: &[u8]) -> Vec<f64> {
    bytes
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
        .collect()
}
pub fn decode_u64(bytes: &[u8]) -> Vec<u64> {
    bytes
        .chunks_exact(8)
        .map(|b| u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
        .collect()
}
pub fn decode_i32(bytes: &[u8]) -> Vec<i32> {
    bytes
        .chunks_exact(4)
        .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn encode_is_deterministic_and_indexable() {
        let arrays = || {
            vec![
                ArrayData::f32("a", vec![2, 3], (0..6).map(|i| i as f32 * 0.5)),
                ArrayData::u64("s", vec![2], [7, u64::MAX]),
            ]
        };
        let bytes = encode(&arrays()).unwrap();
        assert_eq!(bytes, encode(&arrays()).unwrap());
        let p = Path::new("mem.npz");
        let index = NpzIndex::read(Cursor::new(&bytes), p).unwrap();
        let a = check_member(&index, p, "a", Dtype::F32, &[2, 3]).unwrap();
        let start = a.data_offset as usize;
        let vals = decode_f32(&bytes[start..start + a.data_len as usize]);
        assert_eq!(vals, vec![0.0, 0.5, 1.0, 1.5, 2.0, 2.5]);
        let s = check_member(&index, p, "s", Dtype::U64, &[2]).unwrap();
        let start = s.data_offset as usize;
        assert_eq!(decode_u64(&bytes[start..start + 16]), vec![7, u64::MAX]);
        assert!(matches!(
            check_member(&index, p, "a", Dtype::F64, &[2, 3]),
            Err(DatasetError::Dtype { .. })
        ));
        assert!(matches!(
            check_member(&index, p, "a", Dtype::F32, &[3, 2]),
            Err(DatasetError::Shape { .. })
        ));
        assert!(NpzIndex::read(Cursor::new(&bytes[..bytes.len() - 10]), p).is_err());
    }

    #[test]
    fn header_parse() {
        let (d, s) =
            parse_header_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (3, 64, 64), }")
                .unwrap();
        assert_eq!((d.as_str(), s), ("<f4", vec![3, 64, 64]));
        let (_, s) =
            parse_header_dict("{'descr': '<u8', 'fortran_order': False, 'shape': (5,), }").unwrap();
        assert_eq!(s, vec![5]);
        assert!(
            parse_header_dict("{'descr': '<f4', 'fortran_order': True, 'shape': (5,), }").is_err()
        );
    }
}
