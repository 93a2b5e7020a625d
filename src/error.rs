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

/// Warnings found while loading input are held back until the run gets going
/// ([`flush_warnings`]: when a progress bar starts, or when the command succeeds), so that
/// a run that then fails prints one line, its error, and nothing before it.
static PENDING: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

/// Queues `lodtrace: warning: {msg}` for [`flush_warnings`].
pub fn warn(msg: impl Into<String>) {
    if let Ok(mut p) = PENDING.lock() {
        p.push(msg.into());
    }
}

/// Prints the queued warnings (each once).
pub fn flush_warnings() {
    let msgs = PENDING.lock().map(|mut p| std::mem::take(&mut *p)).unwrap_or_default();
    for m in msgs {
        crate::status!("lodtrace: warning: {m}");
    }
}

/// Drops the queued warnings (the run failed: its error line is all it prints).
pub fn discard_warnings() {
    if let Ok(mut p) = PENDING.lock() {
        p.clear();
    }
}

/// Writes `text` to standard output: `Ok(true)` when written, `Ok(false)` when the reader
/// went away (`lodtrace verify | head`: the output ends quietly); any other failure
/// (`> /dev/full`) is an error, not a panic as with `print!`.
pub fn print_stdout(text: &str) -> Result<bool> {
    use std::io::Write;
    let out = std::io::stdout();
    let mut out = out.lock();
    match out.write_all(text.as_bytes()).and_then(|_| out.flush()) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(false),
        Err(e) => Err(Error::io("<stdout>", e)),
    }
}

/// The input files this process has read (resolved paths): meshes, scenes, material
/// libraries, point files, images.
static INPUTS: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Whether `path` (resolved, links followed) is a file this process read as input: the last
/// guard before an output replaces it (an OBJ's `mtllib mats.json` against `--stats
/// mats.json`, a mesh linked into `--out` under a frame's name), for inputs that only
/// loading finds.
pub fn is_input(path: &std::path::Path) -> bool {
    match (std::fs::canonicalize(path), INPUTS.lock()) {
        (Ok(c), Ok(v)) => v.contains(&c),
        _ => false,
    }
}

/// An input must be a regular file (symbolic links followed): a FIFO would block the read
/// forever and `/dev/zero` would fill the memory before any parser could object. Every
/// input is noted ([`is_input`]): no output of the run may replace it.
pub fn check_input_file(path: &std::path::Path) -> Result<()> {
    let m = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if m.is_file() {
        if let (Ok(c), Ok(mut v)) = (std::fs::canonicalize(path), INPUTS.lock()) {
            if !v.contains(&c) {
                v.push(c);
            }
        }
        Ok(())
    } else {
        let what = if m.is_dir() { "a folder" } else { "not a regular file" };
        Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidInput, what)))
    }
}

/// [`check_input_file`], and the memory a whole-file read of `path` takes: `per_byte` times
/// the file's length (the text and what is parsed from it, measured per format at its call).
/// A file larger than the memory aborted the run on a failed allocation (a sparse 3 GiB OFF,
/// TOML or PLY file under `ulimit -v 2000000`: exit 134, no error line; until stop 82).
pub fn check_input_read(path: &std::path::Path, per_byte: u64) -> Result<()> {
    check_input_file(path)?;
    let len = std::fs::metadata(path).map_err(|e| Error::io(path, e))?.len();
    check_memory(len.saturating_mul(per_byte), &format!("reading a file of {:.1} MB", len as f64 / 1e6))
        .map_err(|m| Error::io(path, std::io::Error::new(std::io::ErrorKind::OutOfMemory, m)))
}

/// Refuses work that would need about `bytes` of memory when this process cannot have that
/// much: the smaller of the system's available memory (`MemAvailable`) and what the address
/// space limit (`ulimit -v`) leaves. A failed allocation aborts without an error line; this
/// check turns the predictable ones (image sizes, decoded images) into exit 2. Where the
/// limits cannot be read, nothing is refused.
pub fn check_memory(bytes: u64, what: &str) -> std::result::Result<(), String> {
    match memory_available() {
        Some(avail) if bytes > avail => {
            Err(format!("{what} needs about {:.1} GB of memory, {:.1} GB is available", bytes as f64 / 1e9, avail as f64 / 1e9))
        }
        _ => Ok(()),
    }
}

/// Bytes this process can still allocate, if known (Linux: `/proc`, `getrlimit`).
fn memory_available() -> Option<u64> {
    let kb = |text: &str, key: &str| -> Option<u64> {
        let line = text.lines().find(|l| l.starts_with(key))?;
        line[key.len()..].trim().trim_end_matches("kB").trim().parse::<u64>().ok().map(|k| k * 1024)
    };
    let sys = std::fs::read_to_string("/proc/meminfo").ok().and_then(|t| kb(&t, "MemAvailable:"));
    #[cfg(unix)]
    let limit = {
        let mut rl = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
        // SAFETY: getrlimit writes the struct it is given.
        let ok = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut rl) } == 0;
        if ok && rl.rlim_cur != libc::RLIM_INFINITY {
            let used = std::fs::read_to_string("/proc/self/status").ok().and_then(|t| kb(&t, "VmSize:")).unwrap_or(0);
            Some(rl.rlim_cur.saturating_sub(used))
        } else {
            None
        }
    };
    #[cfg(not(unix))]
    let limit: Option<u64> = None;
    match (sys, limit) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// Longest error line [`one_line`] prints, in characters: the messages echo names from the
/// input (a TOML file's material or mesh names, a scene argument), and a 10 MB name made a
/// 10 MB "line".
pub const MAX_LINE_CHARS: usize = 2000;

/// `s` on one line: control characters (a newline in a file name or an option's value,
/// echoed in the message) are written as escapes (`\n`), so an error stays one line; a line
/// longer than [`MAX_LINE_CHARS`] keeps its beginning and end and says how much is left out.
pub fn one_line(s: &str) -> std::borrow::Cow<'_, str> {
    let s: std::borrow::Cow<'_, str> = if s.chars().any(char::is_control) {
        s.chars().map(|c| if c.is_control() { c.escape_default().to_string() } else { c.to_string() }).collect::<String>().into()
    } else {
        s.into()
    };
    let n = s.chars().count();
    if n <= MAX_LINE_CHARS {
        return s;
    }
    let keep = MAX_LINE_CHARS / 2;
    let head: String = s.chars().take(keep).collect();
    let tail: String = s.chars().skip(n - keep).collect();
    format!("{head} [... {} characters left out ...] {tail}", n - 2 * keep).into()
}

/// `eprintln!` that cannot panic: a status or error line to standard error, dropped when
/// that fails (`2> /dev/full`). A run's outcome is its exit code and its files; a status
/// line that cannot be shown must not turn a finished run into a panic that leaves its
/// outputs half-kept.
#[macro_export]
macro_rules! status {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($t)*);
    }};
}
