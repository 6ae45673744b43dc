//! The **records** of an evaluation as a resumable log (`tnd eval --records FILE`). The first line holds the settings
//! the scores depend on (`{"settings": {…}}`); every further line is one pair's outcome, `{"split", "index",
//! "record"}` or `{"split", "index", "failed"}`, with the pair's index in its dataset split. The file is rewritten
//! atomically after every pair, so a run killed part-way loses at most the pair it was scoring. Started again with
//! the same settings, a run takes the pairs the log holds and scores only the others (a pair's sampler and
//! registration seeds depend on its index alone, so the result equals an uninterrupted run's), and a larger
//! `--limit` extends an earlier run. Pairs that failed are scored again. A log of other settings is refused, naming
//! them, rather than overwritten: an hour of scores is never lost to a changed option.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::evaluate::{EvalError, FailedPair, PairRecord};

/// Errors of an evaluation log; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum EvalLogError {
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: line {line}: {problem}", path.display())]
    Format {
        path: PathBuf,
        line: usize,
        problem: String,
    },
    #[error(
        "{}: holds the records of other settings ({}); choose another --records file, or the same settings to resume",
        path.display(),
        differing.join("; ")
    )]
    OtherSettings {
        path: PathBuf,
        differing: Vec<String>,
    },
    #[error("{}: cannot write: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Eval(#[from] EvalError),
}

/// One pair's outcome as logged (the record boxed: it is 40 times the failure's size).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LoggedPair {
    Record(Box<PairRecord>),
    Failed(FailedPair),
}

/// A line of the log after the settings.
#[derive(Serialize, Deserialize)]
struct Line {
    split: String,
    index: usize,
    #[serde(flatten)]
    outcome: LoggedPair,
}

/// An evaluation's records on disk, by split and pair index.
#[derive(Debug)]
pub struct EvalLog {
    path: PathBuf,
    settings: Value,
    pairs: BTreeMap<(String, usize), LoggedPair>,
}

impl EvalLog {
    /// Whether `path` is a records file tnd wrote: its first line is a settings line.
    pub fn written_by_tnd(path: &Path) -> bool {
        use std::io::BufRead;
        let Ok(file) = std::fs::File::open(path) else {
            return false;
        };
        let mut first = String::new();
        match std::io::BufReader::new(file).read_line(&mut first) {
            Ok(0) => false,
            Ok(_) => {
                serde_json::from_str::<Value>(&first).is_ok_and(|v| v.get("settings").is_some())
            }
            Err(_) => false,
        }
    }

    /// Open the log at `path` for a run with `settings`: an earlier run's records when the file exists and was
    /// written with the same settings (an error naming the differing settings otherwise, or naming the line that
    /// is not a record); a new log, written at once (so that an unwritable path fails before any work), when not.
    pub fn open(path: &Path, settings: Value) -> Result<Self, EvalLogError> {
        let mut log = Self {
            path: path.to_path_buf(),
            settings,
            pairs: BTreeMap::new(),
        };
        let text =
            match crate::io::input::read_text_capped(path, crate::io::input::MAX_RECORDS_BYTES) {
                Ok(text) => text,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    log.write()?;
                    return Ok(log);
                }
                Err(source) => {
                    return Err(EvalLogError::Read {
                        path: path.to_path_buf(),
                        source,
                    })
                }
            };
        let format = |line: usize, problem: String| EvalLogError::Format {
            path: path.to_path_buf(),
            line,
            problem,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let then = lines
            .next()
            .and_then(|(_, l)| serde_json::from_str::<Value>(l).ok())
            .and_then(|v| v.get("settings").cloned())
            .ok_or_else(|| {
                format(
                    1,
                    "no settings line (not a records file, or one written by an earlier tnd); choose another \
                     --records file"
                        .into(),
                )
            })?;
        let differing = crate::io::settings::setting_differences(&log.settings, &then);
        if !differing.is_empty() {
            return Err(EvalLogError::OtherSettings {
                path: path.to_path_buf(),
                differing,
            });
        }
        for (i, l) in lines {
            let line: Line = serde_json::from_str(l)
                .map_err(|e| format(i + 1, format!("not a pair's record: {e}")))?;
            log.pairs.insert((line.split, line.index), line.outcome);
        }
        Ok(log)
    }

    /// The records of the log at `path`, whatever settings it was written with, in split and index order (failed
    /// pairs left out), with its settings.
    pub fn read(path: &Path) -> Result<(Value, Vec<PairRecord>), EvalLogError> {
        let text = crate::io::input::read_text_capped(path, crate::io::input::MAX_RECORDS_BYTES)
            .map_err(|source| EvalLogError::Read {
                path: path.to_path_buf(),
                source,
            })?;
        if text.trim().is_empty() {
            return Err(EvalLogError::Format {
                path: path.to_path_buf(),
                line: 1,
                problem: "empty: no records yet (an evaluation stopped before its first write?)"
                    .into(),
            });
        }
        let settings = text
            .lines()
            .next()
            .and_then(|l| serde_json::from_str::<Value>(l).ok())
            .and_then(|v| v.get("settings").cloned())
            .ok_or_else(|| EvalLogError::Format {
                path: path.to_path_buf(),
                line: 1,
                problem: "no settings line: not a records file of tnd eval".into(),
            })?;
        let log = Self::open(path, settings.clone())?;
        let records = log
            .pairs
            .into_values()
            .filter_map(|p| match p {
                LoggedPair::Record(r) => Some(*r),
                LoggedPair::Failed(_) => None,
            })
            .collect();
        Ok((settings, records))
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Pair `index` of `split` as scored by an earlier run (`None`: not logged, or logged as failed).
    pub fn record(&self, split: &str, index: usize) -> Option<&PairRecord> {
        match self.pairs.get(&(split.to_string(), index)) {
            Some(LoggedPair::Record(r)) => Some(r),
            _ => None,
        }
    }

    /// How many pairs of `split` with indices in `indices` an earlier run scored.
    pub fn scored(&self, split: &str, indices: std::ops::Range<usize>) -> usize {
        indices.filter(|&i| self.record(split, i).is_some()).count()
    }

    /// Every logged pair, in split and index order.
    pub fn pairs(&self) -> impl Iterator<Item = (&str, usize, &LoggedPair)> {
        self.pairs.iter().map(|((s, i), p)| (s.as_str(), *i, p))
    }

    /// Log pair `index` of `split` (replacing what was there) and rewrite the file.
    pub fn insert(
        &mut self,
        split: &str,
        index: usize,
        outcome: LoggedPair,
    ) -> Result<(), EvalLogError> {
        self.pairs.insert((split.to_string(), index), outcome);
        self.write()
    }

    fn write(&self) -> Result<(), EvalLogError> {
        let write = |source: std::io::Error| EvalLogError::Write {
            path: self.path.clone(),
            source,
        };
        let json = |e: serde_json::Error| write(std::io::Error::other(e));
        let mut text =
            serde_json::to_string(&serde_json::json!({"settings": self.settings})).map_err(json)?;
        text.push('\n');
        for ((split, index), outcome) in &self.pairs {
            let line = Line {
                split: split.clone(),
                index: *index,
                outcome: outcome.clone(),
            };
            text.push_str(&serde_json::to_string(&line).map_err(json)?);
            text.push('\n');
        }
        crate::io::write_atomic(&self.path, text.as_bytes()).map_err(write)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn failed(name: &str) -> LoggedPair {
        LoggedPair::Failed(FailedPair {
            name: name.into(),
            object: "o".into(),
            reason: "r".into(),
        })
    }

    #[test]
    fn reopens_under_the_same_settings_and_refuses_others() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.jsonl");
        let mut log = EvalLog::open(&path, json!({"seed": 0})).unwrap();
        assert!(path.exists(), "a new log is written at once");
        log.insert("unseen_objects", 3, failed("unseen_objects/3"))
            .unwrap();
        let again = EvalLog::open(&path, json!({"seed": 0})).unwrap();
        let pairs: Vec<_> = again.pairs().map(|(s, i, _)| (s.to_string(), i)).collect();
        assert_eq!(pairs, [("unseen_objects".to_string(), 3)]);
        // A failed pair is not taken as scored: it is tried again.
        assert!(again.record("unseen_objects", 3).is_none());
        assert_eq!(again.scored("unseen_objects", 0..10), 0);
        let err = EvalLog::open(&path, json!({"seed": 1}))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("seed: 0 -> 1") && err.contains("r.jsonl"),
            "{err}"
        );
        // The refused run left the file as it was.
        assert_eq!(
            EvalLog::open(&path, json!({"seed": 0}))
                .unwrap()
                .pairs()
                .count(),
            1
        );
    }

    #[test]
    fn names_the_line_that_is_not_a_record() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.jsonl");
        std::fs::write(&path, "{\"split\":\"unseen_objects\",\"record\":{}}\n").unwrap();
        let err = EvalLog::open(&path, json!({})).unwrap_err().to_string();
        assert!(err.contains("line 1: no settings line"), "{err}");
        std::fs::write(&path, "{\"settings\":{}}\n\n{\"split\":\"x\"}\n").unwrap();
        let err = EvalLog::open(&path, json!({})).unwrap_err().to_string();
        assert!(err.contains("line 3: not a pair's record"), "{err}");
    }
}
