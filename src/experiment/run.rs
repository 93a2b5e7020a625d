//! Running one method on one scene: the shared core of `render`, `bench` and `demo`.
//! Build time (acceleration structure) and render time are measured separately.

use crate::baseline::accel::{self, AccelKind};
use crate::baseline::render::{render, Integrator, RenderOpts, RenderOutput};
use crate::baseline::shade::TraceCtx;
use crate::cli::Method;
use crate::core::stats::Counter;
use crate::error::{Error, Result};
use crate::lod::chain::LodScenes;
use crate::lod::trace::LodTracer;
use crate::lod::LodArgs;
use crate::multires::trace::{ConeKind, ConeProfile, MultiresScene};
use crate::multires::MultiresArgs;
use crate::scene::Scene;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

pub struct RunResult {
    pub out: RenderOutput,
    pub build_seconds: f64,
    /// Worker threads the build ran on: the run's `--threads`, as the render's (Embree's
    /// own build threads excepted).
    pub build_threads: usize,
    pub accel_bytes: usize,
    /// False when a time budget stopped the render (the image is incomplete).
    pub finished: bool,
    /// The point hierarchy (cone tracers): totals over the unique meshes.
    pub hierarchy: Option<HierarchyStats>,
    /// `--method lod`: chain figures and the pass-1 maps.
    pub lod: Option<LodResult>,
    /// The cone tracers: traversal work by cone kind and per pixel.
    pub cones: Option<ConeReport>,
}

/// Where a cone tracer's traversal work went (`--stats` `cone_profile`, `--aov cost=`).
pub struct ConeReport {
    pub profile: ConeProfile,
    /// Bounding-volume and primitive tests per pixel, row-major.
    pub pixel_tests: Vec<u32>,
    /// Which pixels were traced (a time budget may stop the frame early).
    pub traced: Vec<bool>,
}

/// One cone kind in `cone_profile.kinds`: how many cones, the CPU time inside their
/// traversals (summed over threads, shading excluded), their share of the frame's tests, and
/// the work counters (same names as `counters`).
#[derive(Serialize, Debug, Clone)]
pub struct ConeKindStats {
    pub cones: u64,
    /// Wall-clock seconds each thread spent traversing this kind's cones, summed over the
    /// threads: the CPU time when nothing else runs on the cores, more when something does
    /// (the name predates this note; the stats JSON keeps it).
    pub traversal_cpu_seconds: f64,
    /// Share of the frame's bounding-volume and primitive tests (instance, node,
    /// triangle-bound, triangle, surfel).
    pub share_of_tests: f64,
    /// Those tests per cone.
    pub tests_per_cone: f64,
    #[serde(flatten)]
    pub counters: BTreeMap<String, u64>,
}

/// How the tests spread over the pixels (each pixel with every cone it spawned).
#[derive(Serialize, Debug, Clone, Default)]
pub struct PixelTests {
    /// Pixels traced (the figures below are over these only: a frame stopped by
    /// `--time-budget` leaves the rest untraced, and their zeros made the median 0).
    pub pixels: usize,
    pub mean: f64,
    pub median: u32,
    pub p95: u32,
    pub max: u32,
    /// Share of all tests spent in the 5 % most expensive pixels.
    pub top_5_percent_share: f64,
}

/// `--stats` `cone_profile` (`--method multires` and `cone`).
#[derive(Serialize, Debug, Clone)]
pub struct ConeProfileStats {
    /// `primary`, `primary_shadow` (shadow cones of primary hits), `secondary` (reflected
    /// and refracted cones), `secondary_shadow` (shadow cones of their hits).
    pub kinds: BTreeMap<String, ConeKindStats>,
    pub pixel_tests: PixelTests,
}

impl ConeProfileStats {
    /// The table cells shared by `bench` and the demo: per kind in [`ConeKind::ALL`] order
    /// "CPU s, tests/cone, share" ("–" for no cones), then "median / p95 / max" tests per
    /// pixel and the top 5 %'s share.
    pub fn cells(&self) -> Vec<String> {
        let mut v: Vec<String> = ConeKind::ALL
            .iter()
            .map(|k| match self.kinds.get(k.name()) {
                Some(c) if c.cones > 0 => {
                    format!("{:.3} s, {:.0}/cone, {:.0} %", c.traversal_cpu_seconds, c.tests_per_cone, 100.0 * c.share_of_tests)
                }
                _ => super::NA.into(),
            })
            .collect();
        let t = &self.pixel_tests;
        v.push(format!("{} / {} / {}", t.median, t.p95, t.max));
        v.push(format!("{:.0} %", 100.0 * t.top_5_percent_share));
        v
    }
}

impl ConeReport {
    pub fn stats(&self) -> ConeProfileStats {
        let p = &self.profile;
        let total: u64 = ConeKind::ALL.iter().map(|&k| p.kind_tests(k)).sum();
        let kinds = ConeKind::ALL
            .iter()
            .map(|&kind| {
                let k = kind as usize;
                let tests = p.kind_tests(kind);
                let counters =
                    ConeProfile::COUNTERS.iter().zip(p.work[k]).map(|(c, v)| (Counter::NAMES[*c as usize].to_string(), v)).collect();
                let st = ConeKindStats {
                    cones: p.cones[k],
                    traversal_cpu_seconds: p.nanos[k] as f64 * 1e-9,
                    share_of_tests: tests as f64 / total.max(1) as f64,
                    tests_per_cone: tests as f64 / p.cones[k].max(1) as f64,
                    counters,
                };
                (kind.name().to_string(), st)
            })
            .collect();
        let traced: Vec<u32> = self.pixel_tests.iter().zip(&self.traced).filter(|(_, &t)| t).map(|(&x, _)| x).collect();
        ConeProfileStats { kinds, pixel_tests: pixel_tests(&traced) }
    }
}

/// Mean, median, 95th percentile, maximum and the top 5 %'s share of a per-pixel cost map.
pub fn pixel_tests(v: &[u32]) -> PixelTests {
    if v.is_empty() {
        return PixelTests::default();
    }
    let mut s = v.to_vec();
    s.sort_unstable();
    let n = s.len();
    let total: u64 = s.iter().map(|&x| x as u64).sum();
    let at = |q: f64| s[((q * (n - 1) as f64).round() as usize).min(n - 1)];
    let top = n.div_ceil(20);
    let top_sum: u64 = s[n - top..].iter().map(|&x| x as u64).sum();
    PixelTests {
        pixels: n,
        mean: total as f64 / n as f64,
        median: at(0.5),
        p95: at(0.95),
        max: s[n - 1],
        top_5_percent_share: top_sum as f64 / total.max(1) as f64,
    }
}

/// What `--method lod` reports besides the image.
pub struct LodResult {
    pub stats: LodStats,
    pub maps: crate::lod::trace::LodMaps,
}

/// Figures of the LOD chains and the per-ray selection (Papaioannou et al.).
#[derive(Serialize, Debug, Clone, Default)]
pub struct LodStats {
    pub levels: u32,
    /// Instanced triangles of the scene at each level.
    pub triangles_per_level: Vec<u64>,
    pub chain_seconds: f64,
    pub pass1_seconds: f64,
    /// Mean level of the intersection queries of secondary rays (0 = full detail).
    pub mean_query_level: f64,
    /// Share of pixels whose reflected / transmitted level-1 ray has LOD < 1.
    pub reduced_reflect_share: f64,
    pub reduced_transmit_share: f64,
}

/// Build figures of the multi-resolution point hierarchy (Wand & Straßer Table 1).
#[derive(Serialize, Debug, Clone, Default)]
pub struct HierarchyStats {
    pub trees: usize,
    pub nodes: usize,
    pub points: usize,
    pub triangles_stored: usize,
    pub samples: u64,
    pub max_depth: u32,
    /// Bytes of the point hierarchies ([`crate::multires::build::PointTree::memory_bytes`])
    /// and the instance-level points: the paper's Table 1 "point hierarchy" memory.
    pub bytes: usize,
    pub seconds: f64,
    /// Trees read back from the on-disk cache instead of built.
    pub trees_from_cache: usize,
    /// Instance-level points (`multires::group`): slots with points, points, the surface
    /// samples drawn for them, and their build time (part of `seconds`; never cached).
    pub group_slots: usize,
    pub group_points: usize,
    pub group_samples: u64,
    pub group_seconds: f64,
}

/// The `--stats` JSON (DESIGN.md): at least method, accel, width, height, spp,
/// build_seconds, render_seconds and counters.
#[derive(Serialize, Debug, Clone)]
pub struct Stats {
    pub scene: String,
    pub method: String,
    pub accel: String,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub threads: usize,
    pub build_seconds: f64,
    pub render_seconds: f64,
    /// Process CPU time during the render (with `--threads 1`: the render's own cost).
    pub render_cpu_seconds: f64,
    pub mrays_per_second: f64,
    pub triangles_instanced: u64,
    pub triangles_unique: u64,
    pub accel_bytes: usize,
    pub mesh_bytes: usize,
    /// Peak resident memory of the process during this run (Linux VmHWM, reset when the run
    /// starts, so it counts what was resident then, the scene included), bytes.
    pub peak_rss_bytes: u64,
    /// SIMD level of the binary ([`crate::core::SIMD_LEVEL`]).
    pub simd: &'static str,
    /// False when `--time-budget` stopped the render before the last tile.
    pub finished: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hierarchy: Option<HierarchyStats>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lod: Option<LodStats>,
    pub counters: BTreeMap<String, u64>,
    /// False where Embree traced the rays: it does not report its node and triangle tests,
    /// so `node_tests`, `instance_tests` and `triangle_tests` are 0 for "not counted".
    pub tests_counted: bool,
    /// The cone tracers: the traversal work by cone kind and over the pixels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cone_profile: Option<ConeProfileStats>,
}

fn unsupported(m: Method) -> Error {
    match m {
        Method::Surfel => Error::Usage(
            "--method surfel traces deforming sequences, not triangle scenes: lodtrace render SEQ --method surfel, lodtrace animate or lodtrace bench SEQ --methods surfel:...".into(),
        ),
        _ => Error::Usage(format!("--method {} is not available here; available: whitted, distributed, multires, cone, lod", m.name())),
    }
}

pub fn run(scene: &Scene, method: Method, accel_kind: AccelKind, opts: &RenderOpts, mr: &MultiresArgs, la: &LodArgs) -> Result<RunResult> {
    // `peak_rss_bytes` is this run's peak: a bench row used to report the peak of every
    // render before it in the process (the reference's, the other methods').
    reset_peak_rss();
    let integrator = match method {
        Method::Whitted => Integrator::Whitted,
        Method::Distributed => Integrator::Distributed,
        Method::Multires | Method::Cone => return run_cone(scene, method, opts, mr),
        Method::Lod => return run_lod(scene, accel_kind, opts, la),
        m => return Err(unsupported(m)),
    };
    opts.validate()?;
    // The octree baseline is built with the cone tracers' build options (its own defaults
    // otherwise); the trace options do not apply to it.
    let (octree, _) = mr.params(false)?;
    let leaves = scene.leaf_instances()?;
    let pool = crate::core::thread_pool(opts.threads)?;
    let t0 = Instant::now();
    // On the run's threads: the global pool built a `threads=1` row's BVH on every core.
    let (acc, build_threads) =
        pool.install(|| Ok::<_, Error>((accel::build_with(accel_kind, scene, &octree)?, rayon::current_num_threads())))?;
    let build_seconds = t0.elapsed().as_secs_f64();
    drop(pool);
    let ctx = TraceCtx { scene, leaves: &leaves, accel: acc.as_ref(), max_depth: scene.max_depth };
    let cam = scene.camera.frame(opts.width, opts.height);
    let o = RenderOpts { integrator, ..opts.clone() };
    let out = render(&ctx, &cam, &o)?;
    Ok(RunResult {
        out,
        build_seconds,
        build_threads,
        accel_bytes: acc.memory_bytes(),
        finished: true,
        hierarchy: None,
        lod: None,
        cones: None,
    })
}

/// The `--stats` `hierarchy` figures of the point hierarchies `ms`: totals over its trees (the
/// paper's Table 1), and the instance-level points.
pub(crate) fn hierarchy_stats(ms: &MultiresScene) -> HierarchyStats {
    let mut h = HierarchyStats {
        trees: ms.trees.len(),
        seconds: ms.build_seconds,
        trees_from_cache: ms.trees_from_cache(),
        group_slots: ms.groups.count.iter().filter(|&&n| n > 0).count(),
        group_points: ms.groups.points.len(),
        group_samples: ms.groups.samples,
        group_seconds: ms.group_seconds,
        ..Default::default()
    };
    for t in &ms.trees {
        h.nodes += t.stats.nodes;
        h.points += t.stats.points;
        h.triangles_stored += t.stats.triangles_stored;
        h.samples += t.stats.samples;
        h.max_depth = h.max_depth.max(t.stats.max_depth);
        h.bytes += t.stats.bytes;
    }
    // The instance-level points are part of the hierarchy whose build time `seconds`
    // includes (stop 91: they were left out of its bytes).
    h.bytes += ms.groups.bytes();
    h
}

/// The cone tracers of Wand & Straßer: build the point hierarchies, then trace.
fn run_cone(scene: &Scene, method: Method, opts: &RenderOpts, mr: &MultiresArgs) -> Result<RunResult> {
    let (bp, tp) = mr.params(method == Method::Multires)?;
    opts.validate()?;
    tp.validate()?;
    if opts.spp != 1 {
        return Err(Error::Usage("the cone tracers shoot one cone per pixel: use --spp 1".into()));
    }
    // The point hierarchies on the run's threads, as the render.
    let (ms, build_threads) =
        crate::core::thread_pool(opts.threads)?.install(|| MultiresScene::build(scene, &bp).map(|m| (m, rayon::current_num_threads())))?;
    let h = hierarchy_stats(&ms);
    let cam = scene.camera.frame(opts.width, opts.height);
    let r = crate::multires::render::render(&ms, &tp, &cam, opts)?;
    Ok(RunResult {
        out: r.out,
        build_seconds: ms.build_seconds,
        build_threads,
        accel_bytes: ms.memory_bytes(),
        finished: r.finished,
        hierarchy: Some(h),
        lod: None,
        cones: Some(ConeReport { profile: r.profile, pixel_tests: r.pixel_tests, traced: r.traced }),
    })
}

/// `lodtrace render --debug-pixel X,Y`: one pixel's primary cone traced alone, its A-buffer
/// as composited front to back, as a table.
pub fn explain_cone(scene: &Scene, method: Method, opts: &RenderOpts, mr: &MultiresArgs, px: (u32, u32)) -> Result<String> {
    use std::fmt::Write;
    let (bp, tp) = mr.params(method == Method::Multires)?;
    opts.validate()?;
    let ms = MultiresScene::build(scene, &bp)?;
    let cam = scene.camera.frame(opts.width, opts.height);
    let (r, log, c) = crate::multires::render::explain_pixel(&ms, &tp, &cam, px)?;
    let (parts, tree) = (&log.parts, &log.tree);
    let rgb = |v: glam::Vec3| format!("{:.3} {:.3} {:.3}", v.x, v.y, v.z);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} pixel {},{} of {}x{}, --method {}: the primary cone's A-buffer, front to back (§4.4)",
        scene.name,
        px.0,
        px.1,
        opts.width,
        opts.height,
        method.name()
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "| frag | part | mesh | depth z0..z1 | mean t | footprint axes | weight | facing away | alpha | share | colour | shaded |"
    );
    let _ = writeln!(s, "|---:|---:|---|---|---:|---|---:|---:|---:|---:|---|---|");
    for p in parts {
        let mesh = p.mesh.map_or("instance points".to_string(), |m| scene.meshes[m as usize].name.clone());
        let _ = writeln!(
            s,
            "| {} | {} | {mesh} | {:.4}..{:.4} | {:.4} | {:.4} × {:.4} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {} |",
            p.frag,
            p.part,
            p.z0,
            p.z1,
            p.t,
            p.axes[0],
            p.axes[1],
            p.w,
            p.wb,
            p.alpha,
            p.share,
            rgb(p.color),
            rgb(p.shaded)
        );
    }
    let _ = writeln!(s);
    let frags = parts.last().map_or(0, |p| p.frag + 1);
    let n = parts.len();
    let _ = writeln!(
        s,
        "pixel {} (alpha {:.3}, background {:.3}); {n} part{} of {frags} fragment{} composited",
        rgb(r.color),
        r.alpha,
        1.0 - r.alpha,
        if n == 1 { "" } else { "s" },
        if frags == 1 { "" } else { "s" }
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Every fragment shaded, depth first (depth 0: the parts above; below each, the reflected and refracted cones it spawned):"
    );
    let _ = writeln!(s);
    let _ = writeln!(s, "| depth | mesh | side | mean t | weight | footprint axes | growth per unit t | importance | radiance |");
    let _ = writeln!(s, "|---|---|---|---:|---:|---|---|---:|---|");
    for e in tree {
        let mesh = e.mesh.map_or("instance points".to_string(), |m| scene.meshes[m as usize].name.clone());
        let side = if e.front { "front" } else { "back" };
        let _ = writeln!(
            s,
            "| {}{} | {mesh} | {side} | {:.4} | {:.3} | {:.4} × {:.4} | {:.4} × {:.4} | {:.3} | {} |",
            "· ".repeat(e.depth as usize),
            e.depth,
            e.t,
            e.w,
            e.axes[0],
            e.axes[1],
            e.spread[0],
            e.spread[1],
            e.importance,
            rgb(e.radiance)
        );
    }
    let _ = writeln!(s);
    let named: Vec<String> = c.to_map().into_iter().filter(|(_, v)| *v > 0).map(|(k, v)| format!("{k} {v}")).collect();
    let _ = writeln!(s, "work, shadow and secondary cones included: {}", named.join(", "));
    Ok(s)
}

/// Papaioannou et al.: build the LOD chains and one acceleration structure per level, then
/// the two-pass tracer. Build time covers chains and structures.
fn run_lod(scene: &Scene, accel_kind: AccelKind, opts: &RenderOpts, la: &LodArgs) -> Result<RunResult> {
    let (cp, lp) = la.params()?;
    opts.validate()?;
    if accel_kind == AccelKind::Octree {
        return Err(Error::Usage("--method lod runs on --accel bvh or embree; the octree serves whitted and distributed".into()));
    }
    let pool = crate::core::thread_pool(opts.threads)?;
    let t0 = Instant::now();
    // Chains and structures on the run's threads, as the render.
    let (ls, build_threads) = pool.install(|| LodScenes::build(scene, &cp).map(|ls| (ls, rayon::current_num_threads())))?;
    let accels: Vec<_> = pool.install(|| ls.scenes.iter().map(|s| accel::build(accel_kind, s)).collect::<Result<_>>())?;
    let leaves: Vec<_> = ls.scenes.iter().map(|s| s.leaf_instances()).collect::<Result<_>>()?;
    let build_seconds = t0.elapsed().as_secs_f64();
    drop(pool);
    let mut tr = LodTracer::new(&ls, &leaves, &accels, &lp);
    let cam = scene.camera.frame(opts.width, opts.height);
    let r = crate::lod::trace::render(&mut tr, &cam, opts)?;
    let c = &r.out.counters;
    let q = c.get(Counter::lod_queries).max(1);
    let npix = r.maps.lod_r.len().max(1) as f64;
    let stats = LodStats {
        levels: cp.levels,
        triangles_per_level: ls.triangles_per_level(),
        chain_seconds: ls.build_seconds,
        pass1_seconds: r.pass1_seconds,
        mean_query_level: c.get(Counter::lod_level_sum) as f64 / q as f64,
        reduced_reflect_share: r.maps.lod_r.iter().filter(|&&x| x < 1.0).count() as f64 / npix,
        reduced_transmit_share: r.maps.lod_t.iter().filter(|&&x| x < 1.0).count() as f64 / npix,
    };
    let accel_bytes = accels.iter().map(|a| a.memory_bytes()).sum();
    Ok(RunResult {
        out: r.out,
        build_seconds,
        build_threads,
        accel_bytes,
        finished: true,
        hierarchy: None,
        lod: Some(LodResult { stats, maps: r.maps }),
        cones: None,
    })
}

impl RunResult {
    pub fn stats(&self, scene: &Scene, method: Method, accel_kind: AccelKind, opts: &RenderOpts) -> Stats {
        let (inst, uniq) = scene.triangle_counts().unwrap_or((0, 0));
        let rays = self.out.counters.total_rays();
        Stats {
            scene: scene.name.clone(),
            method: method.name().into(),
            accel: crate::cli::render::accel_name(method, accel_kind).into(),
            width: opts.width,
            height: opts.height,
            spp: opts.spp,
            threads: self.out.threads,
            build_seconds: self.build_seconds,
            render_seconds: self.out.seconds,
            render_cpu_seconds: self.out.cpu_seconds,
            mrays_per_second: rays as f64 / self.out.seconds.max(1e-9) / 1e6,
            triangles_instanced: inst,
            triangles_unique: uniq,
            accel_bytes: self.accel_bytes,
            mesh_bytes: scene.mesh_bytes(),
            peak_rss_bytes: peak_rss_bytes(),
            simd: crate::core::SIMD_LEVEL,
            finished: self.finished,
            hierarchy: self.hierarchy.clone(),
            lod: self.lod.as_ref().map(|l| l.stats.clone()),
            counters: self.out.counters.to_map(),
            tests_counted: !(matches!(method, Method::Whitted | Method::Distributed | Method::Lod) && accel_kind == AccelKind::Embree),
            cone_profile: self.cones.as_ref().map(|c| c.stats()),
        }
    }
}

/// Resets the process's peak resident set size (VmHWM) to its current resident size
/// (`/proc/self/clear_refs`, Linux ≥ 4.0); does nothing where that is not available.
pub fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// Peak resident set size of this process (VmHWM from /proc/self/status), 0 if unknown.
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)).and_then(|k| k.parse::<u64>().ok())
        })
        .map(|kb| kb * 1024)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run's peak memory is its own: 1 GiB touched and freed before it no longer counts
    /// (the margin leaves room for the other tests of this process running beside it).
    #[test]
    fn peak_rss_resets() {
        let big = vec![1u8; 1 << 30];
        std::hint::black_box(&big);
        drop(big);
        let before = peak_rss_bytes();
        reset_peak_rss();
        let after = peak_rss_bytes();
        if before == 0 {
            return; // no /proc here
        }
        assert!(after + (700 << 20) < before, "peak {before} → {after} after the reset");
    }

    /// The build runs on the run's threads, as the render: a `--threads 1` (bench
    /// `threads=1`) row's BVH, point hierarchies and LOD chains were built on the global
    /// pool, every core, beside "thr 1" in the table.
    #[test]
    fn builds_run_on_the_runs_threads() {
        let scene = crate::scene::builtin::get("ico").unwrap();
        for threads in [1, 2] {
            let opts = RenderOpts { width: 8, height: 6, threads, quiet: true, ..Default::default() };
            let (mr, la) = (MultiresArgs::default(), LodArgs::default());
            for (m, a) in [
                (Method::Whitted, AccelKind::Bvh),
                (Method::Whitted, AccelKind::Octree),
                (Method::Multires, AccelKind::Bvh),
                (Method::Lod, AccelKind::Bvh),
            ] {
                let r = run(&scene, m, a, &opts, &mr, &la).unwrap();
                assert_eq!((r.build_threads, r.out.threads), (threads, threads), "{m:?} {a:?}");
            }
        }
    }
}
