//! Image files: PNG beauty (8-bit sRGB), EXR AOVs, all written atomically.

use super::{linear_to_srgb, Film};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// Writes via `write` to a temporary file beside `path`, then renames it into place.
pub fn write_atomic(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        return Err(Error::io(dir, std::io::Error::new(std::io::ErrorKind::NotFound, "output folder does not exist")));
    }
    let name = path.file_name().ok_or_else(|| Error::Usage(format!("{}: not a file name", path.display())))?;
    let ext = path.extension().map(|e| e.to_string_lossy().to_string()).unwrap_or_default();
    let tmp: PathBuf = dir.join(format!(".{}.{}.tmp.{}", name.to_string_lossy(), std::process::id(), ext));
    let r = write(&tmp);
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
        return r;
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
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

pub fn write_rgb8_png(path: &Path, img: &image::RgbImage) -> Result<()> {
    write_atomic(path, |tmp| {
        img.save_with_format(tmp, image::ImageFormat::Png).map_err(|e| Error::Image(format!("{}: {e}", path.display())))
    })
}
