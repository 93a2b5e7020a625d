//! `lodtrace animate SCENE --frames N [--update naive|lazy|lazy-cache|refit]`: ray tracing a
//! deforming point-sampled scene (Adams et al. 2005) frame by frame.
//!
//! SCENE is a built-in sequence (`armadillo-ball`, `bend`, `heads`, `elastic-balls`), a
//! mesh file, which is sampled into surfels, or a PLY point file (surfels as read); either
//! is dropped onto a floor. The motion is simulated and recorded first, so every update
//! mode replays the same frames; a frame's time is the hierarchy update (`begin_frame`: the
//! naive rebuild, or the lazy bookkeeping) plus the rays.
//! Shading: Phong-diffuse surfels in their collection colour, one point light with shadow
//! rays (the §4.4 shadow-ray path), the simulation's static planes and boxes rendered
//! analytically (planes only from their free side, so a hollow box shows as a cut-away).
//! The light is the sequence's (`Sequence::light`): for the hollow boxes of `heads` and
//! `elastic-balls` it hangs above the open top, since the walls shadow what is inside them
//! (until stop 46 it stood outside the front wall and the insides had no direct light).
//! `render_seconds` in `--stats` is the total over all frames.

use crate::baseline::accel::Ray;
use crate::core::stats::{Counter, Counters};
use crate::deform::{Collider, DeformCounters, DeformError, DeformTracer, Sequence, SequenceOptions, TraceParams, UpdateMode};
use crate::error::{Error, Result};
use crate::film::{io, Film};
use crate::scene::camera::CameraFrame;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use wide::f32x8;

/// `animate --bound`: how the lazy update bounds an inner node it does not refit.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Bound {
    /// The smaller of Eq. 9 and the re-centred bound (partition-of-unity maxima, each node's
    /// own rotation factored out) and Eq. 11 around the smallest sphere of both children
    /// (`tree` module docs; additions to the paper).
    Tight,
    /// Eq. 9 and Eq. 11 as the paper writes them (Eq. 9 around the Eq. 3 centre, Eq. 11
    /// around the same centre); only the leaf-disc extension of B_j stays (`tree` module docs).
    Paper,
}

/// `animate --nearest`: the order of a ray's candidate MLS hits ([`TraceParams::nearest_ellipse`]).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Nearest {
    Ellipse,
    Mls,
}

#[derive(clap::Args, Debug, Clone)]
pub struct AnimateArgs {
    /// Built-in sequence (armadillo-ball, bend, heads, elastic-balls), a mesh file (.off/.obj) or a point file (.ply: x y z nx ny nz, optional radius).
    pub scene: String,
    /// Frames to render (default: 90 for a built-in sequence, 60 for a mesh or point file).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub frames: Option<u32>,
    /// Hierarchy update: rebuild every frame (naive), lazy (§4.1), lazy with per-ray caching (§4.2.2), an obvhs BVH2 refitted every frame (refit), or per frame naive or lazy, whichever was cheaper when last tried (auto; the paper's §6 heuristic question).
    #[arg(long, default_value = "lazy-cache")]
    pub update: String,
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub width: u32,
    #[arg(long, default_value_t = 384, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub height: u32,
    /// Folder for the frames (frame_0000.png, ...) and a contact sheet of up to eight of them
    /// evenly spaced over the run (contact_sheet.png); none = no images.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Statistics as JSON: per-frame times and work counts, radius ratios per level, totals
    /// (`-`: to standard output; `none`: not written).
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Surfel and node counts relative to the paper's models (1 ≈ paper size).
    #[arg(long, default_value_t = 1.0)]
    pub detail: f32,
    /// No shadow rays.
    #[arg(long)]
    pub no_shadows: bool,
    /// Worker threads (0 = one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Rays per packet: 8 traces each 4×2 pixel tile's primary rays, then their shadow rays,
    /// as one packet (one sphere update and one f32x8 test per node for all eight); 1 traces
    /// ray by ray. Same images.
    #[arg(long, default_value_t = 8)]
    pub packet: u32,
    /// Lazy modes: the first visit of an inner node over at most this many surfels bounds it
    /// and its whole subtree from their deformed surfels (the leaf balls' box centre, the exact
    /// reach) instead of by Eq. 9 node by node; 0 = Eq. 9 everywhere (with `--bound paper`, the
    /// paper's update as written; at most 2^24; default 4096).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=16_777_216))]
    pub exact_below: Option<u32>,
    /// Lazy modes: the radius bound of an inner node that is not refitted. `tight` (default)
    /// adds to Eq. 9 a re-centred bound with each node's own rotation factored out, and
    /// re-centres Eq. 11; `paper` is Eq. 9 and Eq. 11 as written. `--exact-below 0 --bound
    /// paper` is the paper's update throughout. Same images.
    #[arg(long, value_enum, default_value_t = Bound::Tight)]
    pub bound: Bound,
    /// The MLS support of a surfel grows with its local stretch, at most by this factor (1 =
    /// the rest-pose support, the paper's fixed neighbourhoods of §4.2.1; 1..=8, default 3).
    /// A stretched surface keeps enough neighbours inside the support [default: 3].
    #[arg(long)]
    pub support_stretch: Option<f32>,
    /// Per-ray cache (`--update lazy-cache`, §4.2.2): cache the ancestor this many levels
    /// above the leaf of each ray's closest hit instead of the leaf itself (0, the paper's
    /// choice; at most 64). Under motion a surfel leaves the ray within a frame or two, a
    /// larger node does not.
    #[arg(long, default_value_t = 0)]
    pub cache_up: u32,
    /// Per-ray cache (`--update lazy-cache`): when the cached node holds no hit, climb from it
    /// towards the root, searching each ancestor's other child, until a hit is found (not
    /// in the paper, which then descends from the root unbounded). The smallest node that
    /// bounds the ray, whatever the motion was; pays off with `--unordered`. Same images.
    #[arg(long)]
    pub cache_climb: bool,
    /// Per-ray cache (`--update lazy-cache`) under front-to-back traversal: look the cache up
    /// only while at least this share of its lookups hit and they save 5 % of the sphere and
    /// leaf tests (every 8 frames an open cache skips its lookups for a frame and a closed
    /// one probes, to compare; not in the paper: front to back finds the bound a cached
    /// node gives by itself, so a cache that misses or saves nothing only costs). 0 = look
    /// up every frame, as the paper does; `--unordered` always does. Same images [default:
    /// 0.25]
    #[arg(long)]
    pub cache_gate: Option<f32>,
    /// Visit a node's children left first instead of nearer first (closest-hit rays). This
    /// is the order in which the per-ray cache pays off (§4.2.2: the cached hit bounds the
    /// traversal); front to back (the default) finds that bound by itself. Same images.
    #[arg(long)]
    pub unordered: bool,
    /// Test every instance's root sphere with every ray instead of finding the instances
    /// along the ray in a sphere tree over them (rebuilt every frame; not in the paper).
    /// Same images; for scenes of many objects (`elastic-balls`: 40) it costs time.
    #[arg(long)]
    pub no_instance_tree: bool,
    /// Iterate MLS from every ellipse hit of a clipped surface (§4.3, the paper) instead of
    /// first rejecting those whose surfel lies wholly in the clipped part (its leaf ball more
    /// than its radius in front of both clipping neighbours' planes). Same images; `heads`
    /// runs about half as many MLS iterations with the early rejection.
    #[arg(long)]
    pub no_clip_early: bool,
    /// Which MLS hit is a ray's closest: `ellipse` (default) iterates from the nearest
    /// ellipse hit only; `mls` iterates from every ellipse hit the ray meets (4–5 overlapping
    /// splats per visible point) and keeps the nearest result. Images differ at a few
    /// grazing pixels (`armadillo-ball`: mean FLIP 0.0014; README, "Nearest ellipse").
    #[arg(long, value_enum, default_value_t = Nearest::Ellipse)]
    pub nearest: Nearest,
    /// Profiling: with `--out`, also write each frame's work per pixel as `cost_NNNN.png`:
    /// bounding-volume and ray–surfel tests of the pixel's primary and shadow rays, on a log
    /// scale in magma colours (black none, pale yellow the frame's most). With packets of 8
    /// (the default) each 4×2 tile shows its rays' mean; `--packet 1` gives each pixel its own.
    #[arg(long)]
    pub cost: bool,
    /// Profiling: render every frame a second time, untimed in `seconds`, and report that
    /// pass as `warm_seconds` (per frame, in `--stats`) — the rays alone with every sphere
    /// the first pass reached already current (and tightened by Eq. 11), so `seconds −
    /// warm_seconds` is a lazy frame's update cost and, for `naive`, about its rebuild. The
    /// extra pass disturbs the caches: the timed frames of such a run are slower (≈ 5–15 %).
    #[arg(long)]
    pub warm_pass: bool,
    /// No progress bar (the summary line on stderr stays).
    #[arg(long)]
    pub quiet: bool,
}

impl AnimateArgs {
    /// `lodtrace animate SCENE` with every option at its command-line default, for callers
    /// (render, bench, demo) that set a few (the defaults come from the clap attributes above,
    /// so they cannot drift).
    pub fn new(scene: &str) -> Self {
        use clap::{Args, FromArgMatches};
        let m = Self::augment_args(clap::Command::new("animate")).get_matches_from(["animate", "--", scene]);
        Self::from_arg_matches(&m).expect("the defaults parse")
    }
}

/// Per-frame statistics (the paper's Fig. 5 curves come from `seconds`).
#[derive(Serialize, Debug, Clone)]
pub struct FrameRow {
    pub frame: u32,
    /// The update mode of this frame (`auto/naive` or `auto/lazy` under `--update auto`).
    pub mode: String,
    pub seconds: f64,
    pub update_seconds: f64,
    pub inner_nodes_updated: u64,
    pub surfels_deformed: u64,
    pub sphere_tests: u64,
    pub leaf_tests: u64,
    /// MLS iterations started, and those that converged.
    pub mls_runs: u64,
    pub mls_hits: u64,
    pub mls_iterations_mean: f64,
    pub cache_lookups: u64,
    pub cache_hits: u64,
    pub clipped: u64,
    /// Ellipse hits of surfels whose whole leaf ball is clipped, rejected before the MLS
    /// iteration (not in `mls_runs`).
    pub clipped_early: u64,
    /// Shadow rays: traced, entering an object's root sphere, occluded, and their sphere and
    /// leaf tests (`DeformCounters::shadow_rays` and after).
    pub shadow_rays: u64,
    pub shadow_entered: u64,
    pub shadow_occluded: u64,
    pub shadow_tests: u64,
    /// `--warm-pass`: the same frame's rays again, with its hierarchy already updated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub warm_seconds: Option<f64>,
    /// Sphere tests of the warm pass (`--warm-pass`): against `sphere_tests`, what the first
    /// visits' looser spheres cost in tests.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub warm_sphere_tests: Option<u64>,
}

#[derive(Serialize, Debug, Clone)]
pub struct AnimateStats {
    pub scene: String,
    pub method: String,
    /// The bounding structure: `sphere-tree` (naive, lazy, lazy-cache) or `bvh2` (refit).
    pub accel: String,
    pub update: String,
    /// The tracer's parameters (paper defaults unless an option changed them).
    pub trace_params: TraceParams,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub frames: u32,
    pub threads: usize,
    pub surfels: u64,
    /// Making the sequence: loading or sampling the surfels, their neighbours, the simulation
    /// nodes and the rest pose's sphere hierarchy (§4.1 build, Eq. 9 precomputation).
    pub setup_seconds: f64,
    /// The tracer's own set-up for the update mode (per-instance state, the refit BVH2).
    pub build_seconds: f64,
    pub simulate_seconds: f64,
    /// Total over all frames (update + rays).
    pub render_seconds: f64,
    pub per_frame: Vec<FrameRow>,
    /// Updated radius / tightest radius per level after the last frame (Fig. 3).
    pub radius_ratios: Vec<crate::deform::LevelRatio>,
    /// Sphere tests per frame by tree level, root first (mean over the frames; the objects'
    /// trees only: `DeformCounters::level_tests`). Where a hierarchy spends its tests.
    pub level_tests_per_frame: Vec<f64>,
    pub counters: std::collections::BTreeMap<String, u64>,
    /// The last frame rendered (for image comparisons across update modes).
    #[serde(skip)]
    pub last_frame: Film,
    /// With `--cost`: the last frame's tests per pixel (row-major), else empty.
    #[serde(skip)]
    pub last_cost: Vec<u32>,
}

fn derr(e: DeformError) -> Error {
    match e {
        DeformError::Load(e) => e,
        e => Error::Scene(e.to_string()),
    }
}

pub fn parse_mode(s: &str) -> Result<UpdateMode> {
    s.parse::<UpdateMode>().map_err(|_| Error::Usage(format!("--update {s}: naive, lazy, lazy-cache, refit or auto")))
}

/// `a` with `none` outputs absent: `--out none` means no images, as its help says (until
/// stop 80 the frames went to `./none`), and `--stats none` no statistics (stop 82).
pub(crate) fn none_outputs(a: &AnimateArgs) -> AnimateArgs {
    let mut a = a.clone();
    super::none_is_absent(&mut a.out);
    super::none_is_absent(&mut a.stats);
    a
}

pub fn run(a: &AnimateArgs) -> Result<()> {
    let a = &none_outputs(a);
    let stats = animate(a)?;
    if a.warm_pass {
        let warm: f64 = stats.per_frame.iter().filter_map(|r| r.warm_seconds).sum();
        let n = stats.frames.max(1) as f64;
        crate::status!(
            "warm pass (same rays, hierarchy already updated): {:.1} ms/frame; update cost {:.1} ms/frame",
            1e3 * warm / n,
            1e3 * (stats.render_seconds - warm) / n
        );
    }
    // The share of a frame spent before its rays (`begin_frame`: naive's rebuild, the lazy
    // modes' deformation fields and instance roots); a lazy mode's node updates during the
    // rays are in the rest.
    let before_rays: f64 = stats.per_frame.iter().map(|r| r.update_seconds).sum();
    crate::status!(
        "{}: {} frames {}x{} --update {}: {:.3} s in all, {:.1} ms/frame ({:.1} of them before the rays), {} surfels",
        stats.scene,
        stats.frames,
        stats.width,
        stats.height,
        stats.update,
        stats.render_seconds,
        1e3 * stats.render_seconds / stats.frames.max(1) as f64,
        1e3 * before_rays / stats.frames.max(1) as f64,
        stats.surfels
    );
    if let Some(d) = &a.out {
        let stale = stale_frames(d, stats.frames as usize, a.cost);
        if let Some(first) = stale.first() {
            crate::status!(
                "lodtrace: warning: {} holds {} frame file{} of an earlier run ({first}{}): this run wrote frames 0-{}",
                d.display(),
                stale.len(),
                if stale.len() == 1 { "" } else { "s" },
                if stale.len() > 1 { ", ..." } else { "" },
                stats.frames.saturating_sub(1)
            );
        }
    }
    Ok(())
}

/// The `frame_NNNN.png` (and `cost_NNNN.png`) files in `dir` that a run of `frames` frames
/// (with `--cost` or not) did not write: an earlier, longer run's, which a viewer of the
/// folder would take for this one's. Left in place (they are the user's), named in a warning.
fn stale_frames(dir: &std::path::Path, frames: usize, cost: bool) -> Vec<String> {
    let Ok(rd) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut v: Vec<String> = rd
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| {
            let (prefix, wrote) = if let Some(r) = n.strip_prefix("frame_") {
                (r, true)
            } else if let Some(r) = n.strip_prefix("cost_") {
                (r, cost)
            } else {
                return false;
            };
            let Some(digits) = prefix.strip_suffix(".png") else { return false };
            let Ok(i) = digits.parse::<usize>() else { return false };
            digits.len() >= 4 && digits.bytes().all(|b| b.is_ascii_digit()) && !(wrote && i < frames)
        })
        .collect();
    v.sort();
    v
}

/// Checks the options of an `animate` run before anything is read or written; its update mode.
pub(crate) fn check(a: &AnimateArgs) -> Result<UpdateMode> {
    let mode = parse_mode(&a.update)?;
    if a.frames == Some(0) {
        return Err(Error::Usage("--frames 0: nothing to render".into()));
    }
    if let Some(n) = a.frames {
        if n > 100_000 {
            return Err(Error::Usage(format!("--frames {n} is absurd")));
        }
    }
    if a.width == 0 || a.height == 0 || a.width > 16384 || a.height > 16384 {
        return Err(Error::Usage(format!("image size {}x{} out of range (each side 1..=16384)", a.width, a.height)));
    }
    crate::baseline::render::check_pixels(a.width, a.height)?;
    if !(a.detail.is_finite() && a.detail > 0.0 && a.detail <= 10.0) {
        return Err(Error::Usage(format!("--detail {} out of range (0, 10]", a.detail)));
    }
    if let Some(e) = a.exact_below.filter(|&e| e > crate::deform::trace::MAX_EXACT_BELOW) {
        return Err(Error::Usage(format!("--exact-below {e}: at most {}", crate::deform::trace::MAX_EXACT_BELOW)));
    }
    if let Some(s) = a.support_stretch.filter(|s| !(s.is_finite() && (1.0..=8.0).contains(s))) {
        return Err(Error::Usage(format!("--support-stretch {s} out of range [1, 8]")));
    }
    if a.bound != Bound::Tight && matches!(mode, UpdateMode::Naive | UpdateMode::Refit) {
        return Err(Error::Usage(format!("--bound is an option of the lazy updates; --update {} would ignore it", mode.name())));
    }
    if a.cache_up > crate::deform::trace::MAX_CACHE_UP {
        return Err(Error::Usage(format!("--cache-up {}: at most {}", a.cache_up, crate::deform::trace::MAX_CACHE_UP)));
    }
    if a.cost && a.out.is_none() {
        return Err(Error::Usage("--cost writes cost_NNNN.png beside the frames: give --out DIR".into()));
    }
    if a.cache_up > 0 && mode != UpdateMode::LazyCache {
        return Err(Error::Usage(format!("--cache-up is an option of --update lazy-cache; --update {} would ignore it", mode.name())));
    }
    if a.cache_climb && mode != UpdateMode::LazyCache {
        return Err(Error::Usage(format!("--cache-climb is an option of --update lazy-cache; --update {} would ignore it", mode.name())));
    }
    if let Some(g) = a.cache_gate {
        if mode != UpdateMode::LazyCache {
            return Err(Error::Usage(format!(
                "--cache-gate is an option of --update lazy-cache; --update {} would ignore it",
                mode.name()
            )));
        }
        if !(0.0..=1.0).contains(&g) {
            return Err(Error::Usage(format!("--cache-gate {g}: a share of the lookups, in [0, 1]")));
        }
        // The unordered descent is never gated (`TraceParams::cache_gate`); until stop 80
        // the gate was taken beside it without a word.
        if a.unordered {
            return Err(Error::Usage("--cache-gate has no effect beside --unordered (which looks the cache up every frame)".into()));
        }
    }
    if a.exact_below.is_some() && matches!(mode, UpdateMode::Naive | UpdateMode::Refit) {
        return Err(Error::Usage(format!("--exact-below is an option of the lazy updates; --update {} would ignore it", mode.name())));
    }
    if a.unordered && mode == UpdateMode::Refit {
        return Err(Error::Usage("--unordered orders the sphere tree's traversal; --update refit (an obvhs BVH2) would ignore it".into()));
    }
    if a.packet != 1 && a.packet != 8 {
        return Err(Error::Usage(format!("--packet {}: 1 or 8", a.packet)));
    }
    // `--stats` naming the `--out` folder itself: said as such (it read "is a folder" once the
    // run had made the folder).
    if let (Some(d), Some(p)) = (&a.out, &a.stats) {
        if io::same_path(d, p) {
            return Err(Error::Usage(format!("--stats {} names the --out folder; give it a file name (inside it is fine)", p.display())));
        }
    }
    Ok(mode)
}

/// Runs the animation; writes frames and stats as asked; returns the statistics.
pub fn animate(a: &AnimateArgs) -> Result<AnimateStats> {
    let mode = check(a)?;
    let pool = crate::core::thread_pool(a.threads)?;
    let threads = pool.current_num_threads();
    // A failed run removes the output folder again if it created it.
    io::discard_dir_on_error(a.out.as_deref(), || {
        if let Some(d) = &a.out {
            crate::film::io::create_out_dir(d)?;
            io::check_writable_dir(d)?;
        }
        // After the folder exists: `--stats` may go inside it.
        if let Some(p) = &a.stats {
            super::render::check_json_path(p, "--stats")?;
            // It cannot be one of the frames (`frame_NNNN.png`): `check_json_path` refuses .png.
            io::check_outputs_apart_from_scene(&a.scene, &[p])?;
        }
        pool.install(|| animate_in_pool(a, mode, threads))
    })
}

/// The error for a built-in sequence whose mesh is not installed: worded like a built-in
/// scene's, so that `demo` skips the sequence as it skips such a scene (it took the old
/// "invalid option" for a failure and stopped after the triangle scenes, stop 79).
pub(crate) fn missing_sequence_mesh(seq: &str, path: &std::path::Path) -> Error {
    Error::Scene(format!("sequence '{seq}' needs the mesh {} (not found): {}", path.display(), crate::scene::builtin::MISSING_ASSET_HINT))
}

fn animate_in_pool(a: &AnimateArgs, mode: UpdateMode, threads: usize) -> Result<AnimateStats> {
    let opts =
        SequenceOptions { detail: a.detail, armadillo: crate::scene::builtin::assets_dir().join("armadillo.off"), ..Default::default() };
    let t_setup = Instant::now();
    let mut seq = if Sequence::BUILTIN.contains(&a.scene.as_str()) {
        Sequence::builtin(&a.scene, &opts).map_err(derr).map_err(|e| match e {
            // A built-in sequence's mesh missing: say how to get it (as the built-in scenes do).
            Error::Io { path, source } if source.kind() == std::io::ErrorKind::NotFound => missing_sequence_mesh(&a.scene, &path),
            e => e,
        })?
    } else {
        let p = std::path::Path::new(&a.scene);
        let has_ext = |xs: &[&str]| xs.iter().any(|x| p.extension().is_some_and(|e| e.eq_ignore_ascii_case(x)));
        let named_file = has_ext(&["ply", "off", "obj"]);
        if named_file || p.exists() {
            // A file was meant: say what is wrong with it (missing, a folder, a FIFO).
            crate::error::check_input_file(p)?;
        }
        if !p.is_file() {
            return Err(Error::Usage(format!(
                "unknown sequence '{}' (built-in: {}; or give an .obj, .off or .ply file)",
                a.scene,
                Sequence::BUILTIN.join(", ")
            )));
        }
        if has_ext(&["ply"]) {
            // Every error names the file (the surfel checks' own messages name only the point).
            let named = |e: DeformError| match e {
                DeformError::Ply { .. } => e,
                DeformError::TooSmall(ref m) if m.contains(&*p.to_string_lossy()) => e,
                e => DeformError::Ply { path: p.to_path_buf(), msg: e.to_string() },
            };
            let model = crate::deform::ply::load_ply(p).map_err(|e| derr(named(e)))?;
            Sequence::from_points(model, &opts).map_err(|e| derr(named(e)))?
        } else {
            if !has_ext(&["off", "obj"]) {
                return Err(Error::Usage(format!(
                    "{}: deforming surfels (animate, --method surfel) come from a built-in sequence ({}), an .obj or .off mesh or a .ply point file; scene files (.toml) are for the other methods",
                    a.scene,
                    Sequence::BUILTIN.join(", ")
                )));
            }
            let mesh = crate::scene::load::load_mesh(p, 0)?;
            Sequence::from_mesh(&mesh, &opts).map_err(derr)?
        }
    };
    let setup_seconds = t_setup.elapsed().as_secs_f64();
    let frames = a.frames.unwrap_or(seq.frames);
    let t0 = Instant::now();
    // The motion is simulated whole before the first frame is traced (about 2 ms a frame
    // for the built-in sequences): shown, so that a long run does not look hung.
    let sim_bar = frames_bar(a.quiet, frames, format!("simulate {}", seq.name));
    let rec = seq.record_with(frames, || sim_bar.inc(1)).map_err(derr)?;
    sim_bar.finish_and_clear();
    let simulate_seconds = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let mut tracer = DeformTracer::new(
        &seq.scene,
        mode,
        TraceParams {
            exact_below: a.exact_below.unwrap_or(crate::deform::trace::TraceParams::default().exact_below),
            cache_up: a.cache_up,
            cache_climb: a.cache_climb,
            cache_gate: a.cache_gate.unwrap_or(TraceParams::default().cache_gate),
            ordered: !a.unordered,
            instance_tree: !a.no_instance_tree,
            clip_early: !a.no_clip_early,
            nearest_ellipse: a.nearest == Nearest::Ellipse,
            recentred_bound: a.bound == Bound::Tight,
            node_rotation: a.bound == Bound::Tight,
            recentre_eq11: a.bound == Bound::Tight,
            max_support_stretch: a.support_stretch.unwrap_or(TraceParams::default().max_support_stretch),
            ..TraceParams::default()
        },
    )
    .map_err(derr)?;
    tracer.set_cache_slots((a.width * a.height) as usize);
    let build_seconds = t0.elapsed().as_secs_f64();
    let surfels: u64 = tracer.frame_stats().surfels_total;
    let cam = seq.camera.frame(a.width, a.height);
    let light = seq.light;
    let colliders = seq.world.colliders.clone();
    let colors: Vec<Vec<Vec3>> =
        seq.scene.objects.iter().map(|o| o.model.collections.iter().map(|c| Vec3::from(c.color)).collect()).collect();
    let inst_obj: Vec<usize> = seq.scene.instances.iter().map(|&o| o as usize).collect();
    crate::error::flush_warnings();
    let bar = frames_bar(a.quiet, frames, format!("animate {} {}", seq.name, mode.name()));
    let mut rows = Vec::new();
    let mut total = Counters::default();
    let mut dtotal = DeformCounters::default();
    let mut render_seconds = 0.0;
    // The frame being rendered, reused (`render_frame`); after the loop, the last one.
    let mut last_frame = Film::new(a.width, a.height);
    let mut warm_film: Option<Film> = None;
    let mut last_cost = Vec::new();
    let sheet_frames = contact_frames(frames);
    let mut sheet: Vec<image::RgbImage> = Vec::new();
    for (f, nodes) in rec.frames.iter().enumerate() {
        let t = Instant::now();
        tracer.begin_frame(nodes).map_err(derr)?;
        let sc = ShadeCtx {
            colliders: &colliders,
            boxes: box_union(&colliders),
            colors: &colors,
            inst_obj: &inst_obj,
            light,
            shadows: !a.no_shadows,
        };
        let (c, dc, cost) = render_frame(&tracer, &cam, &sc, &mut last_frame, a.packet, a.cost);
        let secs = t.elapsed().as_secs_f64();
        tracer.end_frame(secs, &dc);
        render_seconds += secs;
        total.merge(&c);
        dtotal.merge(&dc);
        let fs = tracer.frame_stats();
        let warm = a.warm_pass.then(|| {
            let t = Instant::now();
            let (_, wdc, _) =
                render_frame(&tracer, &cam, &sc, warm_film.get_or_insert_with(|| Film::new(a.width, a.height)), a.packet, false);
            (t.elapsed().as_secs_f64(), wdc.sphere_tests)
        });
        let (warm_seconds, warm_sphere_tests) = (warm.map(|w| w.0), warm.map(|w| w.1));
        rows.push(FrameRow {
            frame: f as u32,
            mode: fs.mode.clone(),
            seconds: secs,
            update_seconds: fs.update_seconds,
            inner_nodes_updated: fs.inner_nodes_updated,
            surfels_deformed: fs.surfels_deformed,
            sphere_tests: dc.sphere_tests,
            leaf_tests: dc.leaf_tests,
            mls_runs: dc.mls_runs,
            mls_hits: dc.mls_hits,
            mls_iterations_mean: if dc.mls_runs > 0 { dc.mls_iterations as f64 / dc.mls_runs as f64 } else { 0.0 },
            cache_lookups: dc.cache_lookups,
            cache_hits: dc.cache_hits,
            clipped: dc.clipped,
            clipped_early: dc.clipped_early,
            shadow_rays: dc.shadow_rays,
            shadow_entered: dc.shadow_entered,
            shadow_occluded: dc.shadow_occluded,
            shadow_tests: dc.shadow_tests,
            warm_seconds,
            warm_sphere_tests,
        });
        if let Some(d) = &a.out {
            io::write_png(&d.join(format!("frame_{f:04}.png")), &last_frame)?;
            if sheet_frames.contains(&(f as u32)) {
                sheet.push(thumbnail(&io::to_rgb8(&last_frame)));
            }
            if a.cost {
                let img = crate::film::metrics::cost_map(&cost, a.width, a.height)?;
                io::write_rgb8_png(&d.join(format!("cost_{f:04}.png")), &img)?;
            }
        }
        last_cost = cost;
        bar.inc(1);
    }
    bar.finish_and_clear();
    if let Some(d) = &a.out {
        io::write_rgb8_png(&d.join("contact_sheet.png"), &contact_sheet(&sheet))?;
    }
    let stats = AnimateStats {
        scene: seq.name.clone(),
        method: "surfel".into(),
        accel: if mode == UpdateMode::Refit { "bvh2" } else { "sphere-tree" }.into(),
        update: mode.name().into(),
        trace_params: tracer.params().clone(),
        width: a.width,
        height: a.height,
        spp: 1,
        frames,
        threads,
        surfels,
        setup_seconds,
        build_seconds,
        simulate_seconds,
        render_seconds,
        per_frame: rows,
        radius_ratios: tracer.radius_ratios(64),
        level_tests_per_frame: {
            let used = dtotal.level_tests.iter().rposition(|&t| t > 0).map_or(0, |i| i + 1);
            dtotal.level_tests[..used].iter().map(|&t| t as f64 / frames.max(1) as f64).collect()
        },
        counters: total.to_map(),
        last_frame,
        last_cost,
    };
    if let Some(p) = &a.stats {
        let json = serde_json::to_string_pretty(&stats).expect("stats serialise") + "\n";
        super::render::write_json(p, &json)?;
    }
    Ok(stats)
}

/// The frames a contact sheet shows: up to eight, evenly spaced from the first to the last.
fn contact_frames(frames: u32) -> Vec<u32> {
    let n = frames.min(8);
    (0..n).map(|i| if n > 1 { (i as u64 * (frames as u64 - 1) / (n as u64 - 1)) as u32 } else { 0 }).collect()
}

/// A frame scaled down to at most 320 pixels wide for the contact sheet (kept as it is when
/// smaller).
fn thumbnail(img: &image::RgbImage) -> image::RgbImage {
    const W: u32 = 320;
    if img.width() <= W {
        return img.clone();
    }
    let h = ((img.height() as u64 * W as u64) / img.width() as u64).max(1) as u32;
    image::imageops::resize(img, W, h, image::imageops::FilterType::Triangle)
}

/// Thumbnails in rows of four, in frame order, two pixels of white between them.
fn contact_sheet(th: &[image::RgbImage]) -> image::RgbImage {
    const GAP: u32 = 2;
    let (w, h) = th.first().map_or((1, 1), |t| (t.width(), t.height()));
    let cols = (th.len() as u32).clamp(1, 4);
    let rows = (th.len() as u32).div_ceil(4).max(1);
    let mut out = image::RgbImage::from_pixel(cols * w + (cols - 1) * GAP, rows * h + (rows - 1) * GAP, image::Rgb([255, 255, 255]));
    for (i, t) in th.iter().enumerate() {
        let (c, r) = (i as u32 % 4, i as u32 / 4);
        image::imageops::replace(&mut out, t, (c * (w + GAP)) as i64, (r * (h + GAP)) as i64);
    }
    out
}

/// One frame's primary and shadow rays into `film` (the tracer's frame must be begun).
/// Every pixel's colour is written, so a film is reused from frame to frame without
/// clearing (allocating and filling a new one cost both update modes alike, about 1 ms of
/// a 512×384 frame); its depth and normal layers are not touched.
fn render_frame(
    tr: &DeformTracer,
    cam: &CameraFrame,
    sc: &ShadeCtx,
    film: &mut Film,
    packet: u32,
    want_cost: bool,
) -> (Counters, DeformCounters, Vec<u32>) {
    let w = film.width as usize;
    // Packets: two rows per task, 4×2 pixel tiles.
    let rows_per_task = if packet == 8 { 2 } else { 1 };
    let work = |dc: &DeformCounters| dc.sphere_tests + dc.leaf_tests;
    let parts: Vec<(Counters, DeformCounters, Vec<u32>)> = film
        .color
        .par_chunks_mut(w * rows_per_task)
        .enumerate()
        .map(|(jb, block)| {
            let mut c = Counters::default();
            let mut dc = DeformCounters::default();
            let mut cost = if want_cost { vec![0u32; block.len()] } else { Vec::new() };
            let j0 = jb * rows_per_task;
            if packet == 1 {
                for (i, px) in block.iter_mut().enumerate() {
                    let ray = Ray::new(cam.eye, cam.pixel_center_dir(i as u32, j0 as u32));
                    let slot = Some((j0 * w + i) as u32);
                    let before = work(&dc);
                    *px = shade(tr, &ray, slot, sc, &mut c, &mut dc);
                    if want_cost {
                        cost[i] = (work(&dc) - before).min(u32::MAX as u64) as u32;
                    }
                }
                return (c, dc, cost);
            }
            let nrows = block.len() / w;
            let mut rays = Vec::with_capacity(8);
            let mut slots = Vec::with_capacity(8);
            let mut idx = Vec::with_capacity(8);
            for x0 in (0..w).step_by(4) {
                rays.clear();
                slots.clear();
                idx.clear();
                // The tile's directions in one pass (lanes past the image's edge unused).
                let dirs = cam.pixel_center_dirs_x8(
                    std::array::from_fn(|k| (x0 + k % 4).min(w - 1) as u32),
                    std::array::from_fn(|k| (j0 + k / 4).min(j0 + nrows - 1) as u32),
                );
                for dy in 0..nrows {
                    for x in x0..(x0 + 4).min(w) {
                        let j = j0 + dy;
                        rays.push(Ray::new(cam.eye, dirs[dy * 4 + x - x0]));
                        slots.push(Some((j * w + x) as u32));
                        idx.push(dy * w + x);
                    }
                }
                let before = work(&dc);
                let col = shade_x8(tr, &rays, &slots, sc, &mut c, &mut dc);
                let mean = ((work(&dc) - before) / idx.len() as u64).min(u32::MAX as u64) as u32;
                for (k, &p) in idx.iter().enumerate() {
                    block[p] = col[k];
                    if want_cost {
                        cost[p] = mean;
                    }
                }
            }
            (c, dc, cost)
        })
        .collect();
    let (mut c, mut dc, mut cost) = (Counters::default(), DeformCounters::default(), Vec::new());
    for (pc, pdc, pcost) in parts {
        c.merge(&pc);
        dc.merge(&pdc);
        cost.extend(pcost);
    }
    (c, dc, cost)
}

/// Nearest static collider along the ray: (t, normal).
fn hit_colliders(ray: &Ray, colliders: &[Collider], tmax: f32) -> Option<(f32, Vec3)> {
    let mut best: Option<(f32, Vec3)> = None;
    let mut tb = tmax;
    for c in colliders {
        match *c {
            Collider::Plane { n, d } => {
                let dn = ray.dir.dot(n);
                // Seen from the free side only (a hollow box is a cut-away).
                if dn < 0.0 {
                    let t = (d - ray.org.dot(n)) / dn;
                    if t > ray.tnear && t < tb {
                        tb = t;
                        best = Some((t, n));
                    }
                }
            }
            Collider::Box { lo, hi } => {
                let inv = ray.dir.recip();
                let t0 = (lo - ray.org) * inv;
                let t1 = (hi - ray.org) * inv;
                let (tn, tf) = (t0.min(t1), t0.max(t1));
                let (a, b) = (tn.max_element(), tf.min_element());
                if a <= b && a > ray.tnear && a < tb {
                    tb = a;
                    let axis = if tn.x == a {
                        0
                    } else if tn.y == a {
                        1
                    } else {
                        2
                    };
                    let mut n = Vec3::ZERO;
                    n[axis] = -ray.dir[axis].signum();
                    best = Some((a, n));
                }
            }
        }
    }
    best
}

/// [`hit_colliders`] for up to eight rays at once (f32x8, one collider per step): lane `i`
/// is bit for bit `hit_colliders(&rays[i], colliders, tmax[i])` — the same operations in the
/// same order, `fast_min`/`fast_max` being glam's `a < b ? a : b` — and the lanes past
/// `rays.len()` miss. A scalar call costs ~270 instructions on `bend` (a plane and six
/// bars) and runs for every primary and every unoccluded shadow ray; both update modes pay
/// it alike.
///
/// `boxes` ([`box_union`]) bounds every `Box` collider: when no lane's segment meets it,
/// the boxes are skipped (on `bend` the six bars of the apparatus, most packets). The cull
/// runs only when every lane's direction is finite and nonzero on all axes: the union's
/// slab intervals then contain each box's (rounding is monotonic), so no hit is lost.
fn hit_colliders_x8(rays: &[Ray], colliders: &[Collider], boxes: Option<(Vec3, Vec3)>, tmax: &[f32; 8]) -> [Option<(f32, Vec3)>; 8] {
    let mut out = [None; 8];
    if colliders.is_empty() || rays.is_empty() {
        return out;
    }
    let (mut ol, mut dl, mut nl) = ([[0.0f32; 8]; 3], [[1.0f32; 8]; 3], [f32::INFINITY; 8]);
    for (i, r) in rays.iter().enumerate().take(8) {
        for a in 0..3 {
            ol[a][i] = r.org[a];
            dl[a][i] = r.dir[a];
        }
        nl[i] = r.tnear;
    }
    let (o, d, tnear) = (ol.map(f32x8::from), dl.map(f32x8::from), f32x8::from(nl));
    let inv = [f32x8::ONE / d[0], f32x8::ONE / d[1], f32x8::ONE / d[2]];
    let mut tb = f32x8::from(*tmax);
    let mut hit = f32x8::ZERO;
    let zero = f32x8::ZERO;
    let mut nb = [zero; 3];
    let skip_boxes = boxes.is_some_and(|(lo, hi)| {
        let inf = f32x8::splat(f32::INFINITY);
        let finite = inv[0].abs().simd_lt(inf) & inv[1].abs().simd_lt(inf) & inv[2].abs().simd_lt(inf);
        if finite.to_bitmask() != 0xff {
            return false;
        }
        let (mut a, mut b) = (f32x8::splat(f32::NEG_INFINITY), f32x8::splat(f32::INFINITY));
        for ax in 0..3 {
            let t0 = (f32x8::splat(lo[ax]) - o[ax]) * inv[ax];
            let t1 = (f32x8::splat(hi[ax]) - o[ax]) * inv[ax];
            (a, b) = (a.fast_max(t0.fast_min(t1)), b.fast_min(t0.fast_max(t1)));
        }
        (a.simd_le(b) & b.simd_gt(tnear) & a.simd_lt(tb)).to_bitmask() == 0
    });
    for c in colliders {
        match *c {
            Collider::Plane { n, d: pd } => {
                let dn = d[0] * n.x + d[1] * n.y + d[2] * n.z;
                let t = (f32x8::splat(pd) - (o[0] * n.x + o[1] * n.y + o[2] * n.z)) / dn;
                let m = dn.simd_lt(zero) & t.simd_gt(tnear) & t.simd_lt(tb);
                tb = m.select(t, tb);
                hit |= m;
                for (a, nb) in nb.iter_mut().enumerate() {
                    *nb = m.select(f32x8::splat(n[a]), *nb);
                }
            }
            Collider::Box { .. } if skip_boxes => {}
            Collider::Box { lo, hi } => {
                let mut tn = [zero; 3];
                let mut tf = [zero; 3];
                for a in 0..3 {
                    let t0 = (f32x8::splat(lo[a]) - o[a]) * inv[a];
                    let t1 = (f32x8::splat(hi[a]) - o[a]) * inv[a];
                    (tn[a], tf[a]) = (t0.fast_min(t1), t0.fast_max(t1));
                }
                let a = tn[0].fast_max(tn[1].fast_max(tn[2]));
                let b = tf[0].fast_min(tf[1].fast_min(tf[2]));
                let m = a.simd_le(b) & a.simd_gt(tnear) & a.simd_lt(tb);
                if m.to_bitmask() == 0 {
                    continue;
                }
                tb = m.select(a, tb);
                hit |= m;
                // The entry face: the first axis whose slab entry is the box entry, its normal
                // against the ray (glam's `signum`: ±1 by the sign bit).
                let ex = tn[0].simd_eq(a);
                let ey = !ex & tn[1].simd_eq(a);
                let ez = !(ex | ey);
                for (ax, e) in [ex, ey, ez].into_iter().enumerate() {
                    let away = -(f32x8::ONE | (d[ax] & f32x8::splat(-0.0)));
                    nb[ax] = m.select(e.select(away, zero), nb[ax]);
                }
            }
        }
    }
    let (t, m) = (tb.to_array(), hit.to_bitmask());
    let nb = nb.map(|v| v.to_array());
    for (i, o) in out.iter_mut().enumerate().take(rays.len()) {
        if m & (1 << i) != 0 {
            *o = Some((t[i], Vec3::new(nb[0][i], nb[1][i], nb[2][i])));
        }
    }
    out
}

/// The box around every `Box` collider, if there are two or more ([`hit_colliders_x8`]'s
/// cull; for one box its own test is the cull).
fn box_union(colliders: &[Collider]) -> Option<(Vec3, Vec3)> {
    let mut boxes = colliders.iter().filter_map(|c| match *c {
        Collider::Box { lo, hi } => Some((lo, hi)),
        Collider::Plane { .. } => None,
    });
    let first = boxes.next()?;
    let (mut n, mut u) = (1, first);
    for (lo, hi) in boxes {
        (n, u) = (n + 1, (u.0.min(lo), u.1.max(hi)));
    }
    (n >= 2).then_some(u)
}

/// What shading needs besides the tracer.
struct ShadeCtx<'a> {
    colliders: &'a [Collider],
    /// [`box_union`] of `colliders`.
    boxes: Option<(Vec3, Vec3)>,
    colors: &'a [Vec<Vec3>],
    inst_obj: &'a [usize],
    light: Vec3,
    shadows: bool,
}

const BACKGROUND: Vec3 = Vec3::new(0.45, 0.5, 0.6);

/// The visible point of a primary ray (surfel hit or collider): position, normal facing the
/// ray, albedo and the hit surfel's extent (0 on a collider; [`SHADOW_OFFSET`]); None for
/// the background.
fn surface(tr: &DeformTracer, ray: &Ray, hit: Option<crate::deform::SurfelHit>, sc: &ShadeCtx) -> Option<(Vec3, Vec3, Vec3, f32)> {
    let t_s = hit.as_ref().map(|h| h.t).unwrap_or(f32::INFINITY);
    surface_with(tr, ray, hit, hit_colliders(ray, sc.colliders, t_s), sc)
}

/// [`surface`] with the nearest collider hit before the surfel hit already found.
fn surface_with(
    tr: &DeformTracer,
    ray: &Ray,
    hit: Option<crate::deform::SurfelHit>,
    coll: Option<(f32, Vec3)>,
    sc: &ShadeCtx,
) -> Option<(Vec3, Vec3, Vec3, f32)> {
    let (p, n, albedo, ext) = match (hit, coll) {
        (_, Some((t, n))) => {
            let p = ray.org + ray.dir * t;
            // Checker on the two in-plane axes (the normal's axis would flicker at a boundary).
            let k = |a: usize| if n[a].abs() > 0.5 { 0.0 } else { (p[a] * 2.0).floor() };
            let check = (k(0) + k(1) + k(2)) as i64 & 1;
            (p, n, if check == 0 { Vec3::splat(0.75) } else { Vec3::splat(0.45) }, 0.0)
        }
        (Some(hh), None) => {
            let col = sc
                .colors
                .get(sc.inst_obj.get(hh.instance as usize).copied().unwrap_or(0))
                .and_then(|v| v.get(hh.collection as usize))
                .copied()
                .unwrap_or(Vec3::splat(0.7));
            let n = if hh.n.dot(ray.dir) > 0.0 { -hh.n } else { hh.n };
            (hh.p, n, col, tr.hit_extent(&hh))
        }
        (None, None) => return None,
    };
    (p.is_finite() && n.is_finite()).then_some((p, n, albedo, ext))
}

/// How far a shadow ray leaves a surfel hit along its normal, in units of the hit surfel's
/// extent (its ellipse's longer semi-axis). Each surfel's MLS iteration uses its own fixed
/// neighbourhood (§4.2.1), so the patches of neighbouring surfels disagree by a fraction of
/// the sample spacing; a shadow ray that left by a fixed 1e-3 of the scene's scale met the
/// neighbours' patches wherever the sampling is sparse and irregular (a PLY of the cow's
/// 2,903 vertices was blotched dark on its lit side; 182 of 597 lit points of a random
/// 400-point ball, test `a_sparse_convex_point_set_does_not_shadow_itself`). 0.1 leaves 2
/// of those 597, 0.25 none. Not in the paper, which does not say how its shadow rays start.
const SHADOW_OFFSET: f32 = 0.25;

/// The shadow ray towards the light and the cosine at a lit-side point, or None (facing
/// away); `ext` is the hit surfel's extent (0 for the colliders), see [`SHADOW_OFFSET`].
fn shadow_ray(p: Vec3, n: Vec3, ext: f32, light: Vec3) -> Option<(Ray, f32)> {
    let to_l = light - p;
    let d = to_l.length();
    let ldir = to_l / d.max(1e-9);
    let cos = n.dot(ldir);
    (cos > 0.0).then(|| {
        let eps = (1e-3 * (1.0 + p.abs().max_element())).max(SHADOW_OFFSET * ext);
        (Ray::segment(p + n * eps, ldir, 0.0, d), cos)
    })
}

fn shade(tr: &DeformTracer, ray: &Ray, slot: Option<u32>, sc: &ShadeCtx, c: &mut Counters, dc: &mut DeformCounters) -> Vec3 {
    c.add(Counter::rays_primary, 1);
    c.add(Counter::samples, 1);
    let hit = tr.intersect_ex(ray, slot, c, dc);
    let Some((p, n, albedo, ext)) = surface(tr, ray, hit, sc) else {
        return BACKGROUND;
    };
    let mut l = albedo * 0.2;
    if let Some((sray, cos)) = shadow_ray(p, n, ext, sc.light) {
        if sc.shadows {
            c.add(Counter::rays_shadow, 1);
        }
        let blocked = sc.shadows && (tr.occluded_ex(&sray, c, dc) || hit_colliders(&sray, sc.colliders, sray.tfar).is_some());
        if !blocked {
            l += albedo * cos;
        }
    }
    l
}

/// [`shade`] for a packet of up to eight primary rays: their closest hits, then their shadow
/// rays, each as one packet. Same colours as `shade` ray by ray.
fn shade_x8(tr: &DeformTracer, rays: &[Ray], slots: &[Option<u32>], sc: &ShadeCtx, c: &mut Counters, dc: &mut DeformCounters) -> [Vec3; 8] {
    c.add(Counter::rays_primary, rays.len() as u64);
    c.add(Counter::samples, rays.len() as u64);
    let hits = tr.intersect_x8(rays, slots, c, dc);
    let coll = hit_colliders_x8(
        rays,
        sc.colliders,
        sc.boxes,
        &std::array::from_fn(|i| hits.get(i).copied().flatten().map_or(f32::INFINITY, |h| h.t)),
    );
    let mut out = [BACKGROUND; 8];
    let mut srays = [Ray::new(Vec3::ZERO, Vec3::X); 8];
    let mut lit = [(Vec3::ZERO, 0.0f32); 8];
    let mut smask = 0u8;
    for (i, ray) in rays.iter().enumerate() {
        let Some((p, n, albedo, ext)) = surface_with(tr, ray, hits[i], coll[i], sc) else {
            continue;
        };
        out[i] = albedo * 0.2;
        if let Some((sray, cos)) = shadow_ray(p, n, ext, sc.light) {
            if sc.shadows {
                srays[i] = sray;
                lit[i] = (albedo, cos);
                smask |= 1 << i;
            } else {
                out[i] += albedo * cos;
            }
        }
    }
    if smask != 0 {
        c.add(Counter::rays_shadow, smask.count_ones() as u64);
        let open = smask & !tr.occluded_x8(&srays[..rays.len()], smask, c, dc);
        if open != 0 {
            let tfar = std::array::from_fn(|i| if open & (1 << i) != 0 { srays[i].tfar } else { f32::NEG_INFINITY });
            let blocked = hit_colliders_x8(&srays[..rays.len()], sc.colliders, sc.boxes, &tfar);
            for i in 0..rays.len() {
                if open & (1 << i) != 0 && blocked[i].is_none() {
                    out[i] += lit[i].0 * lit[i].1;
                }
            }
        }
    }
    out
}

/// A progress bar over `frames` frames (hidden with `--quiet`).
fn frames_bar(quiet: bool, frames: u32, prefix: String) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(frames as u64);
    b.set_style(ProgressStyle::with_template("{prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} frames, eta {eta}").unwrap());
    b.set_prefix(prefix);
    b
}
#[cfg(test)]
mod tests {
    /// The contact sheet's frames: the first and the last always, evenly spaced, at most
    /// eight; a sheet of more than four frames wraps into a second row.
    #[test]
    fn contact_sheet_frames_and_layout() {
        assert_eq!(super::contact_frames(1), vec![0]);
        assert_eq!(super::contact_frames(3), vec![0, 1, 2]);
        assert_eq!(super::contact_frames(90), vec![0, 12, 25, 38, 50, 63, 76, 89]);
        let th: Vec<image::RgbImage> = (0..6).map(|i| image::RgbImage::from_pixel(10, 8, image::Rgb([i * 40, 0, 0]))).collect();
        let s = super::contact_sheet(&th);
        assert_eq!(s.dimensions(), (4 * 10 + 3 * 2, 2 * 8 + 2));
        assert_eq!(s.get_pixel(12 + 5, 4)[0], 40);
        assert_eq!(s.get_pixel(12 + 5, 10 + 4)[0], 200);
        assert_eq!(*s.get_pixel(45, 17), image::Rgb([255, 255, 255]), "the empty last cells stay white");
        let big = image::RgbImage::new(640, 480);
        assert_eq!(super::thumbnail(&big).dimensions(), (320, 240));
    }

    /// The packet collider test is the scalar one lane by lane, bit for bit: random rays
    /// (some axis-aligned, some with zero components, some segments, some with NaN) against
    /// planes and boxes, partial packets, and per-lane `tmax` including −∞ (a lane not asked).
    #[test]
    fn packet_collider_test_is_the_scalar_one_per_lane() {
        let mut g = crate::core::rng::Sampler::new(99, 0, 0);
        let mut rnd = || g.next();
        let mut cols = Collider::hollow_box(Vec3::new(-1.5, 0.0, -1.5), Vec3::new(1.5, 4.0, 1.5), true);
        for _ in 0..6 {
            let lo = Vec3::new(rnd() * 2.0 - 1.0, rnd(), rnd() * 2.0 - 1.0);
            cols.push(Collider::Box { lo, hi: lo + Vec3::new(rnd(), rnd(), rnd()) * 0.5 });
        }
        cols.push(Collider::Box { lo: Vec3::new(-0.2, 0.0, -0.2), hi: Vec3::new(0.2, 0.4, 0.2) });
        let (mut hits, mut lanes) = (0, 0);
        for round in 0..4000 {
            let n = 1 + round % 8;
            let rays: Vec<Ray> = (0..n)
                .map(|k| {
                    let o = Vec3::new(rnd() * 2.4 - 1.2, rnd() * 3.0, rnd() * 2.4 - 1.2);
                    let mut d = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
                    match (round + k) % 7 {
                        0 => d = Vec3::new(0.0, -1.0, 0.0),
                        1 => d.x = 0.0,
                        2 => d = Vec3::new(1.0, 0.0, 0.0),
                        3 if round % 97 == 0 => d.y = f32::NAN,
                        _ => {}
                    }
                    if (round + k) % 3 == 0 {
                        Ray::segment(o, d, 0.01, rnd() * 4.0)
                    } else {
                        Ray::new(o, d)
                    }
                })
                .collect();
            let tmax: [f32; 8] = std::array::from_fn(|i| match (round + i) % 5 {
                0 => f32::NEG_INFINITY,
                1 => rnd() * 3.0,
                _ => rays.get(i).map_or(f32::INFINITY, |r| r.tfar),
            });
            let got = hit_colliders_x8(&rays, &cols, box_union(&cols), &tmax);
            assert_eq!(got, hit_colliders_x8(&rays, &cols, None, &tmax), "round {round}: the box union's cull changed a lane");
            for i in 0..8 {
                let want = rays.get(i).and_then(|r| hit_colliders(r, &cols, tmax[i]));
                let same = match (got[i], want) {
                    (Some((ta, na)), Some((tb, nb))) => {
                        ta.to_bits() == tb.to_bits() && na.to_array().map(f32::to_bits) == nb.to_array().map(f32::to_bits)
                    }
                    (a, b) => a.is_none() && b.is_none(),
                };
                assert!(same, "round {round} lane {i}: packet {:?}, scalar {want:?}, ray {:?}", got[i], rays.get(i));
                hits += want.is_some() as u32;
                lanes += rays.get(i).is_some() as u32;
            }
        }
        assert!(hits > lanes / 4 && hits < lanes, "{hits} hits of {lanes} lanes: the rays must both hit and miss");
    }

    /// Every `lodtrace animate` command in the README passes animate's option checks (as
    /// `bench::tests::the_readmes_bench_commands_pass_the_checks` does for bench).
    #[test]
    fn the_readmes_animate_commands_pass_the_checks() {
        let mut checked = 0;
        for (cmd, a) in crate::cli::readme_commands::<AnimateArgs>("animate") {
            if let Err(e) = check(&none_outputs(&a)) {
                panic!("README: {cmd}\n{e}");
            }
            checked += 1;
        }
        assert!(checked >= 4, "only {checked} animate commands found in the README");
    }

    /// The earlier run's frames beyond this run's, and its cost maps when this run made
    /// none, are named; this run's own files and other files are not.
    #[test]
    fn stale_frames_are_the_earlier_runs_only() {
        let d = std::env::temp_dir().join(format!("lodtrace-stale-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        for f in ["frame_0000.png", "frame_0001.png", "frame_0002.png", "cost_0000.png", "frame_12.png", "notes.txt", "frame_0003.exr"] {
            std::fs::write(d.join(f), "x").unwrap();
        }
        assert_eq!(stale_frames(&d, 2, false), ["cost_0000.png", "frame_0002.png"]);
        assert_eq!(stale_frames(&d, 3, true), Vec::<String>::new());
        let _ = std::fs::remove_dir_all(&d);
    }
    use super::*;
    use crate::deform::{Sequence, SequenceOptions};

    /// A convex object cannot shadow itself: on a sparse, irregular point ball (radii from the
    /// 8th neighbour, as a PLY without radii gets them) no lit-side hit's shadow ray may be
    /// occluded. Until stop 56 the shadow ray left the surface by 1e-3 scene units whatever the
    /// splat size and hit the neighbouring splats' MLS patches (each surfel iterates with its
    /// own 16 neighbours, so the patches disagree by a fraction of the sample spacing): a
    /// PLY of the cow's 2,903 vertices showed dark blotches all over its lit side.
    #[test]
    fn a_sparse_convex_point_set_does_not_shadow_itself() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut ply = String::from("ply\nformat ascii 1.0\nelement vertex 400\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n");
        for _ in 0..400 {
            let z = 2.0 * rnd() - 1.0;
            let a = std::f32::consts::TAU * rnd();
            let r = (1.0 - z * z).sqrt();
            let p = Vec3::new(r * a.cos(), z, r * a.sin());
            ply += &format!("{} {} {} {} {} {}\n", p.x, p.y, p.z, p.x, p.y, p.z);
        }
        let model = crate::deform::ply::read_ply(&mut ply.as_bytes(), std::path::Path::new("ball.ply")).unwrap();
        let mut seq = Sequence::from_points(model, &SequenceOptions::default()).unwrap();
        let rec = seq.record(1).unwrap();
        let mut tr = DeformTracer::new(&seq.scene, UpdateMode::Lazy, TraceParams::default()).unwrap();
        tr.begin_frame(&rec.frames[0]).unwrap();
        let sc = ShadeCtx { colliders: &[], boxes: None, colors: &[vec![Vec3::ONE]], inst_obj: &[0], light: seq.light, shadows: true };
        let (w, h) = (96, 72);
        let cam = seq.camera.frame(w, h);
        let (mut c, mut dc) = (Counters::default(), DeformCounters::default());
        let (mut lit, mut blocked) = (0, 0);
        for y in 0..h {
            for x in 0..w {
                let ray = Ray::new(cam.eye, cam.pixel_center_dir(x, y));
                let hit = tr.intersect_ex(&ray, None, &mut c, &mut dc);
                let Some((p, n, _, ext)) = surface(&tr, &ray, hit, &sc) else { continue };
                // Where random sampling left a hole the ray meets the far side's inside,
                // which the near side legitimately shadows: front-facing hits only.
                if hit.is_some_and(|hh| hh.n.dot(ray.dir) >= 0.0) {
                    continue;
                }
                if let Some((sray, cos)) = shadow_ray(p, n, ext, sc.light) {
                    if cos > 0.05 {
                        lit += 1;
                        blocked += tr.occluded_ex(&sray, &mut c, &mut dc) as u32;
                    }
                }
            }
        }
        assert!(lit > 200, "the ball covers {lit} lit pixels only");
        assert_eq!(blocked, 0, "{blocked} of {lit} lit-side points shadowed by their own surface");
    }
}
