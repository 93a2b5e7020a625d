//! Typed library errors. The CLI prints one line per error and exits 2 (bad input or
//! usage); checks that ran and failed (verify, compare thresholds) exit 1 instead.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {msg}")]
    Parse { path: PathBuf, msg: String },
    #[error("invalid scene: {0}")]
    Scene(String),
    #[error("invalid option: {0}")]
    Usage(String),
    #[error("unknown scene '{0}' (see `lodtrace scenes`; or give an .obj, .off or .toml file)")]
    UnknownScene(String),
    #[error("acceleration structure: {0}")]
    Accel(String),
    #[error("image: {0}")]
    Image(String),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    pub fn parse(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Parse { path: path.into(), msg: msg.into() }
    }
}

/// An input must be a regular file (symbolic links followed): a FIFO would block the read
/// forever and `/dev/zero` would fill the memory before any parser could object.
pub fn check_input_file(path: &std::path::Path) -> Result<()> {
    let m = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if m.is_file() {
        Ok(())
    } else {
        let what = if m.is_dir() { "a folder" } else { "not a regular file" };
        Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidInput, what)))
    }
}
