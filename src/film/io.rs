//! Image files: PNG beauty (8-bit sRGB), EXR AOVs, all written atomically.
//!
//! - PNG: 8-bit sRGB (the beauty image for viewing); `--out NAME.exr` writes the beauty image
//!   as linear float EXR instead (`write_beauty`).
//! - EXR (`write_film_exr`, `write_exr_depth`, `write_exr_normal`): 32-bit float, linear,
//!   three channels R, G, B. The `image` crate's EXR encoder writes RGB or RGBA only, so the
//!   depth AOV stores the same value in all three channels (any channel reads it back).
//!   Misses keep depth `+inf`, the DESIGN.md contract (EXR stores infinities; `depth <
//!   inf` is the hit mask). NaN (never expected) is written as 0.
//! - `read_image_linear` reads either back as linear RGB: PNG (8- or 16-bit) is taken to be
//!   sRGB-encoded and decoded with `srgb_to_linear`; EXR is already linear. Bad or missing
//!   files give one error naming the file, never a panic.

use super::{linear_to_srgb, srgb_to_linear, Film};
use crate::error::{Error, Result};
use glam::Vec3;
use std::path::{Path, PathBuf};

/// Writes via `write` to a temporary file beside `path`, then renames it into place.
pub fn write_atomic(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    halt_if_interrupted();
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return Err(Error::io(dir, std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a folder"))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(Error::io(dir, std::io::Error::new(std::io::ErrorKind::NotFound, "output folder does not exist")))
        }
        // Exists but cannot be looked into (permissions): say so.
        Err(e) => return Err(Error::io(dir, e)),
    }
    let name = path.file_name().ok_or_else(|| Error::Usage(format!("{}: not a file name", path.display())))?;
    if crate::error::is_input(path) {
        return Err(Error::Usage(format!("{}: this run read it as an input; an output may not replace it", path.display())));
    }
    let ext = path.extension().map(|e| e.to_string_lossy().to_string()).unwrap_or_default();
    let tmp: PathBuf = dir.join(format!(".{}.{}.tmp.{}", name.to_string_lossy(), std::process::id(), ext));
    if let Ok(mut t) = TEMPS.lock() {
        t.push(std::path::absolute(&tmp).unwrap_or_else(|_| tmp.clone()));
    }
    let r = write(&tmp);
    // Inside a [`discard_dir_on_error`] scope, a file this write replaces is kept aside (a
    // hard link) until the scope ends: a failed re-run into an earlier run's folder puts
    // the earlier files back instead of leaving that run's report without its images.
    let backup = if r.is_ok() && scope_open() && std::fs::symlink_metadata(path).is_ok_and(|m| m.is_file()) {
        let b = dir.join(format!(".{}.{}.old.{}", name.to_string_lossy(), std::process::id(), ext));
        // Already there: this run wrote `path` before and `b` keeps the file from before
        // the run (undone latest first, the later write is simply removed).
        std::fs::hard_link(path, &b).ok().map(|_| b)
    } else {
        None
    };
    // The check of INTERRUPTED, the rename and its record in WRITTEN happen under COMMIT,
    // which the interrupt's cleanup takes after setting the flag: a file is either recorded
    // before the cleanup reads WRITTEN (and removed by it) or never renamed into place.
    // (Without the lock a rename between the check and the record outlived the cleanup:
    // `interrupted_runs_leave_no_outputs` found a frame left behind, stop 72.)
    let commit = COMMIT.lock();
    let r = match r {
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
        // An interrupted run renames nothing into place ([`remove_outputs_of_interrupted_run`]).
        Ok(()) if INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst) => {
            drop(commit);
            let _ = std::fs::remove_file(&tmp);
            halt_if_interrupted();
            unreachable!("halted")
        }
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            Error::io(path, e)
        }),
    };
    if let Ok(mut t) = TEMPS.lock() {
        let a = std::path::absolute(&tmp).unwrap_or_else(|_| tmp.clone());
        if let Some(i) = t.iter().rposition(|x| *x == a) {
            t.swap_remove(i);
        }
    }
    if r.is_err() {
        if let Some(b) = &backup {
            let _ = std::fs::remove_file(b);
        }
    }
    r?;
    record_written(path, backup);
    drop(commit);
    Ok(())
}

/// Held by [`write_atomic`] from its check of INTERRUPTED until the file is renamed and
/// recorded, and taken by [`remove_outputs_of_interrupted_run`] after it sets the flag.
static COMMIT: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Whether a [`discard_dir_on_error`] scope is running.
fn scope_open() -> bool {
    WRITTEN.lock().is_ok_and(|w| w.0 > 0)
}

/// Undoes one write of a failed scope: removes the file, or puts back the file it replaced,
/// or removes the folder it created.
fn undo_write(path: &Path, backup: &Option<PathBuf>) -> bool {
    match backup {
        Some(b) if b.as_os_str() == MADE_DIR => {
            // Counted as no output (its files were counted).
            let _ = std::fs::remove_dir_all(path);
            false
        }
        Some(b) => std::fs::rename(b, path).is_ok(),
        None => std::fs::remove_file(path).is_ok(),
    }
}

/// After SIGINT or SIGTERM a writer waits here for the signal thread to end the process
/// (`main`), rather than fail and let the command report an error of its own.
pub fn halt_if_interrupted() {
    while INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst) {
        std::thread::sleep(std::time::Duration::from_secs(1));
    }
}

/// Temporary files [`write_atomic`] is writing now (absolute paths).
static TEMPS: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
/// Set once SIGINT or SIGTERM arrived: no output is renamed into place after it.
static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
/// The output folders of the [`discard_dir_on_error`] scopes running now: (the folder,
/// its top-most ancestor that did not exist before the run, the scope's first entry in
/// `WRITTEN`).
#[allow(clippy::type_complexity)]
static SCOPES: std::sync::Mutex<Vec<(Option<PathBuf>, Option<PathBuf>, usize)>> = std::sync::Mutex::new(Vec::new());

/// On SIGINT or SIGTERM (`main` calls this from its signal thread, then exits): what a
/// failed run does, for every run in progress. The files written into the running scopes'
/// folders and the folders they created are removed, as are temporary files being
/// written; nothing is renamed into place afterwards. Returns the number of outputs removed.
pub fn remove_outputs_of_interrupted_run() -> usize {
    INTERRUPTED.store(true, std::sync::atomic::Ordering::SeqCst);
    // A write past its check of the flag finishes its rename and record first (COMMIT);
    // every later one sees the flag. Held to the end, so that none renames meanwhile.
    let _commit = COMMIT.lock();
    let mut removed = 0;
    if let Ok(t) = TEMPS.lock() {
        for p in t.iter() {
            let _ = std::fs::remove_file(p);
        }
    }
    let scopes = SCOPES.lock().map(|s| s.clone()).unwrap_or_default();
    let written = WRITTEN.lock().map(|w| w.1.clone()).unwrap_or_default();
    for (abs, fresh, start) in scopes {
        if let Some(a) = &abs {
            // Latest first: a file written twice gets back what was there before the run.
            for (p, b) in written.iter().skip(start).rev().filter(|(p, _)| p.starts_with(a)) {
                removed += undo_write(p, b) as usize;
            }
        }
        if let Some(d) = fresh {
            let _ = std::fs::remove_dir_all(d);
        }
    }
    removed
}

/// Files written by [`write_atomic`] while a [`discard_dir_on_error`] scope runs (absolute
/// paths), and the number of scopes running. Scopes of different output folders may run at
/// once (tests): each removes only files under its own folder.
/// Each with the hard link that keeps the file it replaced, if any ([`write_atomic`]).
#[allow(clippy::type_complexity)]
static WRITTEN: std::sync::Mutex<(usize, Vec<(PathBuf, Option<PathBuf>)>)> = std::sync::Mutex::new((0, Vec::new()));

fn record_written(path: &Path, backup: Option<PathBuf>) {
    if let Ok(mut w) = WRITTEN.lock() {
        if w.0 > 0 {
            let p = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
            let b = backup.map(|b| std::path::absolute(&b).unwrap_or(b));
            w.1.push((p, b));
        } else if let Some(b) = backup {
            let _ = std::fs::remove_file(b);
        }
    }
}

/// Creates an output folder (and its parents). A path that exists as a file, or whose name
/// ends like an image or data file (`--out frames.png`: the commands that take a folder would
/// otherwise create a folder of that name), is refused with a usage error; a folder that
/// cannot be created says so in one line.
pub fn create_out_dir(dir: &Path) -> Result<()> {
    // `-` is standard output for `--stats`; as a folder it made one named `-` (stop 81).
    if dir.as_os_str() == "-" {
        return Err(Error::Usage("--out -: --out names a folder here; only --stats takes - for standard output".into()));
    }
    // `none` means no output where an output is optional (`--stats none`, `bench --out none`,
    // `animate --out none`); a command that always writes refuses it rather than make `./none`.
    if dir.as_os_str() == "none" {
        return Err(Error::Usage("--out none: this command always writes its output; name a folder".into()));
    }
    if dir.exists() && !dir.is_dir() {
        return Err(Error::Usage(format!("{}: exists and is not a folder (--out names a folder here)", dir.display())));
    }
    if !dir.exists() {
        let ext = dir.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        if matches!(ext.as_str(), "png" | "exr" | "jpg" | "jpeg" | "ppm" | "json" | "md" | "html" | "svg") {
            return Err(Error::Usage(format!("{}: --out names a folder here (the files go inside it), not a .{ext} file", dir.display())));
        }
    }
    let abs = std::path::absolute(dir).unwrap_or_else(|_| dir.to_path_buf());
    let fresh = abs.ancestors().take_while(|a| !a.exists()).last().map(Path::to_path_buf);
    std::fs::create_dir_all(dir)
        .map_err(|e| Error::io(dir, std::io::Error::new(e.kind(), format!("cannot create the output folder ({e})"))))?;
    // A folder made inside a scope's existing output folder (the demo's `OUT/spheres/`) goes
    // again with the scope's files if the run fails.
    if let (Some(f), Ok(mut w)) = (fresh, WRITTEN.lock()) {
        if w.0 > 0 {
            w.1.push((f, Some(PathBuf::from(MADE_DIR))));
        }
    }
    Ok(())
}

/// Marks an entry of `WRITTEN` as a folder the run created ([`create_out_dir`]): undone by
/// removing it whole.
const MADE_DIR: &str = "\0made-dir";

/// Fails early, before any work, when a file cannot be created in `dir` (a folder that is
/// read-only or, like `/proc`, takes no new files): creates and removes a probe file there.
pub fn check_writable_dir(dir: &Path) -> Result<()> {
    let probe = dir.join(format!(".lodtrace-probe.{}", std::process::id()));
    match std::fs::File::create(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(Error::Usage(format!("{}: cannot create files in this folder ({e})", dir.display()))),
    }
}

/// Refuses an output path that exists as something other than a regular file: a folder
/// (the rename of the finished file over it fails, after all the work), a device or a pipe
/// (the rename would replace it with a plain file).
pub fn check_not_special(p: &Path) -> Result<()> {
    match std::fs::metadata(p) {
        Ok(m) if m.is_dir() => Err(Error::Usage(format!("{}: is a folder", p.display()))),
        Ok(m) if !m.is_file() => Err(Error::Usage(format!("{}: not a regular file", p.display()))),
        _ => Ok(()),
    }
}

/// [`check_not_special`] for the files `names` a run will write in its output folder `dir`,
/// before any rendering (`bench --out DIR` with a folder `DIR/bench.json` was refused only
/// when the report was written, after every render).
pub fn check_out_files(dir: &Path, names: &[String]) -> Result<()> {
    names.iter().try_for_each(|n| check_not_special(&dir.join(n)))
}

/// A path with its folder resolved, for comparing paths ([`check_distinct`]); an existing
/// file is resolved whole, so that a symbolic link and its target compare equal (`compare
/// a.png alink.png --diff a.png`).
fn key(p: &Path) -> std::path::PathBuf {
    if let Ok(k) = std::fs::canonicalize(p) {
        return k;
    }
    let dir = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    match (std::fs::canonicalize(dir), p.file_name()) {
        (Ok(d), Some(f)) => d.join(f),
        _ => std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf()),
    }
}

/// Whether two paths name the same file once their folders are resolved (as
/// [`check_distinct`] compares them).
pub fn same_path(a: &Path, b: &Path) -> bool {
    key(a) == key(b)
}

/// Paths must differ: two outputs of one run must not overwrite each other (or an input).
/// Paths are compared with their folders resolved (`sub/../a.png` is `a.png`).
pub fn check_distinct(paths: &[&Path]) -> Result<()> {
    for (i, a) in paths.iter().enumerate() {
        if paths[..i].iter().any(|b| key(a) == key(b)) {
            return Err(Error::Usage(format!("{}: given twice (as an output, or as an input and an output)", a.display())));
        }
    }
    Ok(())
}

/// [`check_distinct`] for a command's outputs and its scene argument, when that names a file
/// (a built-in scene name is no file and cannot be overwritten), and the mesh files a TOML
/// scene names.
pub fn check_outputs_apart_from_scene(scene: &str, outputs: &[&Path]) -> Result<()> {
    let scene = Path::new(scene);
    let meshes = if scene.is_file() && scene.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml")) {
        crate::scene::tomlscene::referenced_files(scene)
    } else {
        Vec::new()
    };
    let mut all: Vec<&Path> = if scene.is_file() { vec![scene] } else { Vec::new() };
    all.extend_from_slice(outputs);
    check_distinct(&all)?;
    // An OBJ's material file is found only while loading; no output may be a scene, mesh or
    // material file at all (stop 46's sweep: `--stats` over the OBJ's own .mtl replaced it).
    const INPUTS: [&str; 5] = ["obj", "off", "ply", "mtl", "toml"];
    if let Some(o) = outputs.iter().find(|o| o.extension().is_some_and(|e| INPUTS.iter().any(|x| e.eq_ignore_ascii_case(x)))) {
        return Err(Error::Usage(format!(
            "{}: an output may not be a scene, mesh or material file (.obj, .off, .ply, .mtl, .toml)",
            o.display()
        )));
    }
    // A scene may name one mesh file twice; only an output must not be one of them.
    if let Some(o) = outputs.iter().find(|o| meshes.iter().any(|m| key(m) == key(o))) {
        return Err(Error::Usage(format!("{}: given as an output, but the scene reads it as a mesh", o.display())));
    }
    Ok(())
}

/// The output files of one run, written one after another (each atomically): if the run
/// fails before [`Outputs::keep`], the files it already wrote are removed again, so a failed
/// run leaves no outputs behind.
#[derive(Default)]
pub struct Outputs {
    written: Vec<PathBuf>,
    keep: bool,
}

impl Outputs {
    /// Records `path` as written when `r` (its write) succeeded.
    pub fn wrote(&mut self, path: &Path, r: Result<()>) -> Result<()> {
        r?;
        self.written.push(path.to_path_buf());
        Ok(())
    }
    /// The run succeeded: keep everything.
    pub fn keep(mut self) {
        self.keep = true;
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        if !self.keep {
            for p in &self.written {
                let _ = std::fs::remove_file(p);
            }
        }
    }
}

/// Runs `f`, which may create the output folder `dir` (and its missing parents); if `f`
/// fails, whatever of that path did not exist before is removed again, with the files `f`
/// wrote there. In a folder that existed, the files `f` wrote there (through
/// [`write_atomic`]) are removed and the rest is kept: a failed run leaves none of its own
/// outputs, complete or not, beside those of earlier runs.
pub fn discard_dir_on_error<T>(dir: Option<&Path>, f: impl FnOnce() -> Result<T>) -> Result<T> {
    let abs = dir.and_then(|d| std::path::absolute(d).ok());
    // The top-most ancestor of `dir` that does not exist yet.
    let fresh = abs.as_ref().and_then(|a| a.ancestors().take_while(|a| !a.exists()).last().map(Path::to_path_buf));
    let start = WRITTEN.lock().map(|mut w| {
        w.0 += 1;
        w.1.len()
    });
    if let Ok(mut sc) = SCOPES.lock() {
        sc.push((abs.clone(), fresh.clone(), *start.as_ref().unwrap_or(&0)));
    }
    let r = f();
    if let Ok(mut sc) = SCOPES.lock() {
        if let Some(i) = sc.iter().rposition(|x| x.0 == abs && x.1 == fresh) {
            sc.remove(i);
        }
    }
    // The entries stay while an enclosing scope runs (the demo's around each bench): its
    // failure undoes them too, so their backups are kept until the last scope ends.
    let (mine, ended) = match WRITTEN.lock() {
        Ok(mut w) => {
            let v = start.map(|s| w.1[s.min(w.1.len())..].to_vec()).unwrap_or_default();
            w.0 = w.0.saturating_sub(1);
            let ended = if w.0 == 0 { std::mem::take(&mut w.1) } else { Vec::new() };
            (v, ended)
        }
        Err(_) => (Vec::new(), Vec::new()),
    };
    if r.is_err() {
        // Latest first: a file written twice gets back what was there before the run.
        for (p, b) in mine.iter().rev().filter(|(p, _)| abs.as_ref().is_some_and(|a| p.starts_with(a))) {
            undo_write(p, b);
        }
        if let Some(d) = fresh {
            let _ = std::fs::remove_dir_all(d);
        }
    }
    // Backups not put back (a file no longer there: renamed back above, or never made).
    for b in ended.iter().filter_map(|(_, b)| b.as_ref()).filter(|b| b.as_os_str() != MADE_DIR) {
        let _ = std::fs::remove_file(b);
    }
    r
}

/// 8-bit sRGB pixels of the beauty image.
pub fn to_rgb8(film: &Film) -> image::RgbImage {
    let mut img = image::RgbImage::new(film.width, film.height);
    for (k, p) in img.pixels_mut().enumerate() {
        let c = film.color[k];
        *p = image::Rgb([c.x, c.y, c.z].map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8));
    }
    img
}

pub fn write_png(path: &Path, film: &Film) -> Result<()> {
    let img = to_rgb8(film);
    write_rgb8_png(path, &img)
}

/// The beauty image in the format its extension names: `.exr` linear float (as
/// `write_film_exr`), anything else 8-bit sRGB PNG. `check_beauty_ext` vets the name first.
pub fn write_beauty(path: &Path, film: &Film) -> Result<()> {
    if has_ext(path, "exr") {
        write_film_exr(path, film)
    } else {
        write_png(path, film)
    }
}

fn has_ext(path: &Path, ext: &str) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext))
}

/// A beauty image's file name must end in `.png` or `.exr`; anything else would be written
/// as PNG under a misleading name.
pub fn check_beauty_ext(path: &Path) -> Result<()> {
    if has_ext(path, "png") || has_ext(path, "exr") {
        Ok(())
    } else {
        Err(Error::Usage(format!("{}: the image is written as .png (8-bit sRGB) or .exr (linear float); name it so", path.display())))
    }
}

pub fn write_rgb8_png(path: &Path, img: &image::RgbImage) -> Result<()> {
    // Encoded in memory, then written with `std::fs::write`, whose errors all surface:
    // `image`'s `save` writes through a `BufWriter` whose final flush, on drop, swallows them
    // (a full disk or a file-size limit left a truncated PNG and exit 0).
    let mut buf = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut buf), image::ImageFormat::Png)
        .map_err(|e| Error::Image(format!("{}: {e}", path.display())))?;
    write_atomic(path, |tmp| std::fs::write(tmp, &buf).map_err(|e| Error::io(path, e)))
}

/// Writes `w*h` linear RGB triples as a 32-bit float RGB EXR, atomically.
fn write_rgb32f_exr(path: &Path, w: u32, h: u32, px: impl Iterator<Item = [f32; 3]>) -> Result<()> {
    let n = w as usize * h as usize;
    let mut data = Vec::with_capacity(n * 3);
    for p in px {
        // NaN (never expected) is written as 0; ±inf is kept (the depth AOV's miss value).
        data.extend(p.map(|v| if v.is_nan() { 0.0 } else { v }));
    }
    if data.len() != n * 3 {
        return Err(Error::Image(format!("{}: film buffer has {} pixels, expected {w}x{h}", path.display(), data.len() / 3)));
    }
    let img = image::Rgb32FImage::from_raw(w, h, data)
        .ok_or_else(|| Error::Image(format!("{}: film buffer does not match {w}x{h}", path.display())))?;
    write_atomic(path, |tmp| {
        image::DynamicImage::ImageRgb32F(img).save_with_format(tmp, image::ImageFormat::OpenExr).map_err(|e| {
            // The EXR encoder reports its write errors as "Format error decoding OpenExr: ...".
            let e = e.to_string();
            let why = e.strip_prefix("Format error decoding OpenExr: ").unwrap_or(&e);
            Error::Image(format!("{}: cannot write the EXR file: {why}", path.display()))
        })
    })
}

/// The beauty image as linear RGB float EXR (no tone mapping, no clamping).
pub fn write_film_exr(path: &Path, film: &Film) -> Result<()> {
    write_rgb32f_exr(path, film.width, film.height, film.color.iter().map(|c| c.to_array()))
}

/// The depth AOV as float EXR, the distance in all three channels; misses are `+inf`, as
/// DESIGN.md specifies.
pub fn write_exr_depth(path: &Path, film: &Film) -> Result<()> {
    write_rgb32f_exr(path, film.width, film.height, film.depth.iter().map(|&d| [d, d, d]))
}

/// The normal AOV as float EXR: x, y, z in R, G, B (in [-1, 1]; zero for a miss).
pub fn write_exr_normal(path: &Path, film: &Film) -> Result<()> {
    write_rgb32f_exr(path, film.width, film.height, film.normal.iter().map(|n| n.to_array()))
}

/// A per-pixel scalar (`w*h`, row-major) as float EXR, the value in all three channels.
pub fn write_exr_scalar(path: &Path, w: u32, h: u32, v: &[f32]) -> Result<()> {
    write_rgb32f_exr(path, w, h, v.iter().map(|&x| [x, x, x]))
}

/// Largest image [`read_image_linear`] reads: 100 Mpixels (10000x10000), about 1.2 GB as
/// linear RGB, several of which `compare` holds at once.
pub const MAX_READ_PIXELS: u64 = 100_000_000;

/// A decoder's message without the Debug dump the png crate appends: "... while decoding
/// ChunkType { type: IHDR, critical: true, ... } chunk." becomes "... in the IHDR chunk".
fn plain_decoder_message(msg: &str) -> String {
    match msg.split_once(" while decoding ChunkType {") {
        Some((head, tail)) => {
            let ty = tail.trim_start().strip_prefix("type:").and_then(|t| t.split(',').next()).map(str::trim);
            match ty {
                Some(t) => format!("{head} in the {t} chunk"),
                None => head.to_string(),
            }
        }
        None => msg.to_string(),
    }
}

/// Reads a PNG (sRGB-encoded, converted to linear) or an EXR (already linear) as
/// `(width, height, linear RGB row-major)`. Alpha is dropped.
pub fn read_image_linear(path: &Path) -> Result<(u32, u32, Vec<Vec3>)> {
    let bad = |e: &dyn std::fmt::Display| {
        Error::Image(format!("{}: cannot read image: {}", path.display(), plain_decoder_message(&e.to_string())))
    };
    crate::error::check_input_file(path)?;
    let reader = image::ImageReader::open(path).map_err(|e| Error::io(path, e))?;
    let reader = reader.with_guessed_format().map_err(|e| Error::io(path, e))?;
    let format = reader.format().ok_or_else(|| bad(&"not a PNG or EXR file"))?;
    let linear = match format {
        image::ImageFormat::OpenExr => true,
        image::ImageFormat::Png => false,
        other => return Err(bad(&format!("{other:?} files are not supported (PNG or EXR)"))),
    };
    // The size first: the decoder's default allocation limit (512 MiB) would refuse a
    // 20000x20000 PNG with "Memory limit exceeded", naming neither size nor limit.
    if let Ok((w, h)) = image::image_dimensions(path) {
        let px = w as u64 * h as u64;
        if px > MAX_READ_PIXELS {
            return Err(bad(&format!("{w}x{h} is too large to read (at most {} Mpixels)", MAX_READ_PIXELS / 1_000_000)));
        }
        // Decoded, converted and compared: about 100 bytes per pixel (`compare`, 512² against
        // 2048², `/usr/bin/time -f %M`).
        crate::error::check_memory(px * 100, &format!("{w}x{h}")).map_err(|m| bad(&m))?;
    }
    let mut reader = reader;
    let mut limits = image::Limits::default();
    // Room for the largest image accepted above as 32-bit float RGBA.
    limits.max_alloc = Some(MAX_READ_PIXELS * 16 + (64 << 20));
    reader.limits(limits);
    // A malformed file must give an error, not a panic: decoders are guarded as well.
    let decoded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| reader.decode()))
        .map_err(|_| bad(&"decoder failed on malformed data"))?
        .map_err(|e| bad(&e))?;
    let (w, h) = (decoded.width(), decoded.height());
    if w == 0 || h == 0 {
        return Err(bad(&"image is empty"));
    }
    let rgb = decoded.into_rgb32f();
    // A NaN pixel means nothing to a metric (a float EXR can hold one). Infinity stays: the
    // depth AOV writes it where a ray meets nothing.
    if let Some((i, _)) = rgb.pixels().enumerate().find(|(_, p)| p.0.iter().any(|v| v.is_nan())) {
        let (x, y) = (i as u32 % w, i as u32 / w);
        return Err(bad(&format!("pixel ({x}, {y}) is NaN")));
    }
    let px = rgb
        .pixels()
        .map(|p| {
            let v = Vec3::from_array(p.0);
            if linear {
                v
            } else {
                Vec3::new(srgb_to_linear(v.x), srgb_to_linear(v.y), srgb_to_linear(v.z))
            }
        })
        .collect();
    Ok((w, h, px))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(p: &Path, s: &str) -> Result<()> {
        write_atomic(p, |tmp| std::fs::write(tmp, s).map_err(|e| Error::io(tmp, e)))
    }

    fn listing(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into()).collect();
        v.sort();
        v
    }

    /// A failed run into an earlier run's folder puts back the files it replaced (written
    /// twice included) and removes its new ones; a run that succeeds leaves no backups.
    #[test]
    fn a_failed_rerun_restores_the_earlier_files() {
        let d = std::env::temp_dir().join(format!("lodtrace-io-restore-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let (a, b) = (d.join("a.txt"), d.join("b.txt"));
        text(&a, "first run").unwrap();
        let r: Result<()> = discard_dir_on_error(Some(&d), || {
            text(&a, "second run")?;
            text(&a, "second run, again")?;
            text(&b, "new")?;
            // A folder made inside the existing one (the demo's per-scene folders), and a
            // nested scope that succeeds: the outer failure undoes it all.
            create_out_dir(&d.join("sub/deeper"))?;
            discard_dir_on_error(Some(&d.join("sub")), || text(&d.join("sub/c.txt"), "inner"))?;
            Err(Error::Usage("failed".into()))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "first run");
        assert_eq!(listing(&d), ["a.txt"]);
        discard_dir_on_error(Some(&d), || {
            text(&a, "third run")?;
            text(&b, "new")
        })
        .unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "third run");
        assert_eq!(listing(&d), ["a.txt", "b.txt"]);
        let _ = std::fs::remove_dir_all(&d);
    }
}
