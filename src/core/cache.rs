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
    // An empty variable counts as unset (as the XDG specification says for its own), so
    // `LODTRACE_CACHE=` never means "the current directory".
    let set = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty());
    let d = if let Some(d) = set("LODTRACE_CACHE") {
        PathBuf::from(d)
    } else if let Some(x) = set("XDG_CACHE_HOME") {
        PathBuf::from(x).join("lodtrace")
    } else {
        PathBuf::from(std::env::var_os("HOME")?).join(".cache").join("lodtrace")
    };
    std::fs::create_dir_all(&d).ok()?;
    Some(d)
}

/// Reads a cache file, or None when there is none to read. Only a regular file (after
/// following symlinks) is read, and only as many bytes as its size said: a FIFO, a device
/// (`/dev/zero` behind a symlink) or a directory at the cache path is a miss, never a hang or
/// an unbounded read, as is a file larger than the memory this process can still have. Callers treat None as a miss and rebuild (their atomic write then
/// replaces whatever was there, when the directory allows it).
pub fn read_cache_file(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read;
    let meta = std::fs::metadata(path).ok()?;
    if !meta.is_file() {
        return None;
    }
    let len = meta.len();
    let mut f = std::fs::File::open(path).ok()?;
    // Re-check the opened file itself: the path may have been swapped since the stat.
    if !f.metadata().ok()?.is_file() {
        return None;
    }
    // A file larger than the memory left (a corrupted, or sparse, cache file of gigabytes) is
    // a miss too: `Vec::with_capacity` aborted the run on the failed allocation (exit 134, no
    // error line).
    crate::error::check_memory(len, "").ok()?;
    let mut b = Vec::new();
    b.try_reserve_exact(usize::try_from(len).ok()?).ok()?;
    f.by_ref().take(len).read_to_end(&mut b).ok()?;
    (b.len() as u64 == len).then_some(b)
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

    #[test]
    fn only_regular_files_are_read_from_the_cache() {
        let dir = std::env::temp_dir().join(format!("lodtrace-core-cache-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.bin");
        write_atomic(&p, b"abc").unwrap();
        assert_eq!(read_cache_file(&p).as_deref(), Some(&b"abc"[..]));
        assert_eq!(read_cache_file(&dir.join("missing")), None);
        assert_eq!(read_cache_file(&dir), None, "a directory is a miss");
        #[cfg(unix)]
        {
            // A symlink to an endless device and a FIFO: misses, returned at once.
            let z = dir.join("zero.bin");
            std::os::unix::fs::symlink("/dev/zero", &z).unwrap();
            assert_eq!(read_cache_file(&z), None);
            let fifo = dir.join("fifo.bin");
            let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
            assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
            assert_eq!(read_cache_file(&fifo), None, "a FIFO is not opened (opening it would block)");
            // A symlink to a regular file is followed.
            let l = dir.join("link.bin");
            std::os::unix::fs::symlink(&p, &l).unwrap();
            assert_eq!(read_cache_file(&l).as_deref(), Some(&b"abc"[..]));
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
