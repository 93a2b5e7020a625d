//! `lodtrace compare A B [--diff FILE.png] [--max-flip F] [--min-psnr DB] [--json]`.
//!
//! Loads two images (PNG as sRGB, EXR as linear; see `film::io::read_image_linear`), A being
//! the reference, and prints RMSE, PSNR, mean FLIP and SSIM (`film::metrics`) as a small
//! table, or as one JSON object with `--json` (`psnr_db` is `null` when the images are
//! identical, i.e. PSNR is infinite). `--diff` writes FLIP's magma-coloured error map.
//! Exit codes: 0 all thresholds met, 1 a threshold failed (each failure is named on stderr),
//! 2 bad input (unreadable files, different sizes, bad thresholds).

use crate::error::{Error, Result};
use crate::film::{io, metrics};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct CompareArgs {
    /// Reference image (.png or .exr).
    pub a: PathBuf,
    /// Test image (.png or .exr), same size as A.
    pub b: PathBuf,
    /// Write the FLIP error map (magma colours) to this PNG.
    #[arg(long)]
    pub diff: Option<PathBuf>,
    /// Fail (exit 1) if the mean FLIP error is above this value.
    #[arg(long)]
    pub max_flip: Option<f64>,
    /// Fail (exit 1) if the PSNR in dB is below this value.
    #[arg(long)]
    pub min_psnr: Option<f64>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &CompareArgs) -> Result<i32> {
    for (name, v) in [("--max-flip", a.max_flip), ("--min-psnr", a.min_psnr)] {
        if let Some(v) = v {
            if v.is_nan() {
                return Err(Error::Usage(format!("{name} must be a number, not NaN")));
            }
        }
    }
    let (wa, ha, ia) = io::read_image_linear(&a.a)?;
    let (wb, hb, ib) = io::read_image_linear(&a.b)?;
    if (wa, ha) != (wb, hb) {
        return Err(Error::Usage(format!(
            "compare needs images of the same size: {} is {wa}x{ha}, {} is {wb}x{hb}",
            a.a.display(),
            a.b.display()
        )));
    }
    let (w, h) = (wa, ha);
    let rmse = metrics::rmse(&ia, &ib, w, h);
    let psnr = metrics::psnr(&ia, &ib, w, h);
    let ssim = metrics::ssim(&ia, &ib, w, h);
    let (flip, flip_map) = metrics::flip_mean(&ia, &ib, w, h)?;
    if let Some(p) = &a.diff {
        io::write_rgb8_png(p, &flip_map)?;
    }

    let mut failed = Vec::new();
    if let Some(m) = a.max_flip {
        if flip > m {
            failed.push(format!("mean FLIP {flip:.6} is above --max-flip {m}"));
        }
    }
    if let Some(m) = a.min_psnr {
        if psnr < m {
            failed.push(format!("PSNR {psnr:.3} dB is below --min-psnr {m}"));
        }
    }

    if a.json {
        let v = serde_json::json!({
            "a": a.a.display().to_string(),
            "b": a.b.display().to_string(),
            "width": w,
            "height": h,
            "rmse": rmse,
            "psnr_db": if psnr.is_finite() { Some(psnr) } else { None },
            "flip_mean": flip,
            "ssim": ssim,
            "pass": failed.is_empty(),
            "failed": failed,
        });
        println!("{}", serde_json::to_string_pretty(&v).map_err(|e| Error::Usage(format!("json: {e}")))?);
    } else {
        println!("A: {} ({w}x{h})", a.a.display());
        println!("B: {}", a.b.display());
        let psnr_s = if psnr.is_finite() { format!("{psnr:.3}") } else { "inf".to_string() };
        for (k, v) in
            [("RMSE", format!("{rmse:.6}")), ("PSNR (dB)", psnr_s), ("mean FLIP", format!("{flip:.6}")), ("SSIM", format!("{ssim:.6}"))]
        {
            println!("  {k:<10} {v:>12}");
        }
    }
    for f in &failed {
        eprintln!("lodtrace: compare: FAIL: {f}");
    }
    Ok(if failed.is_empty() { 0 } else { 1 })
}
