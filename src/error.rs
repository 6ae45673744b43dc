//! Rendering errors **once**, at the edge (CLI `main`, the workbench's status bar): an error's message followed by
//! those of its sources that it does not already contain.
//!
//! Library errors keep their cause as `#[source]`, and many also quote it in their own message so that a plain
//! `to_string()` is useful; printing the whole chain naively (anyhow's `{:#}`) then says the same thing twice
//! ("object mesh: …: object mesh: …"). [`render`] walks the chain and skips every source whose text is already part
//! of what has been written.

/// `err` and the sources it does not already quote, joined by `": "`.
///
/// ```
/// #[derive(Debug, thiserror::Error)]
/// #[error("cannot open mesh.obj: {0}")]
/// struct Outer(#[source] std::io::Error);
/// let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
/// assert_eq!(tactile_derender::error::render(&Outer(io)), "cannot open mesh.obj: no such file");
/// ```
pub fn render(err: &dyn std::error::Error) -> String {
    let mut out = err.to_string();
    let mut source = err.source();
    while let Some(s) = source {
        let message = s.to_string();
        if !message.is_empty() && !out.contains(&message) {
            out.push_str(": ");
            out.push_str(&message);
        }
        source = s.source();
    }
    out
}

/// `path: error`, or the error alone when its message names `path` already (an error from
/// [`crate::io::write_atomic`] does), so that each path is printed once.
pub fn with_path(path: &std::path::Path, error: &dyn std::fmt::Display) -> String {
    let message = error.to_string();
    let shown = path.display().to_string();
    if message.contains(&shown) {
        message
    } else {
        format!("{shown}: {message}")
    }
}

/// A setting, or a value given as text, that cannot be used: which one (`"guidance.step"`, `"resolution"`; a UI
/// can mark that field) and a message saying what it may be and what it was.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct InvalidSetting {
    /// The setting's name, dotted as in the config files (`sampler.steps`).
    pub setting: &'static str,
    /// What is wrong and what to change, one line.
    pub message: String,
}

impl InvalidSetting {
    pub fn new(setting: &'static str, message: impl Into<String>) -> Self {
        Self {
            setting,
            message: message.into(),
        }
    }

    /// Run a check written with text errors, typing its error as `setting`'s.
    pub fn wrap<T>(
        setting: &'static str,
        f: impl FnOnce() -> Result<T, String>,
    ) -> Result<T, Self> {
        f().map_err(|message| Self { setting, message })
    }
}

/// Input that cannot be used as given: bytes or text that do not hold what their format says, an image of a size
/// the sensor does not make, frames that cannot calibrate: what it is (`"PLY"`, `"sensor_msgs/Image"`, `"reference
/// frames"`) and what is wrong, one line (the caller names the file).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct InvalidInput {
    /// What the input is: a format or a kind of data.
    pub what: &'static str,
    /// What is wrong with it, one line.
    pub message: String,
}

impl InvalidInput {
    pub fn new(what: &'static str, message: impl Into<String>) -> Self {
        Self {
            what,
            message: message.into(),
        }
    }

    /// Run a check written with text errors, typing its error as `what`'s.
    pub fn wrap<T>(what: &'static str, f: impl FnOnce() -> Result<T, String>) -> Result<T, Self> {
        f().map_err(|message| Self { what, message })
    }
}

/// The message alone, for code that reports in text.
impl From<InvalidSetting> for String {
    fn from(e: InvalidSetting) -> Self {
        e.message
    }
}

/// The message alone, for code that reports in text.
impl From<InvalidInput> for String {
    fn from(e: InvalidInput) -> Self {
        e.message
    }
}

/// [`render`] for an `anyhow::Error` (its context lines and the library error beneath them).
pub fn render_anyhow(err: &anyhow::Error) -> String {
    render(err.as_ref())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("object 'bunny': {0}")]
    struct Quoting(#[source] Inner);

    #[derive(Debug, thiserror::Error)]
    #[error("bunny.obj: 4 bad edges")]
    struct Inner;

    #[derive(Debug, thiserror::Error)]
    #[error("evaluation stopped")]
    struct Terse(#[source] Inner);

    #[test]
    fn quoted_sources_are_said_once_and_unquoted_ones_are_appended() {
        assert_eq!(
            render(&Quoting(Inner)),
            "object 'bunny': bunny.obj: 4 bad edges"
        );
        assert_eq!(
            render(&Terse(Inner)),
            "evaluation stopped: bunny.obj: 4 bad edges"
        );
        let any = anyhow::Error::new(Quoting(Inner)).context("tnd eval data/real");
        assert_eq!(
            render_anyhow(&any),
            "tnd eval data/real: object 'bunny': bunny.obj: 4 bad edges"
        );
        // anyhow's alternate form repeats the quoted source: what this module exists to avoid.
        assert_eq!(format!("{any:#}").matches("4 bad edges").count(), 2);
    }
}
