//! `lodtrace scenes`: the built-in scenes with their triangle counts, then the deforming
//! sequences of `lodtrace animate` (named only: building one samples its surfels). A scene
//! whose assets are missing (run `tools/setup`) is listed as unavailable instead of failing
//! the listing.
use crate::error::Result;
use crate::scene::builtin::BUILTINS;

pub fn run() -> Result<()> {
    // Row by row (each loads its scene); `lodtrace scenes | head` stops when the reader goes.
    let line = |s: String| crate::error::print_stdout(&(s + "\n"));
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
    let seqs = crate::deform::Sequence::BUILTIN.join(", ");
    line(format!("\ndeforming sequences (lodtrace animate SEQ; lodtrace bench SEQ --methods surfel:...): {seqs}"))?;
    Ok(())
}
