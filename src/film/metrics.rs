//! Image error metrics used by `lodtrace compare` and the bench tables.
//!
//! All functions take two images of the same size as linear RGB, row-major (`w*h` pixels).
//! `a` is the reference, `b` the test image.
//!
//! - **RMSE** — root of the mean squared difference over all pixels and the three linear
//!   RGB channels, on the raw linear values (no clamping, so HDR differences count in full).
//!   A non-finite component (NaN, ±inf) is treated as 0, so one bad pixel cannot make the
//!   whole figure NaN (it still counts as an error against a non-zero reference).
//! - **PSNR** — `20·log10(peak / RMSE)` with peak 1.0 (linear white), in dB; `+inf` for
//!   identical images. A constant difference of 0.1 gives RMSE 0.1 and PSNR 20 dB.
//! - **FLIP** — NVIDIA's perceptual difference (Andersson et al. 2020, "FLIP: A Difference
//!   Evaluator for Alternating Images"), LDR variant, via the `nv-flip` crate, on the 8-bit
//!   sRGB versions of both images (as written to PNG, i.e. clamped to \[0, 1\]) at the default
//!   67 pixels per degree. We report the exact mean of the per-pixel error map (0 = same,
//!   1 = maximal) and return the map coloured with the magma LUT, as FLIP's own tool does.
//! - **SSIM** — structural similarity (Wang et al. 2004) on the luma of the sRGB-encoded
//!   values (`Y' = 0.299 R' + 0.587 G' + 0.114 B'`, the usual `rgb2gray`), in \[0, 1\]
//!   so `C1 = (0.01)^2`, `C2 = (0.03)^2`; 11x11 Gaussian window with σ = 1.5, evaluated at
//!   the "valid" positions only (the window fully inside the image) and averaged, as in the
//!   reference implementation. Images smaller than 11 pixels on a side use the largest odd
//!   window that fits, σ scaled with it. 1 for identical images.
//! - **diff image** — per-channel absolute difference of the linear values, normalised so the
//!   largest difference is full white, then sRGB-encoded (which brightens small differences)
//!   so that the structure of the error is visible.
//! - **cost map** ([`cost_map`]) — not a metric: a per-pixel count (the cone tracers' tests
//!   per pixel) on a log scale, ln(1 + v) / ln(1 + max), coloured with the same magma LUT
//!   (black = 0, pale yellow = the maximum).

use super::linear_to_srgb;
use crate::error::{Error, Result};
use glam::Vec3;

#[inline]
fn finite_or_zero(v: f32) -> f64 {
    if v.is_finite() {
        v as f64
    } else {
        0.0
    }
}

fn check(a: &[Vec3], b: &[Vec3], w: u32, h: u32) -> Result<usize> {
    let n = w as usize * h as usize;
    if a.len() != n || b.len() != n {
        return Err(Error::Usage(format!("image metrics: sizes differ (expected {w}x{h} = {n} pixels, got {} and {})", a.len(), b.len())));
    }
    Ok(n)
}

/// Root mean squared error over the linear RGB channels (non-finite values count as 0).
pub fn rmse(a: &[Vec3], b: &[Vec3], w: u32, h: u32) -> f64 {
    debug_assert_eq!(a.len(), w as usize * h as usize);
    debug_assert_eq!(b.len(), w as usize * h as usize);
    let n = a.len().min(b.len());
    if n == 0 {
        return 0.0;
    }
    let mut sum = 0.0f64;
    for (p, q) in a.iter().zip(b) {
        for c in 0..3 {
            let d = finite_or_zero(p[c]) - finite_or_zero(q[c]);
            sum += d * d;
        }
    }
    (sum / (3 * n) as f64).sqrt()
}

/// Peak signal-to-noise ratio in dB with peak 1.0; `+inf` for identical images.
pub fn psnr(a: &[Vec3], b: &[Vec3], w: u32, h: u32) -> f64 {
    let e = rmse(a, b, w, h);
    if e == 0.0 {
        f64::INFINITY
    } else {
        -20.0 * e.log10()
    }
}

/// 8-bit sRGB bytes of a linear image, quantised as `io::to_rgb8` does.
fn srgb8(a: &[Vec3]) -> Vec<u8> {
    let mut out = Vec::with_capacity(a.len() * 3);
    for c in a {
        for v in [c.x, c.y, c.z] {
            out.push((linear_to_srgb(v) * 255.0 + 0.5) as u8);
        }
    }
    out
}

/// Mean LDR FLIP error of `b` against reference `a`, and the magma-coloured error map.
pub fn flip_mean(a: &[Vec3], b: &[Vec3], w: u32, h: u32) -> Result<(f64, image::RgbImage)> {
    let (values, map) = flip_map(a, b, w, h)?;
    Ok((mean_finite(&values), map))
}

/// Per-pixel LDR FLIP error of `b` against reference `a` (row-major, `w·h` values in [0, 1]),
/// and the magma-coloured map of it. Region means are taken from this full-image map, so a
/// region's figure sees the same filtered neighbourhood as the whole image's mean.
pub fn flip_map(a: &[Vec3], b: &[Vec3], w: u32, h: u32) -> Result<(Vec<f32>, image::RgbImage)> {
    let n = check(a, b, w, h)?;
    if n == 0 {
        return Err(Error::Usage("FLIP: images are empty".into()));
    }
    let ref_img = nv_flip::FlipImageRgb8::with_data(w, h, &srgb8(a));
    let test_img = nv_flip::FlipImageRgb8::with_data(w, h, &srgb8(b));
    let err = nv_flip::flip(ref_img, test_img, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    // The exact values (FlipPool's mean is histogram-based, i.e. binned).
    let values = err.to_vec();
    let vis = err.apply_color_lut(&nv_flip::magma_lut());
    let map = image::RgbImage::from_raw(w, h, vis.to_vec()).ok_or_else(|| Error::Image("FLIP: error map has the wrong size".into()))?;
    Ok((values, map))
}

/// Mean of the finite values (non-finite count as 0); 0 for none.
pub fn mean_finite(v: &[f32]) -> f64 {
    v.iter().map(|&x| finite_or_zero(x)).sum::<f64>() / v.len().max(1) as f64
}

/// Luma of the sRGB-encoded values, in \[0, 1\].
fn luma(a: &[Vec3]) -> Vec<f64> {
    a.iter().map(|c| 0.299 * linear_to_srgb(c.x) as f64 + 0.587 * linear_to_srgb(c.y) as f64 + 0.114 * linear_to_srgb(c.z) as f64).collect()
}

/// Normalised 1-D Gaussian of odd size `k`.
fn gaussian(k: usize, sigma: f64) -> Vec<f64> {
    let r = (k / 2) as f64;
    let g: Vec<f64> = (0..k).map(|i| (-((i as f64 - r).powi(2)) / (2.0 * sigma * sigma)).exp()).collect();
    let s: f64 = g.iter().sum();
    g.into_iter().map(|v| v / s).collect()
}

/// Separable "valid" filtering of a `w x h` image with kernel `g`: output `(w-k+1) x (h-k+1)`.
fn filter_valid(x: &[f64], w: usize, h: usize, g: &[f64]) -> Vec<f64> {
    let k = g.len();
    let (ow, oh) = (w + 1 - k, h + 1 - k);
    // Horizontal pass: h rows of ow.
    let mut tmp = vec![0.0; ow * h];
    for j in 0..h {
        let row = &x[j * w..(j + 1) * w];
        for i in 0..ow {
            tmp[j * ow + i] = g.iter().zip(&row[i..i + k]).map(|(a, b)| a * b).sum();
        }
    }
    // Vertical pass.
    let mut out = vec![0.0; ow * oh];
    for j in 0..oh {
        for i in 0..ow {
            let mut s = 0.0;
            for (t, gt) in g.iter().enumerate() {
                s += gt * tmp[(j + t) * ow + i];
            }
            out[j * ow + i] = s;
        }
    }
    out
}

/// Mean SSIM of the sRGB luma (11x11 Gaussian window, σ 1.5, valid positions only).
pub fn ssim(a: &[Vec3], b: &[Vec3], w: u32, h: u32) -> f64 {
    debug_assert_eq!(a.len(), w as usize * h as usize);
    debug_assert_eq!(b.len(), w as usize * h as usize);
    let (wu, hu) = (w as usize, h as usize);
    if wu * hu == 0 || a.len() != wu * hu || b.len() != wu * hu {
        return if a == b { 1.0 } else { 0.0 };
    }
    const C1: f64 = 0.01 * 0.01;
    const C2: f64 = 0.03 * 0.03;
    let mut k = 11.min(wu).min(hu);
    if k % 2 == 0 {
        k -= 1;
    }
    let g = gaussian(k, 1.5 * k as f64 / 11.0);
    let ya = luma(a);
    let yb = luma(b);
    let prod = |p: &[f64], q: &[f64]| p.iter().zip(q).map(|(x, y)| x * y).collect::<Vec<f64>>();
    let mu_a = filter_valid(&ya, wu, hu, &g);
    let mu_b = filter_valid(&yb, wu, hu, &g);
    let s_aa = filter_valid(&prod(&ya, &ya), wu, hu, &g);
    let s_bb = filter_valid(&prod(&yb, &yb), wu, hu, &g);
    let s_ab = filter_valid(&prod(&ya, &yb), wu, hu, &g);
    let mut sum = 0.0;
    for t in 0..mu_a.len() {
        let (ma, mb) = (mu_a[t], mu_b[t]);
        let va = s_aa[t] - ma * ma;
        let vb = s_bb[t] - mb * mb;
        let cov = s_ab[t] - ma * mb;
        sum += ((2.0 * ma * mb + C1) * (2.0 * cov + C2)) / ((ma * ma + mb * mb + C1) * (va + vb + C2));
    }
    sum / mu_a.len() as f64
}

/// The magma-coloured log-scale map of a per-pixel count (module docs); all black when every
/// count is 0.
pub fn cost_map(v: &[u32], w: u32, h: u32) -> Result<image::RgbImage> {
    cost_map_to(v, w, h, v.iter().copied().max().unwrap_or(0))
}

/// [`cost_map`] on a given scale: `max` (and above) is the LUT's brightest colour, so that
/// maps of two runs compare.
pub fn cost_map_to(v: &[u32], w: u32, h: u32, max: u32) -> Result<image::RgbImage> {
    if v.len() != w as usize * h as usize {
        return Err(Error::Image(format!("cost map: {} values for {w}x{h} pixels", v.len())));
    }
    let lut = nv_flip::magma_lut().to_vec();
    let n = lut.len() / 3;
    let scale = if max > 0 { 1.0 / (max as f64).ln_1p() } else { 0.0 };
    let mut img = image::RgbImage::new(w, h);
    for (p, &x) in img.pixels_mut().zip(v) {
        let i = (((x as f64).ln_1p() * scale) * (n - 1) as f64).round() as usize;
        let i = i.min(n - 1);
        *p = image::Rgb([lut[3 * i], lut[3 * i + 1], lut[3 * i + 2]]);
    }
    Ok(img)
}

/// Visible absolute difference: |a-b| per linear channel, normalised so the largest
/// difference is white, then sRGB-encoded. All black for identical images.
pub fn diff_image(a: &[Vec3], b: &[Vec3], w: u32, h: u32) -> image::RgbImage {
    debug_assert_eq!(a.len(), w as usize * h as usize);
    debug_assert_eq!(b.len(), w as usize * h as usize);
    let d: Vec<[f64; 3]> = a.iter().zip(b).map(|(p, q)| [0, 1, 2].map(|c| (finite_or_zero(p[c]) - finite_or_zero(q[c])).abs())).collect();
    let max = d.iter().flatten().fold(0.0f64, |m, &v| m.max(v));
    let scale = if max > 0.0 { 1.0 / max } else { 0.0 };
    let mut img = image::RgbImage::new(w, h);
    for (p, v) in img.pixels_mut().zip(&d) {
        *p = image::Rgb(v.map(|x| (linear_to_srgb((x * scale) as f32) * 255.0 + 0.5) as u8));
    }
    img
}
