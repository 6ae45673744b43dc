//! **Reading input files safely**: only regular files (a FIFO would block forever, `/dev/zero` never ends) and only
//! up to a size cap per kind of file, so that a wrong path gives one line instead of a hang or an exhausted memory.

use std::io::Read;
use std::path::Path;

/// Largest mesh file read, bytes (a 20-million-triangle binary STL is 1 GB).
pub const MAX_MESH_BYTES: u64 = 1 << 30;
/// Largest settings file read (sensor, posterior calibration), bytes.
pub const MAX_SETTINGS_BYTES: u64 = 16 << 20;
/// Largest records file read (`tnd eval --records`, `--json` outputs), bytes: ~100 000 pairs.
pub const MAX_RECORDS_BYTES: u64 = 1 << 30;
/// Largest array file read (.npy), bytes: a 4096 x 4096 float64 image is 128 MiB.
pub const MAX_ARRAY_BYTES: u64 = 1 << 30;

/// Read `path` whole if it is a regular file (links followed) of at most `max` bytes; otherwise an error saying
/// what it is (its kind, or its size against the cap). The message does not repeat the path: callers name it.
pub fn read_capped(path: &Path, max: u64) -> std::io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| explained(path, e))?;
    if let Some(kind) = super::output::file_kind(&meta) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{kind}, not a file"),
        ));
    }
    if meta.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "a folder, not a file",
        ));
    }
    if meta.len() > max {
        return Err(too_big(meta.len(), max));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    // The file may grow while it is read: never past the cap.
    std::fs::File::open(path)?
        .take(max + 1)
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max {
        return Err(too_big(bytes.len() as u64, max));
    }
    Ok(bytes)
}

/// [`read_capped`] as UTF-8 text.
pub fn read_text_capped(path: &Path, max: u64) -> std::io::Result<String> {
    String::from_utf8(read_capped(path, max)?)
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidData, "not UTF-8 text"))
}

/// `e`, an error opening `path`, said better where it can be: a link to nowhere is named as such, not "No such
/// file" of a name that is there.
pub fn explained(path: &Path, e: std::io::Error) -> std::io::Error {
    match std::fs::read_link(path) {
        Ok(target) if e.kind() == std::io::ErrorKind::NotFound => std::io::Error::new(
            e.kind(),
            format!(
                "a symbolic link to {}, which does not exist",
                target.display()
            ),
        ),
        _ => e,
    }
}

fn too_big(len: u64, max: u64) -> std::io::Error {
    let mb = |b: u64| b as f64 / (1u64 << 20) as f64;
    std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!(
            "{:.0} MiB, more than the {:.0} MiB such a file may be",
            mb(len),
            mb(max)
        ),
    )
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn special_files_and_oversized_files_are_refused_in_words() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("a.txt");
        std::fs::write(&f, "hello").unwrap();
        assert_eq!(read_capped(&f, 5).unwrap(), b"hello");
        let e = read_capped(&f, 4).unwrap_err().to_string();
        assert!(e.contains("more than"), "{e}");
        let e = read_capped(Path::new("/dev/zero"), 1 << 20)
            .unwrap_err()
            .to_string();
        assert!(e.contains("device"), "{e}");
        let e = read_capped(dir.path(), 1 << 20).unwrap_err().to_string();
        assert!(e.contains("folder"), "{e}");
        // A link to /dev/zero is the device it points to.
        let link = dir.path().join("mesh.obj");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        assert!(read_capped(&link, 1 << 20)
            .unwrap_err()
            .to_string()
            .contains("device"));
    }
}
