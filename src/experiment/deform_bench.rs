//! `lodtrace bench SEQUENCE... --methods surfel:update=naive,surfel:update=lazy,...`: the
//! comparisons of Adams et al. §5 on deforming sequences.
//!
//! Every spec replays the same recorded motion (the simulation is deterministic), so the rows
//! differ only in how the hierarchy follows the deformation. Per row: time per frame (update +
//! rays, the paper's Fig. 5 quantity), speed-up against the first spec, bounding-volume and
//! leaf tests per frame (with and without the per-ray cache: the paper's "27 % fewer
//! intersection tests"), MLS iterations, nodes updated, the radius ratio updated/tightest at
//! the root and over all levels (Fig. 3), and whether the last frame is identical to the first
//! spec's (all modes must render the same image). Outputs in `--out`: `deform.json` rows
//! inside bench.json, per sequence `SEQ-frame-times.png` (Fig. 5) and `SEQ-sphere-tests.png`,
//! `radius-ratio.png` (Fig. 3, first lazy spec of each sequence), and each spec's last frame.

use super::bench::MethodSpec;
use super::plot;
use crate::cli::animate::{animate, AnimateArgs};
use crate::deform::LevelRatio;
use crate::error::{Error, Result};
use serde::Serialize;
use std::path::Path;

/// `surfel` spec options (keys `update=`, `frames=`, `detail=`, `shadows=`, `exact=`,
/// `bound=`, `stretch=`, `warm=`, `cache_up=`, `climb=`, `gate=`, `ordered=`, `top=`, `nearest=`; the spec's `packet=` chooses packets of 8 or single rays).
#[derive(Clone, Debug, Serialize)]
pub struct SurfelSpec {
    pub update: String,
    pub frames: Option<u32>,
    pub detail: f32,
    pub shadows: bool,
    /// `--exact-below` of `animate` (`exact=N`; unset: animate's default, lazy modes only).
    pub exact_below: Option<u32>,
    /// `--bound` of `animate` (`bound=tight|paper`, lazy modes only).
    pub bound: crate::cli::animate::Bound,
    /// `--support-stretch` of `animate` (`stretch=F`; unset: animate's default).
    pub support_stretch: Option<f32>,
    /// `--warm-pass` of `animate` (`warm=1`): also time each frame's rays with the hierarchy
    /// already updated, for the table's "rays ms/frame" column.
    pub warm: bool,
    /// `--cache-up` of `animate` (`cache_up=N`, lazy-cache only).
    pub cache_up: u32,
    /// `climb=1`: `--cache-climb` of `animate` (lazy-cache only).
    pub cache_climb: bool,
    /// `gate=R`: `--cache-gate` of `animate` (lazy-cache only; unset: animate's default).
    pub cache_gate: Option<f32>,
    /// `ordered=0`: `--unordered` of `animate`.
    pub ordered: bool,
    /// `top=0`: `--no-instance-tree` of `animate`.
    pub top: bool,
    /// `nearest=mls`: `--nearest mls` of `animate`.
    pub nearest_ellipse: bool,
}

impl Default for SurfelSpec {
    fn default() -> Self {
        SurfelSpec {
            update: "lazy-cache".into(),
            frames: None,
            detail: 1.0,
            shadows: true,
            exact_below: None,
            bound: crate::cli::animate::Bound::Tight,
            support_stretch: None,
            warm: false,
            cache_up: 0,
            cache_climb: false,
            cache_gate: None,
            ordered: true,
            top: true,
            nearest_ellipse: true,
        }
    }
}

/// One (sequence, spec) row.
#[derive(Clone, Debug, Serialize)]
pub struct DeformRow {
    pub scene: String,
    pub spec: String,
    /// Image size of the row (`bench --sizes` runs several).
    pub width: u32,
    pub height: u32,
    pub update: String,
    pub surfels: u64,
    pub frames: u32,
    pub threads: usize,
    pub build_seconds: f64,
    /// Total over all frames (update + rays).
    pub render_seconds: f64,
    pub ms_per_frame: f64,
    /// ms/frame of the first spec ÷ this one's (> 1 = faster), each the best of the repeats.
    pub speedup_vs_first: f64,
    /// With `--repeat` ≥ 2: the same ratio within each round of repeats (the first spec's
    /// ms/frame in that round ÷ this spec's in the same round), in round order. A round runs
    /// the specs one after the other, so each ratio pairs runs a few seconds apart; their
    /// median is robust to a slow phase of the machine that the per-spec bests are not
    /// (README, "Current figures"). Empty with one repeat.
    pub per_round_speedups: Vec<f64>,
    pub update_ms_per_frame: f64,
    /// `warm=1`: ms/frame of the second, untimed-in-`ms_per_frame` pass over each frame's
    /// rays, once its hierarchy is updated (`animate --warm-pass`); `ms_per_frame` minus this
    /// is the update's cost within a frame.
    pub rays_ms_per_frame: Option<f64>,
    pub sphere_tests_per_frame: f64,
    pub leaf_tests_per_frame: f64,
    /// MLS iterations started per frame (one per closest-hit ray under the nearest-ellipse
    /// rule, one per ellipse hit under the paper's).
    pub mls_runs_per_frame: f64,
    pub mls_iterations_mean: f64,
    pub cache_lookups: u64,
    pub cache_hits: u64,
    pub inner_nodes_updated_per_frame: f64,
    /// Lazy modes: updated / tightest radius at the root and over all sampled nodes, after the
    /// last frame.
    pub root_radius_ratio: Option<f64>,
    pub mean_radius_ratio: Option<f64>,
    /// The last frame equals the first spec's last frame, pixel for pixel.
    pub same_image_as_first: bool,
    /// The `update=naive` spec of this sequence and size whose other options are this spec's
    /// ([`naive_partners`]): its ms/frame ÷ this one's (best of the repeats each; the paper's
    /// speed-up, also where the first spec has other options, e.g. `shadows=0`), the same
    /// ratio round by round, and whether the two last frames are identical. `None` and empty
    /// without such a spec.
    pub speedup_vs_naive: Option<f64>,
    pub per_round_vs_naive: Vec<f64>,
    pub same_image_as_naive: Option<bool>,
    pub per_frame_ms: Vec<f64>,
    pub per_frame_sphere_tests: Vec<u64>,
    pub radius_ratios: Vec<LevelRatio>,
    pub image: Option<String>,
}

/// Runs every spec on every sequence (best of `repeat` runs by total time, the repeats
/// interleaved across the specs).
#[allow(clippy::too_many_arguments)]
pub fn run(
    seqs: &[String],
    specs: &[MethodSpec],
    width: u32,
    height: u32,
    threads: usize,
    repeat: u32,
    out: Option<&Path>,
    quiet: bool,
) -> Result<Vec<DeformRow>> {
    let mut rows = Vec::new();
    // Each spec's update=naive partner (the same for every sequence).
    let partners = naive_partners(specs, threads);
    for seq in seqs {
        let mut seq_rows: Vec<DeformRow> = Vec::new();
        // Each row's last frame, for the image checks against the first spec and the naive
        // partner.
        let mut seq_pix: Vec<Vec<[f32; 3]>> = Vec::new();
        let argv: Vec<AnimateArgs> = specs
            .iter()
            .map(|spec| {
                let s = &spec.surfel;
                AnimateArgs {
                    frames: s.frames,
                    update: s.update.clone(),
                    width,
                    height,
                    detail: s.detail,
                    no_shadows: !s.shadows,
                    threads: spec.threads.unwrap_or(threads),
                    packet: spec.packet,
                    exact_below: s.exact_below,
                    bound: s.bound,
                    support_stretch: s.support_stretch,
                    cache_up: s.cache_up,
                    cache_climb: s.cache_climb,
                    cache_gate: s.cache_gate,
                    unordered: !s.ordered,
                    no_instance_tree: !s.top,
                    nearest: if s.nearest_ellipse { crate::cli::animate::Nearest::Ellipse } else { crate::cli::animate::Nearest::Mls },
                    warm_pass: s.warm,
                    quiet,
                    ..AnimateArgs::new(seq)
                }
            })
            .collect();
        // Best of `repeat` by ms/frame, the repeats taken round the specs.
        let (bests, rounds) = super::bench::best_of_rounds(
            specs.len(),
            repeat,
            |i| animate(&argv[i]),
            |st| 1e3 * st.render_seconds / st.frames.max(1) as f64,
        )?;
        let paired = super::bench::per_round_speedups(&rounds);
        for ((spec, st), per_round_speedups) in specs.iter().zip(bests).zip(paired) {
            let s = &spec.surfel;
            let n = st.frames.max(1) as f64;
            let ms = 1e3 * st.render_seconds / n;
            let pixels: Vec<[f32; 3]> = st.last_frame.color.iter().map(|c| [c.x, c.y, c.z]).collect();
            let ms0 = seq_rows.first().map_or(ms, |r| r.ms_per_frame);
            let same = seq_pix.first().is_none_or(|p0| *p0 == pixels);
            let lazy = st.update.starts_with("lazy") && st.radius_ratios.iter().any(|r| r.sampled > 0);
            let tot: u64 = st.radius_ratios.iter().map(|r| r.sampled).sum();
            let image = match out {
                Some(o) => {
                    let name = super::bench::image_name(&st.scene, &spec.slug(), "");
                    crate::film::io::write_png(&o.join(&name), &st.last_frame)?;
                    Some(name)
                }
                None => None,
            };
            let row = DeformRow {
                scene: st.scene.clone(),
                spec: spec.text.clone(),
                width,
                height,
                update: st.update.clone(),
                surfels: st.surfels,
                frames: st.frames,
                threads: st.threads,
                build_seconds: st.build_seconds,
                render_seconds: st.render_seconds,
                ms_per_frame: ms,
                speedup_vs_first: ms0 / ms.max(1e-12),
                per_round_speedups,
                update_ms_per_frame: 1e3 * st.per_frame.iter().map(|r| r.update_seconds).sum::<f64>() / n,
                rays_ms_per_frame: s.warm.then(|| 1e3 * st.per_frame.iter().filter_map(|r| r.warm_seconds).sum::<f64>() / n),
                sphere_tests_per_frame: st.per_frame.iter().map(|r| r.sphere_tests).sum::<u64>() as f64 / n,
                leaf_tests_per_frame: st.per_frame.iter().map(|r| r.leaf_tests).sum::<u64>() as f64 / n,
                mls_runs_per_frame: st.per_frame.iter().map(|r| r.mls_runs).sum::<u64>() as f64 / n,
                // Over all MLS runs of the sequence, not a mean of the frames' means (a frame
                // without runs would count as 0 iterations).
                mls_iterations_mean: st.per_frame.iter().map(|r| r.mls_iterations_mean * r.mls_runs as f64).sum::<f64>()
                    / st.per_frame.iter().map(|r| r.mls_runs).sum::<u64>().max(1) as f64,
                cache_lookups: st.per_frame.iter().map(|r| r.cache_lookups).sum(),
                cache_hits: st.per_frame.iter().map(|r| r.cache_hits).sum(),
                inner_nodes_updated_per_frame: st.per_frame.iter().map(|r| r.inner_nodes_updated).sum::<u64>() as f64 / n,
                root_radius_ratio: lazy.then(|| st.radius_ratios.first().map(|r| r.mean_ratio)).flatten(),
                mean_radius_ratio: (lazy && tot > 0)
                    .then(|| st.radius_ratios.iter().map(|r| r.mean_ratio * r.sampled as f64).sum::<f64>() / tot as f64),
                same_image_as_first: same,
                speedup_vs_naive: None,
                per_round_vs_naive: Vec::new(),
                same_image_as_naive: None,
                per_frame_ms: st.per_frame.iter().map(|r| 1e3 * r.seconds).collect(),
                per_frame_sphere_tests: st.per_frame.iter().map(|r| r.sphere_tests).collect(),
                radius_ratios: st.radius_ratios.clone(),
                image,
            };
            if !quiet {
                crate::status!("  {} {}: {:.1} ms/frame", row.scene, row.spec, row.ms_per_frame);
            }
            seq_rows.push(row);
            seq_pix.push(pixels);
        }
        for (j, partner) in partners.iter().enumerate() {
            if let Some(i) = *partner {
                let ms_i = seq_rows[i].ms_per_frame;
                let r = &mut seq_rows[j];
                r.speedup_vs_naive = Some(ms_i / r.ms_per_frame.max(1e-12));
                r.per_round_vs_naive = if rounds.len() < 2 { Vec::new() } else { rounds.iter().map(|t| t[i] / t[j].max(1e-12)).collect() };
                r.same_image_as_naive = Some(seq_pix[i] == seq_pix[j]);
            }
        }
        if let Some(o) = out {
            plots(o, &seq_rows)?;
        }
        rows.extend(seq_rows);
    }
    if let Some(o) = out {
        radius_plot(o, &rows)?;
    }
    Ok(rows)
}

/// For each spec, the index of its `update=naive` partner among `specs`: the first spec with
/// `update=naive` whose other options are this spec's, the options only the lazy updates take
/// left aside (`exact=0:bound=paper` pairs with the plain naive spec). The naive spec is its
/// own partner. The options are compared as parsed, threads as run (`threads` is the bench's
/// `--threads`): until stop 80 the spec texts were, so `shadows=1`, `detail=1`, `packet=8` or
/// a `threads=` equal to `--threads` left a row without its partner.
pub fn naive_partners(specs: &[MethodSpec], threads: usize) -> Vec<Option<usize>> {
    let rest = |m: &MethodSpec| -> String {
        let d = SurfelSpec::default();
        let s = SurfelSpec {
            update: d.update,
            exact_below: d.exact_below,
            bound: d.bound,
            cache_up: d.cache_up,
            cache_climb: d.cache_climb,
            cache_gate: d.cache_gate,
            ..m.surfel.clone()
        };
        format!("{} packet {} threads {}", serde_json::to_string(&s).expect("spec serialises"), m.packet, m.threads.unwrap_or(threads))
    };
    specs
        .iter()
        .map(|m| {
            let key = rest(m);
            specs.iter().position(|n| n.surfel.update == "naive" && rest(n) == key)
        })
        .collect()
}

/// `radius-ratio.png` (the paper's Fig. 3): the updated / tightest radius per level of the
/// first lazy row of every sequence in `rows`.
pub fn radius_plot(out: &Path, rows: &[DeformRow]) -> Result<()> {
    let ratios: Vec<(String, Vec<(f64, f64)>)> = rows
        .iter()
        .filter(|r| r.update == "lazy" || r.update == "lazy-cache")
        .fold(Vec::<&DeformRow>::new(), |mut v, r| {
            if !v.iter().any(|x| x.scene == r.scene) {
                v.push(r);
            }
            v
        })
        .into_iter()
        .map(|r| (r.scene.clone(), r.radius_ratios.iter().filter(|l| l.sampled > 0).map(|l| (l.level as f64, l.mean_ratio)).collect()))
        .filter(|(_, v): &(String, Vec<(f64, f64)>)| !v.is_empty())
        .collect();
    if ratios.is_empty() {
        return Ok(());
    }
    plot::line_chart(
        &out.join("radius-ratio.png"),
        "Updated / tightest sphere radius per level (lazy, last frame)",
        "tree level (0 = root)",
        "radius ratio",
        &ratios,
    )
}

/// Fig. 5 (time per frame) and the bounding-volume tests per frame of one sequence's rows.
fn plots(out: &Path, rows: &[DeformRow]) -> Result<()> {
    let Some(seq) = rows.first().map(|r| r.scene.clone()) else { return Ok(()) };
    // The legend names the update mode as the tables do, not the whole spec.
    let names = short_labels(rows);
    let series = |f: &dyn Fn(&DeformRow) -> Vec<f64>| -> Vec<(String, Vec<(f64, f64)>)> {
        rows.iter().zip(&names).map(|(r, n)| (n.clone(), f(r).into_iter().enumerate().map(|(i, y)| (i as f64, y)).collect())).collect()
    };
    plot::line_chart(
        &out.join(super::bench::image_name(&seq, "frame-times", "")),
        &format!("{seq}: time per frame"),
        "frame",
        "ms",
        &series(&|r| r.per_frame_ms.clone()),
    )?;
    plot::line_chart(
        &out.join(super::bench::image_name(&seq, "sphere-tests", "")),
        &format!("{seq}: bounding-volume tests per frame"),
        "frame",
        "tests",
        &series(&|r| r.per_frame_sphere_tests.iter().map(|x| *x as f64).collect()),
    )?;
    Ok(())
}

/// The rows as a Markdown table.
pub fn table(rows: &[DeformRow]) -> String {
    let mut s = String::from("\nDeforming sequences (Adams et al.):\n\n");
    s.push_str("| sequence | method | size | surfels | frames | thr | ms/frame | speed-up vs first | per-round speed-up: median [range] | ÷ naive, same options: best (per-round median) | update ms/frame | rays ms/frame (warm) | BV tests/frame | leaf tests/frame | MLS runs/frame | MLS it. | cache hits (all frames) | inner nodes updated/frame | root ratio | mean ratio | same image |\n");
    s.push_str("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n");
    for r in rows {
        let f = |x: Option<f64>| x.map(|v| format!("{v:.2}")).unwrap_or_else(|| super::NA.into());
        s.push_str(&format!(
            "| {} | {} | {}x{} | {} | {} | {} | {:.1} | {:.2}x | {} | {} | {:.1} | {} | {:.0} | {:.0} | {:.0} | {:.2} | {} | {:.0} | {} | {} | {} |\n",
            super::bench::md_cell(&r.scene),
            r.spec,
            r.width,
            r.height,
            r.surfels,
            r.frames,
            r.threads,
            r.ms_per_frame,
            r.speedup_vs_first,
            super::bench::median_range(&r.per_round_speedups),
            vs_naive(r),
            r.update_ms_per_frame,
            r.rays_ms_per_frame.map(|v| format!("{v:.1}")).unwrap_or_else(|| super::NA.into()),
            r.sphere_tests_per_frame,
            r.leaf_tests_per_frame,
            r.mls_runs_per_frame,
            r.mls_iterations_mean,
            if r.cache_lookups > 0 { format!("{}/{}", r.cache_hits, r.cache_lookups) } else { super::NA.into() },
            r.inner_nodes_updated_per_frame,
            f(r.root_radius_ratio),
            f(r.mean_radius_ratio),
            if r.same_image_as_first { "yes" } else { "NO" },
        ));
    }
    s
}

/// The table's "÷ naive, same options" cell: "–" without a naive partner, "=" for the naive
/// spec itself; a trailing "≠ image" if the partners' last frames differ.
fn vs_naive(r: &DeformRow) -> String {
    let Some(x) = r.speedup_vs_naive else { return super::NA.into() };
    if r.update == "naive" {
        return "=".into();
    }
    let med = super::bench::median(&r.per_round_vs_naive).map(|m| format!(" ({m:.2}x)")).unwrap_or_default();
    let diff = if r.same_image_as_naive == Some(false) { ", ≠ image" } else { "" };
    format!("{x:.2}x{med}{diff}")
}

/// The (width, height) of `rows` in first-seen order.
fn sizes_of(rows: &[DeformRow]) -> Vec<(u32, u32)> {
    let mut v: Vec<(u32, u32)> = Vec::new();
    for r in rows {
        if !v.contains(&(r.width, r.height)) {
            v.push((r.width, r.height));
        }
    }
    v
}

/// `bench --sizes`: each method's speed-up over the first method of its sequence, one column
/// per image size (Markdown).
pub fn size_table(rows: &[DeformRow]) -> String {
    let sizes = sizes_of(rows);
    let mut s = String::from("\nSpeed-up over the first method by image size (ms/frame in brackets):\n\n| sequence | method |");
    for (w, h) in &sizes {
        let n = *w as u64 * *h as u64;
        let px = if n < 10_000 { format!("{n} px") } else { format!("{} k px", n / 1000) };
        s.push_str(&format!(" {w}x{h} ({px}) |"));
    }
    s.push_str("\n|---|---|");
    s.push_str(&"---:|".repeat(sizes.len()));
    s.push('\n');
    let mut keys: Vec<(&str, &str)> = Vec::new();
    for r in rows {
        if !keys.contains(&(r.scene.as_str(), r.spec.as_str())) {
            keys.push((&r.scene, &r.spec));
        }
    }
    for (scene, spec) in keys {
        s.push_str(&format!("| {scene} | {spec} |"));
        for &(w, h) in &sizes {
            match rows.iter().find(|r| r.scene == scene && r.spec == spec && (r.width, r.height) == (w, h)) {
                Some(r) => s.push_str(&format!(" {:.2}x ({:.1}) |", r.speedup_vs_first, r.ms_per_frame)),
                None => s.push_str(&format!(" {} |", super::NA)),
            }
        }
        s.push('\n');
    }
    s
}

/// `speedup-vs-size.png`: each method's speed-up over the first method of its sequence
/// against the pixels (primary rays) per frame, logarithmic; one curve per (sequence, method)
/// other than the first. Where the rebuild dominates a frame (few rays) the lazy update
/// gains most (the paper's 2–3× regime).
pub fn size_plot(out: &Path, rows: &[DeformRow]) -> Result<()> {
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let names = short_labels(rows);
    for r in rows {
        let first = rows.iter().find(|f| f.scene == r.scene && (f.width, f.height) == (r.width, r.height)).map(|f| f.spec.as_str());
        if first == Some(r.spec.as_str()) {
            continue;
        }
        let name = format!("{} {}", r.scene, names[rows.iter().position(|x| x.spec == r.spec).unwrap_or(0)]);
        let p = ((r.width as f64) * (r.height as f64), r.speedup_vs_first);
        match series.iter_mut().find(|s| s.0 == name) {
            Some(s) => s.1.push(p),
            None => series.push((name, vec![p])),
        }
    }
    if series.is_empty() {
        return Ok(());
    }
    let first = names.first().cloned().unwrap_or_default();
    // The paper's target for the lazy update against the rebuild (Adams et al. §6).
    let target = (first == "naive").then_some((2.0, "paper: lazy-cache ≥ 2× naive"));
    plot::line_chart_fmt(
        &out.join("speedup-vs-size.png"),
        &format!("Speed-up over {first} by image size"),
        "pixels per frame",
        "speed-up (x)",
        &series,
        true,
        &|n| if n >= 1e6 { format!("{} M", plot::fmt_axis(n / 1e6)) } else { format!("{} k", plot::fmt_axis(n / 1e3)) },
        target,
    )
}

/// Legend names of `rows`: [`update_label`] where that tells the specs apart, else the specs
/// (`bench` may compare two specs of one mode, e.g. at two detail levels).
fn short_labels(rows: &[DeformRow]) -> Vec<String> {
    let short: Vec<String> = rows.iter().map(|r| update_label(&r.update, &r.spec)).collect();
    let ambiguous = rows.iter().enumerate().any(|(i, r)| rows.iter().enumerate().any(|(j, o)| short[i] == short[j] && r.spec != o.spec));
    if ambiguous {
        rows.iter().map(|r| r.spec.clone()).collect()
    } else {
        short
    }
}

/// A row's update mode as the tables and legends show it: the mode, and the cache ablation
/// switches of its spec (`lazy-cache, unordered, cache 8 up`), not the whole spec.
pub fn update_label(update: &str, spec: &str) -> String {
    let mut l = update.to_string();
    if spec.contains("ordered=0") {
        l.push_str(", unordered");
    }
    if let Some(n) = spec.split(':').find_map(|k| k.strip_prefix("cache_up=")) {
        l.push_str(&format!(", cache {n} up"));
    }
    if spec.split(':').any(|k| k == "bound=paper") {
        l.push_str(", paper bound");
    }
    if spec.split(':').any(|k| k == "climb=1") {
        l.push_str(", cache climbs");
    }
    if let Some(g) = spec.split(':').find_map(|k| k.strip_prefix("gate=")) {
        l.push_str(&if g.parse::<f32>() == Ok(0.0) { ", cache every frame".to_string() } else { format!(", cache gate {g}") });
    }
    l
}

/// Checks a `surfel` spec's options before any work.
pub fn validate(spec: &MethodSpec) -> Result<()> {
    let s = &spec.surfel;
    let mode = crate::cli::animate::parse_mode(&s.update)?;
    let bad = |msg: String| Err(Error::Usage(format!("method spec '{}': {msg}", spec.text)));
    if !(s.detail.is_finite() && s.detail > 0.0 && s.detail <= 10.0) {
        return bad(format!("detail={} out of range (0, 10]", s.detail));
    }
    use crate::deform::trace::{MAX_CACHE_UP, MAX_EXACT_BELOW};
    for (key, v, max) in [("exact", s.exact_below.unwrap_or(0), MAX_EXACT_BELOW), ("cache_up", s.cache_up, MAX_CACHE_UP)] {
        if v > max {
            return bad(format!("{key}={v} above {max}"));
        }
    }
    if s.cache_up > 0 && mode != crate::deform::UpdateMode::LazyCache {
        return bad("cache_up is a key of update=lazy-cache".into());
    }
    if s.cache_climb && mode != crate::deform::UpdateMode::LazyCache {
        return bad("climb is a key of update=lazy-cache".into());
    }
    if let Some(g) = s.cache_gate {
        if mode != crate::deform::UpdateMode::LazyCache {
            return bad("gate is a key of update=lazy-cache".into());
        }
        if !(0.0..=1.0).contains(&g) {
            return bad(format!("gate={g}: a share of the lookups, in [0, 1]"));
        }
        // As `animate --cache-gate` beside `--unordered` (stop 80): never gated.
        if !s.ordered {
            return bad("gate has no effect beside ordered=0 (which looks the cache up every frame)".into());
        }
    }
    use crate::deform::UpdateMode::{Naive, Refit};
    if s.exact_below.is_some() && matches!(mode, Naive | Refit) {
        return bad(format!("exact is a key of the lazy updates; update={} would ignore it", mode.name()));
    }
    if s.bound != crate::cli::animate::Bound::Tight && matches!(mode, Naive | Refit) {
        return bad(format!("bound is a key of the lazy updates; update={} would ignore it", mode.name()));
    }
    if let Some(x) = s.support_stretch.filter(|x| !(x.is_finite() && (1.0..=8.0).contains(x))) {
        return bad(format!("stretch={x} out of range [1, 8]"));
    }
    if !s.ordered && mode == Refit {
        return bad("ordered is a key of the sphere tree's traversal; update=refit (an obvhs BVH2) would ignore it".into());
    }
    if s.frames == Some(0) || s.frames.is_some_and(|f| f > 100_000) {
        return bad(format!("frames={} out of range (1..=100000)", s.frames.unwrap_or(0)));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_spec_pairs_with_the_naive_spec_of_its_other_options() {
        let specs = crate::experiment::bench::parse_list(
            "surfel:update=naive:frames=8,surfel:update=lazy-cache:frames=8,surfel:frames=8:shadows=0:update=naive,\
             surfel:update=lazy:shadows=0:frames=8,surfel:update=lazy:detail=0.5:frames=8,surfel:frames=8,\
             surfel:update=lazy:frames=8:exact=0:bound=paper,surfel:update=lazy-cache:gate=0:frames=8:shadows=0:cache_up=2",
        )
        .unwrap();
        // The sixth spec takes the default update (lazy-cache) and pairs like the second; the
        // last two pair across their lazy-only keys.
        assert_eq!(naive_partners(&specs, 2), [Some(0), Some(0), Some(2), Some(2), None, Some(0), Some(0), Some(2)]);
    }

    /// The options are compared as they run, not as written (stop 80): a key at its default
    /// value (`shadows=1`, `detail=1`, `packet=8`) or `threads=` equal to the bench's
    /// `--threads` left the row without its naive partner ("–" and `null`).
    #[test]
    fn naive_partner_options_are_compared_as_they_run() {
        let specs = crate::experiment::bench::parse_list(
            "surfel:update=naive:frames=8,surfel:update=lazy-cache:frames=8:shadows=1:detail=1:packet=8,\
             surfel:update=lazy:frames=8:threads=2,surfel:update=lazy:frames=8:threads=1",
        )
        .unwrap();
        assert_eq!(naive_partners(&specs, 2), [Some(0), Some(0), Some(0), None]);
    }

    #[test]
    fn legends_use_short_labels_unless_ambiguous() {
        let row = |spec: &str, update: &str| DeformRow {
            scene: "bend".into(),
            spec: spec.into(),
            width: 1,
            height: 1,
            update: update.into(),
            surfels: 0,
            frames: 1,
            threads: 1,
            build_seconds: 0.0,
            render_seconds: 0.0,
            ms_per_frame: 1.0,
            speedup_vs_first: 1.0,
            per_round_speedups: Vec::new(),
            update_ms_per_frame: 0.0,
            rays_ms_per_frame: None,
            sphere_tests_per_frame: 0.0,
            leaf_tests_per_frame: 0.0,
            mls_runs_per_frame: 0.0,
            mls_iterations_mean: 0.0,
            cache_lookups: 0,
            cache_hits: 0,
            inner_nodes_updated_per_frame: 0.0,
            root_radius_ratio: None,
            mean_radius_ratio: None,
            same_image_as_first: true,
            speedup_vs_naive: None,
            per_round_vs_naive: Vec::new(),
            same_image_as_naive: None,
            per_frame_ms: Vec::new(),
            per_frame_sphere_tests: Vec::new(),
            radius_ratios: Vec::new(),
            image: None,
        };
        let a = [row("surfel:update=naive:frames=8", "naive"), row("surfel:update=lazy-cache:ordered=0:cache_up=8:frames=8", "lazy-cache")];
        assert_eq!(short_labels(&a), ["naive", "lazy-cache, unordered, cache 8 up"]);
        let b = [row("surfel:update=lazy:detail=0.2", "lazy"), row("surfel:update=lazy:detail=0.4", "lazy")];
        assert_eq!(short_labels(&b), ["surfel:update=lazy:detail=0.2", "surfel:update=lazy:detail=0.4"]);
    }
}
