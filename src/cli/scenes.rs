//! `lodtrace scenes`: the built-in scenes with their triangle counts. A scene whose assets
//! are missing (run `tools/setup`) is listed as unavailable instead of failing the listing.
use crate::error::{Error, Result};
use crate::scene::builtin::BUILTINS;
use std::io::Write;

pub fn run() -> Result<()> {
    let out = std::io::stdout();
    let mut out = out.lock();
    let mut line = |s: String| -> Result<bool> {
        match writeln!(out, "{s}") {
            Ok(()) => Ok(true),
            // `lodtrace scenes | head`: the reader went away; stop quietly.
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(false),
            Err(e) => Err(Error::io("<stdout>", e)),
        }
    };
    if !line(format!("{:<10} {:>12} {:>12}  description", "scene", "triangles", "unique"))? {
        return Ok(());
    }
    for b in BUILTINS {
        let row = match crate::scene::builtin::get(b.name).and_then(|s| s.triangle_counts()) {
            Ok((inst, uniq)) => format!("{:<10} {:>12} {:>12}  {}", b.name, inst, uniq, b.about),
            Err(e) => format!("{:<10} {:>12} {:>12}  {} [unavailable: {e}]", b.name, "-", "-", b.about),
        };
        if !line(row)? {
            return Ok(());
        }
    }
    Ok(())
}
