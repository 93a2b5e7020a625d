//! `lodtrace compare A B [--diff FILE.png] [--region NAME=X0,Y0,X1,Y1]... [--max-flip F]
//! [--min-psnr DB] [--json]`.
//!
//! Loads two images (PNG as sRGB, EXR as linear; see `film::io::read_image_linear`), A being
//! the reference, and prints RMSE, PSNR, mean FLIP and SSIM (`film::metrics`) as a small
//! table, or as one JSON object with `--json` (`psnr_db` is `null` when the images are
//! identical, i.e. PSNR is infinite). `--diff` writes FLIP's magma-coloured error map.
//! `--region` (repeatable) splits the error by image region: each rectangle's mean FLIP
//! (taken from the whole image's map), its share of the image's total FLIP error, and its
//! RMSE — which part of a scene (the plants of `complex`, its floor) carries the error.
//! Exit codes: 0 all thresholds met, 1 a threshold failed (each failure is named on stderr),
//! 2 bad input (unreadable files, different sizes, a NaN pixel or an infinity in one image
//! only, bad thresholds).

use crate::error::{Error, Result};
use crate::film::{io, metrics};
use std::fmt::Write as _;
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
    #[arg(long, allow_hyphen_values = true)]
    pub max_flip: Option<f64>,
    /// Fail (exit 1) if the PSNR in dB is below this value.
    #[arg(long, allow_hyphen_values = true)]
    pub min_psnr: Option<f64>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Report the error inside a pixel rectangle, `NAME=X0,Y0,X1,Y1` (half-open, rows from the
    /// top; NAME= is optional), repeatable: mean FLIP, share of the total FLIP error, RMSE,
    /// luminance bias against the reference and the smooth share of the squared error
    /// (scales of 8 pixels or more: bias rather than noise or aliasing).
    #[arg(long = "region", value_name = "NAME=X0,Y0,X1,Y1")]
    pub regions: Vec<String>,
}

/// A `--region`: name and half-open pixel rectangle.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    pub name: String,
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

/// Parses `NAME=X0,Y0,X1,Y1` (or `X0,Y0,X1,Y1`) and checks it against a `w`×`h` image.
/// All `--region` options: each parsed, and their names distinct (they key the JSON).
pub fn parse_regions(list: &[String], w: u32, h: u32) -> Result<Vec<Region>> {
    let regions = list.iter().map(|s| parse_region(s, w, h)).collect::<Result<Vec<_>>>()?;
    for (i, r) in regions.iter().enumerate() {
        if regions[..i].iter().any(|q| q.name == r.name) {
            return Err(Error::Usage(format!("--region name '{}' given twice", r.name)));
        }
    }
    Ok(regions)
}

pub fn parse_region(s: &str, w: u32, h: u32) -> Result<Region> {
    let bad = |why: &str| Error::Usage(format!("--region '{s}': {why} (expected NAME=X0,Y0,X1,Y1 inside the {w}x{h} image)"));
    let (name, rect) = match s.split_once('=') {
        Some((n, r)) => (n.trim().to_string(), r),
        None => (s.trim().to_string(), s),
    };
    if name.is_empty() {
        return Err(bad("empty name"));
    }
    // The name heads a column of the tables (stdout, bench.md): a newline split the row, a
    // '|' added a column to the Markdown table.
    if name.chars().any(|c| c.is_control() || c == '|') {
        return Err(bad("the name may not hold control characters or '|'"));
    }
    let v: Vec<u32> = rect
        .split(',')
        .map(|t| t.trim().parse::<u32>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad("four whole pixel numbers"))?;
    let [x0, y0, x1, y1] = v[..] else { return Err(bad("four whole pixel numbers")) };
    if !(x0 < x1 && y0 < y1) {
        return Err(bad("empty rectangle"));
    }
    if x1 > w || y1 > h {
        return Err(bad("outside the image"));
    }
    Ok(Region { name, x0, y0, x1, y1 })
}

/// Side of the blocks [`region_figures`] splits a region's squared error over: error that
/// survives averaging over 8×8 pixels is systematic (coverage, colour, shading), the rest is
/// fine-scale (aliasing, noise).
pub const SMOOTH_BLOCK: u32 = 8;

/// Where a region's error sits and what kind it is.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct RegionFigures {
    /// Mean of the whole image's per-pixel FLIP values over the region.
    pub flip_mean: f64,
    /// The region's part of the image's FLIP sum.
    pub flip_share: f64,
    pub rmse: f64,
    /// Relative luminance bias, mean Y(b) ÷ mean Y(a) − 1 (Rec. 709 weights on linear
    /// display values, clamped to [0, 1] as FLIP sees them): above 0 the image under test is brighter than the reference there (for
    /// foliage, typically too much coverage of a bright surface or too little of a dark one).
    /// `None` (shown as n/a, `null` in JSON) where the reference region is black: the ratio
    /// is undefined there.
    pub luma_bias: Option<f64>,
    /// The part of the region's squared error at scales of [`SMOOTH_BLOCK`] pixels or more:
    /// Σ over blocks of n·(block mean of the difference)² ÷ Σ difference², per channel
    /// summed, on display values (clamped to [0, 1]). It is exact: the remainder is the
    /// within-block variance of the difference.
    /// Near 0 the error is aliasing or noise; near 1 it is bias that no amount of samples
    /// would remove. `None` (n/a, `null` in JSON) for a region narrower or lower than one
    /// block: there every block is cut, scales under 8 pixels count as smooth, and a region
    /// of one pixel read 100 % (until stop 81).
    pub smooth_share: Option<f64>,
}

/// Per-region figures ([`RegionFigures`]) from the whole image's per-pixel FLIP values
/// `flip` (their sum `total`) and the two images `a` (reference) and `b`.
pub fn region_figures(r: &Region, flip: &[f32], total: f64, a: &[glam::Vec3], b: &[glam::Vec3], w: u32) -> RegionFigures {
    // As `metrics::rmse`: a non-finite channel counts as 0.
    let fz = |v: f32| if v.is_finite() { v as f64 } else { 0.0 };
    // The kind of error is judged on display values, as FLIP is: unclamped, the squared
    // error of a film is dominated by a few highlights far above 1.
    let fd = |v: f32| fz(v).clamp(0.0, 1.0);
    let luma = |v: glam::Vec3| 0.2126 * fd(v.x) + 0.7152 * fd(v.y) + 0.0722 * fd(v.z);
    let (mut fsum, mut sq, mut n) = (0.0f64, 0.0f64, 0usize);
    let (mut ya, mut yb, mut smooth, mut sq_display) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for by in (r.y0..r.y1).step_by(SMOOTH_BLOCK as usize) {
        for bx in (r.x0..r.x1).step_by(SMOOTH_BLOCK as usize) {
            let (mut dsum, mut nb) = ([0.0f64; 3], 0usize);
            for y in by..(by + SMOOTH_BLOCK).min(r.y1) {
                for x in bx..(bx + SMOOTH_BLOCK).min(r.x1) {
                    let i = (y * w + x) as usize;
                    let f = flip[i];
                    fsum += if f.is_finite() { f as f64 } else { 0.0 };
                    for (c, ds) in dsum.iter_mut().enumerate() {
                        let d = fz(b[i][c]) - fz(a[i][c]);
                        sq += d * d;
                        let dd = fd(b[i][c]) - fd(a[i][c]);
                        sq_display += dd * dd;
                        *ds += dd;
                    }
                    ya += luma(a[i]);
                    yb += luma(b[i]);
                    n += 1;
                    nb += 1;
                }
            }
            smooth += dsum.iter().map(|d| d * d).sum::<f64>() / nb as f64;
        }
    }
    RegionFigures {
        flip_mean: fsum / n as f64,
        flip_share: if total > 0.0 { fsum / total } else { 0.0 },
        rmse: (sq / (3 * n) as f64).sqrt(),
        luma_bias: (ya > 0.0).then(|| yb / ya - 1.0),
        smooth_share: (r.x1 - r.x0 >= SMOOTH_BLOCK && r.y1 - r.y0 >= SMOOTH_BLOCK).then_some(if sq_display > 0.0 {
            (smooth / sq_display).min(1.0)
        } else {
            0.0
        }),
    }
}

/// A smooth share ([`RegionFigures::smooth_share`]) as a percentage with `digits` decimals
/// and `sep` before the `%`, or `n/a` for a region smaller than a block.
pub fn smooth_share_text(s: Option<f64>, digits: usize, sep: &str) -> String {
    s.map_or_else(|| "n/a".to_string(), |v| format!("{:.digits$}{sep}%", 100.0 * v))
}

/// A luma bias as a signed percentage (`+1.2%`, with `sep` before the `%`), or `n/a` where
/// it is undefined (a black reference region).
pub fn luma_bias_text(b: Option<f64>, sep: &str) -> String {
    b.map_or_else(|| "n/a".to_string(), |b| format!("{:+.1}{sep}%", 100.0 * b))
}

pub fn run(a: &CompareArgs) -> Result<i32> {
    for (name, v) in [("--max-flip", a.max_flip), ("--min-psnr", a.min_psnr)] {
        if let Some(v) = v {
            if v.is_nan() {
                return Err(Error::Usage(format!("{name} must be a number, not NaN")));
            }
        }
    }
    // Mean FLIP lies in [0, 1]; a negative bound could never pass. (`--min-psnr inf` is
    // meaningful: it asks for identical images; −inf would pass anything.)
    if let Some(m) = a.min_psnr {
        if m == f64::NEG_INFINITY || m.abs() > 1e6 && m.is_finite() {
            return Err(Error::Usage(format!("--min-psnr {m:e} out of range: a PSNR bound in dB, or inf for identical images")));
        }
    }
    if let Some(m) = a.max_flip {
        if !(0.0..=1.0).contains(&m) {
            let m = if m.abs() < 1e9 { format!("{m}") } else { format!("{m:e}") };
            return Err(Error::Usage(format!("--max-flip {m} out of range [0, 1]")));
        }
    }
    if let Some(p) = &a.diff {
        super::render::check_out_path(p)?;
        if p.extension().map(|e| e.to_ascii_lowercase()) != Some("png".into()) {
            return Err(Error::Usage(format!("{}: the --diff map is a PNG; name it NAME.png", p.display())));
        }
        io::check_distinct(&[&a.a, p])?;
        io::check_distinct(&[&a.b, p])?;
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
    // The metrics count a non-finite channel as 0: right where both images have the same
    // infinity (a depth AOV's background, where no ray meets anything), but elsewhere +inf
    // against 0.25 counted as an error of 0.25 and could pass a gate (the sweeps of stops 65
    // and 75). An infinity in one image only is refused, as a NaN is (`io::read_image_linear`).
    let inf = |p: &glam::Vec3, q: &glam::Vec3| (0..3).find(|&c| (p[c].is_infinite() || q[c].is_infinite()) && p[c] != q[c]);
    let mut at = ia.iter().zip(&ib).enumerate().filter_map(|(i, (p, q))| inf(p, q).map(|c| (i, c)));
    if let Some((i, c)) = at.next() {
        let n_inf = 1 + at.count();
        let (p, q) = (ia[i][c], ib[i][c]);
        let (file, v, other, ov) = if p.is_infinite() { (&a.a, p, &a.b, q) } else { (&a.b, q, &a.a, p) };
        return Err(Error::parse(
            file,
            format!(
                "pixel ({}, {}) is {v} where {} has {ov} ({n_inf} pixel{} infinite in one image only): the metrics cannot measure that difference; only infinities both images share (a depth AOV's background) are compared",
                i as u32 % w,
                i as u32 / w,
                other.display(),
                if n_inf == 1 { "" } else { "s" }
            ),
        ));
    }
    // FLIP and SSIM judge display values clamped to [0, 1]: above 1 (HDR highlights, depth
    // AOVs) every value looks alike to them (two depth maps of different views: FLIP 0, SSIM 1).
    let over = ia.iter().zip(&ib).filter(|(p, q)| p.max_element() > 1.0 || q.max_element() > 1.0).count();
    if over * 100 > ia.len() {
        crate::error::warn(format!(
            "{:.1} % of the pixels exceed 1 (HDR or an AOV such as depth): FLIP and SSIM see display values clamped to [0, 1] and cannot tell those apart; judge by RMSE and PSNR",
            100.0 * over as f64 / ia.len().max(1) as f64
        ));
    }
    let regions = parse_regions(&a.regions, w, h)?;
    let rmse = metrics::rmse(&ia, &ib, w, h);
    let psnr = metrics::psnr(&ia, &ib, w, h);
    let ssim = metrics::ssim(&ia, &ib, w, h);
    let (flip_values, flip_map) = metrics::flip_map(&ia, &ib, w, h)?;
    let flip = metrics::mean_finite(&flip_values);
    // Removed again if the report cannot be printed (`> /dev/full`): a failed run leaves
    // no outputs.
    let mut outs = io::Outputs::default();
    if let Some(p) = &a.diff {
        outs.wrote(p, io::write_rgb8_png(p, &flip_map))?;
    }
    let per_region: Vec<RegionFigures> =
        regions.iter().map(|r| region_figures(r, &flip_values, flip * flip_values.len() as f64, &ia, &ib, w)).collect();

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

    // Written to stdout in one piece (errors there are errors, not panics).
    let mut text = String::new();
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
            "regions": regions.iter().zip(&per_region).map(|(r, g)| serde_json::json!({
                "name": r.name, "x0": r.x0, "y0": r.y0, "x1": r.x1, "y1": r.y1,
                "flip_mean": g.flip_mean, "flip_share": g.flip_share, "rmse": g.rmse,
                "luma_bias": g.luma_bias, "smooth_share": g.smooth_share,
            })).collect::<Vec<_>>(),
            "pass": failed.is_empty(),
            "failed": failed,
        });
        text = serde_json::to_string_pretty(&v).map_err(|e| Error::Usage(format!("json: {e}")))? + "\n";
    } else {
        let _ = writeln!(text, "A: {} ({w}x{h})", a.a.display());
        let _ = writeln!(text, "B: {}", a.b.display());
        let psnr_s = if psnr.is_finite() { format!("{psnr:.3}") } else { "inf".to_string() };
        for (k, v) in
            [("RMSE", format!("{rmse:.6}")), ("PSNR (dB)", psnr_s), ("mean FLIP", format!("{flip:.6}")), ("SSIM", format!("{ssim:.6}"))]
        {
            let _ = writeln!(text, "  {k:<10} {v:>12}");
        }
        if !regions.is_empty() {
            let nw = regions.iter().map(|r| r.name.len()).max().unwrap_or(0).max(6);
            let _ = writeln!(
                text,
                "  {:<nw$}  {:>19}  {:>6}  {:>9}  {:>11}  {:>9}  {:>10}  {:>12}",
                "region", "x0,y0,x1,y1", "area", "mean FLIP", "FLIP share", "RMSE", "luma bias", "smooth share"
            );
            for (r, g) in regions.iter().zip(&per_region) {
                let area = ((r.x1 - r.x0) as f64 * (r.y1 - r.y0) as f64) / (w as f64 * h as f64);
                let rect = format!("{},{},{},{}", r.x0, r.y0, r.x1, r.y1);
                let _ = writeln!(
                    text,
                    "  {:<nw$}  {rect:>19}  {:>5.1}%  {:>9.6}  {:>10.1}%  {:>9.6}  {:>10}  {:>12}",
                    r.name,
                    100.0 * area,
                    g.flip_mean,
                    100.0 * g.flip_share,
                    g.rmse,
                    luma_bias_text(g.luma_bias, ""),
                    smooth_share_text(g.smooth_share, 1, "")
                );
            }
        }
    }
    crate::error::print_stdout(&text)?;
    outs.keep();
    for f in &failed {
        crate::status!("lodtrace: compare: FAIL: {f}");
    }
    Ok(if failed.is_empty() { 0 } else { 1 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn figures(b: impl Fn(u32, u32) -> Vec3, r: Region) -> RegionFigures {
        let (w, h) = (21u32, 13u32);
        let a = vec![Vec3::splat(0.5); (w * h) as usize];
        let b: Vec<Vec3> = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| b(x, y)).collect();
        let flip = vec![0.1f32; (w * h) as usize];
        region_figures(&r, &flip, 0.1 * (w * h) as f64, &a, &b, w)
    }

    fn region(x0: u32, y0: u32, x1: u32, y1: u32) -> Region {
        Region { name: "r".into(), x0, y0, x1, y1 }
    }

    #[test]
    fn a_uniform_offset_is_all_smooth_error_and_shows_as_bias() {
        // Blocks cut by the region's edges (21×13 is not a multiple of 8) still sum exactly.
        let g = figures(|_, _| Vec3::splat(0.6), region(0, 0, 21, 13));
        assert!((g.smooth_share.unwrap() - 1.0).abs() < 1e-9, "{g:?}");
        assert!((g.luma_bias.unwrap() - 0.2).abs() < 1e-6, "{g:?}");
        assert!((g.rmse - 0.1).abs() < 1e-6, "{g:?}");
        assert!((g.flip_mean - 0.1).abs() < 1e-6 && (g.flip_share - 1.0).abs() < 1e-6, "{g:?}");
    }

    #[test]
    fn pixel_scale_noise_is_fine_error_without_bias() {
        // ±0.1 in a pixel checkerboard: every 8×8 block (even sides) averages to zero.
        let g = figures(|x, y| Vec3::splat(if (x + y) % 2 == 0 { 0.6 } else { 0.4 }), region(1, 2, 17, 10));
        assert!(g.smooth_share.unwrap().abs() < 1e-9, "{g:?}");
        assert!(g.luma_bias.unwrap().abs() < 1e-6, "{g:?}");
        assert!((g.rmse - 0.1).abs() < 1e-6, "{g:?}");
    }

    #[test]
    fn smooth_share_splits_mixed_error_exactly() {
        // Offset +0.1 plus ±0.1 checkerboard: a smooth part of 0.01 and a fine part of 0.01
        // per pixel and channel, so half the squared error is smooth.
        let g = figures(|x, y| Vec3::splat(if (x + y) % 2 == 0 { 0.7 } else { 0.5 }), region(0, 0, 16, 8));
        assert!((g.smooth_share.unwrap() - 0.5).abs() < 1e-9, "{g:?}");
        // A black reference region: no bias figure to divide by, reported as undefined (n/a),
        // not NaN and not 0 (which read as "no bias").
        let w = 4u32;
        let a = vec![Vec3::ZERO; 16];
        let b = vec![Vec3::ONE; 16];
        let z = region_figures(&region(0, 0, 4, 4), &[0.0; 16], 0.0, &a, &b, w);
        assert!(z.luma_bias.is_none() && z.flip_share == 0.0, "{z:?}");
        assert_eq!(luma_bias_text(z.luma_bias, ""), "n/a");
        assert_eq!(luma_bias_text(Some(0.0123), " "), "+1.2 %");
        // A highlight far above 1 counts as display white for bias, not as 9.5² of error.
        let g = figures(|x, y| Vec3::splat(if (x, y) == (3, 3) { 10.0 } else { 0.5 }), region(0, 0, 8, 8));
        assert!((g.luma_bias.unwrap() - 0.5 / 64.0 / 0.5).abs() < 1e-9, "{g:?}");
        assert!((g.smooth_share.unwrap() - 1.0 / 64.0).abs() < 1e-9, "{g:?}");
    }

    /// A region narrower or lower than one block has no scale split: n/a, not the 100 % that
    /// a one-pixel region read (every block cut, all its error counted as smooth).
    #[test]
    fn smooth_share_of_a_region_smaller_than_a_block_is_undefined() {
        let fine = |x: u32, y: u32| Vec3::splat(if (x + y).is_multiple_of(2) { 0.6 } else { 0.4 });
        for r in [region(3, 3, 4, 4), region(0, 0, 7, 13), region(0, 0, 21, 7)] {
            let g = figures(fine, r.clone());
            assert!(g.smooth_share.is_none(), "{r:?}: {g:?}");
        }
        assert_eq!(smooth_share_text(None, 1, ""), "n/a");
        assert_eq!(smooth_share_text(Some(0.25), 0, " "), "25 %");
        // One block exactly: defined, and this pixel-scale error is all fine.
        assert!(figures(fine, region(0, 0, 8, 8)).smooth_share.unwrap().abs() < 1e-9);
    }
}
