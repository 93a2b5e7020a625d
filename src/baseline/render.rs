//! The image loop of the conventional tracers: tiles in parallel (rayon), per-tile counters
//! merged at the end, random numbers from a hash of (seed, pixel, sample, dimension) so the
//! image is bit-identical for any `--threads`, and a progress bar once a render passes one
//! second.
//!
//! - Whitted (`--method whitted`): one ray through each pixel centre, or `--spp N` jittered
//!   rays. Primary rays go in packets of K = 8 (one tile row segment) through
//!   [`Accel::intersect8`](super::accel::Accel::intersect8); secondary rays are single.
//! - Adaptive distributed (`--method distributed`, Wand & Straßer §6): pass 1 shoots
//!   `first_pass_spp` jittered samples per pixel (paper: 1–3); the luminance variance of the
//!   pixel means over each 5×5 neighbourhood decides where pass 2 adds g×g stratified jittered
//!   samples (g = ⌊√(spp − first_pass_spp)⌋), so `--spp` is the per-pixel maximum. Area lights,
//!   glossy reflection and depth of field are sampled. With `--variance-threshold 0` every
//!   pixel is refined: that is the ground-truth reference. Below that, the estimate carries
//!   the usual small bias of adaptive sampling: whether a pixel is refined depends on its own
//!   pass-1 samples (they are in its 5×5 variance), and those samples stay in its mean. A
//!   review at stop 79 saw a 0.04 % darker mean on 8-bit images; not corrected, as the
//!   paper's baseline keeps its first pass too.

use super::accel::{Hit, Ray, K};
use super::shade::TraceCtx;
use crate::core::luminance;
use crate::core::rng::Sampler;
use crate::core::stats::{Counter, Counters};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::scene::camera::CameraFrame;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

pub const TILE: u32 = 16;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Integrator {
    Whitted,
    Distributed,
}

#[derive(Clone, Debug)]
pub struct RenderOpts {
    pub integrator: Integrator,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub seed: u32,
    /// 0 = all cores.
    pub threads: usize,
    /// Primary-ray packet width: 1 or 8.
    pub packet: u32,
    pub first_pass_spp: u32,
    pub variance_threshold: f32,
    /// Fill the depth and normal AOVs (from the pixel-centre pinhole ray).
    pub aov: bool,
    pub quiet: bool,
    /// Shown beside the progress bar.
    pub label: String,
}

impl Default for RenderOpts {
    fn default() -> Self {
        RenderOpts {
            integrator: Integrator::Whitted,
            width: 64,
            height: 64,
            spp: 1,
            seed: 0,
            threads: 0,
            packet: 8,
            first_pass_spp: 2,
            variance_threshold: 0.001,
            aov: true,
            quiet: true,
            label: String::new(),
        }
    }
}

/// Upper limit of `--spp`, `--first-pass-spp` and the bench keys `spp=`, `fps=`.
pub const MAX_SPP: u32 = 65536;

/// Upper limit of width × height × spp for one image (2³⁶ ≈ 6.9·10¹⁰ samples).
pub const MAX_SAMPLES: u64 = 1 << 36;

/// Upper limit of width × height (the film alone takes tens of bytes per pixel).
pub const MAX_PIXELS: u64 = 1 << 27;

/// Memory a frame takes per pixel, at most: the film, the per-pixel outputs and the
/// encoder's buffers (measured with `/usr/bin/time -f %M`, 512² against 2048²: whitted 67,
/// multires 70, animate 65, lod 145 bytes per pixel).
pub const BYTES_PER_PIXEL: u64 = 150;

/// Refuses images of more than [`MAX_PIXELS`] pixels, or more than the memory this process
/// can have holds ([`crate::error::check_memory`]), before any memory is allocated: an
/// allocation that fails aborts the process, with no error line and exit 134.
pub fn check_pixels(width: u32, height: u32) -> Result<()> {
    if width as u64 * height as u64 > MAX_PIXELS {
        return Err(Error::Usage(format!("image size {width}x{height} is too large (at most {MAX_PIXELS} pixels in all)")));
    }
    crate::error::check_memory(width as u64 * height as u64 * BYTES_PER_PIXEL, &format!("a {width}x{height} image")).map_err(Error::Usage)
}

impl RenderOpts {
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            return Err(Error::Usage(format!("image size {}x{} must be at least 1x1", self.width, self.height)));
        }
        if self.width > 32768 || self.height > 32768 {
            return Err(Error::Usage(format!("image size {}x{} is too large (max 32768 per side)", self.width, self.height)));
        }
        check_pixels(self.width, self.height)?;
        if !(1..=MAX_SPP).contains(&self.spp) {
            return Err(Error::Usage(format!("--spp {} out of range (1..={MAX_SPP})", self.spp)));
        }
        let samples = self.width as u64 * self.height as u64 * self.spp.max(self.first_pass_spp) as u64;
        if samples > MAX_SAMPLES {
            return Err(Error::Usage(format!(
                "{}x{} at {} spp is {samples} samples, beyond {MAX_SAMPLES} (a 4K reference at 4096 spp is 3.4e10)",
                self.width,
                self.height,
                self.spp.max(self.first_pass_spp)
            )));
        }
        if self.packet != 1 && self.packet != 8 {
            return Err(Error::Usage(format!("--packet {} must be 1 or 8", self.packet)));
        }
        if !(1..=MAX_SPP).contains(&self.first_pass_spp) {
            return Err(Error::Usage(format!("--first-pass-spp {} out of range (1..={MAX_SPP})", self.first_pass_spp)));
        }
        if !(self.variance_threshold >= 0.0) || !self.variance_threshold.is_finite() {
            return Err(Error::Usage("--variance-threshold must be a finite number >= 0".into()));
        }
        crate::core::check_threads(self.threads)
    }
}

pub struct RenderOutput {
    pub film: Film,
    pub counters: Counters,
    pub seconds: f64,
    /// CPU time (user + system) of the whole process during the render: with one thread it
    /// is the render's own cost, barely affected by other work on the machine.
    pub cpu_seconds: f64,
    pub threads: usize,
}

impl RenderOutput {
    /// The output of a render that started at `start` with the process at `cpu0` CPU seconds.
    pub fn timed(film: Film, counters: Counters, start: Instant, cpu0: f64, threads: usize) -> Self {
        RenderOutput { film, counters, seconds: start.elapsed().as_secs_f64(), cpu_seconds: process_cpu_seconds() - cpu0, threads }
    }
}

/// User + system CPU seconds of this process so far: `clock_gettime(CLOCK_PROCESS_CPUTIME_ID)`
/// (nanoseconds; until stop 56 `/proc/self/stat`'s 10 ms ticks, which rounded the bench's
/// "CPU time saved" of thumbnail renders to whole ticks), 0 where unavailable.
pub fn process_cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `ts` is a valid, writable timespec; the call only writes it.
        if unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9;
        }
    }
    0.0
}

#[derive(Clone, Copy)]
pub(crate) struct Tile {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

pub(crate) fn tiles(w: u32, h: u32) -> Vec<Tile> {
    let mut v = Vec::new();
    for y0 in (0..h).step_by(TILE as usize) {
        for x0 in (0..w).step_by(TILE as usize) {
            v.push(Tile { x0, y0, x1: (x0 + TILE).min(w), y1: (y0 + TILE).min(h) });
        }
    }
    v
}

/// A progress bar that stays hidden for the first second.
pub(crate) struct Progress {
    bar: ProgressBar,
    start: Instant,
    shown: AtomicBool,
    quiet: bool,
}

impl Progress {
    pub(crate) fn new(len: u64, label: &str, quiet: bool) -> Self {
        // The inputs loaded: their warnings are shown before the long part starts.
        crate::error::flush_warnings();
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
        bar.set_style(ProgressStyle::with_template("{prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} tiles, eta {eta}").unwrap());
        bar.set_prefix(label.to_string());
        Progress { bar, start: Instant::now(), shown: AtomicBool::new(false), quiet }
    }
    pub(crate) fn tick(&self) {
        self.bar.inc(1);
        if !self.quiet
            && !self.shown.load(Ordering::Relaxed)
            && self.start.elapsed() > Duration::from_secs(1)
            && !self.shown.swap(true, Ordering::Relaxed)
        {
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
        }
    }
    pub(crate) fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

struct PixelOut {
    idx: usize,
    color: Vec3,
    depth: f32,
    normal: Vec3,
}

/// Renders one frame with the conventional tracers.
pub fn render(ctx: &TraceCtx, cam: &CameraFrame, opts: &RenderOpts) -> Result<RenderOutput> {
    opts.validate()?;
    let pool = crate::core::thread_pool(opts.threads)?;
    let threads = pool.current_num_threads();
    let start = Instant::now();
    let cpu0 = process_cpu_seconds();
    let (film, counters) = pool.install(|| match opts.integrator {
        Integrator::Whitted => whitted(ctx, cam, opts),
        Integrator::Distributed => distributed(ctx, cam, opts),
    });
    let mut out = RenderOutput::timed(film, counters, start, cpu0, threads);
    if opts.aov && !(opts.integrator == Integrator::Whitted && opts.spp == 1) {
        pool.install(|| aov_probes(ctx, cam, &mut out.film));
    }
    Ok(out)
}

/// Depth and normal AOVs of a supersampled render: one pixel-centre ray per pixel, after the
/// timed render and with its own counters, so that asking for an AOV changes neither the
/// frame's time nor its counted tests (until stop 56 these probes ran inside the render and
/// added about 5 % to the triangle tests of a 4-spp frame without counting a ray). The
/// 1-spp Whitted frame takes its AOVs from its own primary hits.
pub(crate) fn aov_probes(ctx: &TraceCtx, cam: &CameraFrame, film: &mut Film) {
    let w = film.width;
    let px: Vec<(f32, Vec3)> = (0..film.width * film.height)
        .into_par_iter()
        .map_init(Counters::default, |c, k| {
            let ray = Ray::new(cam.eye, cam.pixel_center_dir(k % w, k / w));
            let h = ctx.accel.intersect1(&ray, c);
            aov_of(ctx, &ray, h.as_ref())
        })
        .collect();
    for (k, (d, n)) in px.into_iter().enumerate() {
        film.depth[k] = d;
        film.normal[k] = n;
    }
}

fn scatter(film: &mut Film, results: Vec<(Vec<PixelOut>, Counters)>) -> Counters {
    let mut total = Counters::default();
    for (px, c) in results {
        total.merge(&c);
        for p in px {
            film.color[p.idx] = p.color;
            film.depth[p.idx] = p.depth;
            film.normal[p.idx] = p.normal;
        }
    }
    total
}

/// Pixel-centre rays of row `j`, columns `x0..x1`, K at a time (`packet` 8: one
/// [`Accel::intersect8`](super::accel::Accel::intersect8) call per K; 1: single rays), counted as primary rays and samples;
/// `f(i, ray, hit, counters)` sees each pixel in order. Shared by the Whitted and the LOD
/// tracer so both shoot bit-identical primary rays.
// Called per row by both tracers: a struct of its inputs would only be unpacked again.
#[allow(clippy::too_many_arguments)]
pub(crate) fn primary_row(
    accel: &dyn super::accel::Accel,
    cam: &CameraFrame,
    j: u32,
    x0: u32,
    x1: u32,
    packet: u32,
    c: &mut Counters,
    mut f: impl FnMut(u32, &Ray, Option<&Hit>, &mut Counters),
) {
    let mut i0 = x0;
    while i0 < x1 {
        let n = (x1 - i0).min(K as u32) as usize;
        let mut rays = [Ray::new(cam.eye, Vec3::Z); K];
        for (l, r) in rays.iter_mut().enumerate().take(n) {
            *r = Ray::new(cam.eye, cam.pixel_center_dir(i0 + l as u32, j));
        }
        let mut hits = [None; K];
        if packet == 8 {
            accel.intersect8(&rays, ((1u32 << n) - 1) as u8, &mut hits, c);
        } else {
            for l in 0..n {
                hits[l] = accel.intersect1(&rays[l], c);
            }
        }
        c.add(Counter::rays_primary, n as u64);
        c.add(Counter::samples, n as u64);
        for l in 0..n {
            f(i0 + l as u32, &rays[l], hits[l].as_ref(), c);
        }
        i0 += n as u32;
    }
}

/// Depth and normal of the pixel-centre ray's hit.
fn aov_of(ctx: &TraceCtx, ray: &Ray, hit: Option<&Hit>) -> (f32, Vec3) {
    match hit {
        Some(h) => (h.t, ctx.surface(ray, h).ns),
        None => (f32::INFINITY, Vec3::ZERO),
    }
}

fn whitted(ctx: &TraceCtx, cam: &CameraFrame, opts: &RenderOpts) -> (Film, Counters) {
    let mut film = Film::new(opts.width, opts.height);
    let ts = tiles(opts.width, opts.height);
    let prog = Progress::new(ts.len() as u64, &opts.label, opts.quiet);
    let w = opts.width;
    let results: Vec<(Vec<PixelOut>, Counters)> = ts
        .par_iter()
        .map(|t| {
            let mut c = Counters::default();
            let mut out = Vec::with_capacity(((t.x1 - t.x0) * (t.y1 - t.y0)) as usize);
            for j in t.y0..t.y1 {
                if opts.spp == 1 {
                    // Pixel-centre rays, K at a time along the row.
                    primary_row(ctx.accel, cam, j, t.x0, t.x1, opts.packet, &mut c, |i, ray, hit, c| {
                        let color = match hit {
                            Some(h) => ctx.shade(ray, h, 0, None, c),
                            None => ctx.scene.background,
                        };
                        let (depth, normal) = if opts.aov { aov_of(ctx, ray, hit) } else { (f32::INFINITY, Vec3::ZERO) };
                        out.push(PixelOut { idx: (j * w + i) as usize, color, depth, normal });
                    });
                } else {
                    for i in t.x0..t.x1 {
                        let pix = j * w + i;
                        let mut sum = Vec3::ZERO;
                        for s in 0..opts.spp {
                            let mut smp = Sampler::new(opts.seed, pix, s);
                            let (u, v) = smp.next2();
                            let ray = Ray::new(cam.eye, cam.dir_at(i as f32 + u, j as f32 + v));
                            c.inc(Counter::rays_primary);
                            c.inc(Counter::samples);
                            sum += ctx.radiance(&ray, 0, None, &mut c);
                        }
                        // AOVs: `aov_probes`, after the timed render.
                        out.push(PixelOut { idx: pix as usize, color: sum / opts.spp as f32, depth: f32::INFINITY, normal: Vec3::ZERO });
                    }
                }
            }
            prog.tick();
            (out, c)
        })
        .collect();
    prog.finish();
    let c = scatter(&mut film, results);
    (film, c)
}

/// One distributed-ray-tracing sample of pixel (i, j) at image position (i+u, j+v).
// Called per sample by both passes: a struct of its inputs would only be unpacked again.
#[allow(clippy::too_many_arguments)]
fn dist_sample(ctx: &TraceCtx, cam: &CameraFrame, i: u32, j: u32, u: f32, v: f32, smp: &mut Sampler, c: &mut Counters) -> Vec3 {
    let d = cam.dir_at(i as f32 + u, j as f32 + v);
    let (lu, lv) = smp.next2();
    let (o, dir) = cam.lens_ray(d, lu, lv);
    c.inc(Counter::rays_primary);
    c.inc(Counter::samples);
    ctx.radiance(&Ray::new(o, dir), 0, Some(smp), c)
}

fn distributed(ctx: &TraceCtx, cam: &CameraFrame, opts: &RenderOpts) -> (Film, Counters) {
    let (w, h) = (opts.width, opts.height);
    let n1 = opts.first_pass_spp.min(opts.spp);
    let g = if opts.spp > n1 { ((opts.spp - n1) as f32).sqrt().floor() as u32 } else { 0 };
    let ts = tiles(w, h);
    let passes = if g > 0 { 2 } else { 1 };
    let prog = Progress::new((ts.len() * passes) as u64, &opts.label, opts.quiet);
    let npix = (w * h) as usize;

    // Pass 1: fixed jittered oversampling.
    let mut sums = vec![Vec3::ZERO; npix];
    let mut film = Film::new(w, h);
    let pass1: Vec<(Vec<PixelOut>, Counters)> = ts
        .par_iter()
        .map(|t| {
            let mut c = Counters::default();
            let mut out = Vec::new();
            for j in t.y0..t.y1 {
                for i in t.x0..t.x1 {
                    let pix = j * w + i;
                    let mut sum = Vec3::ZERO;
                    for s in 0..n1 {
                        let mut smp = Sampler::new(opts.seed, pix, s);
                        let (u, v) = smp.next2();
                        sum += dist_sample(ctx, cam, i, j, u, v, &mut smp, &mut c);
                    }
                    // AOVs: `aov_probes`, after the timed render.
                    out.push(PixelOut { idx: pix as usize, color: sum, depth: f32::INFINITY, normal: Vec3::ZERO });
                }
            }
            prog.tick();
            (out, c)
        })
        .collect();
    let mut counters = scatter(&mut film, pass1);
    for (s, col) in sums.iter_mut().zip(film.color.iter_mut()) {
        *s = *col;
        *col = *s / n1 as f32;
    }
    if g == 0 {
        prog.finish();
        return (film, counters);
    }

    // Variance of the (display-clamped) luminance of pixel means over 5×5 neighbourhoods.
    let lum: Vec<f32> = film.color.iter().map(|c| luminance(c.clamp(Vec3::ZERO, Vec3::ONE))).collect();
    let refine: Vec<bool> = (0..npix)
        .into_par_iter()
        .map(|k| {
            let (i, j) = ((k as u32 % w) as i32, (k as u32 / w) as i32);
            let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
            for dj in -2..=2 {
                for di in -2..=2 {
                    let (x, y) = (i + di, j + dj);
                    if x >= 0 && y >= 0 && x < w as i32 && y < h as i32 {
                        let v = lum[(y as u32 * w + x as u32) as usize] as f64;
                        s += v;
                        s2 += v * v;
                        n += 1.0;
                    }
                }
            }
            let var = (s2 / n - (s / n) * (s / n)).max(0.0);
            var > opts.variance_threshold as f64 || opts.variance_threshold == 0.0
        })
        .collect();

    // Pass 2: g×g stratified jittered samples in the pixels of high variance.
    let sums_ref = &sums;
    let refine_ref = &refine;
    let pass2: Vec<(Vec<(usize, Vec3)>, Counters)> = ts
        .par_iter()
        .map(|t| {
            let mut c = Counters::default();
            let mut out = Vec::new();
            for j in t.y0..t.y1 {
                for i in t.x0..t.x1 {
                    let pix = (j * w + i) as usize;
                    if !refine_ref[pix] {
                        continue;
                    }
                    c.inc(Counter::pixels_refined);
                    let mut sum = sums_ref[pix];
                    for sy in 0..g {
                        for sx in 0..g {
                            let s = n1 + sy * g + sx;
                            let mut smp = Sampler::new(opts.seed, pix as u32, s);
                            let (a, b) = smp.next2();
                            let u = (sx as f32 + a) / g as f32;
                            let v = (sy as f32 + b) / g as f32;
                            sum += dist_sample(ctx, cam, i, j, u, v, &mut smp, &mut c);
                        }
                    }
                    out.push((pix, sum / (n1 + g * g) as f32));
                }
            }
            prog.tick();
            (out, c)
        })
        .collect();
    prog.finish();
    for (px, c) in pass2 {
        counters.merge(&c);
        for (k, col) in px {
            film.color[k] = col;
        }
    }
    (film, counters)
}

#[cfg(test)]
mod cpu_clock_tests {
    /// The process CPU clock resolves far below the 10 ms ticks of `/proc/self/stat`: the
    /// first change seen while spinning is under a millisecond.
    #[test]
    fn process_cpu_clock_is_finer_than_the_tick() {
        let t0 = super::process_cpu_seconds();
        let mut x = 0u64;
        let step = loop {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(std::hint::black_box(1));
            let t = super::process_cpu_seconds();
            if t != t0 {
                break t - t0;
            }
        };
        std::hint::black_box(x);
        assert!(step > 0.0 && step < 1e-3, "CPU clock step {step} s");
    }
}
