//! **Outputs a command owns**: before a command writes, it claims its output ([`claim`]), which resolves symbolic
//! links (the lock and every write go to the real file), refuses an output that is one of the command's inputs, a
//! special file, the file-system root, the home folder or the current folder, and refuses to write into what tnd did
//! not write unless told to (`--force`):
//!
//! - **A folder output** carries a ledger, `.tnd-output.json`, written when tnd first claims it: the entries the
//!   folder held *before* tnd wrote there (a user's files), and, when a run ends, the entries tnd wrote. A new or
//!   empty folder has none of the user's; a folder that holds other files and no ledger is refused without
//!   `--force`, naming what is there; with `--force` its files are recorded in the ledger. Entries that appear
//!   between runs are the user's too, also after a run was killed: each run records its entries in the ledger as
//!   it writes them (an empty folder it made counts as its own). The user's entries are **protected**:
//!   [`super::write_atomic`] and [`super::atomic::replace_dir_atomic`] refuse to replace them, for this run and
//!   every later one, and a folder replaced whole keeps them (hard links, not copies). So `--force` never deletes
//!   a user's file. A run that writes nothing (refused after its claim) takes the ledger back.
//! - **A file output** that exists is replaced only when the command recognises it as its own (a caller's test of
//!   its format, e.g. the MCAP header tnd writes) *and* it is as tnd left it (size and modification time recorded
//!   in `.tnd-files.json` beside it at each write: a sensor file the user edited is theirs), or with `--force`.
//!
//! The ledger is written before any other file, so a run killed at any point leaves a folder the next run (a resume)
//! recognises as tnd's. A write inside a claimed folder that a symbolic link would take out of it is refused. There is no guessing from file names: a folder a tnd older than the ledger wrote is, to this
//! one, a folder of someone else's.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

use serde::{Deserialize, Serialize};

use super::lock::{LockError, OutputLock};
pub use super::paths::{file_kind, resolve};
use super::paths::{lexical_absolute, reserved_folder};

/// The ledger file inside a folder output.
pub const LEDGER_FILE: &str = ".tnd-output.json";

/// Whether an output is one file or a folder of files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    File,
    Folder,
}

/// Why an output was refused.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error(transparent)]
    Lock(#[from] LockError),
    #[error("{}: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{flag} {}: {what}; choose another output", .path.display())]
    Refused {
        flag: String,
        path: PathBuf,
        what: String,
    },
    #[error("{flag} {}: holds {} that tnd did not write ({}); choose a new or empty folder, or --force to write beside them (they are kept)", .path.display(), plural(*.count, "entry", "entries"), .names)]
    Foreign {
        flag: String,
        path: PathBuf,
        count: usize,
        names: String,
    },
    #[error("{flag} {}: exists and was not written by this command; choose another name, or --force to replace it", .path.display())]
    ForeignFile { flag: String, path: PathBuf },
}

fn plural(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

/// What a command is about to write.
pub struct Claim<'a> {
    /// The flag that named the output, for messages (`--out`).
    pub flag: &'a str,
    pub path: &'a Path,
    pub kind: OutputKind,
    /// `--force`: write into a folder holding others' files (they are kept), or replace a file tnd did not write.
    pub force: bool,
    /// The files and folders the command reads: the output may be none of them, nor hold one.
    pub inputs: Vec<&'a Path>,
    /// For a file output that exists: whether it is this command's own output (replaced without `--force`).
    pub ours: Option<&'a dyn Fn(&Path) -> bool>,
}

impl<'a> Claim<'a> {
    /// A folder output named by `flag`.
    pub fn folder(flag: &'a str, path: &'a Path) -> Self {
        Self {
            flag,
            path,
            kind: OutputKind::Folder,
            force: false,
            inputs: Vec::new(),
            ours: None,
        }
    }

    /// A file output named by `flag`.
    pub fn file(flag: &'a str, path: &'a Path) -> Self {
        Self {
            kind: OutputKind::File,
            ..Self::folder(flag, path)
        }
    }

    pub fn force(mut self, force: bool) -> Self {
        self.force = force;
        self
    }

    /// Add inputs (paths that do not exist are ignored).
    pub fn inputs<P: AsRef<Path> + ?Sized + 'a>(
        mut self,
        inputs: impl IntoIterator<Item = &'a P>,
    ) -> Self {
        self.inputs.extend(inputs.into_iter().map(AsRef::as_ref));
        self
    }

    pub fn ours(mut self, test: &'a dyn Fn(&Path) -> bool) -> Self {
        self.ours = Some(test);
        self
    }
}

/// A claimed output: held (locked) until dropped; its user files stay protected until then.
#[derive(Debug)]
pub struct Claimed {
    path: PathBuf,
    protected: Vec<PathBuf>,
    kind: OutputKind,
    /// The claim made the folder: left without anything in it, it is removed again.
    created: bool,
    /// The claim wrote the folder's ledger: what the folder held then. A run that wrote nothing (refused after its
    /// claim) takes the ledger back, so that a refusal never marks a user's folder as tnd's.
    fresh_ledger: Option<BTreeSet<String>>,
    _lock: OutputLock,
}

impl Claimed {
    /// The output's real path (symbolic links resolved): write here.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for Claimed {
    fn drop(&mut self) {
        if self.kind == OutputKind::File {
            // Written by a writer of its own (a rerun stream): recorded as it ends.
            if self.path.exists() {
                after_write(&self.path);
            }
            let mut files = CLAIMED_FILES.lock().unwrap_or_else(PoisonError::into_inner);
            if let Some(i) = files.iter().position(|q| *q == self.path) {
                files.swap_remove(i);
            }
        }
        if self.kind == OutputKind::Folder {
            let state = {
                let mut folders = CLAIMED_FOLDERS
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner);
                folders
                    .iter()
                    .position(|f| f.real == self.path)
                    .map(|i| folders.swap_remove(i))
            };
            let foreign = state.map(|f| f.foreign).unwrap_or_default();
            let now = entries(&self.path).unwrap_or_default();
            if self.fresh_ledger.as_ref() == Some(&now) {
                // A run refused after its claim (a bad mesh, a missing model) leaves no ledger, and no folder it
                // made.
                let _ = std::fs::remove_file(self.path.join(LEDGER_FILE));
                if self.created {
                    let _ = std::fs::remove_dir(&self.path);
                }
            } else {
                // The run ended: what it left beside the user's entries is tnd's.
                let ledger = Ledger {
                    written_by: "tnd".into(),
                    written: now.difference(&foreign).cloned().collect(),
                    foreign,
                    running: false,
                };
                let _ = write_ledger(&self.path, &ledger);
            }
        }
        let mut set = PROTECTED.lock().unwrap_or_else(PoisonError::into_inner);
        for p in &self.protected {
            if let Some(i) = set.iter().position(|q| q == p) {
                set.swap_remove(i);
            }
        }
    }
}

/// Paths this process must not replace or delete (the user files of claimed folders).
static PROTECTED: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The output files this process holds claims on: each write of one is recorded beside it ([`after_write`]).
static CLAIMED_FILES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// A folder this process holds a claim on, as its writes see it.
struct FolderState {
    /// The name the command was given (absolute, `..` resolved; maybe through a link).
    given: PathBuf,
    /// Its real path.
    real: PathBuf,
    foreign: BTreeSet<String>,
    /// The entries tnd wrote there so far: recorded in the ledger as they appear, so that a run killed part-way
    /// leaves a ledger that tells its files from those a user adds before the resume.
    written: BTreeSet<String>,
}

static CLAIMED_FOLDERS: Mutex<Vec<FolderState>> = Mutex::new(Vec::new());

/// Before a write of `path` ([`super::write_atomic`], the training log's append): refused when it is a user's
/// protected file, or when it lies in a claimed folder by name but outside it in fact (a symbolic link inside the
/// folder to a user's folder elsewhere); otherwise its entry in a claimed folder is said to be tnd's, in the ledger,
/// before the write (a kill between the write and the record would leave a file the next run takes for the
/// user's). The real path, for [`after_write`]; `None` when this process holds no claim (nothing to check).
pub(crate) fn before_write(path: &Path) -> std::io::Result<Option<PathBuf>> {
    let no_claims = |m: &Mutex<Vec<_>>| m.lock().unwrap_or_else(PoisonError::into_inner).is_empty();
    if no_claims(&PROTECTED)
        && no_claims(&CLAIMED_FILES)
        && CLAIMED_FOLDERS
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .is_empty()
    {
        return Ok(None);
    }
    let lexical = lexical_absolute(path)?;
    let real = resolve(path).unwrap_or_else(|_| lexical.clone());
    if let Some(kept) = protected_at(&real) {
        return Err(protected_error(&kept));
    }
    for f in CLAIMED_FOLDERS
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .iter()
    {
        let inside_by_name = lexical.starts_with(&f.given) || lexical.starts_with(&f.real);
        if inside_by_name && !real.starts_with(&f.real) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::PermissionDenied,
                format!(
                    "{} leads out of the output folder {} through a symbolic link; tnd writes only inside it",
                    path.display(),
                    f.real.display()
                ),
            ));
        }
    }
    record_in_folder(&real);
    Ok(Some(real))
}

/// The hidden file, in a folder where tnd wrote single output files, that records each one's size and modification
/// time as tnd left it: a file that no longer matches was changed by someone else, and is theirs.
pub const WRITTEN_FILES: &str = ".tnd-files.json";

/// (size, modification time in ns) of a file.
fn stat_of(path: &Path) -> Option<(u64, u128)> {
    let meta = std::fs::metadata(path).ok()?;
    let modified = meta
        .modified()
        .ok()?
        .duration_since(std::time::UNIX_EPOCH)
        .ok()?;
    Some((meta.len(), modified.as_nanos()))
}

fn written_files(dir: &Path) -> std::collections::BTreeMap<String, (u64, u128)> {
    super::input::read_text_capped(&dir.join(WRITTEN_FILES), super::input::MAX_SETTINGS_BYTES)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default()
}

fn record_in_folder(real: &Path) {
    let mut updates = Vec::new();
    let mut folders = CLAIMED_FOLDERS
        .lock()
        .unwrap_or_else(PoisonError::into_inner);
    for f in folders.iter_mut() {
        let Ok(rest) = real.strip_prefix(&f.real) else {
            continue;
        };
        let Some(name) = rest.components().next() else {
            continue;
        };
        let name = name.as_os_str().to_string_lossy().into_owned();
        if name == LEDGER_FILE || f.foreign.contains(&name) || !f.written.insert(name) {
            continue;
        }
        let ledger = Ledger {
            written_by: "tnd".into(),
            foreign: f.foreign.clone(),
            written: f.written.clone(),
            running: true,
        };
        updates.push((f.real.clone(), ledger));
    }
    // Written under the lock: two threads each adding an entry must not write their ledgers in the other order
    // (the older one last would drop the newer entry, and a run killed then leaves a file the next run takes for
    // the user's).
    for (dir, ledger) in updates {
        let _ = write_ledger(&dir, &ledger);
    }
    drop(folders);
}

/// Whether `path` is as tnd last wrote it ([`WRITTEN_FILES`]).
fn written_as_recorded(path: &Path) -> bool {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
        return false;
    };
    let name = name.to_string_lossy().into_owned();
    written_files(dir)
        .get(&name)
        .is_some_and(|&r| stat_of(path) == Some(r))
}

/// After a write of `real` (the path [`before_write`] gave): when it is a claimed output file, record it as tnd left
/// it ([`WRITTEN_FILES`]); a failure to record only means the next run asks for `--force`.
pub(crate) fn after_write(real: &Path) {
    if !CLAIMED_FILES
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .iter()
        .any(|f| f == real)
    {
        return;
    }
    let (Some(dir), Some(name), Some(stat)) = (real.parent(), real.file_name(), stat_of(real))
    else {
        return;
    };
    let mut files = written_files(dir);
    files.insert(name.to_string_lossy().into_owned(), stat);
    if let Ok(text) = serde_json::to_string(&files) {
        let _ = super::atomic::write_plain(&dir.join(WRITTEN_FILES), text.as_bytes());
    }
}

/// The protected path `path` is, or lies under, if any ([`Claimed`]).
pub fn protected_by(path: &Path) -> Option<PathBuf> {
    if PROTECTED
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .is_empty()
    {
        return None;
    }
    protected_at(&resolve(path).unwrap_or_else(|_| path.to_path_buf()))
}

/// [`protected_by`] of a path already resolved.
fn protected_at(real: &Path) -> Option<PathBuf> {
    let set = PROTECTED.lock().unwrap_or_else(PoisonError::into_inner);
    set.iter().find(|p| real.starts_with(p)).cloned()
}

/// The error a writer gives for a protected path.
pub(crate) fn protected_error(path: &Path) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        format!(
            "{} was not written by tnd and is kept; move it away or choose another output",
            path.display()
        ),
    )
}

/// The folder's ledger ([module docs](self)).
#[derive(Debug, Default, Serialize, Deserialize)]
struct Ledger {
    /// Always "tnd".
    written_by: String,
    /// The user's entries: those the folder held before tnd first wrote there, and those added between runs.
    foreign: BTreeSet<String>,
    /// The entries tnd's runs had written when the last one ended.
    #[serde(default)]
    written: BTreeSet<String>,
    /// A run holds the folder: set when it is claimed, cleared when the run ends. Found set by the next claim, the
    /// run was killed, and the entries it left are tnd's (a resume goes on with them).
    #[serde(default)]
    running: bool,
}

/// Claim an output ([module docs](self)): check it, lock it, and for a folder write its ledger.
pub fn claim(c: Claim<'_>) -> Result<Claimed, OutputError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| OutputError::Io { path, source }
    };
    let refuse = |what: String| OutputError::Refused {
        flag: c.flag.to_string(),
        path: c.path.to_path_buf(),
        what,
    };
    let path = resolve(c.path).map_err(io(c.path))?;
    if let Some(file) = path.ancestors().skip(1).find(|a| a.is_file()) {
        return Err(refuse(format!(
            "{} is a file, not a folder",
            file.display()
        )));
    }
    if let Ok(meta) = std::fs::metadata(&path) {
        match (c.kind, file_kind(&meta)) {
            (_, Some(special)) => {
                return Err(refuse(format!("is {special}, not a file or folder")))
            }
            (OutputKind::Folder, None) if !meta.is_dir() => {
                return Err(refuse(
                    "is a file, not a folder (tnd never replaces a file with a folder)".into(),
                ))
            }
            (OutputKind::File, None) if meta.is_dir() => {
                return Err(refuse("is a folder; give a file name".into()))
            }
            _ => {}
        }
    }
    for input in &c.inputs {
        let Ok(real) = resolve(input) else { continue };
        if !real.exists() {
            continue;
        }
        if real == path {
            return Err(refuse(format!("is also an input ({})", input.display())));
        }
        if c.kind == OutputKind::Folder && real.starts_with(&path) {
            return Err(refuse(format!("holds an input ({})", input.display())));
        }
        // A file or folder of an input folder (a diffusers folder's weights, a dataset's shards) is part of it.
        if real.is_dir() && path != real && path.starts_with(&real) && path.exists() {
            return Err(refuse(format!("is part of an input ({})", input.display())));
        }
    }
    if c.kind == OutputKind::Folder {
        if let Some(what) = reserved_folder(&path) {
            return Err(refuse(format!(
                "is {what}; tnd writes into a folder of its own"
            )));
        }
    }
    let lock = OutputLock::acquire(&path)?;
    let created = c.kind == OutputKind::Folder && !path.exists();
    let (ledger, fresh_ledger) = match c.kind {
        OutputKind::Folder => claim_folder(&c, &path).map_err(|e| match e {
            FolderRefusal::Io(p, source) => OutputError::Io { path: p, source },
            FolderRefusal::Foreign(names) => OutputError::Foreign {
                flag: c.flag.to_string(),
                path: c.path.to_path_buf(),
                count: names.len(),
                names: list(&names),
            },
        })?,
        OutputKind::File => {
            // tnd's own: of its format, and as tnd left it (an edited sensor file is the user's now).
            let own = |p: &Path| c.ours.is_some_and(|ours| ours(p)) && written_as_recorded(p);
            if path.exists() && !c.force && !own(&path) {
                return Err(OutputError::ForeignFile {
                    flag: c.flag.to_string(),
                    path: c.path.to_path_buf(),
                });
            }
            (Ledger::default(), None)
        }
    };
    let protected = protected_paths(&path, &ledger.foreign);
    PROTECTED
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .extend(protected.iter().cloned());
    if c.kind == OutputKind::File {
        CLAIMED_FILES
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(path.clone());
    } else {
        CLAIMED_FOLDERS
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(FolderState {
                given: lexical_absolute(c.path).unwrap_or_else(|_| path.clone()),
                real: path.clone(),
                foreign: ledger.foreign,
                written: ledger.written,
            });
    }
    Ok(Claimed {
        path,
        protected,
        kind: c.kind,
        created,
        fresh_ledger,
        _lock: lock,
    })
}

enum FolderRefusal {
    Io(PathBuf, std::io::Error),
    Foreign(Vec<String>),
}

/// Read or write the ledger of a folder output we hold: the ledger, and what the folder held when this claim wrote
/// the ledger first.
type FolderClaim = (Ledger, Option<BTreeSet<String>>);

fn claim_folder(c: &Claim<'_>, dir: &Path) -> Result<FolderClaim, FolderRefusal> {
    let ledger_path = dir.join(LEDGER_FILE);
    let entries = entries(dir).map_err(|e| FolderRefusal::Io(dir.to_path_buf(), e))?;
    if std::fs::symlink_metadata(&ledger_path).is_ok() && ledger_of(&ledger_path).is_none() {
        return Err(FolderRefusal::Io(
            ledger_path.clone(),
            std::io::Error::other("not tnd's ledger (a file of yours of that name?); move it away"),
        ));
    }
    let (ledger, fresh) = match ledger_of(&ledger_path) {
        Some(mut ledger) => {
            // Entries neither the user's nor tnd's (tnd's runs record each entry as they write it, a killed one
            // too): the user added them since, and they are theirs, kept like the rest — but for an empty folder,
            // which holds nothing to lose (a killed run may have made it before writing into it).
            let new: Vec<String> = entries
                .iter()
                .filter(|e| !ledger.foreign.contains(*e) && !ledger.written.contains(*e))
                .cloned()
                .collect();
            for name in new {
                let empty_dir =
                    std::fs::read_dir(dir.join(&name)).is_ok_and(|mut d| d.next().is_none());
                if empty_dir
                    && !std::fs::symlink_metadata(dir.join(&name)).is_ok_and(|m| m.is_symlink())
                {
                    ledger.written.insert(name);
                } else {
                    ledger.foreign.insert(name);
                }
            }
            (ledger, None)
        }
        None => {
            if !entries.is_empty() && !c.force {
                return Err(FolderRefusal::Foreign(entries.into_iter().collect()));
            }
            let ledger = Ledger {
                written_by: "tnd".into(),
                foreign: entries.clone(),
                ..Ledger::default()
            };
            (ledger, Some(entries))
        }
    };
    let ledger = Ledger {
        running: true,
        ..ledger
    };
    write_ledger(dir, &ledger).map_err(|e| FolderRefusal::Io(ledger_path.clone(), e))?;
    Ok((ledger, fresh))
}

fn write_ledger(dir: &Path, ledger: &Ledger) -> std::io::Result<()> {
    let text = serde_json::to_string_pretty(ledger).map_err(std::io::Error::other)?;
    super::atomic::write_plain(&dir.join(LEDGER_FILE), format!("{text}\n").as_bytes())
}

/// The paths of a folder's user entries: a name is one entry; an empty or a path-like one (a hand-edited ledger)
/// protects nothing more.
fn protected_paths(dir: &Path, foreign: &BTreeSet<String>) -> Vec<PathBuf> {
    foreign
        .iter()
        .filter(|n| !n.is_empty() && *n != "." && *n != ".." && !n.contains(['/', '\\']))
        .map(|name| dir.join(name))
        .collect()
}

fn ledger_of(path: &Path) -> Option<Ledger> {
    let text = super::input::read_text_capped(path, super::input::MAX_SETTINGS_BYTES).ok()?;
    serde_json::from_str::<Ledger>(&text)
        .ok()
        .filter(|l| l.written_by == "tnd")
}

/// Whether `dir` is a folder tnd claimed (it holds a ledger).
pub fn is_tnd_folder(dir: &Path) -> bool {
    ledger_of(&dir.join(LEDGER_FILE)).is_some()
}

/// A folder's entries, leaving out the lock files and temporary siblings of tnd's writers.
fn entries(dir: &Path) -> std::io::Result<BTreeSet<String>> {
    let mut out = BTreeSet::new();
    let Ok(read) = std::fs::read_dir(dir) else {
        return Ok(out);
    };
    for entry in read {
        let name = entry?.file_name().to_string_lossy().into_owned();
        let writer_file = name.starts_with('.')
            && (name.ends_with(".tnd-lock") || name.contains(".tmp.") || name.contains(".old."));
        if !writer_file && name != LEDGER_FILE {
            out.insert(name);
        }
    }
    Ok(out)
}

fn list(names: &[String]) -> String {
    const SHOWN: usize = 4;
    let mut s = names
        .iter()
        .take(SHOWN)
        .cloned()
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > SHOWN {
        s.push_str(&format!(", and {} more", names.len() - SHOWN));
    }
    s
}

#[cfg(test)]
#[path = "output_tests.rs"]
mod tests;
