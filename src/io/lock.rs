//! One writer per output: an advisory lock on a run directory, dataset, records file, export folder or session.
//!
//! Every command that writes an output takes an [`OutputLock`] on it before touching it; a second writer is refused at
//! once with the output and the holder's pid named ("run: in use by another tnd run (pid 4242)"), instead of the two
//! interleaving or deleting each other's files. Readers of an output that may be half-written (an evaluation of a
//! dataset still being generated) ask [`check_not_written`].
//!
//! The lock is the operating system's advisory file lock (`flock` on Unix, `LockFileEx` on Windows, through
//! `std::fs::File::try_lock`) on a hidden sibling file `.<name>.tnd-lock`, so it works the same for files and for
//! folders that are replaced whole. The OS releases it when the process dies, so a killed run never leaves a lock that
//! traps the next one; the file itself is removed when the lock is dropped. Removing a lock file another process may
//! be opening is safe because [`OutputLock::acquire`] checks, after locking, that the path still names the file it
//! locked, and starts over if not.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use super::atomic::parent_and_name;

/// Why an output could not be locked.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another process holds the lock.
    #[error("{}: in use by another tnd run{}; wait for it to finish or choose another output", .output.display(), holder(*.pid))]
    InUse {
        /// The output named by the user.
        output: PathBuf,
        /// The holder's process id, when it wrote one.
        pid: Option<u32>,
    },
    /// A reader found the output being written by another process.
    #[error("{}: being written by another tnd run{}; wait for it to finish", .output.display(), holder(*.pid))]
    BeingWritten {
        /// The output the reader asked for.
        output: PathBuf,
        /// The writer's process id, when it wrote one.
        pid: Option<u32>,
    },
    /// The lock file could not be created or locked.
    #[error("{}: cannot write there (lock file {}): {source}", .output.display(), .lock.display())]
    Io {
        /// The output named by the user.
        output: PathBuf,
        /// The lock file.
        lock: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
}

fn holder(pid: Option<u32>) -> String {
    pid.map(|p| format!(" (pid {p})")).unwrap_or_default()
}

/// An exclusive lock on one output, held until dropped.
#[derive(Debug)]
pub struct OutputLock {
    file: Option<File>,
    lock_path: PathBuf,
}

/// The hidden sibling file that carries `output`'s lock.
pub fn lock_path(output: &Path) -> PathBuf {
    let (parent, name) = parent_and_name(output);
    parent.join(format!(".{name}.tnd-lock"))
}

impl OutputLock {
    /// Lock `output` (a file or a folder, existing or not) for writing, or say who holds it. The parent folder is
    /// created if needed.
    pub fn acquire(output: &Path) -> Result<Self, LockError> {
        // The lock is on the real file: two names of one output (a symbolic link) share it.
        let real = super::output::resolve(output).unwrap_or_else(|_| output.to_path_buf());
        let lock = lock_path(&real);
        let io = |source: std::io::Error| LockError::Io {
            output: output.to_path_buf(),
            lock: lock.clone(),
            source,
        };
        if let Some(parent) = lock.parent() {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        loop {
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&lock)
                .map_err(io)?;
            match file.try_lock() {
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => {
                    return Err(LockError::InUse {
                        output: output.to_path_buf(),
                        pid: read_pid(&mut file),
                    })
                }
                Err(TryLockError::Error(e)) => return Err(io(e)),
            }
            // The holder we waited on may have removed the file before unlocking: then we locked an unlinked file
            // and must start over on the path's new one.
            if !same_file(&file, &lock) {
                continue;
            }
            remove_leftovers(&real);
            file.set_len(0).map_err(io)?;
            file.rewind().map_err(io)?;
            write!(file, "{}", std::process::id()).map_err(io)?;
            file.flush().map_err(io)?;
            return Ok(Self {
                file: Some(file),
                lock_path: lock,
            });
        }
    }
}

impl Drop for OutputLock {
    fn drop(&mut self) {
        // Remove while still holding the lock (see `acquire`), then release by closing.
        let _ = std::fs::remove_file(&self.lock_path);
        drop(self.file.take());
    }
}

/// Refuse to read `output` while another tnd run writes it ("being written by another tnd run (pid N)"); Ok when no
/// one holds its lock.
pub fn check_not_written(output: &Path) -> Result<(), LockError> {
    let real = super::output::resolve(output).unwrap_or_else(|_| output.to_path_buf());
    let lock = lock_path(&real);
    let Ok(mut file) = File::open(&lock) else {
        return Ok(());
    };
    match file.try_lock_shared() {
        Ok(()) => Ok(()),
        Err(TryLockError::WouldBlock) => Err(LockError::BeingWritten {
            output: output.to_path_buf(),
            pid: read_pid(&mut file),
        }),
        // A file system without locks: reading is allowed, as before.
        Err(TryLockError::Error(_)) => Ok(()),
    }
}

/// A writer's sibling name `.<name>.<kind>.<pid>` ([`super::atomic::sibling`]), or `.<name>.tmp.<pid>_<n>` (a
/// file's atomic write), left by a process that no longer runs: `(name, kind)`, kind `tmp` or `old`.
fn dead_sibling(file_name: &std::ffi::OsStr) -> Option<(&str, &str)> {
    let rest = file_name.to_str()?.strip_prefix('.')?;
    let (rest, pid) = rest.rsplit_once('.')?;
    let (name, kind) = rest.rsplit_once('.')?;
    let pid = match pid.split_once('_') {
        Some((pid, n)) if kind == "tmp" && n.parse::<u64>().is_ok() => pid,
        Some(_) => return None,
        None => pid,
    };
    let pid: u32 = pid.parse().ok()?;
    (matches!(kind, "tmp" | "old") && pid != std::process::id() && !alive(pid))
        .then_some((name, kind))
}

/// Temporary files and folders of killed runs on `output`, which we now hold: `.<name>.tmp.<pid>[_<n>]` beside it
/// (a folder replacement or an atomic write under way), the same inside it and one level below (its files' atomic
/// writes), and an old folder parked by an interrupted replacement, which is put back when the new one never
/// arrived. Best effort: what cannot be removed stays as it was.
fn remove_leftovers(output: &Path) {
    let (parent, name) = parent_and_name(output);
    if let Ok(entries) = std::fs::read_dir(&parent) {
        for entry in entries.flatten() {
            let file_name = entry.file_name();
            let Some((of, kind)) = dead_sibling(&file_name) else {
                continue;
            };
            if of != name {
                continue;
            }
            let path = entry.path();
            if kind == "old" && !output.exists() {
                let _ = std::fs::rename(&path, output);
            } else {
                remove_any(&path);
            }
        }
    }
    remove_temp_files_in(output, 2);
}

fn remove_temp_files_in(dir: &Path, depth: usize) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let is_dir = entry.file_type().map(|t| t.is_dir()).unwrap_or(false);
        if dead_sibling(&entry.file_name()).is_some_and(|(_, kind)| kind == "tmp") {
            remove_any(&entry.path());
        } else if is_dir && depth > 1 {
            remove_temp_files_in(&entry.path(), depth - 1);
        }
    }
}

fn remove_any(path: &Path) {
    if path.is_dir() {
        let _ = std::fs::remove_dir_all(path);
    } else {
        let _ = std::fs::remove_file(path);
    }
}

#[cfg(unix)]
fn alive(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: signal 0 only checks whether the process exists; nothing is sent.
    let rc = unsafe { libc::kill(pid, 0) };
    rc == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

#[cfg(not(unix))]
fn alive(_pid: u32) -> bool {
    // No cheap check: leave other processes' temporary files alone.
    true
}

fn read_pid(file: &mut File) -> Option<u32> {
    let mut text = String::new();
    file.rewind().ok()?;
    file.read_to_string(&mut text).ok()?;
    text.trim().parse().ok()
}

#[cfg(unix)]
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_file: &File, path: &Path) -> bool {
    // Windows refuses to delete an open file, so the path cannot have moved on under the lock.
    path.exists()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn a_dead_writers_numbered_temporary_file_is_recognised() {
        // A pid above Linux's largest (2^22) runs no process; this process's own are alive.
        let name = |s: &str| std::ffi::OsString::from(s);
        assert_eq!(
            dead_sibling(&name(".ledger.json.tmp.999999999_3")),
            Some(("ledger.json", "tmp"))
        );
        assert_eq!(
            dead_sibling(&name(".ledger.json.tmp.999999999")),
            Some(("ledger.json", "tmp"))
        );
        let own = format!(".ledger.json.tmp.{}_3", std::process::id());
        assert_eq!(dead_sibling(&name(&own)), None);
        // Only a temporary file is numbered; a user's file that looks like one otherwise is not touched.
        assert_eq!(dead_sibling(&name(".run.old.999999999_3")), None);
        assert_eq!(dead_sibling(&name(".ledger.json.tmp.999999999_x")), None);
    }

    #[test]
    fn a_second_writer_is_refused_with_the_holders_pid_until_the_first_drops() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("run");
        let first = OutputLock::acquire(&out).unwrap();
        // A second open file description conflicts with the first even inside one process (flock semantics).
        let e = OutputLock::acquire(&out).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("in use by another tnd run"), "{text}");
        assert!(
            text.contains(&format!("pid {}", std::process::id())),
            "{text}"
        );
        assert!(text.starts_with(&out.display().to_string()), "{text}");
        assert!(check_not_written(&out).is_err());
        drop(first);
        assert!(!lock_path(&out).exists(), "lock file left behind");
        assert!(check_not_written(&out).is_ok());
        let again = OutputLock::acquire(&out).unwrap();
        drop(again);
    }

    #[test]
    fn a_stale_lock_file_without_a_holder_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("records.jsonl");
        // A killed run's lock file: the OS released its lock, the file stayed.
        std::fs::write(lock_path(&out), "999999").unwrap();
        let lock = OutputLock::acquire(&out).unwrap();
        assert_eq!(
            std::fs::read_to_string(lock_path(&out)).unwrap(),
            std::process::id().to_string()
        );
        drop(lock);
    }

    #[test]
    fn leftovers_of_killed_runs_are_removed_and_a_parked_old_folder_is_put_back() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run");
        std::fs::create_dir_all(run.join("sub")).unwrap();
        // pid 4000000 is above Linux's pid_max: no such process.
        let dead = 4_000_000u32;
        let mine = std::process::id();
        for f in [
            format!("run/.model.safetensors.tmp.{dead}"),
            format!("run/sub/.state.tmp.{dead}"),
            format!(".run.tmp.{dead}"),
            format!("run/.log.tmp.{mine}"),
            "run/model.safetensors".to_string(),
        ] {
            std::fs::write(dir.path().join(&f), "x").unwrap();
        }
        drop(OutputLock::acquire(&run).unwrap());
        let exists = |f: &str| dir.path().join(f).exists();
        assert!(!exists(&format!("run/.model.safetensors.tmp.{dead}")));
        assert!(!exists(&format!("run/sub/.state.tmp.{dead}")));
        assert!(!exists(&format!(".run.tmp.{dead}")));
        assert!(
            exists(&format!("run/.log.tmp.{mine}")),
            "a live process's file"
        );
        assert!(exists("run/model.safetensors"));
        // A replacement killed between its two renames: the old folder comes back.
        let model = dir.path().join("model");
        let parked = dir.path().join(format!(".model.old.{dead}"));
        std::fs::create_dir(&parked).unwrap();
        std::fs::write(parked.join("config.json"), "old").unwrap();
        drop(OutputLock::acquire(&model).unwrap());
        assert_eq!(
            std::fs::read_to_string(model.join("config.json")).unwrap(),
            "old"
        );
        assert!(!parked.exists());
    }
}
