//! The on-disk cache of derived geometry shared by the methods that preprocess meshes: the
//! LOD chains of Papaioannou et al. (`lod::chain`) and the point hierarchies of Wand & Straßer
//! (`multires::cache`). Each user keys its files by a hash of everything its result depends
//! on, treats any read failure or inconsistency as a miss (and rebuilds), and writes through
//! [`write_atomic`], so no reader ever sees a half-written file.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The cache directory: `$LODTRACE_CACHE`, else `$XDG_CACHE_HOME/lodtrace`, else
/// `~/.cache/lodtrace` (None when none can be made: then everything is rebuilt every run).
pub fn cache_dir() -> Option<PathBuf> {
    let d = if let Some(d) = std::env::var_os("LODTRACE_CACHE") {
        PathBuf::from(d)
    } else if let Some(x) = std::env::var_os("XDG_CACHE_HOME") {
        PathBuf::from(x).join("lodtrace")
    } else {
        PathBuf::from(std::env::var_os("HOME")?).join(".cache").join("lodtrace")
    };
    std::fs::create_dir_all(&d).ok()?;
    Some(d)
}

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename.
/// The temporary name is unique per process *and* per call, so two threads writing the same
/// key at once (two identical meshes in one scene) never interleave their bytes; the rename is
/// atomic, so a reader sees either the old file, no file, or the complete new one. On failure
/// the temporary is removed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    static SEQ: AtomicU64 = AtomicU64::new(0);
    let seq = SEQ.fetch_add(1, Ordering::Relaxed);
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let tmp = path.with_extension(format!("{ext}.tmp{}-{seq}", std::process::id()));
    let r = std::fs::write(&tmp, bytes).and_then(|_| std::fs::rename(&tmp, path));
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("lodtrace-core-cache-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("x.bin");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two!").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two!");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "no temporary left behind");
        // Into a missing directory: an error, not a panic, and nothing left.
        assert!(write_atomic(&dir.join("missing").join("y.bin"), b"z").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
