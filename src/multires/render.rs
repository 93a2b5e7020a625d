//! The image loop of the cone tracers (`--method multires` and `--method cone`): one primary
//! cone per pixel (§4.2), tiles in parallel with per-tile counters, a progress bar, and an
//! optional time budget after which the remaining tiles are skipped and the frame is
//! reported as unfinished (the paper's classic cone tracer with secondary rays "did not
//! terminate within a reasonable amount of time"). Beside the image: the traversal work per
//! pixel (`--aov cost=`) and by cone kind ([`ConeProfile`], `--stats` `cone_profile`).

use super::cone::Cone;
use super::trace::{ConeProfile, MultiresScene, ShadeScratch, TraceParams, Tracer};
use crate::baseline::render::{tiles, Progress, RenderOpts, RenderOutput};
use crate::core::stats::{Counter, Counters};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::scene::camera::CameraFrame;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

pub struct ConeRender {
    pub out: RenderOutput,
    /// False when the time budget ran out (the image is then incomplete).
    pub finished: bool,
    /// Traversal work by cone kind.
    pub profile: ConeProfile,
    /// Bounding-volume and primitive tests per pixel, row-major ([`ConeProfile::tests`]):
    /// every cone the pixel's primary cone spawned included.
    pub pixel_tests: Vec<u32>,
    /// Which pixels were traced (all unless the time budget ran out).
    pub traced: Vec<bool>,
}

pub fn render(ms: &MultiresScene, tp: &TraceParams, cam: &CameraFrame, opts: &RenderOpts) -> Result<ConeRender> {
    opts.validate()?;
    tp.validate()?;
    if opts.spp != 1 {
        return Err(Error::Usage("the cone tracers shoot one cone per pixel: use --spp 1".into()));
    }
    let pool = crate::core::thread_pool(opts.threads)?;
    let threads = pool.current_num_threads();
    let start = Instant::now();
    let cpu0 = crate::baseline::render::process_cpu_seconds();
    let abort = AtomicBool::new(false);
    let (lo, hi) = ms.scene.bounds()?;
    let tracer =
        Tracer::new(ms, tp, 1e-7 * (hi - lo).max_element().max(1e-6), &abort, tp.time_budget.map(|b| start + Duration::from_secs_f64(b)));
    let (w, h) = (opts.width, opts.height);
    let ts = tiles(w, h);
    let prog = Progress::new(ts.len() as u64, &opts.label, opts.quiet);
    let max_depth = ms.scene.max_depth;
    type Px = (usize, Vec3, f32, Vec3, u32);
    let results: Vec<(Vec<Px>, Counters, ConeProfile)> = pool.install(|| {
        ts.par_iter()
            .map_init(
                || ShadeScratch::new(tp.max_fragments, max_depth),
                |ss, t| {
                    let mut c = Counters::default();
                    let mut out = Vec::with_capacity(((t.x1 - t.x0) * (t.y1 - t.y0)) as usize);
                    for j in t.y0..t.y1 {
                        if tracer.past_deadline() {
                            break;
                        }
                        for i in t.x0..t.x1 {
                            let cone = Cone::primary(cam, i, j, tp.cone_scale, tp.lens_scale);
                            c.inc(Counter::rays_primary);
                            c.inc(Counter::samples);
                            let before = ConeProfile::tests(&c);
                            let r = tracer.radiance(&cone, 0, 1.0, ss, &mut c);
                            let tests = (ConeProfile::tests(&c) - before).min(u32::MAX as u64) as u32;
                            let col = if r.color.is_finite() { r.color } else { Vec3::ZERO };
                            out.push(((j * w + i) as usize, col, r.depth, r.normal, tests));
                        }
                    }
                    prog.tick();
                    (out, c, std::mem::take(&mut ss.profile))
                },
            )
            .collect()
    });
    prog.finish();
    let mut film = Film::new(w, h);
    let mut counters = Counters::default();
    counters.add(Counter::trees_from_cache, ms.trees_from_cache() as u64);
    let mut profile = ConeProfile::default();
    let mut pixel_tests = vec![0u32; (w * h) as usize];
    let mut traced = vec![false; (w * h) as usize];
    for (px, c, p) in results {
        counters.merge(&c);
        profile.merge(&p);
        for (k, col, d, n, tests) in px {
            film.color[k] = col;
            film.depth[k] = d;
            film.normal[k] = n;
            pixel_tests[k] = tests;
            traced[k] = true;
        }
    }
    let finished = !abort.load(Ordering::Relaxed);
    Ok(ConeRender { out: RenderOutput::timed(film, counters, start, cpu0, threads), finished, profile, pixel_tests, traced })
}

/// One pixel's primary cone, traced alone (`lodtrace render --debug-pixel`): its result, the
/// parts of its A-buffer as composited front to back, every fragment shaded in its cone
/// tree, and the work it took (shadow and secondary cones included).
pub fn explain_pixel(
    ms: &MultiresScene,
    tp: &TraceParams,
    cam: &CameraFrame,
    (i, j): (u32, u32),
) -> Result<(super::trace::ConeResult, super::trace::DebugLog, Counters)> {
    tp.validate()?;
    if i >= cam.width || j >= cam.height {
        return Err(Error::Usage(format!("--debug-pixel {i},{j} lies outside the {}x{} image", cam.width, cam.height)));
    }
    let abort = AtomicBool::new(false);
    let (lo, hi) = ms.scene.bounds()?;
    let tracer = Tracer::new(ms, tp, 1e-7 * (hi - lo).max_element().max(1e-6), &abort, None);
    let mut ss = ShadeScratch::new(tp.max_fragments, ms.scene.max_depth);
    let mut c = Counters::default();
    let (r, log) = tracer.explain(&Cone::primary(cam, i, j, tp.cone_scale, tp.lens_scale), &mut ss, &mut c);
    Ok((r, log, c))
}
