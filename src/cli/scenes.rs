//! `lodtrace scenes`: the built-in scenes with their triangle counts.
use crate::error::Result;
use crate::scene::builtin::BUILTINS;

pub fn run() -> Result<()> {
    println!("{:<10} {:>12} {:>12}  description", "scene", "triangles", "unique");
    for b in BUILTINS {
        let s = crate::scene::builtin::get(b.name)?;
        let (inst, uniq) = s.triangle_counts()?;
        println!("{:<10} {:>12} {:>12}  {}", b.name, inst, uniq, b.about);
    }
    Ok(())
}
