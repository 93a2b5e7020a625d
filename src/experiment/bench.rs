//! `lodtrace bench SCENE... --methods LIST [--reference SPEC] [--out DIR]`: every method on
//! the same scene in one process, one after the other on the same machine, so the ratios
//! are comparable. Prints a table (build time, render time, Mrays/s, ratio to the first
//! method, error against the reference) and writes `bench.json`, a plot and the images.
//!
//! A method spec is `METHOD[:ACCEL][:key=value...]`, keys: `spp`, `threads`, `packet`,
//! `fps` (distributed first-pass spp), `vt` (distributed variance threshold), `depth`; for
//! the cone tracers (`multires`, `cone`): `k`, `c` (oversampling), `stay` (`--stay-reps`), `tdepth` (`--max-tree-depth`), `clamp`, `clamp2` (secondary cones), `lod`, `dtol`,
//! `cs` (cone scale), `lens` (lens scale), `mip=0`, `primary=1`, `budget` (seconds), `eigen=per-box|exact`, `tri=paper|coverage|mass`, `term=paper|final`, `pw=area|voxel`, `spread=0`, `groups=0`, `agg=0` (surface shadow skip for aggregates too), `plane=0` (`--no-plane-skip`), `tight=1` (a triangle fragment's depth interval from its vertices, not its plane), `mask=1` (`--coverage-masks`);
//! for `lod`: `f`, `a` (a_LOD), `thres`, `sel=0` (no selective tracing), `selon=model|value`
//! (`--lod-selective-on`), `levels`, `dist`
//! (distance criterion), `force` (fixed LOD), `net=1` (net disparity), `select=cone` (the
//! ray-cone selector); for `surfel`: `update`, `frames`, `detail`, `shadows=0`, `exact`,
//! `warm=1`, `cache_up`, `climb=1`, `gate`, `ordered=0`, `top=0` (`--no-instance-tree`), `nearest=mls`.
//!
//! A `lod` row is also compared with the full-detail row of the same scene (the first
//! `whitted` row with the same accel, spp, threads, packet and depth): triangle tests and time saved, the maximum
//! and mean pixel difference (8-bit display values, as the paper's percentages), a
//! magnified difference image like the paper's Fig. 4e, and the two distortion maps. Beside
//! them stands the *floor* of those difference figures ([`DiffFloor`]): the same full-detail
//! render on the other exact back-end (Embree ↔ bvh), which in chaotic glass scenes already
//! differs by tens of per cent in a few pixels.
//! Examples: `whitted:embree`, `whitted:bvh:threads=1`, `distributed:embree:spp=64`.
//!
//! `--region NAME=X0,Y0,X1,Y1` (repeatable, with `--reference`) splits every row's error by
//! pixel rectangle as `lodtrace compare --region` does ([`RegionRow`]); with `--sweep` each
//! method also meets the sweep's curve of each region's error ([`RegionEqualTime`]), so a
//! method that wins on one part of the image (prefiltered texture) and loses on another
//! (foliage) shows both.

use super::run;
use crate::baseline::accel::AccelKind;
use crate::baseline::render::RenderOpts;
use crate::cli::compare::{parse_regions, region_figures, Region, RegionFigures};
use crate::cli::Method;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::scene::Scene;
use clap::ValueEnum;
use serde::Serialize;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug, Clone)]
pub struct BenchArgs {
    /// Scenes (built-in names or files).
    #[arg(required = true)]
    pub scenes: Vec<String>,
    /// Comma-separated method specs `METHOD[:ACCEL][:KEY=VALUE]...`, e.g.
    /// `whitted:embree,whitted:bvh,distributed:embree:spp=16`. Methods: whitted, distributed,
    /// multires, cone, lod, surfel; accelerators: embree, bvh, octree (whitted and
    /// distributed), embree, bvh (lod). Keys: spp, threads, packet, fps, vt, depth; cone
    /// tracers: k, c, clamp, clamp2, lod, dtol, cs, lens, rough, light, mip, primary, budget,
    /// eigen, tri, stri, facing, split, term, pw, spread, groups, agg, plane, tight, mask, paper;
    /// lod: f, a, thres, sel, select, selon, levels, dist, force, net; surfel: update,
    /// frames, detail, shadows, exact, bound, stretch, warm, cache_up, climb, gate, ordered, top, nearest. Each key is the
    /// `render`/`animate` option of the same meaning (README, "Using it").
    #[arg(long, required = true)]
    pub methods: String,
    /// Reference spec for the error columns, e.g. `distributed:embree:spp=256:vt=0`.
    #[arg(long)]
    pub reference: Option<String>,
    /// Output folder for bench.json, the plot and the images (created if missing; none or
    /// absent: the table only).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[arg(long, default_value_t = 640, value_parser = clap::value_parser!(u32).range(1..=32768))]
    pub width: u32,
    #[arg(long, default_value_t = 480, value_parser = clap::value_parser!(u32).range(1..=32768))]
    pub height: u32,
    /// Default thread count for methods that don't set `threads=` (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Repeat each render this many times and keep the fastest (rendering only). The repeats go
    /// round the methods, so a slow phase of the machine hits all alike, and each row also
    /// gets its speed-up within every round ("per-round speed-up").
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub repeat: u32,
    /// Equal-time comparison: render this stochastic spec (e.g. `distributed:embree`) at
    /// 1, 2, 4, … samples per pixel until it is both slower and better than every other
    /// method (or reaches `--sweep-max-spp`), then report for each method the sweep's error
    /// at the same time and the time the sweep needs to reach the method's error (mean
    /// FLIP against `--reference`, interpolated in log time). Only methods run on as many
    /// threads as the sweep are compared (and bound it). Needs `--reference`.
    /// Repeatable: `--sweep distributed:embree --sweep distributed:octree` compares each
    /// method with the fast back-end and with the paper's distributed tracer on the same
    /// code basis (§6) in one run.
    #[arg(long)]
    pub sweep: Vec<String>,
    /// Largest spp of the sweep (default 256).
    #[arg(long)]
    pub sweep_max_spp: Option<u32>,
    /// Split each row's error by image region, `NAME=X0,Y0,X1,Y1` (pixels, half-open, rows
    /// from the top), repeatable, as `lodtrace compare --region`: mean FLIP, share of the
    /// image's FLIP error, RMSE, luminance bias and smooth share per region. Needs
    /// `--reference`.
    #[arg(long = "region", value_name = "NAME=X0,Y0,X1,Y1")]
    pub regions: Vec<String>,
    /// Deforming sequences (`surfel` specs) only: run every spec at each of these image
    /// sizes instead of `--width`×`--height`, e.g. `128x96,256x192,512x384,1024x768`. Adds a
    /// table and, with two methods or more, a plot (`speedup-vs-size.png`) of each method's
    /// speed-up over the first against the rays per frame; each size's images and per-frame plots go to `OUT/WxH/`.
    /// Refused beside an explicit `--width` or `--height`, even one equal to the default.
    #[arg(long, value_name = "WxH,...", allow_hyphen_values = true, conflicts_with_all = ["width", "height"])]
    pub sizes: Option<String>,
    /// No progress bars or per-run lines on stderr; the tables still go to stdout.
    #[arg(long)]
    pub quiet: bool,
}

/// A parsed method spec.
#[derive(Clone, Debug, Serialize)]
pub struct MethodSpec {
    pub text: String,
    pub method: Method,
    pub accel: AccelKind,
    pub spp: u32,
    pub threads: Option<usize>,
    pub packet: u32,
    pub first_pass_spp: u32,
    pub variance_threshold: f32,
    pub max_depth: Option<u32>,
    /// Cone-tracer options (`multires`, `cone`).
    #[serde(skip)]
    pub multires: crate::multires::MultiresArgs,
    /// Per-ray LOD options (`lod`).
    #[serde(skip)]
    pub lod: crate::lod::LodArgs,
    /// Deforming-sequence options (`surfel`).
    pub surfel: super::deform_bench::SurfelSpec,
    /// Random-number seed. The reference is rendered with [`REFERENCE_SEED`]: with the
    /// same seed as the methods, a distributed render at the reference's spp would share
    /// its samples and score an error far too low.
    #[serde(skip)]
    pub seed: u32,
}

/// Seed of the `--reference` render (independent of the methods' seed 0).
pub const REFERENCE_SEED: u32 = 0x5eed_4ef0;

impl MethodSpec {
    pub fn parse(s: &str) -> Result<Self> {
        let bad = |m: String| Error::Usage(format!("method spec '{s}': {m}"));
        let mut parts = s.trim().split(':');
        let m = parts.next().unwrap_or("");
        // Case-sensitive, as `render --method`.
        let method = Method::from_str(m, false)
            .map_err(|_| bad(format!("unknown method '{m}' (whitted, distributed, multires, cone, lod, surfel)")))?;
        let mut spec = MethodSpec {
            text: s.trim().to_string(),
            method,
            accel: AccelKind::Embree,
            spp: 1,
            threads: None,
            packet: 8,
            first_pass_spp: 2,
            variance_threshold: 0.001,
            max_depth: None,
            multires: Default::default(),
            lod: Default::default(),
            surfel: Default::default(),
            seed: 0,
        };
        let mut seen: Vec<&str> = Vec::new();
        for p in parts {
            // Each key (and the accelerator) once: `spp=2:spp=4` is a typo, not "the last wins".
            let key = p.split_once('=').map_or("accel", |(k, _)| k);
            if seen.contains(&key) {
                return Err(bad(if key == "accel" {
                    format!("'{p}': a second accelerator (keys take a value: key=value)")
                } else {
                    format!("{key} given twice")
                }));
            }
            seen.push(key);
            if let Some((k, v)) = p.split_once('=') {
                // Any number: its range is checked where `render` checks the option the key
                // sets (`plan`: `c=-1` is "--oversampling -1 out of range (1..=10000)"), so
                // the two cannot drift apart and the error names the allowed values.
                let num = |v: &str| v.parse::<f64>().map_err(|_| bad(format!("bad value '{v}' for {k}: a number")));
                // Counts are whole numbers: `k=2.5` is an error, not k = 2.
                let int = |v: &str| {
                    v.parse::<u32>().map_err(|_| {
                        bad(if v.parse::<u128>().is_ok() {
                            format!("{k}={v} is too large")
                        } else {
                            format!("bad value '{v}' for {k}: a whole number")
                        })
                    })
                };
                // Switches are 0 or 1: `spread=2` is a typo, not "on".
                let on = |v: &str| match v {
                    "0" => Ok(false),
                    "1" => Ok(true),
                    _ => Err(bad(format!("bad value '{v}' for {k}: 0 or 1"))),
                };
                match k {
                    "spp" | "fps" => {
                        // The ranges of `render --spp` / `--first-pass-spp`, named by key.
                        let n = int(v)?;
                        use crate::baseline::render::MAX_SPP;
                        if !(1..=MAX_SPP).contains(&n) {
                            return Err(bad(format!("{k}={n} out of range (1..={MAX_SPP})")));
                        }
                        if k == "spp" {
                            spec.spp = n
                        } else {
                            spec.first_pass_spp = n
                        }
                    }
                    "threads" => spec.threads = Some(int(v)? as usize),
                    "packet" => {
                        spec.packet = int(v)?;
                        if spec.packet != 1 && spec.packet != 8 {
                            return Err(bad(format!("packet={v}: 1 or 8")));
                        }
                    }
                    "vt" => spec.variance_threshold = num(v)? as f32,
                    "depth" => {
                        let d = int(v)?;
                        if d > crate::scene::MAX_DEPTH {
                            return Err(bad(format!("depth={d} out of range [0, {}]", crate::scene::MAX_DEPTH)));
                        }
                        spec.max_depth = Some(d)
                    }
                    "k" => spec.multires.k = int(v)?,
                    "c" => spec.multires.oversampling = num(v)? as f32,
                    "stay" => spec.multires.stay_reps = int(v)?,
                    "tdepth" => spec.multires.max_tree_depth = int(v)?,
                    "clamp" => spec.multires.anisotropy_clamp = num(v)? as f32,
                    "clamp2" => spec.multires.secondary_clamp = Some(num(v)? as f32),
                    "lod" => spec.multires.lod_scale = num(v)? as f32,
                    "dtol" => spec.multires.depth_tolerance = num(v)? as f32,
                    "cs" => spec.multires.cone_scale = num(v)? as f32,
                    "lens" => spec.multires.lens_scale = num(v)? as f32,
                    "rough" => spec.multires.rough_scale = num(v)? as f32,
                    "light" => spec.multires.light_scale = num(v)? as f32,
                    "mip" => spec.multires.no_mipmap = !on(v)?,
                    "primary" => spec.multires.primary_only = on(v)?,
                    "budget" => spec.multires.time_budget = Some(num(v)?),
                    "spread" => spec.multires.no_normal_spread = !on(v)?,
                    "groups" => spec.multires.no_group_points = !on(v)?,
                    "agg" => spec.multires.no_aggregate_shadow = !on(v)?,
                    "plane" => spec.multires.no_plane_skip = !on(v)?,
                    "paper" => spec.multires.paper = on(v)?,
                    "tight" => spec.multires.tight_depth = on(v)?,
                    "mask" => spec.multires.coverage_masks = on(v)?,
                    "pw" => {
                        spec.multires.point_weights = crate::multires::build::PointWeights::from_str(v, true)
                            .map_err(|_| bad(format!("pw={v}: area or voxel")))?
                    }
                    "term" => {
                        spec.multires.termination = crate::multires::trace::Termination::from_str(v, true)
                            .map_err(|_| bad(format!("term={v}: paper or final")))?
                    }
                    "tri" => {
                        spec.multires.tri_weight = crate::multires::trace::TriWeight::from_str(v, true)
                            .map_err(|_| bad(format!("tri={v}: paper, coverage or mass")))?
                    }
                    "stri" => {
                        spec.multires.shadow_tri_weight = Some(
                            crate::multires::trace::TriWeight::from_str(v, true)
                                .map_err(|_| bad(format!("stri={v}: paper, coverage or mass")))?,
                        )
                    }
                    "facing" => spec.multires.no_facing = !on(v)?,
                    "split" => spec.multires.merge_meshes = !on(v)?,
                    "f" => spec.lod.lod_f = num(v)? as f32,
                    "a" => spec.lod.lod_a = num(v)? as f32,
                    "thres" => spec.lod.lod_threshold = num(v)? as f32,
                    "sel" => spec.lod.no_selective = !on(v)?,
                    "levels" => spec.lod.lod_levels = int(v)?,
                    "dist" => spec.lod.lod_distance = Some(num(v)? as f32),
                    "force" => spec.lod.lod_force = Some(num(v)? as f32),
                    "net" => spec.lod.lod_net_disparity = on(v)?,
                    "selon" => {
                        spec.lod.lod_selective_on =
                            crate::lod::trace::SelectiveOn::from_str(v, true).map_err(|_| bad(format!("selon={v}: model or value")))?
                    }
                    "select" => {
                        spec.lod.lod_selector = crate::lod::trace::Selector::from_str(v, true).map_err(|_| bad(format!("select={v}: disparity or cone")))?
                    }
                    "update" => spec.surfel.update = v.to_string(),
                    "frames" => spec.surfel.frames = Some(int(v)?),
                    "detail" => spec.surfel.detail = num(v)? as f32,
                    "shadows" => spec.surfel.shadows = on(v)?,
                    "exact" => spec.surfel.exact_below = Some(int(v)?),
                    "warm" => spec.surfel.warm = on(v)?,
                    "cache_up" => spec.surfel.cache_up = int(v)?,
                    "climb" => spec.surfel.cache_climb = on(v)?,
                    "gate" => spec.surfel.cache_gate = Some(num(v)? as f32),
                    "ordered" => spec.surfel.ordered = on(v)?,
                    "top" => spec.surfel.top = on(v)?,
                    "bound" => {
                        spec.surfel.bound = crate::cli::animate::Bound::from_str(v, true).map_err(|_| bad(format!("bound={v}: tight or paper")))?
                    }
                    "stretch" => spec.surfel.support_stretch = Some(num(v)? as f32),
                    "nearest" => {
                        spec.surfel.nearest_ellipse = match v {
                            "ellipse" => true,
                            "mls" => false,
                            _ => return Err(bad(format!("nearest={v}: ellipse or mls"))),
                        }
                    }
                    "eigen" => {
                        spec.multires.eigen = crate::multires::trace::EigenMode::from_str(v, true)
                            .map_err(|_| bad(format!("eigen={v}: per-box or exact")))?
                    }
                    _ => {
                        return Err(bad(format!(
                            "unknown key '{k}' (spp, threads, packet, fps, vt, depth; cone tracers: k, c, stay, tdepth, clamp, clamp2, lod, dtol, cs, lens, rough, light, mip, primary, budget, eigen, tri, stri, facing, split, term, pw, spread, groups, agg, plane, tight, mask, paper; lod: f, a, thres, sel, select, selon, levels, dist, force, net; surfel: update, frames, detail, shadows, exact, bound, stretch, warm, cache_up, climb, gate, ordered, top, nearest)"
                        )))
                    }
                }
            } else {
                spec.accel = AccelKind::from_str(p, true).map_err(|_| bad(format!("unknown accel '{p}' (embree, bvh, octree)")))?;
            }
        }
        // A key the method would ignore is an error, as for `render`'s options.
        let cone = matches!(method, Method::Multires | Method::Cone);
        let octree = matches!(method, Method::Whitted | Method::Distributed) && spec.accel == AccelKind::Octree;
        for key in &seen {
            let of = match *key {
                "k" | "c" | "stay" | "tdepth" | "pw" if !(cone || octree) => "multires and cone, and of the accel octree",
                // As `render --packet` (stop 91: `multires:packet=1` ran without a word).
                "packet" if cone => "the ray tracers (whitted, distributed, lod) and surfel",
                "clamp" | "clamp2" | "lod" | "dtol" | "cs" | "lens" | "rough" | "light" | "mip" | "primary" | "budget" | "spread"
                | "groups" | "agg" | "plane" | "tight" | "mask" | "term" | "tri" | "eigen" | "stri" | "facing" | "split" | "paper"
                    if !cone =>
                {
                    "multires and cone"
                }
                "f" | "a" | "thres" | "sel" | "selon" | "levels" | "dist" | "force" | "net" | "select" if method != Method::Lod => "lod",
                "update" | "frames" | "detail" | "shadows" | "exact" | "warm" | "cache_up" | "climb" | "gate" | "ordered" | "top"
                | "nearest" | "bound" | "stretch"
                    if method != Method::Surfel =>
                {
                    "surfel"
                }
                "fps" | "vt" if method != Method::Distributed => "distributed",
                "spp" | "depth" if method == Method::Surfel => "the scene-file methods",
                "accel" if cone || method == Method::Surfel => {
                    return Err(bad(format!(
                        "the accelerator is the triangle tracers' choice ({}); {} traces its own {}",
                        crate::baseline::accel::ACCEL_USE,
                        method.name(),
                        if cone { "multi-resolution octree" } else { "sphere tree" }
                    )))
                }
                _ => continue,
            };
            return Err(bad(format!("{key} is a key of {of}; {} would ignore it", method.name())));
        }
        // `paper=1` sets these keys to the paper's choice; one given beside it, even at its
        // default value, would be overridden without a word (as `render --paper` refuses them).
        if spec.multires.paper {
            let paper_keys = ["pw", "tri", "cs", "lens", "rough", "light", "facing", "split", "spread", "groups", "agg", "plane"];
            if let Some(key) = seen.iter().find(|k| paper_keys.contains(k)) {
                return Err(bad(format!("paper=1 sets {key} to the paper's choice; give one or the other")));
            }
        }
        // As `render --max-depth` beside `--primary-only` (stop 80): no reflected or refracted
        // cones to limit.
        if cone && spec.multires.primary_only && seen.contains(&"depth") {
            return Err(bad("depth has no effect beside primary=1 (no reflected or refracted cones)".into()));
        }
        // Refused here, before any method of the list runs, not when its turn comes.
        if method == Method::Lod && spec.accel == AccelKind::Octree {
            return Err(bad("lod runs on bvh or embree; the octree serves whitted and distributed".into()));
        }
        Ok(spec)
    }

    pub fn opts(&self, width: u32, height: u32, default_threads: usize, quiet: bool) -> RenderOpts {
        RenderOpts {
            width,
            height,
            spp: self.spp,
            threads: self.threads.unwrap_or(default_threads),
            packet: self.packet,
            first_pass_spp: self.first_pass_spp,
            variance_threshold: self.variance_threshold,
            aov: false,
            quiet,
            label: self.text.clone(),
            ..Default::default()
        }
    }

    /// A file-name-safe form of the spec.
    pub fn slug(&self) -> String {
        Self::slug_of(&self.text)
    }

    /// [`MethodSpec::slug`] of a spec's text.
    pub fn slug_of(text: &str) -> String {
        text.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect()
    }
}

pub fn parse_list(s: &str) -> Result<Vec<MethodSpec>> {
    if s.trim().is_empty() {
        return Err(Error::Usage("--methods is empty".into()));
    }
    // An empty item (`whitted,,cone`, a trailing comma) is a typo, as in `--sizes`.
    if s.split(',').any(|p| p.trim().is_empty()) {
        return Err(Error::Usage(format!("--methods '{s}': an empty item (two commas, or one at either end)")));
    }
    let v: Vec<MethodSpec> = s.split(',').map(MethodSpec::parse).collect::<Result<_>>()?;
    // Images and table rows are named after the spec.
    for (i, m) in v.iter().enumerate() {
        if let Some(o) = v[..i].iter().find(|o| o.slug() == m.slug()) {
            return Err(Error::Usage(if o.text == m.text {
                format!("--methods: '{}' given twice", m.text)
            } else {
                format!("--methods: '{}' and '{}' would write the same image files ({})", o.text, m.text, m.slug())
            }));
        }
    }
    Ok(v)
}

/// One row of the table.
#[derive(Serialize, Debug, Clone)]
pub struct BenchRow {
    pub scene: String,
    pub spec: String,
    pub stats: run::Stats,
    /// render_seconds of the first method ÷ this method's (so > 1 is faster).
    pub speedup_vs_first: f64,
    /// The same ratio within each round of `--repeat` (the renders go round the methods):
    /// on a machine whose speed drifts, its spread says how far the best-of ratio can be
    /// trusted. Empty for one round and for the sweeps' rows.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub per_round_speedups: Vec<f64>,
    pub rmse: Option<f64>,
    pub psnr: Option<f64>,
    pub flip: Option<f64>,
    /// `--region` split of the error against the reference.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub regions: Vec<RegionRow>,
    pub image: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lod_vs_full: Option<LodComparison>,
    /// This row against each `--sweep` curve of its scene, in the order of the sweeps.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub equal_time: Vec<EqualTime>,
    /// For the rows a sweep rendered: that sweep's spec (without `spp=`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sweep: Option<String>,
}

/// One `--region` of a row: where in the image its error sits.
#[derive(Serialize, Debug, Clone)]
pub struct RegionRow {
    pub name: String,
    /// Half-open pixel rectangle `[x0, y0, x1, y1]`.
    pub rect: [u32; 4],
    /// Mean FLIP, its share of the image's FLIP error (the shares add up to 1 when the
    /// regions tile the image), RMSE, luminance bias and smooth share, flattened into the
    /// row's JSON.
    #[serde(flatten)]
    pub figures: RegionFigures,
}

/// A method against the stochastic sweep at equal time and at equal error (Wand & Straßer
/// §6: "the stochastic raytracer needs at least an order of magnitude more time").
#[derive(Serialize, Debug, Clone)]
pub struct EqualTime {
    pub sweep: String,
    /// The sweep's mean FLIP at this row's render time (interpolated in log time); `None`
    /// when this row is faster than the sweep's 1-spp render (below its curve).
    pub sweep_flip_at_equal_time: Option<f64>,
    /// Samples per pixel the sweep affords in this row's time (interpolated): the mean the
    /// sweep's renders actually took (the `samples` counter over the pixels), which for the
    /// adaptive distributed tracer is below its `spp=` setting (`spp=64` takes at most 51,
    /// 33 with the default variance threshold). Until stop 49 this was the setting.
    pub sweep_spp_at_equal_time: Option<f64>,
    /// Render seconds the sweep needs to reach this row's FLIP; `None` when the sweep did
    /// not reach it (then `sweep_max_seconds` is a lower bound).
    pub sweep_seconds_to_match: Option<f64>,
    /// The sweep's time ÷ this row's time at equal error (> 1: this method is faster).
    pub time_ratio_at_equal_error: Option<f64>,
    /// The sweep's first (1-spp) point already has a lower FLIP than this row: the two
    /// figures above are upper bounds (its 1-spp time), not interpolated.
    pub sweep_match_at_most: bool,
    /// This row took longer than the sweep's last (slowest) render: the two figures at equal
    /// time are that last render's, a bound (in this row's time the sweep would do at least
    /// as well), not an interpolation.
    pub sweep_beyond: bool,
    pub sweep_max_seconds: f64,
    /// The same comparison inside each `--region`: the sweep's curve of that region's mean
    /// FLIP against this row's. A method can win one part of the image at equal time (the
    /// prefiltered floor) and lose another (the foliage).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub regions: Vec<RegionEqualTime>,
}

/// [`EqualTime`] inside one `--region`.
#[derive(Serialize, Debug, Clone)]
pub struct RegionEqualTime {
    pub name: String,
    /// This row's mean FLIP in the region.
    pub flip: f64,
    pub sweep_flip_at_equal_time: Option<f64>,
    pub sweep_seconds_to_match: Option<f64>,
    pub time_ratio_at_equal_error: Option<f64>,
    /// As [`EqualTime::sweep_match_at_most`].
    pub sweep_match_at_most: bool,
    /// As [`EqualTime::sweep_beyond`].
    pub sweep_beyond: bool,
}

/// Interpolates the sweep curve (`(seconds, spp, flip)`, sorted by spp) for a method at
/// `(t, flip)`: see [`EqualTime`]. Interpolation is linear in log time between the two
/// neighbouring sweep points; error is interpolated linearly.
pub fn equal_time(sweep: &[(f64, f64, f64)], t: f64, flip: f64, name: &str) -> EqualTime {
    let lt = |x: f64| x.max(1e-9).ln();
    let (mut at_t, mut beyond) = (None, false);
    for w in sweep.windows(2) {
        let ((t0, s0, f0), (t1, s1, f1)) = (w[0], w[1]);
        if t >= t0 && t <= t1 {
            let a = if lt(t1) > lt(t0) { (lt(t) - lt(t0)) / (lt(t1) - lt(t0)) } else { 0.0 };
            at_t = Some((f0 + a * (f1 - f0), (lt(s0) + a * (lt(s1) - lt(s0))).exp()));
            break;
        }
    }
    if at_t.is_none() {
        if let Some(&(tl, sl, fl)) = sweep.last() {
            if t >= tl {
                // Slower than the whole sweep: its last point is the best known bound.
                (at_t, beyond) = (Some((fl, sl)), t > tl);
            }
        }
    }
    let mut to_match = None;
    let mut at_most = false;
    if let Some(&(t0, _, f0)) = sweep.first() {
        if f0 <= flip {
            to_match = Some(t0);
            at_most = f0 < flip;
        }
    }
    if to_match.is_none() {
        for w in sweep.windows(2) {
            let ((t0, _, f0), (t1, _, f1)) = (w[0], w[1]);
            if f0 > flip && f1 <= flip {
                let a = (f0 - flip) / (f0 - f1);
                to_match = Some((lt(t0) + a * (lt(t1) - lt(t0))).exp());
                break;
            }
        }
    }
    EqualTime {
        sweep: name.to_string(),
        sweep_flip_at_equal_time: at_t.map(|x| x.0),
        sweep_spp_at_equal_time: at_t.map(|x| x.1),
        sweep_seconds_to_match: to_match,
        time_ratio_at_equal_error: to_match.map(|m| m / t.max(1e-12)),
        sweep_match_at_most: at_most,
        sweep_beyond: beyond,
        regions: Vec::new(),
        sweep_max_seconds: sweep.iter().map(|x| x.0).fold(0.0, f64::max),
    }
}

/// A traversal counter for the table, or "–" where the back-end does not count it: Embree's
/// traversal is opaque, and its rows carry 0 (not a measurement) for every test counter.
pub fn counted(stats: &run::Stats, key: &str) -> String {
    if stats.accel == AccelKind::Embree.name() {
        return super::NA.into();
    }
    stats.counters.get(key).copied().unwrap_or(0).to_string()
}

/// A share as "12.3 %", or "–" where it was not measured.
pub fn pct_or_dash(x: Option<f64>) -> String {
    x.map_or(super::NA.into(), |v| format!("{:.1} %", 100.0 * v))
}

/// A `lod` row against its full-detail Whitted counterpart (Papaioannou et al. Fig. 4).
#[derive(Serialize, Debug, Clone)]
pub struct LodComparison {
    pub against: String,
    /// 1 − tests(lod)/tests(full), so 0.3 = 30 % fewer ray–triangle tests; `None` where the
    /// back-end does not count its tests (Embree), shown as "–" rather than a false 0 %.
    pub triangle_test_reduction: Option<f64>,
    /// 1 − time(lod)/time(full).
    pub time_reduction: f64,
    /// The same from process CPU time (with one thread: robust against a busy machine).
    pub cpu_time_reduction: f64,
    /// Largest per-pixel difference of 8-bit display values, as a fraction of 255.
    pub max_pixel_diff: f64,
    /// Pixel (x, y) of the largest difference.
    pub max_at: [u32; 2],
    /// 99th percentile of the per-pixel difference (one pixel in a hundred differs more).
    pub p99_pixel_diff: f64,
    pub mean_pixel_diff: f64,
    /// Largest difference among the pixels whose level-1 rays all kept the full-detail
    /// model L₀ (e.g. those seen in a flat mirror): 0 unless deeper rays degraded.
    pub max_diff_full_lod_pixels: f64,
    /// The same full-detail render on the other exact back-end (Embree ↔ bvh), same
    /// samples: what two correct intersectors differ by on this scene (None without Embree).
    pub floor: Option<DiffFloor>,
}

/// The measurement floor of the pixel-difference figures: the full-detail Whitted render on
/// one exact back-end against the same render on the other. In scenes of stacked bumpy
/// glass (the chessboard) ray paths are chaotic: a last-bit difference in one refraction
/// sends a sample elsewhere after a few bounces, so two correct intersectors already differ
/// by tens of per cent in a few pixels. A LOD difference at or below this floor is not
/// distinguishable from float rounding.
#[derive(Serialize, Debug, Clone)]
pub struct DiffFloor {
    pub against: String,
    pub max_pixel_diff: f64,
    pub p99_pixel_diff: f64,
    pub mean_pixel_diff: f64,
    /// Pixels where the LOD render differs from full detail by more than `max_pixel_diff`
    /// (0: no pixel differs more than the two exact back-ends do somewhere).
    pub lod_pixels_above_floor_max: u64,
}

impl DiffFloor {
    /// "max / 99th / mean" in per cent, for the tables.
    pub fn summary(&self) -> String {
        format!("{:.1} % / {:.1} % / {:.2} %", 100.0 * self.max_pixel_diff, 100.0 * self.p99_pixel_diff, 100.0 * self.mean_pixel_diff)
    }
}

/// (max, index of max, 99th percentile, mean) of a per-pixel difference.
fn diff_summary(d: &[f32]) -> (f32, usize, f32, f64) {
    let (imax, dmax) = d.iter().copied().enumerate().fold((0, 0.0f32), |a, (i, x)| if x > a.1 { (i, x) } else { a });
    let mut sorted = d.to_vec();
    sorted.sort_by(f32::total_cmp);
    // Nearest rank, ⌈0.99 n⌉-th value: one pixel in a hundred differs more (stop 80: ⌊0.99 n⌋
    // as an index took the value above it wherever 0.99 n is whole, as at 640×480).
    let p99 = sorted.get((sorted.len() * 99).div_ceil(100).saturating_sub(1)).copied().unwrap_or(0.0);
    (dmax, imax, p99, d.iter().map(|&x| x as f64).sum::<f64>() / d.len().max(1) as f64)
}

/// Per-pixel largest channel difference of the 8-bit display images, in [0, 1].
pub fn pixel_diff(a: &Film, b: &Film) -> Vec<f32> {
    let (x, y) = (crate::film::io::to_rgb8(a), crate::film::io::to_rgb8(b));
    x.pixels()
        .zip(y.pixels())
        .map(|(p, q)| (0..3).map(|c| (p[c] as i32 - q[c] as i32).unsigned_abs()).max().unwrap_or(0) as f32 / 255.0)
        .collect()
}

/// A [`floor_diff`]: (the other back-end, the per-pixel difference).
type FloorDiff = (String, Vec<f32>);

/// The full-detail spec `fs` (film `ff`) rendered again on the other exact back-end, with
/// the same samples, and its per-pixel difference to `ff` (see [`DiffFloor`]). None when
/// the other back-end is not built in (no Embree) or `fs` is on neither.
fn floor_diff(scene: &Scene, fs: &MethodSpec, ff: &Film, a: &BenchArgs) -> Result<Option<FloorDiff>> {
    let other = match fs.accel {
        AccelKind::Bvh if cfg!(feature = "embree") => AccelKind::Embree,
        AccelKind::Embree => AccelKind::Bvh,
        _ => return Ok(None),
    };
    let mut spec = fs.clone();
    spec.accel = other;
    spec.text = format!("{} on {}", fs.text, other.name());
    let (film, ..) = run_spec(scene, &spec, a.width, a.height, a.threads, 1, a.quiet)?;
    Ok(Some((spec.text, pixel_diff(&film, ff))))
}

/// The difference magnified like the paper's Fig. 4e: white = equal, black = the largest
/// difference of the image.
pub fn diff_image(d: &[f32], w: u32, h: u32) -> image::RgbImage {
    let m = d.iter().copied().fold(0.0f32, f32::max).max(1e-6);
    image::RgbImage::from_fn(w, h, |x, y| {
        let g = 255 - (d[(y * w + x) as usize] / m * 255.0).round() as u8;
        image::Rgb([g, g, g])
    })
}

#[derive(Serialize, Debug, Clone)]
pub struct BenchReport {
    /// The image size; with `--sizes`, the first of them (`sizes` lists them all).
    pub width: u32,
    pub height: u32,
    /// `--sizes`: every image size the deforming sequences ran at, `[width, height]`, in
    /// order (omitted without `--sizes`; `width` and `height` alone named only the first).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sizes: Vec<[u32; 2]>,
    /// SIMD level of the binary ([`crate::core::SIMD_LEVEL`]).
    pub simd: &'static str,
    /// `--repeat`: every time is the best of this many rounds of renders (each round renders
    /// every method once).
    pub repeat: u32,
    /// `--threads` (0 = all cores); each row's `stats.threads` is the count it ran with.
    pub threads: usize,
    pub reference: Option<String>,
    pub rows: Vec<BenchRow>,
    /// `surfel` specs on deforming sequences (Adams et al.).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub deform: Vec<super::deform_bench::DeformRow>,
}

/// One bench row's render: the image, its stats, the LOD maps (`--method lod`) and the tests
/// per pixel (the cone tracers).
pub type SpecRun = (Film, run::Stats, Option<crate::lod::trace::LodMaps>, Option<Vec<u32>>);

/// Runs `count` methods `repeat` times each, the repeats taken round the methods (1, 2, …,
/// 1, 2, …): a slow phase of the machine (this VM's speed drifts by ±10–20 % over tens of
/// seconds) then hits every method of a comparison alike instead of all the runs of one.
/// `run(i)` runs method i once; `time` is the figure of a run (smaller is better). Returns
/// each method's best run and the times of every run, rounds × methods
/// ([`per_round_speedups`]).
pub fn best_of_rounds<T>(
    count: usize,
    repeat: u32,
    mut run: impl FnMut(usize) -> Result<T>,
    time: impl Fn(&T) -> f64,
) -> Result<(Vec<T>, Vec<Vec<f64>>)> {
    let mut bests: Vec<Option<T>> = (0..count).map(|_| None).collect();
    let mut rounds = Vec::new();
    for _ in 0..repeat.max(1) {
        let mut round = Vec::with_capacity(count);
        for (i, best) in bests.iter_mut().enumerate() {
            let r = run(i)?;
            round.push(time(&r));
            if best.as_ref().is_none_or(|b| time(&r) < time(b)) {
                *best = Some(r);
            }
        }
        rounds.push(round);
    }
    Ok((bests.into_iter().map(|b| b.expect("at least one run")).collect(), rounds))
}

/// Per method, the first method's time ÷ its own in each round of `rounds` (rounds × methods,
/// from [`best_of_rounds`]);
/// empty lists with fewer than two rounds, where the best-of speed-up says the same.
pub fn per_round_speedups(rounds: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let specs = rounds.first().map_or(0, Vec::len);
    (0..specs).map(|j| if rounds.len() < 2 { Vec::new() } else { rounds.iter().map(|r| r[0] / r[j].max(1e-12)).collect() }).collect()
}

/// "median [min–max]" of per-round speed-ups, or "–" for none.
pub fn median_range(v: &[f64]) -> String {
    let Some(med) = median(v) else { return super::NA.into() };
    let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    format!("{med:.2}x [{lo:.2}–{hi:.2}]")
}

/// The median of `v` (the mean of the middle two for an even count), or None if empty.
pub fn median(v: &[f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    Some(if n % 2 == 1 { s[n / 2] } else { 0.5 * (s[n / 2 - 1] + s[n / 2]) })
}

/// Renders `spec` on `scene` (best of `repeat` renders).
pub fn run_spec(scene: &Scene, spec: &MethodSpec, width: u32, height: u32, threads: usize, repeat: u32, quiet: bool) -> Result<SpecRun> {
    let mut sc;
    let scene = if let Some(d) = spec.max_depth {
        sc = scene.clone();
        sc.max_depth = d;
        &sc
    } else {
        scene
    };
    let mut opts = spec.opts(width, height, threads, quiet);
    opts.seed = spec.seed;
    let (mut best, _) =
        best_of_rounds(1, repeat, |_| run::run(scene, spec.method, spec.accel, &opts, &spec.multires, &spec.lod), |r| r.out.seconds)?;
    let r = best.pop().expect("one method");
    let stats = r.stats(scene, spec.method, spec.accel, &opts);
    Ok((r.out.film, stats, r.lod.map(|l| l.maps), r.cones.map(|c| c.pixel_tests)))
}

/// Errors of `film` against `reference`: (RMSE, PSNR dB, mean FLIP), the per-pixel FLIP values
/// and the FLIP error map.
pub fn errors(film: &Film, reference: &Film) -> Result<(f64, f64, f64, Vec<f32>, image::RgbImage)> {
    use crate::film::metrics;
    let (w, h) = (film.width, film.height);
    if (w, h) != (reference.width, reference.height) {
        return Err(Error::Usage(format!("image {w}x{h} and reference {}x{} differ in size", reference.width, reference.height)));
    }
    let rmse = metrics::rmse(&reference.color, &film.color, w, h);
    let psnr = metrics::psnr(&reference.color, &film.color, w, h);
    let (values, map) = metrics::flip_map(&reference.color, &film.color, w, h)?;
    Ok((rmse, psnr, metrics::mean_finite(&values), values, map))
}

pub fn run(a: &BenchArgs) -> Result<()> {
    // The table on stdout is part of the run: if it cannot be printed, the outputs go too.
    crate::film::io::discard_dir_on_error(a.out.as_deref(), || print_table(&bench(a)?))
}

/// Runs the whole bench and writes its outputs; returns the report.
pub fn bench(a: &BenchArgs) -> Result<BenchReport> {
    if a.repeat == 0 || a.repeat > 1000 {
        return Err(Error::Usage(format!("--repeat {} out of range [1, 1000]", a.repeat)));
    }
    // Outputs are named after the scenes: two files with one stem (`a/x.obj b/x.off`) would
    // overwrite each other's images (stop 46's sweep).
    let stem = |s: &str| crate::scene::load::stem_name(std::path::Path::new(s), s);
    for (i, s) in a.scenes.iter().enumerate() {
        if let Some(t) = a.scenes[..i].iter().find(|t| stem(t) == stem(s)) {
            return Err(Error::Usage(format!(
                "scenes '{t}' and '{s}' share the name '{}': their outputs would overwrite each other",
                stem(s)
            )));
        }
    }
    // A failed bench removes the output folder again if it created it.
    crate::film::io::discard_dir_on_error(a.out.as_deref(), || bench_in(a))
}

/// A bench run's parsed and checked arguments ([`plan`]).
pub(crate) struct Plan {
    specs: Vec<MethodSpec>,
    reference: Option<MethodSpec>,
    sweeps: Vec<MethodSpec>,
    regions: Vec<Region>,
    /// Largest spp of the sweeps.
    sweep_max_spp: u32,
    /// Deforming sequences (surfel specs): the image sizes to run; then `scenes` is empty.
    surfel_sizes: Option<Vec<(u32, u32)>>,
    scenes: Vec<Scene>,
}

/// Checks every argument of a bench run and loads its scenes, before anything is rendered or
/// written (the demo's test checks its own runs' arguments with it).
pub(crate) fn plan(a: &BenchArgs) -> Result<Plan> {
    let mut plan = plan_options(a)?;
    if plan.surfel_sizes.is_some() {
        return Ok(plan);
    }
    let scenes: Vec<Scene> = a.scenes.iter().map(|s| crate::scene::load::load_scene(s)).collect::<Result<_>>()?;
    for (i, s) in scenes.iter().enumerate() {
        if let Some(t) = scenes[..i].iter().position(|t| t.name == s.name) {
            return Err(Error::Usage(format!(
                "scenes '{}' and '{}' are both named '{}': their outputs would overwrite each other",
                a.scenes[t], a.scenes[i], s.name
            )));
        }
    }
    plan.scenes = scenes;
    Ok(plan)
}

/// [`plan`] without loading the scenes (`scenes` is empty): every option checked.
fn plan_options(a: &BenchArgs) -> Result<Plan> {
    let specs = parse_list(&a.methods)?;
    let mut reference = a.reference.as_deref().map(MethodSpec::parse).transpose()?;
    if let Some(r) = &mut reference {
        r.seed = REFERENCE_SEED;
    }
    let sweeps: Vec<MethodSpec> = a.sweep.iter().map(|s| MethodSpec::parse(s)).collect::<Result<_>>()?;
    // As `render --first-pass-spp`: above the per-pixel maximum it would be capped unseen.
    // (A sweep caps it at each of its points, which is its purpose.)
    for sp in specs.iter().chain(&reference) {
        if sp.text.split(':').any(|p| p.starts_with("fps=")) && sp.first_pass_spp > sp.spp {
            return Err(Error::Usage(format!(
                "method spec '{}': fps={} exceeds spp={} (the per-pixel maximum, which caps it): raise spp",
                sp.text, sp.first_pass_spp, sp.spp
            )));
        }
        // As `render --variance-threshold` (stop 80): the threshold picks the second pass's
        // pixels, and a spec whose first pass takes every sample has none. Accepted without
        // effect until stop 82.
        if sp.text.split(':').any(|p| p.starts_with("vt=")) && sp.first_pass_spp >= sp.spp {
            return Err(Error::Usage(format!(
                "method spec '{}': vt has no effect at spp={} with fps={}: the first pass takes every sample, there is no second pass",
                sp.text,
                sp.spp,
                sp.first_pass_spp.min(sp.spp)
            )));
        }
    }
    if specs.iter().any(|s| s.method == Method::Surfel) && (!a.regions.is_empty() || !sweeps.is_empty()) {
        // Before "needs --reference", which they would refuse as well.
        return Err(Error::Usage(
            "surfel specs bench deforming sequences: there is no reference image to split by --region or to --sweep against".into(),
        ));
    }
    let regions = parse_regions(&a.regions, a.width, a.height)?;
    if !regions.is_empty() && reference.is_none() {
        return Err(Error::Usage("--region splits the error against the reference: it needs --reference".into()));
    }
    let sweep_max_spp = a.sweep_max_spp.unwrap_or(256);
    if !(1..=crate::baseline::render::MAX_SPP).contains(&sweep_max_spp) {
        return Err(Error::Usage(format!("--sweep-max-spp {sweep_max_spp} out of range (1..={})", crate::baseline::render::MAX_SPP)));
    }
    for (i, sw) in sweeps.iter().enumerate() {
        if sweeps[..i].iter().any(|o| o.text == sw.text) {
            return Err(Error::Usage(format!("--sweep '{}' given twice", sw.text)));
        }
        if reference.is_none() {
            return Err(Error::Usage("--sweep compares errors: it needs --reference".into()));
        }
        if !matches!(sw.method, Method::Distributed | Method::Whitted) {
            return Err(Error::Usage(format!(
                "--sweep '{}': only a stochastic method (distributed, whitted) can be swept over spp",
                sw.text
            )));
        }
        if sw.text.split(':').any(|p| p.starts_with("spp=")) {
            return Err(Error::Usage(format!("--sweep '{}': the sweep sets spp itself; leave it out", sw.text)));
        }
        // A method that is one of the sweep's points would write the same image.
        let mut spp = 1u32;
        while spp <= sweep_max_spp {
            let point = format!("{}:spp={spp}", sw.text);
            if let Some(m) = specs.iter().find(|m| m.slug() == MethodSpec::slug_of(&point)) {
                return Err(Error::Usage(format!(
                    "--methods '{}' is a point of --sweep '{}' (its spp={spp} render): leave one of them out",
                    m.text, sw.text
                )));
            }
            spp *= 2; // at most 2 × MAX_SPP, checked above
        }
    }
    if sweeps.is_empty() && a.sweep_max_spp.is_some() {
        return Err(Error::Usage("--sweep-max-spp bounds a --sweep; there is none".into()));
    }
    let surfel = specs.iter().filter(|s| s.method == Method::Surfel).count();
    // clap refuses `--sizes` beside an explicit `--width`/`--height`; this catches arguments
    // built in code (the demo's jobs).
    if a.sizes.is_some() && (a.width, a.height) != (640, 480) {
        return Err(Error::Usage("--sizes gives the image sizes; --width and --height would be ignored".into()));
    }
    if a.sizes.is_some() && surfel == 0 {
        return Err(Error::Usage("--sizes is for deforming sequences (surfel specs); use --width and --height".into()));
    }
    if surfel > 0 {
        // Deforming sequences: a different kind of SCENE, and no reference image.
        if surfel < specs.len() || reference.is_some() {
            return Err(Error::Usage(
                "surfel specs bench deforming sequences: run them without other methods and without --reference".into(),
            ));
        }
        specs.iter().try_for_each(super::deform_bench::validate)?;
        let sizes = match &a.sizes {
            Some(s) => parse_sizes(s)?,
            None => {
                check_size(a.width, a.height)?;
                vec![(a.width, a.height)]
            }
        };
        return Ok(Plan { specs, reference, sweeps, regions, sweep_max_spp, surfel_sizes: Some(sizes), scenes: Vec::new() });
    }
    // Validate everything before the first (possibly long) render.
    for s in specs.iter().chain(reference.iter()).chain(sweeps.iter()) {
        // The spec named, its key by the option it sets (`c` is `--oversampling`).
        let named = |e: Error| match e {
            Error::Usage(m) => Error::Usage(format!("method spec '{}': {m}", s.text)),
            e => e,
        };
        s.opts(a.width, a.height, a.threads, true).validate().map_err(named)?;
        // The octree baseline takes the build keys (k, c, pw) as well.
        let octree = matches!(s.method, Method::Whitted | Method::Distributed) && s.accel == AccelKind::Octree;
        if matches!(s.method, Method::Multires | Method::Cone) || octree {
            let (_, tp) = s.multires.params(s.method == Method::Multires).map_err(named)?;
            tp.validate().map_err(named)?;
        }
        if s.method == Method::Lod {
            s.lod.params().map_err(named)?;
        }
    }
    Ok(Plan { specs, reference, sweeps, regions, sweep_max_spp, surfel_sizes: None, scenes: Vec::new() })
}

/// The files a bench run may write in its output folder (names inside it, `WxH/` for the
/// sizes of `--sizes`): the report, the plots, and each row's, the reference's and every
/// sweep point's images, including those only some methods write (cost, LOD maps). Checked
/// before the first render ([`crate::film::io::check_out_files`]), `scenes` the triangle
/// scenes' names.
/// The file name of one of a run's images in its output folder: `NAME-PART.png`, or
/// `NAME-PART-KIND.png` when `kind` is not empty (a scene or sequence name, then a method's
/// slug or the figure's name). The writers and the check of the outputs before the first
/// render ([`output_names`]) take names from here, so the two lists cannot drift apart.
pub(crate) fn image_name(name: &str, part: &str, kind: &str) -> String {
    if kind.is_empty() {
        format!("{name}-{part}.png")
    } else {
        format!("{name}-{part}-{kind}.png")
    }
}

fn output_names(a: &BenchArgs, plan: &Plan, scenes: &[String]) -> Vec<String> {
    let mut names: Vec<String> = ["bench.json", "bench.md", "bench-time.png"].map(String::from).into();
    if let Some(sizes) = &plan.surfel_sizes {
        names.extend(["radius-ratio.png", "speedup-vs-size.png"].map(String::from));
        let seqs: Vec<String> = a.scenes.iter().map(|s| crate::scene::load::stem_name(Path::new(s), s)).collect();
        for &(w, h) in sizes {
            let dir = if a.sizes.is_some() { format!("{w}x{h}/") } else { String::new() };
            for seq in &seqs {
                names.push(format!("{dir}{}", image_name(seq, "frame-times", "")));
                names.push(format!("{dir}{}", image_name(seq, "sphere-tests", "")));
                names.extend(plan.specs.iter().map(|s| format!("{dir}{}", image_name(seq, &s.slug(), ""))));
            }
        }
        return names;
    }
    let reference = plan.reference.as_ref();
    if reference.is_some() {
        names.push("bench-error.png".into());
    }
    for s in scenes {
        if let Some(r) = reference {
            names.push(image_name(s, "reference", &r.slug()));
        }
        if !plan.sweeps.is_empty() {
            names.push(image_name(s, "equal-time", ""));
        }
        let mut rows: Vec<(String, Method)> = plan.specs.iter().map(|m| (m.slug(), m.method)).collect();
        for sw in &plan.sweeps {
            let mut spp = 1u32;
            while spp <= plan.sweep_max_spp {
                rows.push((MethodSpec::slug_of(&format!("{}:spp={spp}", sw.text)), sw.method));
                spp *= 2;
            }
        }
        for (slug, m) in rows {
            names.push(image_name(s, &slug, ""));
            if reference.is_some() {
                names.push(image_name(s, &slug, "flip"));
            }
            names.push(image_name(s, &slug, "cost"));
            if m == Method::Lod {
                names.extend(["diff", "disparity-r", "disparity-t"].map(|k| image_name(s, &slug, k)));
            }
        }
    }
    names
}

/// Two triangle scenes whose images would have the same file name: scene `a`'s reference
/// `a-reference-whitted.png` is scene `a-reference`'s Whitted row (stop 91: the second
/// replaced the first without a word). The file names come from [`output_names`], scene by
/// scene; one scene's own repeats (a sweep point that is also a row) are not a clash.
fn check_name_clash(a: &BenchArgs, plan: &Plan, scenes: &[String]) -> Result<()> {
    if plan.surfel_sizes.is_some() {
        return Ok(()); // built-in sequences only, named apart
    }
    let report: std::collections::HashSet<String> = output_names(a, plan, &[]).into_iter().collect();
    let mut owner: std::collections::HashMap<String, String> = report.iter().map(|n| (n.clone(), "the report".to_string())).collect();
    for s in scenes {
        let mut mine = output_names(a, plan, std::slice::from_ref(s));
        mine.retain(|n| !report.contains(n));
        mine.sort();
        mine.dedup();
        for n in mine {
            if let Some(o) = owner.insert(n.clone(), format!("scene '{s}'")) {
                return Err(Error::Usage(format!("{o} and scene '{s}' would both write {n} in the output folder: rename a scene file")));
            }
        }
    }
    Ok(())
}

/// [`output_names`] of a bench run whose scenes are not loaded yet, named `scenes` (the
/// demo checks every job's outputs before its first job renders).
pub(crate) fn output_names_unloaded(a: &BenchArgs, scenes: &[String]) -> Result<Vec<String>> {
    Ok(output_names(a, &plan_options(a)?, scenes))
}

fn bench_in(a: &BenchArgs) -> Result<BenchReport> {
    let plan = plan(a)?;
    if let Some(out) = &a.out {
        // The plots need a font, and no output may be a folder: say so before the renders,
        // not after them (the font was loaded, and the outputs written, only at the end).
        super::plot::check_font()?;
        let scenes: Vec<String> = plan.scenes.iter().map(|s| s.name.clone()).collect();
        check_name_clash(a, &plan, &scenes)?;
        crate::film::io::create_out_dir(out)?;
        crate::film::io::check_writable_dir(out)?;
        if let (Some(sizes), true) = (&plan.surfel_sizes, a.sizes.is_some()) {
            for &(w, h) in sizes {
                crate::film::io::create_out_dir(&out.join(format!("{w}x{h}")))?;
            }
        }
        crate::film::io::check_out_files(out, &output_names(a, &plan, &scenes))?;
    }
    let Plan { specs, reference, sweeps, regions, sweep_max_spp, surfel_sizes, scenes } = plan;
    if let Some(sizes) = surfel_sizes {
        let mut deform = Vec::new();
        for &(w, h) in &sizes {
            let dir = match (&a.out, a.sizes.is_some()) {
                (Some(out), true) => Some(out.join(format!("{w}x{h}"))),
                (out, _) => out.clone(),
            };
            if a.sizes.is_some() && !a.quiet {
                crate::status!("bench: {w}x{h}");
            }
            deform.extend(super::deform_bench::run(&a.scenes, &specs, w, h, a.threads, a.repeat, dir.as_deref(), a.quiet)?);
        }
        let (width, height) = sizes[0];
        let report = BenchReport {
            width,
            height,
            sizes: if a.sizes.is_some() { sizes.iter().map(|&(w, h)| [w, h]).collect() } else { Vec::new() },
            simd: crate::core::SIMD_LEVEL,
            repeat: a.repeat,
            threads: a.threads,
            reference: None,
            rows: Vec::new(),
            deform,
        };
        if let Some(out) = &a.out {
            write_outputs(out, &report)?;
            if a.sizes.is_some() {
                super::deform_bench::size_plot(out, &report.deform)?;
            }
        }
        return Ok(report);
    }
    let mut rows = Vec::new();
    for scene in &scenes {
        let ref_film = match &reference {
            Some(r) => {
                let (film, ..) = run_spec(scene, r, a.width, a.height, a.threads, 1, a.quiet)?;
                if let Some(out) = &a.out {
                    crate::film::io::write_png(&out.join(image_name(&scene.name, "reference", &r.slug())), &film)?;
                }
                Some(film)
            }
            None => None,
        };
        let mut first_time = None;
        // Floor differences already rendered: (full-detail spec, (other back-end, difference)).
        let mut floors: Vec<(String, Option<FloorDiff>)> = Vec::new();
        // Best of `--repeat` renders per method, taken round the methods as for the deforming
        // sequences; each round gives a ratio of its own.
        let (bests, rounds) = best_of_rounds(
            specs.len(),
            a.repeat,
            |i| run_spec(scene, &specs[i], a.width, a.height, a.threads, 1, a.quiet),
            |r| r.1.render_seconds,
        )?;
        let paired = per_round_speedups(&rounds);
        // Full-detail Whitted films of this scene, for the lod rows: all of them, taken before
        // the rows (stop 80: gathered row by row, a Whitted row listed after the lod row was
        // not yet there, and the lod row got no comparison at all).
        let full: Vec<(MethodSpec, Film, run::Stats)> = specs
            .iter()
            .zip(&bests)
            .filter(|(s, _)| s.method == Method::Whitted)
            .map(|(s, (f, st, ..))| (s.clone(), f.clone(), st.clone()))
            .collect();
        for ((spec, (film, stats, maps, pixel_tests)), per_round) in specs.iter().zip(bests).zip(paired) {
            if let (Some(out), Some(v)) = (&a.out, &pixel_tests) {
                // Where the cone tracer's work went: tests per pixel, log-scale heat map.
                crate::film::io::write_rgb8_png(
                    &out.join(image_name(&scene.name, &spec.slug(), "cost")),
                    &crate::film::metrics::cost_map(v, film.width, film.height)?,
                )?;
            }
            let mut lod_vs_full = None;
            if spec.method == Method::Lod {
                // Traced alike but for the LOD: the packet width too (a `packet=1` row taken as
                // the partner credited the LOD with the packets' speed-up).
                // Threads and depth as run, not as written (stop 80: `threads=1` beside
                // `--threads 1`, or `depth=6` on a depth-6 scene, found no partner).
                let depth = |m: &MethodSpec| m.max_depth.unwrap_or(scene.max_depth);
                if let Some((fs, ff, fst)) = full.iter().find(|(f, _, fst)| {
                    f.accel == spec.accel
                        && f.spp == spec.spp
                        && depth(f) == depth(spec)
                        && fst.threads == stats.threads
                        && f.packet == spec.packet
                }) {
                    let d = pixel_diff(&film, ff);
                    let tests = |s: &run::Stats| s.counters.get("triangle_tests").copied().unwrap_or(0) as f64;
                    let (dmax, imax, p99, mean) = diff_summary(&d);
                    // Pixels whose level-1 LODs select the full-detail model L₀ (§2: k =
                    // lvl_max − ⌈LOD·lvl_max⌉), not only LOD = 1: a flat mirror's absolute
                    // disparity (the pixel's own angle) leaves its LOD just below 1, at L₀.
                    // In every sample: the lowest LOD, not the mean over the samples (stop 80).
                    let lvl_max = spec.lod.lod_levels.saturating_sub(1);
                    let at_l0 = |x: f32| crate::lod::chain::level_of(x, lvl_max) == 0;
                    let full_lod = maps
                        .as_ref()
                        .map(|m| (0..d.len()).filter(|&i| at_l0(m.lod_min[i])).map(|i| d[i]).fold(0.0f32, f32::max))
                        .unwrap_or(0.0);
                    if !floors.iter().any(|(t, _)| *t == fs.text) {
                        floors.push((fs.text.clone(), floor_diff(scene, fs, ff, a)?));
                    }
                    let floor = floors.iter().find(|(t, _)| *t == fs.text).and_then(|(_, f)| f.as_ref()).map(|(against, fd)| {
                        let (fmax, _, fp99, fmean) = diff_summary(fd);
                        DiffFloor {
                            against: against.clone(),
                            max_pixel_diff: fmax as f64,
                            p99_pixel_diff: fp99 as f64,
                            mean_pixel_diff: fmean,
                            lod_pixels_above_floor_max: d.iter().filter(|&&x| x > fmax).count() as u64,
                        }
                    });
                    lod_vs_full = Some(LodComparison {
                        against: fs.text.clone(),
                        triangle_test_reduction: (tests(fst) > 0.0).then(|| 1.0 - tests(&stats) / tests(fst)),
                        time_reduction: 1.0 - stats.render_seconds / fst.render_seconds.max(1e-12),
                        cpu_time_reduction: 1.0 - stats.render_cpu_seconds / fst.render_cpu_seconds.max(1e-12),
                        max_pixel_diff: dmax as f64,
                        max_at: [imax as u32 % film.width, imax as u32 / film.width],
                        p99_pixel_diff: p99 as f64,
                        mean_pixel_diff: mean,
                        max_diff_full_lod_pixels: full_lod as f64,
                        floor,
                    });
                    if let Some(out) = &a.out {
                        crate::film::io::write_rgb8_png(
                            &out.join(image_name(&scene.name, &spec.slug(), "diff")),
                            &diff_image(&d, film.width, film.height),
                        )?;
                    }
                }
                if let (Some(out), Some(m)) = (&a.out, &maps) {
                    for k in ["disparity-r", "disparity-t"] {
                        crate::film::io::write_rgb8_png(
                            &out.join(image_name(&scene.name, &spec.slug(), k)),
                            &crate::lod::maps_image(m, k),
                        )?;
                    }
                }
            }
            let t0 = *first_time.get_or_insert(stats.render_seconds);
            let mut row = finish_row(scene, spec, &film, stats, ref_film.as_ref().map(|f| (f, &regions[..])), a.out.as_deref(), a.quiet)?;
            row.speedup_vs_first = t0 / row.stats.render_seconds.max(1e-12);
            row.per_round_speedups = per_round;
            row.lod_vs_full = lod_vs_full;
            rows.push(row);
        }
        let first = rows.len() - specs.len();
        for (sw, rf) in sweeps.iter().filter_map(|sw| ref_film.as_ref().map(|rf| (sw, rf))) {
            let t0 = first_time.unwrap_or(1.0);
            // The sweep's thread count (of its first render) and the bounds it must pass:
            // the slowest time and best error of the methods' rows on as many threads.
            let mut sweep_threads: Option<usize> = None;
            let (mut t_slowest, mut f_best) = (0.0, f64::INFINITY);
            let mut curve = Vec::new();
            let mut region_curves: Vec<Vec<(f64, f64, f64)>> = Vec::new();
            let mut spp = 1u32;
            loop {
                let mut spec = sw.clone();
                spec.spp = spp;
                spec.first_pass_spp = spec.first_pass_spp.min(spp);
                spec.text = format!("{}:spp={spp}", sw.text);
                let (film, stats, ..) = run_spec(scene, &spec, a.width, a.height, a.threads, a.repeat, a.quiet)?;
                let mut row = finish_row(scene, &spec, &film, stats, Some((rf, &regions[..])), a.out.as_deref(), a.quiet)?;
                row.speedup_vs_first = t0 / row.stats.render_seconds.max(1e-12);
                row.sweep = Some(sw.text.clone());
                if sweep_threads.is_none() {
                    let thr = row.stats.threads;
                    sweep_threads = Some(thr);
                    // The methods' rows only (not an earlier sweep's), on the sweep's threads.
                    for r in rows[first..first + specs.len()].iter().filter(|r| r.stats.threads == thr) {
                        if let Some(f) = r.flip {
                            t_slowest = f64::max(t_slowest, r.stats.render_seconds);
                            f_best = f64::min(f_best, f);
                        }
                    }
                }
                let (t, f) = (row.stats.render_seconds, row.flip.unwrap_or(0.0));
                // Samples actually taken per pixel (the adaptive tracer takes fewer than its
                // setting); the setting where a tracer does not count them.
                let taken = row.stats.counters.get("samples").copied().unwrap_or(0) as f64 / (a.width as f64 * a.height as f64);
                let n = if taken > 0.0 { taken } else { spp as f64 };
                curve.push((t, n, f));
                region_curves.resize(row.regions.len(), Vec::new());
                for (c, g) in region_curves.iter_mut().zip(&row.regions) {
                    c.push((t, n, g.figures.flip_mean));
                }
                rows.push(row);
                if (t >= t_slowest && f <= f_best) || spp.saturating_mul(2) > sweep_max_spp {
                    break;
                }
                spp *= 2;
            }
            for r in &mut rows[first..first + specs.len()] {
                // Equal time is equal wall-clock time on equal threads: a one-thread row against
                // a two-thread sweep made the sweep look about twice as fast as it is.
                if Some(r.stats.threads) != sweep_threads {
                    continue;
                }
                if let Some(f) = r.flip {
                    let mut e = equal_time(&curve, r.stats.render_seconds, f, &sw.text);
                    for (g, c) in r.regions.iter().zip(&region_curves) {
                        let ge = equal_time(c, r.stats.render_seconds, g.figures.flip_mean, &sw.text);
                        e.regions.push(RegionEqualTime {
                            name: g.name.clone(),
                            flip: g.figures.flip_mean,
                            sweep_flip_at_equal_time: ge.sweep_flip_at_equal_time,
                            sweep_seconds_to_match: ge.sweep_seconds_to_match,
                            time_ratio_at_equal_error: ge.time_ratio_at_equal_error,
                            sweep_match_at_most: ge.sweep_match_at_most,
                            sweep_beyond: ge.sweep_beyond,
                        });
                    }
                    r.equal_time.push(e);
                }
            }
        }
    }
    let report = BenchReport {
        width: a.width,
        height: a.height,
        sizes: Vec::new(),
        simd: crate::core::SIMD_LEVEL,
        repeat: a.repeat,
        threads: a.threads,
        reference: a.reference.clone(),
        rows,
        deform: Vec::new(),
    };
    if let Some(out) = &a.out {
        write_outputs(out, &report)?;
    }
    Ok(report)
}

/// The row of one render: errors against the reference (and the FLIP map), the image.
fn finish_row(
    scene: &Scene,
    spec: &MethodSpec,
    film: &Film,
    stats: run::Stats,
    reference: Option<(&Film, &[Region])>,
    out: Option<&Path>,
    quiet: bool,
) -> Result<BenchRow> {
    let mut region_rows = Vec::new();
    let (rmse, psnr, flip) = match reference {
        Some((r, regions)) => {
            let (x, y, z, values, map) = errors(film, r)?;
            let total = z * values.len() as f64;
            for g in regions {
                region_rows.push(RegionRow {
                    name: g.name.clone(),
                    rect: [g.x0, g.y0, g.x1, g.y1],
                    figures: region_figures(g, &values, total, &r.color, &film.color, film.width),
                });
            }
            if let Some(out) = out {
                crate::film::io::write_rgb8_png(&out.join(image_name(&scene.name, &spec.slug(), "flip")), &map)?;
            }
            // PSNR is +inf for an identical image; JSON has no infinity.
            (Some(x), y.is_finite().then_some(y), Some(z))
        }
        None => (None, None, None),
    };
    let image = match out {
        Some(out) => {
            let name = image_name(&scene.name, &spec.slug(), "");
            crate::film::io::write_png(&out.join(&name), film)?;
            Some(name)
        }
        None => None,
    };
    if !quiet {
        crate::status!("  {} {}: render {:.3} s", scene.name, spec.text, stats.render_seconds);
    }
    Ok(BenchRow {
        scene: scene.name.clone(),
        spec: spec.text.clone(),
        speedup_vs_first: 1.0,
        per_round_speedups: Vec::new(),
        stats,
        rmse,
        psnr,
        flip,
        regions: region_rows,
        image,
        lod_vs_full: None,
        equal_time: Vec::new(),
        sweep: None,
    })
}

/// `bench.json` (every figure) and `bench.md` (the tables) of `report` in `out`.
pub fn write_report(out: &Path, report: &BenchReport) -> Result<()> {
    let json = serde_json::to_string_pretty(report).expect("report serialises") + "\n";
    let p = out.join("bench.json");
    crate::film::io::write_atomic(&p, |tmp| std::fs::write(tmp, json).map_err(|e| Error::io(&p, e)))?;
    let p = out.join("bench.md");
    let md = table_string(report);
    crate::film::io::write_atomic(&p, |tmp| std::fs::write(tmp, md).map_err(|e| Error::io(&p, e)))
}

fn write_outputs(out: &Path, report: &BenchReport) -> Result<()> {
    write_report(out, report)?;
    let mut bars: Vec<(String, f64)> = report.rows.iter().map(|r| (format!("{} {}", r.scene, r.spec), r.stats.render_seconds)).collect();
    // Deforming sequences as the table gives them: time per frame (until stop 56 the bars
    // were the totals over all frames beside the table's ms/frame), in ms when no frame
    // renders share the chart; the size in brackets only when sizes vary.
    let sizes_vary = report.deform.iter().any(|r| (r.width, r.height) != (report.width, report.height));
    let ms = report.rows.is_empty();
    bars.extend(report.deform.iter().map(|r| {
        let size = if sizes_vary { format!(" ({}x{})", r.width, r.height) } else { String::new() };
        (format!("{} {}{size}", r.scene, r.spec), if ms { r.ms_per_frame } else { r.ms_per_frame * 1e-3 })
    }));
    let size = if sizes_vary { String::new() } else { format!(", {}x{}", report.width, report.height) };
    let (title, unit) = match (report.rows.is_empty(), report.deform.is_empty()) {
        (true, false) => (format!("Render time per frame{size}"), "ms per frame"),
        (false, false) => (format!("Render time (sequences: per frame){size}"), "seconds"),
        _ => (format!("Render time{size}"), "seconds"),
    };
    super::plot::bar_chart(&out.join("bench-time.png"), &title, unit, &bars)?;
    // Error against the reference versus time, one curve per scene: the trade-off a
    // multi-resolution method is meant to win. With a sweep, each scene gets its own plot:
    // the sweep as a curve, every other method as a point on it or off it.
    let mut scenes: Vec<&str> = Vec::new();
    for r in &report.rows {
        if !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
    }
    let mut scatter: Vec<(String, String, f64, f64)> = Vec::new();
    for sc in &scenes {
        let rows = report.rows.iter().filter(|r| r.scene == *sc && r.flip.is_some());
        if report.rows.iter().any(|r| r.scene == *sc && r.sweep.is_some()) {
            let points: Vec<PlotPoint> = rows
                .map(|r| PlotPoint {
                    spec: &r.spec,
                    sweep: r.sweep.as_deref(),
                    threads: r.stats.threads,
                    seconds: r.stats.render_seconds,
                    flip: r.flip.unwrap_or(0.0),
                })
                .collect();
            let per = equal_time_series(&points);
            // Fast, noisy renders sit top left and the converged sweep bottom right. Times
            // spanning more than a decade go on a log axis: on a linear one the fast methods
            // crowded into one spot at the left edge.
            let ts = per.iter().flat_map(|c| c.1.iter().map(|p| p.0)).filter(|t| *t > 0.0);
            let (tl, th) = ts.fold((f64::INFINITY, 0.0f64), |(a, b), t| (a.min(t), b.max(t)));
            super::plot::line_chart_fmt(
                &out.join(image_name(sc, "equal-time", "")),
                &format!("{sc}: mean FLIP against the reference vs render time"),
                "render time (s)",
                "mean FLIP",
                &per,
                th / tl > 8.0,
                &super::plot::fmt_axis,
                None,
            )?;
        } else {
            scatter.extend(rows.filter_map(|r| r.flip.map(|f| (sc.to_string(), r.spec.clone(), r.stats.render_seconds, f))));
        }
    }
    if !scatter.is_empty() {
        // One point per (scene, method): measurements, not a curve.
        super::plot::scatter_chart(
            &out.join("bench-error.png"),
            "Error against the reference vs render time",
            "render time (s)",
            "mean FLIP",
            &scatter,
        )?;
    }
    Ok(())
}

/// A region's column heading, `NAME X0,Y0,X1,Y1`; a region given without a name (`--region
/// 0,0,40,30`, named after its rectangle) shows the rectangle once, not `0,0,40,30 0,0,40,30`.
pub fn region_heading(name: &str, rect: [u32; 4]) -> String {
    let r = format!("{},{},{},{}", rect[0], rect[1], rect[2], rect[3]);
    if name == r {
        r
    } else {
        format!("{name} {r}")
    }
}

/// One row of a scene as the equal-time plot sees it.
#[derive(Clone, Copy, Debug)]
pub struct PlotPoint<'a> {
    pub spec: &'a str,
    /// The sweep that rendered the row, `None` for a method's row.
    pub sweep: Option<&'a str>,
    pub threads: usize,
    pub seconds: f64,
    pub flip: f64,
}

/// The series of a scene's `SCENE-equal-time.png`: each sweep a curve (first in the
/// legend), then each method a point. A method run on another thread count than every
/// sweep is left out, as the equal-time tables leave it out: its wall-clock time on the
/// sweep's time axis compared unequal resources (a one-thread row beside a two-thread
/// sweep sat twice as far right as it would on two threads).
pub fn equal_time_series(points: &[PlotPoint]) -> Vec<(String, Vec<(f64, f64)>)> {
    let sweep_threads: Vec<usize> = points.iter().filter(|p| p.sweep.is_some()).map(|p| p.threads).collect();
    let mut curves: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let mut per: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for p in points {
        let xy = (p.seconds, p.flip);
        match p.sweep {
            Some(name) => {
                let name = format!("{name}, spp 1, 2, 4, ...");
                match curves.iter_mut().find(|c| c.0 == name) {
                    Some(c) => c.1.push(xy),
                    None => curves.push((name, vec![xy])),
                }
            }
            None if sweep_threads.contains(&p.threads) => per.push((p.spec.to_string(), vec![xy])),
            None => {}
        }
    }
    curves.append(&mut per);
    curves
}

/// A Markdown header and rule: `fixed` columns (scene and method left-aligned, the rest
/// right-aligned) followed by one right-aligned column per entry of `extra` (the regions).
fn table_header(fixed: &[&str], extra: &[String]) -> String {
    let names: Vec<&str> = fixed.iter().copied().chain(extra.iter().map(String::as_str)).collect();
    let rule: Vec<&str> = (0..names.len()).map(|i| if i < 2 { "---" } else { "---:" }).collect();
    format!("| {} |\n|{}|\n", names.join(" | "), rule.join("|"))
}

/// The table as Markdown (printed to stdout and written to bench.md).
/// A Markdown table cell's text: `|` escaped (a scene file may be named `p|q.off`, and a raw
/// `|` split its row into one column more than the header; review finding, stop 78).
pub fn md_cell(s: &str) -> std::borrow::Cow<'_, str> {
    if s.contains('|') {
        s.replace('|', "\\|").into()
    } else {
        s.into()
    }
}

/// The "build s" cell: the seconds, and when the point hierarchies came from the on-disk
/// cache (a later `--repeat` round, or an earlier run) how many, so that a read is not taken
/// for a build (review finding, stop 78).
fn build_cell(st: &run::Stats) -> String {
    format!("{:.3}{}", st.build_seconds, cache_note(st))
}

/// " (N of M trees from the cache)" when some point hierarchies were read from the on-disk
/// cache rather than built (their "build" time is then a read), else nothing.
pub(crate) fn cache_note(st: &run::Stats) -> String {
    match &st.hierarchy {
        Some(h) if h.trees_from_cache > 0 => format!(" ({} of {} trees from the cache)", h.trees_from_cache, h.trees),
        _ => String::new(),
    }
}

pub fn table_string(report: &BenchReport) -> String {
    let mut s = String::new();
    // A `--sizes` bench names every size, not only the first.
    let mut sizes: Vec<(u32, u32)> = vec![(report.width, report.height)];
    for r in &report.deform {
        if !sizes.contains(&(r.width, r.height)) {
            sizes.push((r.width, r.height));
        }
    }
    let sizes: Vec<String> = sizes.iter().map(|(w, h)| format!("{w}x{h}")).collect();
    s.push_str(&format!(
        "{}, SIMD {}{}\n\n",
        sizes.join(", "),
        report.simd,
        report.reference.as_ref().map(|r| format!(", errors against {r}")).unwrap_or_default()
    ));
    if report.rows.is_empty() && !report.deform.is_empty() {
        // The table opens with the blank line that parts it from a render table above.
        s.push_str(super::deform_bench::table(&report.deform).trim_start_matches('\n'));
        if report.deform.iter().any(|r| (r.width, r.height) != (report.width, report.height)) {
            s.push_str(&super::deform_bench::size_table(&report.deform));
        }
        return s;
    }
    s.push_str("| scene | method | thr | build s | render s | Mrays/s | speed-up vs first | per-round speed-up: median [range] | RMSE | PSNR dB | FLIP | triangle tests | node tests | point tests | eigen solves | fragments merged |\n");
    s.push_str("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in &report.rows {
        let f = |x: Option<f64>, p: usize| x.map(|v| format!("{v:.p$}")).unwrap_or_else(|| super::NA.into());
        s.push_str(&format!(
            "| {} | {}{} | {} | {} | {:.3} | {:.2} | {:.2}x | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            md_cell(&r.scene),
            r.spec,
            if r.stats.finished { "" } else { " (stopped at its time budget: incomplete image)" },
            r.stats.threads,
            build_cell(&r.stats),
            r.stats.render_seconds,
            r.stats.mrays_per_second,
            r.speedup_vs_first,
            median_range(&r.per_round_speedups),
            f(r.rmse, 4),
            f(r.psnr, 2),
            f(r.flip, 4),
            counted(&r.stats, "triangle_tests"),
            counted(&r.stats, "node_tests"),
            counted(&r.stats, "surfel_tests"),
            counted(&r.stats, "eigen_decompositions"),
            counted(&r.stats, "fragments_merged"),
        ));
    }
    if let Some(first) = report.rows.iter().find(|r| !r.regions.is_empty()) {
        s.push_str("\nError by region (mean FLIP against the reference; in brackets the region's share of the image's FLIP error):\n\n");
        let cols: Vec<String> = first.regions.iter().map(|g| region_heading(&g.name, g.rect)).collect();
        s.push_str(&table_header(&["scene", "method", "render s", "FLIP (whole)"], &cols));
        for r in report.rows.iter().filter(|r| !r.regions.is_empty()) {
            s.push_str(&format!("| {} | {} | {:.3} | {:.4} |", md_cell(&r.scene), r.spec, r.stats.render_seconds, r.flip.unwrap_or(0.0)));
            for g in &r.regions {
                s.push_str(&format!(" {:.4} ({:.0} %) |", g.figures.flip_mean, 100.0 * g.figures.flip_share));
            }
            s.push('\n');
        }
        s.push_str(
            "\nKind of error by region (luminance against the reference's, and the part of the squared error at \
             scales of 8 pixels or more: near 100 % it is bias that more samples would not remove, near 0 % aliasing \
             or noise):\n\n",
        );
        s.push_str(&table_header(&["scene", "method"], &cols));
        for r in report.rows.iter().filter(|r| !r.regions.is_empty()) {
            s.push_str(&format!("| {} | {} |", md_cell(&r.scene), r.spec));
            for g in &r.regions {
                s.push_str(&format!(
                    " {} / {} |",
                    crate::cli::compare::luma_bias_text(g.figures.luma_bias, " "),
                    crate::cli::compare::smooth_share_text(g.figures.smooth_share, 0, " ")
                ));
            }
            s.push('\n');
        }
    }
    // One pair of tables per sweep, in the order of the sweeps.
    let mut sweeps: Vec<&str> = Vec::new();
    for e in report.rows.iter().flat_map(|r| &r.equal_time) {
        if !sweeps.contains(&e.sweep.as_str()) {
            sweeps.push(&e.sweep);
        }
    }
    for name in sweeps {
        let eq: Vec<(&BenchRow, &EqualTime)> =
            report.rows.iter().filter_map(|r| r.equal_time.iter().find(|e| e.sweep == name).map(|e| (r, e))).collect();
        s.push_str(&format!("\nEqual time and equal error against {name} (mean FLIP against the reference; the rows run on as many threads as the sweep):\n\n"));
        s.push_str("| scene | method | render s | FLIP | sweep FLIP at equal time (samples taken per pixel) | sweep time to match FLIP | time ratio at equal error |\n");
        s.push_str("|---|---|---:|---:|---:|---:|---:|\n");
        for &(r, e) in &eq {
            let at = match (e.sweep_flip_at_equal_time, e.sweep_spp_at_equal_time) {
                (Some(f), Some(n)) if e.sweep_beyond => format!("≤ {f:.4} ({n:.1}; slower than the whole sweep)"),
                (Some(f), Some(n)) => format!("{f:.4} ({n:.1})"),
                _ => "faster than 1 spp".into(),
            };
            let (m, q) = match (e.sweep_seconds_to_match, e.time_ratio_at_equal_error) {
                (Some(m), Some(q)) if e.sweep_match_at_most => (format!("≤ {m:.3} s (1 spp is better)"), format!("≤ {q:.2}x")),
                (Some(m), Some(q)) => (format!("{m:.3} s"), format!("{q:.2}x")),
                _ => (
                    format!("> {:.3} s (not reached)", e.sweep_max_seconds),
                    format!("> {:.2}x", e.sweep_max_seconds / r.stats.render_seconds.max(1e-12)),
                ),
            };
            s.push_str(&format!(
                "| {} | {} | {:.3} | {:.4} | {} | {} | {} |\n",
                md_cell(&r.scene),
                r.spec,
                r.stats.render_seconds,
                r.flip.unwrap_or(0.0),
                at,
                m,
                q
            ));
        }
        let eqr: Vec<&(&BenchRow, &EqualTime)> = eq.iter().filter(|(_, e)| !e.regions.is_empty()).collect();
        if let Some((_, first)) = eqr.first() {
            s.push_str(&format!("\nEqual time by region against {name} (the row's mean FLIP in the region / the sweep's there at the row's time; in brackets the time ratio at equal error, > 1: the method is faster):\n\n"));
            let cols: Vec<String> = first.regions.iter().map(|g| g.name.clone()).collect();
            s.push_str(&table_header(&["scene", "method", "render s"], &cols));
            for &&(r, e) in &eqr {
                s.push_str(&format!("| {} | {} | {:.3} |", md_cell(&r.scene), r.spec, r.stats.render_seconds));
                for g in &e.regions {
                    let at = g.sweep_flip_at_equal_time.map_or(super::NA.into(), |f| {
                        if g.sweep_beyond {
                            format!("≤ {f:.4}")
                        } else {
                            format!("{f:.4}")
                        }
                    });
                    let q = g.time_ratio_at_equal_error.map_or_else(
                        || format!("> {:.2}x", e.sweep_max_seconds / r.stats.render_seconds.max(1e-12)),
                        |q| if g.sweep_match_at_most { format!("≤ {q:.2}x") } else { format!("{q:.2}x") },
                    );
                    s.push_str(&format!(" {:.4} / {at} ({q}) |", g.flip));
                }
                s.push('\n');
            }
        }
    }
    let cones: Vec<&BenchRow> = report.rows.iter().filter(|r| r.stats.cone_profile.is_some()).collect();
    if !cones.is_empty() {
        s.push_str(
            "\nWhere the cone tracers' traversal work goes, by cone kind (traversal thread-seconds: wall-clock time on each thread, summed over the threads; \
             tests per cone, share of the frame's tests; tests = instance, node, triangle-bound, triangle and surfel \
             tests), and over the pixels:\n\n",
        );
        s.push_str("| scene | method | render s | primary | shadow of primary | reflected / refracted | shadow of secondary | tests per pixel: median / p95 / max | top 5 % pixels' share |\n");
        s.push_str("|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
        for r in cones {
            let p = r.stats.cone_profile.as_ref().expect("filtered");
            s.push_str(&format!("| {} | {} | {:.3} | {} |\n", md_cell(&r.scene), r.spec, r.stats.render_seconds, p.cells().join(" | ")));
        }
    }
    let lod: Vec<&BenchRow> = report.rows.iter().filter(|r| r.lod_vs_full.is_some()).collect();
    if !lod.is_empty() {
        s.push_str("\nPer-ray LOD against full detail (Papaioannou et al.):\n\n");
        s.push_str("| scene | method | against | triangle tests saved | time saved | CPU time saved | max pixel diff (at) | 99th pct diff | mean pixel diff | max diff, full-LOD pixels | mean level | rays dropped | floor: exact back-ends max / 99th / mean | LOD pixels above floor max |\n");
        s.push_str("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
        for r in lod {
            let c = r.lod_vs_full.as_ref().expect("filtered");
            s.push_str(&format!(
                "| {} | {} | {} | {} | {:.1} % | {:.1} % | {:.1} % ({},{}) | {:.1} % | {:.2} % | {:.1} % | {:.2} | {} | {} | {} |\n",
                md_cell(&r.scene),
                r.spec,
                c.against,
                pct_or_dash(c.triangle_test_reduction),
                100.0 * c.time_reduction,
                100.0 * c.cpu_time_reduction,
                100.0 * c.max_pixel_diff,
                c.max_at[0],
                c.max_at[1],
                100.0 * c.p99_pixel_diff,
                100.0 * c.mean_pixel_diff,
                100.0 * c.max_diff_full_lod_pixels,
                r.stats.lod.as_ref().map(|l| l.mean_query_level).unwrap_or(0.0),
                r.stats.counters.get("lod_rays_dropped").copied().unwrap_or(0),
                c.floor.as_ref().map_or(super::NA.into(), DiffFloor::summary),
                c.floor.as_ref().map_or(super::NA.into(), |f| f.lod_pixels_above_floor_max.to_string()),
            ));
        }
    }
    s
}

/// A deforming-sequence image size: each side in 1..=16384, at most
/// [`MAX_PIXELS`](crate::baseline::render::MAX_PIXELS) pixels.
fn check_size(w: u32, h: u32) -> Result<()> {
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(Error::Usage(format!("image size {w}x{h} out of range (each side 1..=16384)")));
    }
    crate::baseline::render::check_pixels(w, h)
}

/// `--sizes W1xH1,W2xH2,...` (distinct sizes, each checked as `--width`/`--height`).
fn parse_sizes(s: &str) -> Result<Vec<(u32, u32)>> {
    let mut v: Vec<(u32, u32)> = Vec::new();
    for item in s.split(',') {
        let item = item.trim();
        let wh = item.split_once(['x', 'X']).and_then(|(w, h)| Some((w.trim().parse::<u32>().ok()?, h.trim().parse::<u32>().ok()?)));
        let Some((w, h)) = wh else {
            return Err(Error::Usage(format!("--sizes: '{item}' is not WIDTHxHEIGHT (e.g. 256x192)")));
        };
        check_size(w, h).map_err(|e| match e {
            Error::Usage(m) => Error::Usage(format!("--sizes: {m}")),
            other => other,
        })?;
        if v.contains(&(w, h)) {
            return Err(Error::Usage(format!("--sizes: {w}x{h} given twice")));
        }
        v.push((w, h));
    }
    Ok(v)
}

pub fn print_table(report: &BenchReport) -> Result<()> {
    crate::error::print_stdout(&table_string(report)).map(|_| ())
}

/// Test fixtures: a row's stats and a row without errors, for the table and demo tests.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::*;

    pub fn stats(method: &str, accel: &str, seconds: f64, counters: &[(&str, u64)]) -> run::Stats {
        run::Stats {
            scene: "s".into(),
            method: method.into(),
            accel: accel.into(),
            width: 4,
            height: 4,
            spp: 1,
            threads: 2,
            build_seconds: 0.0,
            render_seconds: seconds,
            render_cpu_seconds: 2.0 * seconds,
            mrays_per_second: 1.0,
            triangles_instanced: 0,
            triangles_unique: 0,
            accel_bytes: 0,
            mesh_bytes: 0,
            peak_rss_bytes: 0,
            simd: "sse2",
            finished: true,
            hierarchy: None,
            lod: None,
            counters: counters.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            tests_counted: accel != "embree",
            cone_profile: None,
        }
    }

    pub fn row(scene: &str, spec: &str, stats: run::Stats) -> BenchRow {
        BenchRow {
            scene: scene.into(),
            spec: spec.into(),
            stats,
            speedup_vs_first: 1.0,
            per_round_speedups: Vec::new(),
            rmse: None,
            psnr: None,
            flip: None,
            regions: Vec::new(),
            image: None,
            lod_vs_full: None,
            equal_time: Vec::new(),
            sweep: None,
        }
    }

    pub fn report(rows: Vec<BenchRow>) -> BenchReport {
        BenchReport {
            width: 4,
            height: 4,
            sizes: Vec::new(),
            simd: "sse2",
            repeat: 1,
            threads: 0,
            reference: None,
            rows,
            deform: Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each round pairs the methods' runs: a round in a slow phase (all three 2× slower) gives
    /// the same ratios as a fast one, while the per-spec bests may come from different phases.
    #[test]
    fn per_round_speedups_pair_runs_of_one_round() {
        let rounds = vec![vec![200.0, 100.0, 80.0], vec![400.0, 200.0, 160.0], vec![210.0, 140.0, 70.0]];
        let p = per_round_speedups(&rounds);
        assert_eq!(p[0], [1.0, 1.0, 1.0]);
        assert_eq!(p[1], [2.0, 2.0, 1.5]);
        assert_eq!(p[2], [2.5, 2.5, 3.0]);
        assert_eq!(median_range(&p[1]), "2.00x [1.50–2.00]");
        assert_eq!(median_range(&[3.0, 1.0]), "2.00x [1.00–3.00]");
        assert_eq!(median_range(&[]), crate::experiment::NA);
        // One round: nothing to pair beyond the best-of speed-up.
        assert!(per_round_speedups(&[vec![1.0, 2.0]]).iter().all(Vec::is_empty));
        assert!(per_round_speedups(&[]).is_empty());
    }

    /// The repeats go round the methods (0, 1, 2, 0, 1, 2), each method keeps its fastest
    /// run, every time is kept per round, and an error ends the rounds.
    #[test]
    fn best_of_rounds_goes_round_the_methods() {
        let times = [[3.0, 5.0, 2.0], [1.0, 6.0, 4.0]];
        let mut order = Vec::new();
        let (bests, rounds) = best_of_rounds(
            3,
            2,
            |i| {
                order.push(i);
                Ok((order.len() - 1, times[(order.len() - 1) / 3][i]))
            },
            |r| r.1,
        )
        .unwrap();
        assert_eq!(order, [0, 1, 2, 0, 1, 2]);
        assert_eq!(bests, [(3, 1.0), (1, 5.0), (2, 2.0)]);
        assert_eq!(rounds, times.map(|r| r.to_vec()).to_vec());
        let failed = best_of_rounds(2, 3, |i| if i == 1 { Err(Error::Usage("no".into())) } else { Ok(1.0) }, |t| *t);
        assert!(failed.is_err());
    }

    /// Every `lodtrace bench` command in the README passes bench's checks ([`plan`]): a
    /// command a user copies must not be refused (stop 58's new refusals broke the demo's own
    /// bench runs, stop 59). Shell continuation lines are joined as the shell joins them;
    /// commands naming a mesh that `tools/setup` has not fetched are skipped.
    #[test]
    fn the_readmes_bench_commands_pass_the_checks() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut checked = 0;
        for (cmd, mut a) in crate::cli::readme_commands::<BenchArgs>("bench") {
            if a.scenes.iter().any(|s| s.contains('/') && !root.join(s).exists()) {
                continue;
            }
            a.scenes =
                a.scenes.iter().map(|s| if s.contains('/') { root.join(s).to_string_lossy().into_owned() } else { s.clone() }).collect();
            if let Err(e) = plan(&a) {
                panic!("README: {cmd}\n{e}");
            }
            checked += 1;
        }
        assert!(checked >= 10, "only {checked} bench commands found in the README");
    }

    /// Embree does not count its tests: its rows read "–", not a measured 0 (a reader took
    /// the 0 for "no triangle tests"); the CWBVH's counts stay.
    #[test]
    fn uncounted_tests_show_as_a_dash() {
        let tests = [("triangle_tests", 0), ("node_tests", 0)];
        let rows = vec![
            fixtures::row("s", "whitted:embree", fixtures::stats("whitted", "embree", 1.0, &tests)),
            fixtures::row("s", "whitted:bvh", fixtures::stats("whitted", "bvh", 2.0, &[("triangle_tests", 7), ("node_tests", 9)])),
        ];
        let t = table_string(&fixtures::report(rows));
        let line = |spec: &str| t.lines().find(|l| l.starts_with(&format!("| s | {spec} |"))).unwrap().to_string();
        assert!(line("whitted:embree").ends_with("| – | – | – | – | – |"), "{}", line("whitted:embree"));
        assert!(line("whitted:bvh").ends_with("| 7 | 9 | 0 | 0 | 0 |"), "{}", line("whitted:bvh"));
    }
    #[test]
    fn parses_specs() {
        let v = parse_list("whitted:bvh,distributed:embree:spp=16:vt=0,whitted:bvh:threads=1:packet=1").unwrap();
        assert_eq!(v.len(), 3);
        assert_eq!(v[0].accel, AccelKind::Bvh);
        assert_eq!(v[1].spp, 16);
        assert_eq!(v[1].variance_threshold, 0.0);
        assert_eq!(v[2].threads, Some(1));
        assert_eq!(v[2].packet, 1);
        assert!(parse_list("nope").is_err());
        // Empty items are typos, not skipped; names are case-sensitive, as `render --method`.
        for bad in ["whitted,", ",whitted", "whitted,,cone", " , ", "WHITTED", "Whitted,whitted"] {
            assert!(parse_list(bad).is_err(), "{bad}");
        }
        assert!(parse_list("whitted:gpu").is_err());
        assert!(parse_list("whitted:spp=x").is_err());
        // Refused when the list is read, before any method runs (a helper saw three minutes of
        // renders thrown away before `lod:octree` failed).
        assert!(parse_list("whitted,lod:octree").is_err());
        assert!(parse_list("lod:bvh,lod").is_ok());
        // Switches take 0 or 1; a bare word after the accelerator is named as such.
        assert!(parse_list("multires:spread=0").unwrap()[0].multires.no_normal_spread);
        let e = |s: &str| parse_list(s).unwrap_err().to_string();
        assert!(e("multires:spread=2").contains("0 or 1"), "{}", e("multires:spread=2"));
        assert!(e("whitted:embree:foo").contains("a second accelerator"), "{}", e("whitted:embree:foo"));
        assert!(e("whitted:spp=99999999999").contains("too large"), "{}", e("whitted:spp=99999999999"));
        assert!(e("whitted:spp=-1").contains("a whole number"), "{}", e("whitted:spp=-1"));
        assert!(e("distributed:fps=0").contains("fps=0 out of range"), "{}", e("distributed:fps=0"));
        assert!(e("whitted:packet=4").contains("packet=4"), "{}", e("whitted:packet=4"));
    }

    /// The 99th percentile is the value one pixel in a hundred exceeds (nearest rank): of
    /// 100 differences 0.00, 0.01, …, 0.99 it is 0.98, which 0.99 alone exceeds. Until stop 80
    /// it was the 100th value (the maximum here) wherever a hundredth of the pixels is a whole
    /// number, as at the default 640×480.
    #[test]
    fn p99_is_exceeded_by_one_pixel_in_a_hundred() {
        let d: Vec<f32> = (0..100).map(|i| i as f32 / 100.0).collect();
        let (max, at, p99, _) = diff_summary(&d);
        assert_eq!((max, at), (0.99, 99));
        assert_eq!(p99, 0.98);
        let d: Vec<f32> = (0..250).map(|i| i as f32).collect();
        assert_eq!(diff_summary(&d).2, 247.0, "ceil(0.99 × 250) = 248th value");
        assert_eq!(diff_summary(&[0.5]).2, 0.5);
        assert_eq!(diff_summary(&[]).2, 0.0);
    }

    #[test]
    fn unmeasured_shares_show_as_a_dash() {
        assert_eq!(pct_or_dash(None), crate::experiment::NA);
        assert_eq!(pct_or_dash(Some(0.0)), "0.0 %");
        assert_eq!(pct_or_dash(Some(0.1234)), "12.3 %");
    }

    #[test]
    fn equal_time_interpolates_in_log_time() {
        // (seconds, spp, flip): 1 spp in 1 s at 0.4, 4 spp in 4 s at 0.1.
        let c = [(1.0, 1.0, 0.4), (4.0, 4.0, 0.1)];
        let e = equal_time(&c, 2.0, 0.25, "d");
        // 2 s is halfway in log time: flip halfway, spp the geometric mean.
        assert!((e.sweep_flip_at_equal_time.unwrap() - 0.25).abs() < 1e-9);
        assert!((e.sweep_spp_at_equal_time.unwrap() - 2.0).abs() < 1e-9);
        // Flip 0.25 is reached halfway: at 2 s, so the ratio is 1.
        assert!((e.sweep_seconds_to_match.unwrap() - 2.0).abs() < 1e-9);
        assert!((e.time_ratio_at_equal_error.unwrap() - 1.0).abs() < 1e-9);
        // Better than the whole sweep: not reached; slower than the sweep: its last point.
        let e = equal_time(&c, 8.0, 0.05, "d");
        assert_eq!(e.sweep_seconds_to_match, None);
        assert_eq!(e.sweep_flip_at_equal_time, Some(0.1));
        assert_eq!(e.sweep_max_seconds, 4.0);
        // ... which is a bound, flagged (stop 49; it was printed as an interpolated value).
        assert!(e.sweep_beyond);
        assert!(!equal_time(&c, 2.0, 0.25, "d").sweep_beyond);
        assert!(!equal_time(&c, 4.0, 0.25, "d").sweep_beyond, "the last point itself is not beyond the sweep");
        // Faster than 1 spp: no equal-time point; worse than 1 spp: matched by its time, at
        // most (an upper bound, flagged).
        let e = equal_time(&c, 0.5, 0.5, "d");
        assert_eq!(e.sweep_flip_at_equal_time, None);
        assert_eq!(e.sweep_seconds_to_match, Some(1.0));
        assert!((e.time_ratio_at_equal_error.unwrap() - 2.0).abs() < 1e-9);
        assert!(e.sweep_match_at_most);
        assert!(!equal_time(&c, 2.0, 0.25, "d").sweep_match_at_most);
        assert!(!equal_time(&c, 0.5, 0.4, "d").sweep_match_at_most, "exactly 1 spp's error is matched, not bounded");
    }
}
