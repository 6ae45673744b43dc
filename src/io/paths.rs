//! Paths of outputs and inputs as the file system sees them: the real path of a name (links resolved, also for a
//! path not yet made), `..` taken as creating the path would, the folders no command may take as its output, and
//! special files (FIFOs, devices) in words.

use std::path::{Path, PathBuf};

/// `path` made absolute with `.` and `..` taken lexically (as creating it would).
pub(crate) fn lexical_absolute(path: &Path) -> std::io::Result<PathBuf> {
    let mut out = PathBuf::new();
    for part in std::path::absolute(path)?.components() {
        match part {
            std::path::Component::ParentDir => {
                out.pop();
            }
            std::path::Component::CurDir => {}
            other => out.push(other),
        }
    }
    Ok(out)
}

/// `/`, the home folder, or the current folder or one above it, which no command may take as its output folder.
pub(crate) fn reserved_folder(path: &Path) -> Option<&'static str> {
    if path.parent().is_none() {
        return Some("the file system's root");
    }
    let home = std::env::var_os("HOME").and_then(|h| resolve(Path::new(&h)).ok());
    if home.as_deref() == Some(path) {
        return Some("your home folder");
    }
    let cwd = std::env::current_dir().ok().and_then(|d| resolve(&d).ok());
    if cwd.is_some_and(|cwd| cwd.starts_with(path)) {
        return Some("the current folder or one above it");
    }
    None
}

/// A FIFO, socket or device: what it is, in words; `None` for files, folders and links.
pub fn file_kind(meta: &std::fs::Metadata) -> Option<&'static str> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_socket() {
            return Some("a socket");
        }
        if t.is_block_device() || t.is_char_device() {
            return Some("a device");
        }
    }
    let _ = meta;
    None
}

/// The real path of `path`: absolute, symbolic links resolved, also for a path that does not exist yet (its
/// nearest existing ancestor is resolved). A link to nowhere is an error naming its target.
pub fn resolve(path: &Path) -> std::io::Result<PathBuf> {
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        if meta.file_type().is_symlink() && !path.exists() {
            // A link to nowhere, named as such.
            return Err(super::input::explained(
                path,
                std::io::ErrorKind::NotFound.into(),
            ));
        }
        return std::fs::canonicalize(path);
    }
    // `new/..` is the folder it is in, as creating the path would make it (`absolute` keeps the `..`).
    let absolute = lexical_absolute(path)?;
    let mut rest = Vec::new();
    let mut base = absolute.as_path();
    loop {
        if base.exists() {
            let mut real = std::fs::canonicalize(base)?;
            for part in rest.iter().rev() {
                real.push(part);
            }
            return Ok(real);
        }
        match (base.parent(), base.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                base = parent;
            }
            _ => return Ok(absolute),
        }
    }
}
