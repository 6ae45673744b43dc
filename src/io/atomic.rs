//! Atomic file writes: data goes to a temporary file in the destination directory, is flushed to disk, then renamed
//! over the destination, so a reader (or a run killed half-way) never sees a half-written file.

use std::io::Write;
use std::path::{Path, PathBuf};

/// The folder `path` is in (`.` for a bare name) and its file name: where a writer's temporary siblings go.
pub(crate) fn parent_and_name(path: &Path) -> (PathBuf, String) {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    (parent, name)
}

/// `.<name>.<kind>.<pid>` beside `path`: a write under way (`tmp`) or an old folder parked during a replacement
/// (`old`). [`super::lock`] recognises these names to clean up after killed runs.
pub(crate) fn sibling(path: &Path, kind: &str, pid: u32) -> PathBuf {
    let (parent, name) = parent_and_name(path);
    parent.join(format!(".{name}.{kind}.{pid}"))
}

/// A temporary sibling of `path` no other write of this process uses: `.<name>.tmp.<pid>_<n>`. Two threads
/// writing one file (a folder's ledger, updated as each entry is written) must not share a temporary file: the
/// second's create would empty the first's just before it is renamed into place, and a run killed then would leave
/// an empty file.
fn unique_tmp(path: &Path) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let (parent, name) = parent_and_name(path);
    parent.join(format!(".{name}.tmp.{}_{n}", std::process::id()))
}

/// Write `bytes` to `path` atomically (temp file in the same directory + fsync + rename). Parent directories are
/// created. The error message names `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// Like [`write_atomic`], streaming the content through `fill`.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let real = super::output::before_write(path)?;
    write_plain_with(path, fill)?;
    if let Some(real) = real {
        super::output::after_write(&real);
    }
    Ok(())
}

/// [`write_atomic`] without the output checks and records ([`super::output`]): for the ledger and records themselves.
pub(crate) fn write_plain(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_plain_with(path, |f| f.write_all(bytes))
}

fn write_plain_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let named =
        |e: std::io::Error| std::io::Error::new(e.kind(), format!("{}: {e}", path.display()));
    let (dir, _) = parent_and_name(path);
    std::fs::create_dir_all(&dir).map_err(|e| match dir.ancestors().find(|a| a.is_file()) {
        // `--out results.txt` where results.txt is a file: say so, not "File exists".
        Some(file) => std::io::Error::new(
            e.kind(),
            format!(
                "{} is a file, not a directory; give another output directory",
                file.display()
            ),
        ),
        None => named(e),
    })?;
    let tmp = unique_tmp(path);
    let result = (|| {
        let file = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(file);
        fill(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(named)
}

/// Replace the folder `dir` as a whole: `fill` writes the new content into a sibling temporary folder, which is
/// synced and then swapped in for `dir` in one rename, so that a run killed or a disk filled at any point leaves
/// either the old folder complete or the new one complete, never a mix. Files of the old folder that `fill` did not
/// write (a user's notes) are copied across first. Without an old folder the new one appears by the rename alone.
/// A temporary folder of a killed run is removed by the next run's output lock ([`super::lock::OutputLock`]).
pub fn replace_dir_atomic<T>(
    dir: &Path,
    fill: impl FnOnce(&Path) -> std::io::Result<T>,
) -> std::io::Result<T> {
    let named =
        |e: std::io::Error| std::io::Error::new(e.kind(), format!("{}: {e}", dir.display()));
    if dir.file_name().is_none() {
        return Err(named(std::io::Error::other("not a folder name")));
    }
    if let Some(kept) = super::output::protected_by(dir) {
        return Err(super::output::protected_error(&kept));
    }
    let (parent, _) = parent_and_name(dir);
    std::fs::create_dir_all(&parent).map_err(named)?;
    let tmp = sibling(dir, "tmp", std::process::id());
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(named)?;
    }
    let result = (|| {
        std::fs::create_dir(&tmp)?;
        let value = fill(&tmp)?;
        for entry in std::fs::read_dir(&tmp)? {
            if let Some(kept) = super::output::protected_by(&dir.join(entry?.file_name())) {
                return Err(super::output::protected_error(&kept));
            }
        }
        if dir.is_dir() {
            link_missing(dir, &tmp)?;
        }
        sync_dir(&tmp)?;
        if dir.exists() {
            swap_in(&tmp, dir)?;
        } else {
            std::fs::rename(&tmp, dir)?;
        }
        sync_dir(&parent)?;
        Ok(value)
    })();
    if tmp.exists() {
        // The old folder after a swap, or the unfinished new one after an error.
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result.map_err(named)
}

/// Carry across what `from` holds and `to` does not (recursively), so a replacement keeps files it did not write:
/// as hard links (the same files, byte for byte, whatever they are: symbolic links stay links, a FIFO is not read),
/// or, on a file system without hard links, as copies of regular files and re-made symbolic links.
fn link_missing(from: &Path, to: &Path) -> std::io::Result<()> {
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let target = to.join(entry.file_name());
        if std::fs::symlink_metadata(&target).is_ok() {
            continue;
        }
        let source = entry.path();
        let kind = entry.file_type()?;
        if kind.is_dir() {
            std::fs::create_dir(&target)?;
            link_missing(&source, &target)?;
        } else if let Err(e) = std::fs::hard_link(&source, &target) {
            if kind.is_symlink() {
                #[cfg(unix)]
                std::os::unix::fs::symlink(std::fs::read_link(&source)?, &target)?;
                #[cfg(not(unix))]
                return Err(e);
            } else if kind.is_file() {
                std::fs::copy(&source, &target)?;
            } else {
                return Err(std::io::Error::new(
                    e.kind(),
                    format!(
                        "{}: cannot carry it into the new folder: {e}",
                        source.display()
                    ),
                ));
            }
        }
    }
    Ok(())
}

fn sync_dir(dir: &Path) -> std::io::Result<()> {
    // Directories cannot be opened for syncing on Windows; there the renames are what is atomic.
    #[cfg(unix)]
    std::fs::File::open(dir)?.sync_all()?;
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// Exchange `new` and `dir`: afterwards `dir` is the new folder and `new` holds the old one.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn swap_in(new: &Path, dir: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        std::ffi::CString::new(p.as_os_str().as_bytes())
            .map_err(|_| std::io::Error::other("a path with a NUL byte"))
    };
    let (a, b) = (c(new)?, c(dir)?);
    // SAFETY: both arguments are valid NUL-terminated paths that outlive the call.
    let rc = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if rc == 0 {
        return Ok(());
    }
    let e = std::io::Error::last_os_error();
    // File systems without the exchange (some network mounts): two renames.
    match e.raw_os_error() {
        Some(libc::EINVAL) | Some(libc::ENOSYS) => swap_by_two_renames(new, dir),
        _ => Err(e),
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn swap_in(new: &Path, dir: &Path) -> std::io::Result<()> {
    swap_by_two_renames(new, dir)
}

/// `dir` → a sibling, `new` → `dir`, the old one → `new`. Between the first two renames `dir` is absent and the old
/// folder is complete under `.<name>.old.<pid>`; the next run's output lock puts it back if the run dies there.
fn swap_by_two_renames(new: &Path, dir: &Path) -> std::io::Result<()> {
    let old = sibling(dir, "old", std::process::id());
    std::fs::rename(dir, &old)?;
    if let Err(e) = std::fs::rename(new, dir) {
        let _ = std::fs::rename(&old, dir);
        return Err(e);
    }
    std::fs::rename(&old, new)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_and_replaces_without_leftovers() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sub/a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(p.parent().unwrap()).unwrap().collect();
        assert_eq!(names.len(), 1, "temporary file left behind");
    }

    #[test]
    fn threads_writing_one_file_never_show_a_reader_a_partial_one() {
        // Invariant of an atomic write: whatever a reader finds is one writer's whole content, never an empty or
        // cut file — also when several threads of one process write the same file at once (a folder's ledger).
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ledger.json");
        write_atomic(&p, &[b'0'; 4096]).unwrap();
        let done = std::sync::atomic::AtomicBool::new(false);
        std::thread::scope(|scope| {
            let writers: Vec<_> = (0..4u8)
                .map(|t| {
                    let p = &p;
                    scope.spawn(move || {
                        for _ in 0..150 {
                            write_atomic(p, &[b'a' + t; 4096]).unwrap();
                        }
                    })
                })
                .collect();
            let reader = scope.spawn(|| {
                let mut reads = 0;
                while !done.load(std::sync::atomic::Ordering::Relaxed) {
                    let bytes = std::fs::read(&p).unwrap();
                    assert_eq!(bytes.len(), 4096, "a reader saw {} bytes", bytes.len());
                    assert!(bytes.iter().all(|&b| b == bytes[0]), "a mixed file");
                    reads += 1;
                }
                reads
            });
            for w in writers {
                w.join().unwrap();
            }
            done.store(true, std::sync::atomic::Ordering::Relaxed);
            assert!(reader.join().unwrap() > 0);
        });
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "temporary files left behind");
    }

    #[test]
    fn an_output_directory_that_is_a_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("results.txt");
        std::fs::write(&file, b"keep").unwrap();
        let e = write_atomic(&file.join("depth.npy"), b"x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("results.txt is a file, not a directory"), "{e}");
        assert_eq!(std::fs::read(&file).unwrap(), b"keep");
    }

    #[test]
    fn failed_fill_keeps_old_content() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        write_atomic(&p, b"old").unwrap();
        let err = write_atomic_with(&p, |_| Err(std::io::Error::other("boom"))).unwrap_err();
        assert!(err.to_string().contains("a.txt"));
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
    }

    #[test]
    fn a_folder_is_replaced_whole_keeping_foreign_files_and_kept_whole_on_failure() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("model");
        replace_dir_atomic(&dir, |d| {
            std::fs::write(d.join("config.json"), "old")?;
            std::fs::write(d.join("weights"), "old")
        })
        .unwrap();
        std::fs::write(dir.join("notes.txt"), "mine").unwrap();
        // A failure half-way (after one file of the new model): the old folder is untouched.
        let e = replace_dir_atomic(&dir, |d| {
            std::fs::write(d.join("config.json"), "new")?;
            Err::<(), _>(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(e.to_string().contains("disk full"), "{e}");
        assert_eq!(
            std::fs::read_to_string(dir.join("config.json")).unwrap(),
            "old"
        );
        assert_eq!(std::fs::read_to_string(dir.join("weights")).unwrap(), "old");
        replace_dir_atomic(&dir, |d| {
            std::fs::write(d.join("config.json"), "new")?;
            std::fs::write(d.join("weights"), "new")
        })
        .unwrap();
        for (file, text) in [
            ("config.json", "new"),
            ("weights", "new"),
            ("notes.txt", "mine"),
        ] {
            assert_eq!(
                std::fs::read_to_string(dir.join(file)).unwrap(),
                text,
                "{file}"
            );
        }
        let names: Vec<_> = std::fs::read_dir(root.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("model")], "leftovers");
    }

    #[test]
    fn the_two_rename_fallback_swaps_too() {
        let root = tempfile::tempdir().unwrap();
        let (new, dir) = (root.path().join("new"), root.path().join("dir"));
        std::fs::create_dir(&new).unwrap();
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(new.join("a"), "new").unwrap();
        std::fs::write(dir.join("a"), "old").unwrap();
        swap_by_two_renames(&new, &dir).unwrap();
        assert_eq!(std::fs::read_to_string(dir.join("a")).unwrap(), "new");
        assert_eq!(std::fs::read_to_string(new.join("a")).unwrap(), "old");
    }
}
