//! Film outputs and image metrics: known answers for RMSE/PSNR/SSIM/FLIP, EXR and PNG round
//! trips, bad input, the `compare` command's exit codes, and the plot writers.

use glam::Vec3;
use lodtrace::film::{io, linear_to_srgb, metrics, Film};
use std::process::Command;

const W: u32 = 64;
const H: u32 = 48;

use crate::common::Scratch;

/// A fresh, empty folder unique to this test and process, removed when the test passes.
fn tmp(name: &str) -> Scratch {
    Scratch::new("lodtrace-film-test", name)
}

/// Deterministic pseudo-random value in [0,1).
fn hash01(k: u32) -> f32 {
    let mut x = k.wrapping_mul(0x9E37_79B9) ^ 0x85EB_CA6B;
    x ^= x >> 16;
    x = x.wrapping_mul(0x7FEB_352D);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846C_A68B);
    x ^= x >> 16;
    (x >> 8) as f32 / (1u32 << 24) as f32
}

/// A smooth colour gradient with some structure, values in [0.1, 0.8].
fn gradient(w: u32, h: u32) -> Vec<Vec3> {
    let mut v = Vec::new();
    for j in 0..h {
        for i in 0..w {
            let u = i as f32 / w as f32;
            let t = j as f32 / h as f32;
            let ring = 0.5 + 0.5 * ((u * 12.0).sin() * (t * 9.0).cos());
            v.push(Vec3::new(0.1 + 0.7 * u, 0.1 + 0.7 * t, 0.1 + 0.7 * ring));
        }
    }
    v
}

fn noisy(a: &[Vec3], amp: f32) -> Vec<Vec3> {
    a.iter()
        .enumerate()
        .map(|(k, c)| {
            let n = Vec3::new(hash01(3 * k as u32), hash01(3 * k as u32 + 1), hash01(3 * k as u32 + 2)) - 0.5;
            (*c + n * 2.0 * amp).max(Vec3::ZERO)
        })
        .collect()
}

fn film_from(w: u32, h: u32, color: Vec<Vec3>) -> Film {
    let mut f = Film::new(w, h);
    f.color = color;
    f
}

#[test]
fn rmse_psnr_identical() {
    let a = gradient(W, H);
    assert_eq!(metrics::rmse(&a, &a, W, H), 0.0);
    assert!(metrics::psnr(&a, &a, W, H).is_infinite());
}

#[test]
fn rmse_psnr_constant_offset() {
    let a = gradient(W, H);
    let b: Vec<Vec3> = a.iter().map(|c| *c + Vec3::splat(0.1)).collect();
    let r = metrics::rmse(&a, &b, W, H);
    assert!((r - 0.1).abs() < 1e-6, "rmse {r}");
    let p = metrics::psnr(&a, &b, W, H);
    assert!((p - 20.0).abs() < 1e-4, "psnr {p}");
    // One channel off by 0.3: rmse = sqrt(0.09 / 3).
    let c: Vec<Vec3> = a.iter().map(|c| *c + Vec3::new(0.3, 0.0, 0.0)).collect();
    assert!((metrics::rmse(&a, &c, W, H) - (0.03f64).sqrt()).abs() < 1e-6);
}

#[test]
fn rmse_treats_non_finite_as_zero() {
    let a = vec![Vec3::ZERO; 4];
    let mut b = a.clone();
    b[0] = Vec3::new(f32::NAN, f32::INFINITY, 0.0);
    assert_eq!(metrics::rmse(&a, &b, 2, 2), 0.0);
    b[1] = Vec3::splat(1.0);
    assert!(metrics::rmse(&a, &b, 2, 2).is_finite());
}

#[test]
fn ssim_identical_and_degraded() {
    let a = gradient(W, H);
    let s = metrics::ssim(&a, &a, W, H);
    assert!((s - 1.0).abs() < 1e-9, "ssim {s}");
    let b = noisy(&a, 0.1);
    let s2 = metrics::ssim(&a, &b, W, H);
    assert!(s2 < 0.95 && s2 > 0.0, "ssim degraded {s2}");
    let c = noisy(&a, 0.3);
    assert!(metrics::ssim(&a, &c, W, H) < s2, "more noise must lower SSIM");
    // Tiny images still work (window shrinks).
    let t = gradient(5, 4);
    assert!((metrics::ssim(&t, &t, 5, 4) - 1.0).abs() < 1e-9);
}

#[test]
fn flip_identical_and_very_different() {
    let a = gradient(W, H);
    let (m, map) = metrics::flip_mean(&a, &a, W, H).unwrap();
    assert!(m < 1e-4, "flip identical {m}");
    assert_eq!(map.dimensions(), (W, H));
    let black = vec![Vec3::ZERO; (W * H) as usize];
    let white = vec![Vec3::ONE; (W * H) as usize];
    let (m2, _) = metrics::flip_mean(&black, &white, W, H).unwrap();
    assert!(m2 > 0.3, "flip black/white {m2}");
    let (m3, _) = metrics::flip_mean(&a, &noisy(&a, 0.1), W, H).unwrap();
    assert!(m3 > m && m3 < m2, "flip noisy {m3}");
    // Mismatched sizes are an error, not a panic.
    assert!(metrics::flip_mean(&a, &black[..10], W, H).is_err());
}

#[test]
fn diff_image_visible() {
    let a = gradient(W, H);
    let same = metrics::diff_image(&a, &a, W, H);
    assert!(same.pixels().all(|p| p.0 == [0, 0, 0]));
    let mut b = a.clone();
    b[5] += Vec3::new(0.01, 0.0, 0.0);
    let d = metrics::diff_image(&a, &b, W, H);
    assert_eq!(d.get_pixel(5, 0).0[0], 255, "largest difference is white");
}

#[test]
fn exr_roundtrips() {
    let d = tmp("exr");
    let mut f = film_from(W, H, gradient(W, H));
    f.color[3] = Vec3::new(4.5, 0.0, 12.0); // HDR survives
    for (k, z) in f.depth.iter_mut().enumerate() {
        *z = if k % 7 == 0 { f32::INFINITY } else { 1.0 + k as f32 * 0.25 };
    }
    for (k, n) in f.normal.iter_mut().enumerate() {
        *n = if k % 7 == 0 { Vec3::ZERO } else { Vec3::new((k as f32).sin(), (k as f32).cos(), -0.5).normalize() };
    }
    let (pc, pd, pn) = (d.join("color.exr"), d.join("depth.exr"), d.join("normal.exr"));
    io::write_film_exr(&pc, &f).unwrap();
    io::write_exr_depth(&pd, &f).unwrap();
    io::write_exr_normal(&pn, &f).unwrap();

    let (w, h, c) = io::read_image_linear(&pc).unwrap();
    assert_eq!((w, h), (W, H));
    assert_eq!(c, f.color);

    let (w, h, z) = io::read_image_linear(&pd).unwrap();
    assert_eq!((w, h), (W, H));
    for (k, v) in z.iter().enumerate() {
        let want = f.depth[k]; // misses stay +inf (DESIGN.md)
        assert_eq!(*v, Vec3::splat(want), "depth pixel {k}");
    }

    let (_, _, n) = io::read_image_linear(&pn).unwrap();
    assert_eq!(n, f.normal);
    // No temporary files left behind.
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 3);
}

#[test]
fn png_roundtrip_within_quantisation() {
    let d = tmp("png");
    let f = film_from(W, H, gradient(W, H));
    let p = d.join("beauty.png");
    io::write_png(&p, &f).unwrap();
    let (w, h, c) = io::read_image_linear(&p).unwrap();
    assert_eq!((w, h), (W, H));
    for (x, y) in c.iter().zip(&f.color) {
        for k in 0..3 {
            let e = (linear_to_srgb(x[k]) - linear_to_srgb(y[k])).abs();
            assert!(e <= 0.5 / 255.0 + 1e-5, "sRGB error {e}");
        }
    }
    assert!(metrics::psnr(&c, &f.color, W, H) > 45.0);
}

#[test]
fn read_bad_files_is_err() {
    let d = tmp("bad");
    let missing = d.join("nope.png");
    let e = io::read_image_linear(&missing).unwrap_err().to_string();
    assert!(e.contains("nope.png"), "{e}");
    for (name, bytes) in
        [("garbage.png", &b"this is not an image at all"[..]), ("garbage.exr", &b"\x76\x2f\x31\x01garbage"[..]), ("empty.png", &b""[..])]
    {
        let p = d.join(name);
        std::fs::write(&p, bytes).unwrap();
        let e = io::read_image_linear(&p).unwrap_err().to_string();
        assert!(e.contains(name), "{e}");
        assert!(!e.contains('\n'), "one line: {e}");
    }
    // A truncated PNG.
    let good = d.join("good.png");
    io::write_png(&good, &film_from(W, H, gradient(W, H))).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let cut = d.join("cut.png");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    assert!(io::read_image_linear(&cut).is_err());
    // A CRC error in the header chunk: named plainly, without the decoder's Debug dump
    // ("while decoding ChunkType { type: IHDR, critical: true, ... }").
    let mut crc = bytes.clone();
    crc[29] ^= 1; // the first byte of IHDR's CRC (after the 8-byte signature, length, type and 13 data bytes)
    let p = d.join("crc.png");
    std::fs::write(&p, &crc).unwrap();
    let e = io::read_image_linear(&p).unwrap_err().to_string();
    assert!(e.contains("crc.png") && e.contains("IHDR") && !e.contains('{'), "{e}");
}

fn lodtrace(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_lodtrace")).args(args).output().unwrap()
}

#[test]
fn compare_cli() {
    let d = tmp("cli");
    let a = gradient(W, H);
    let (pa, pb, pc, pdiff) = (d.join("a.png"), d.join("b.png"), d.join("small.png"), d.join("flip.png"));
    io::write_png(&pa, &film_from(W, H, a.clone())).unwrap();
    io::write_png(&pb, &film_from(W, H, noisy(&a, 0.02))).unwrap();
    io::write_png(&pc, &film_from(W / 2, H, gradient(W / 2, H))).unwrap();

    let o = lodtrace(&["compare".as_ref(), pa.as_os_str(), pb.as_os_str(), "--diff".as_ref(), pdiff.as_os_str()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "stdout {out} stderr {}", String::from_utf8_lossy(&o.stderr));
    for k in ["RMSE", "PSNR", "FLIP", "SSIM"] {
        assert!(out.contains(k), "{k} missing in {out}");
    }
    let map = image::open(&pdiff).unwrap();
    assert_eq!((map.width(), map.height()), (W, H));

    let o = lodtrace(&["compare".as_ref(), pa.as_os_str(), pb.as_os_str(), "--min-psnr".as_ref(), "1000".as_ref()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("min-psnr"));

    let o = lodtrace(&["compare".as_ref(), pa.as_os_str(), pa.as_os_str(), "--json".as_ref(), "--max-flip".as_ref(), "0.001".as_ref()]);
    assert_eq!(o.status.code(), Some(0));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["rmse"].as_f64(), Some(0.0));
    assert!(v["psnr_db"].is_null(), "identical → infinite PSNR → null");
    assert_eq!(v["ssim"].as_f64(), Some(1.0));
    assert_eq!(v["pass"].as_bool(), Some(true));

    let o = lodtrace(&["compare".as_ref(), pa.as_os_str(), pc.as_os_str()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.starts_with("lodtrace: error:"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");

    let o = lodtrace(&["compare".as_ref(), pa.as_os_str(), d.join("missing.png").as_os_str()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.starts_with("lodtrace: error:") && err.contains("missing.png"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
}

/// `compare --region`: the error of an image noisy only on its right half is all in a
/// right-half region; a left-half region, away from the seam, has none of it; the region
/// shares add up to the whole image's error; bad rectangles are exit-2 errors.
#[test]
fn compare_regions_split_the_error() {
    let d = tmp("regions");
    let a = gradient(W, H);
    let noisy_all = noisy(&a, 0.05);
    let b: Vec<Vec3> = (0..(W * H) as usize).map(|i| if (i as u32 % W) >= W / 2 { noisy_all[i] } else { a[i] }).collect();
    let (pa, pb) = (d.join("a.png"), d.join("b.png"));
    io::write_png(&pa, &film_from(W, H, a)).unwrap();
    io::write_png(&pb, &film_from(W, H, b)).unwrap();
    let (h2, w2, w4) = (W / 2, W / 2, W / 4);
    let regions = [format!("left={},0,{},{H}", 0, w4), format!("right={w2},0,{W},{H}"), format!("lefthalf=0,0,{h2},{H}")];
    let mut args: Vec<std::ffi::OsString> = vec!["compare".into(), pa.clone().into(), pb.clone().into(), "--json".into()];
    for r in &regions {
        args.push("--region".into());
        args.push(r.into());
    }
    let args_ref: Vec<&std::ffi::OsStr> = args.iter().map(|s| s.as_os_str()).collect();
    let o = lodtrace(&args_ref);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let r = v["regions"].as_array().unwrap();
    assert_eq!(r.len(), 3);
    let f = |i: usize, k: &str| r[i][k].as_f64().unwrap();
    let total = v["flip_mean"].as_f64().unwrap();
    assert!(total > 0.01, "the noise must show: {total}");
    assert_eq!(f(0, "flip_mean"), 0.0, "untouched quarter away from the seam");
    assert_eq!(f(0, "rmse"), 0.0);
    assert!(f(1, "flip_share") > 0.95, "the noisy half holds the error: {}", f(1, "flip_share"));
    assert!((f(1, "flip_share") + f(2, "flip_share") - 1.0).abs() < 1e-9, "two halves make the whole");
    assert!((f(1, "flip_mean") * 0.5 + f(2, "flip_mean") * 0.5 - total).abs() < 1e-9);
    assert!(f(1, "rmse") > 0.01);
    let whole_rmse = v["rmse"].as_f64().unwrap();
    assert!((f(1, "rmse").powi(2) * 0.5 + f(2, "rmse").powi(2) * 0.5 - whole_rmse.powi(2)).abs() < 1e-9, "halves' MSE make the whole's");

    // A black reference region has no luminance to take a ratio of: its bias is n/a (null in
    // JSON), not "+0.0%" (stop 75's review: it read as "no bias" where B is white).
    let black: Vec<Vec3> = (0..(W * H) as usize).map(|i| if (i as u32 / W) < H / 2 { Vec3::ZERO } else { Vec3::splat(0.5) }).collect();
    let (pk, pw) = (d.join("black.png"), d.join("white.png"));
    io::write_png(&pk, &film_from(W, H, black)).unwrap();
    io::write_png(&pw, &film_from(W, H, vec![Vec3::ONE; (W * H) as usize])).unwrap();
    let (top, bottom) = (format!("top=0,0,{W},{}", H / 2), format!("bottom=0,{},{W},{H}", H / 2));
    let args = |json: bool| {
        let mut v: Vec<&std::ffi::OsStr> = vec!["compare".as_ref(), pk.as_os_str(), pw.as_os_str()];
        v.extend::<[&std::ffi::OsStr; 4]>(["--region".as_ref(), top.as_ref(), "--region".as_ref(), bottom.as_ref()]);
        if json {
            v.push("--json".as_ref());
        }
        lodtrace(&v)
    };
    let o = args(false);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    let row = |name: &str| out.lines().find(|l| l.trim_start().starts_with(name)).unwrap_or_else(|| panic!("{name}: {out}")).to_string();
    assert!(row("top").contains(" n/a ") && !row("top").contains("+0.0%"), "{out}");
    // B twice as bright there (8-bit sRGB rounding aside).
    let bias = row("bottom").split_whitespace().find_map(|t| t.strip_prefix('+')?.strip_suffix('%')?.parse::<f64>().ok());
    assert!(bias.is_some_and(|b| (b - 100.0).abs() < 2.0), "{out}");
    let o = args(true);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let r = v["regions"].as_array().unwrap();
    assert!(r[0].get("luma_bias").is_some_and(|b| b.is_null()), "{}", r[0]);
    assert!((r[1]["luma_bias"].as_f64().unwrap() - 1.0).abs() < 0.02, "{}", r[1]);

    for bad in ["x=0,0,0,4", "x=0,0,4", "x=0,0,4,99999", "=0,0,4,4", "x=a,0,4,4"] {
        let o = lodtrace(&["compare".as_ref(), pa.as_os_str(), pb.as_os_str(), "--region".as_ref(), bad.as_ref()]);
        assert_eq!(o.status.code(), Some(2), "{bad}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.starts_with("lodtrace: error:") && err.contains("--region"), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    }
}

#[test]
fn plots_write_pngs() {
    let d = tmp("plot");
    let bars = vec![("embree".to_string(), 1.0), ("bvh".to_string(), 2.37), ("multires".to_string(), 0.41), ("lod".to_string(), f64::NAN)];
    let pb = d.join("bars.png");
    lodtrace::experiment::plot::bar_chart(&pb, "Render time", "seconds", &bars).unwrap();
    let series = vec![
        ("whitted".to_string(), vec![(64.0, 0.1), (128.0, 0.35), (256.0, 1.3)]),
        ("multires".to_string(), vec![(64.0, 0.05), (128.0, 0.2), (256.0, 0.7)]),
    ];
    let pl = d.join("lines.png");
    lodtrace::experiment::plot::line_chart(&pl, "Scaling", "width (px)", "seconds", &series).unwrap();
    for p in [&pb, &pl] {
        assert!(std::fs::metadata(p).unwrap().len() > 1000);
        let img = image::open(p).unwrap().into_rgb8();
        if p == &pl {
            assert_eq!(img.dimensions(), (800, 500));
        } else {
            assert!(img.width() >= 600 && img.height() >= 200, "{:?}", img.dimensions());
        }
        // Something besides the white background was drawn.
        assert!(img.pixels().filter(|p| p.0 != [255, 255, 255]).count() > 1000);
    }
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 2, "no temporary files left");
    assert!(lodtrace::experiment::plot::bar_chart(&d.join("e.png"), "t", "y", &[]).is_err());
    assert!(lodtrace::experiment::plot::line_chart(&d.join("e.png"), "t", "x", "y", &[]).is_err());
    // Edge cases draw without error: one bar, negative and all-zero values, a one-point series.
    let edge = d.join("edge");
    std::fs::create_dir_all(&edge).unwrap();
    let plot = &lodtrace::experiment::plot::bar_chart;
    plot(&edge.join("one.png"), "one", "x", &[("a".into(), 3.0)]).unwrap();
    plot(&edge.join("neg.png"), "neg", "x", &[("a".into(), -1.5), ("b".into(), 2.0)]).unwrap();
    plot(&edge.join("zero.png"), "zero", "x", &[("a".into(), 0.0), ("b".into(), 0.0)]).unwrap();
    lodtrace::experiment::plot::line_chart(&edge.join("pt.png"), "pt", "x", "y", &[("s".into(), vec![(1.0, 2.0)])]).unwrap();
    assert_eq!(std::fs::read_dir(&edge).unwrap().count(), 4);
    // Many long labels (a bench of 24 method specs) make the chart taller and wider, not
    // the labels smaller: 26 pixels a bar, the longest label's width beside the bars.
    let long: Vec<(String, f64)> = (0..24).map(|i| (format!("armadillo-ball surfel:update=lazy-cache:frames=16 {i}"), i as f64)).collect();
    let pm = d.join("many.png");
    lodtrace::experiment::plot::bar_chart(&pm, "many", "seconds", &long).unwrap();
    let img = image::open(&pm).unwrap().into_rgb8();
    assert!(img.height() >= 24 * 26 && img.width() >= 900, "{:?}", img.dimensions());
}
