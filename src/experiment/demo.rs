//! `lodtrace demo`: the main job. Renders the built-in paper scenes with every method that
//! exists, side by side through [`super::bench`], cross-checks the intersectors against
//! Embree, and writes images, tables, plots and an `index.html` a person can open.

use super::bench::{self, BenchArgs, BenchReport};
use super::deform_bench::update_label;
use crate::error::{Error, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug, Clone)]
pub struct DemoArgs {
    /// Folder for the images, tables, plots and `index.html` (created; the demo's own files
    /// in it are replaced).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Smaller images, fewer reference samples and frames: about 1.5 minutes on 2 cores instead of about 7 (Intel Xeon, stop 90; 1–4 and 11–13 minutes on a slower machine).
    #[arg(long)]
    pub quick: bool,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// No progress bars or progress lines on stderr (the tables on stdout, warnings such as
    /// a skipped scene, and an error stay).
    #[arg(long)]
    pub quiet: bool,
}

struct Job {
    scene: &'static str,
    /// The job's folder under the demo's output folder, and its section's heading: the
    /// scene's name, or another for a second job on the same scene ([`CONE_DIR`]).
    dir: &'static str,
    /// What the section shows, above its table (empty: the table says it).
    intro: &'static str,
    /// A classic cone job: its rows are judged apart ([`classic_cone_row`]).
    classic: bool,
    width: u32,
    height: u32,
    methods: String,
    reference: Option<String>,
    /// Stochastic specs swept over spp for the equal-time comparison (`bench --sweep`).
    sweep: Vec<String>,
    /// `bench --region` rectangles: where in the image the error sits.
    regions: Vec<String>,
}

/// `complex`'s parts as `--region` rectangles, measured at 640×480 and scaled to `w`×`h`:
/// the plant rows (far foliage, the paper's §7 problem case), the animals, the open
/// checkerboard (prefiltered texture detail), the front glass bunny (refraction; its box
/// starts below the plant rows behind it, which stop 27 found carried much of its error).
fn complex_regions(w: u32, h: u32) -> Vec<String> {
    let sx = |x: u32| x * w / 640;
    let sy = |y: u32| y * h / 480;
    [("plants", 0, 128, 640, 250), ("animals", 0, 250, 640, 370), ("board", 0, 370, 640, 480), ("bunny", 40, 262, 210, 370)]
        .iter()
        .map(|&(n, x0, y0, x1, y1)| format!("{n}={},{},{},{}", sx(x0), sy(y0), sx(x1), sy(y1)))
        .collect()
}

fn jobs(quick: bool) -> Vec<Job> {
    let accel_list = if cfg!(feature = "embree") { vec!["embree", "bvh"] } else { vec!["bvh"] };
    let a0 = accel_list[0];
    let mut m = Vec::new();
    for a in &accel_list {
        m.push(format!("whitted:{a}"));
    }
    m.push(format!("whitted:{a0}:threads=1"));
    // Wand & Straßer: the same-code-basis baseline (conventional tracer on the octree) and
    // the multi-resolution cone tracer.
    m.push("whitted:octree".into());
    m.push("multires".into());
    // The paper's clamp and level rule turned past their defaults for speed (BENCHMARKS.md, stop
    // 28: `complex` at 1.8× the octree Whitted frame instead of 3.0×).
    m.push("multires:clamp2=1:lod=4".into());
    let methods = m.join(",");
    // Fig. 8, also with the shadow cones' triangles by their mass (stop 39: the paper's
    // overestimated shadow region, §7, mostly gone) and with every cone's.
    let fx = format!("whitted:{a0},multires,multires:stri=mass,multires:tri=mass");
    // Distributed ray tracing at 1, 2, 4, … spp: the equal-time and equal-error comparison,
    // on the fast back-end and, as in the paper's §6 ("a distributed raytracer based on the
    // same code basis"), on the octree the multi-resolution tracer and its Whitted baseline
    // use.
    let sw = vec![format!("distributed:{a0}"), "distributed:octree".to_string()];
    let (swd, sh, cw, ch, sref, cref) = if quick { (256, 256, 320, 240, 66, 27) } else { (512, 512, 640, 480, 258, 102) };
    let r = |spp: u32| Some(format!("distributed:{a0}:spp={spp}:vt=0"));
    // Papaioannou et al.: per-ray LOD against the full-detail tracer, 2×2 supersampling as
    // in the paper, on both back-ends; the chessboard also at one thread (speed-up per
    // processor).
    let mut lod = Vec::new();
    for a in &accel_list {
        lod.push(format!("whitted:{a}:spp=4"));
        lod.push(format!("lod:{a}:spp=4"));
    }
    let lod_cb = format!("{},whitted:bvh:spp=4:threads=1,lod:bvh:spp=4:threads=1", lod.join(","));
    let lod = lod.join(",");
    let (lw, lh) = if quick { (256, 256) } else { (512, 512) };
    let job = |scene: &'static str, (width, height): (u32, u32), methods: String, reference: Option<String>, sweep: Vec<String>| Job {
        scene,
        dir: scene,
        intro: "",
        classic: false,
        width,
        height,
        methods,
        reference,
        sweep,
        regions: vec![],
    };
    let (full, budget) = cone_full_specs(quick);
    // Classic cone tracing against multires (§6) on `complex`: primary cones only, with the
    // exact triangle mass and the default weight, and the whole frame (secondary cones) with
    // the exact mass, where the classic tracer runs into its time budget. At the paper's
    // frame (the quick demo's smaller one), and the primary cones again at the smaller
    // frames of [`CONE_SMALL`], whose footprints are wider against the same triangles:
    // how much the points save grows with the footprint ([`cone_size_plot`]).
    let primary = CONE_PAIRS.iter().flat_map(|(_, m, c)| [*m, *c]).collect::<Vec<_>>().join(",");
    let cone_job = |dir: &'static str, intro: &'static str, size: (u32, u32), methods: String| Job {
        dir,
        intro,
        classic: true,
        ..job("complex", size, methods, None, vec![])
    };
    let mut v = vec![
        job("spheres", (swd, sh), methods.clone(), r(sref), sw.clone()),
        Job { regions: complex_regions(cw, ch), ..job("complex", (cw, ch), methods, r(cref), sw.clone()) },
        cone_job(CONE_DIR, CONE_INTRO, (cw, ch), format!("{primary},{full},{budget}")),
    ];
    for &(dir, size) in CONE_SMALL.iter().filter(|(_, (w, _))| *w < cw) {
        v.push(cone_job(dir, CONE_INTRO_SMALL, size, primary.clone()));
    }
    v.extend([
        // Fig. 8: soft shadows, depth of field, blurry reflections at three roughnesses.
        job("effects", (swd, sh), fx, r(sref), sw[..1].to_vec()),
        job("chessboard", (lw, lh), lod_cb, None, vec![]),
        job("cabinet", (lw, lh), lod.clone(), None, vec![]),
        job("reflector", (lw, lh), lod, None, vec![]),
    ]);
    v
}

/// The folders (and headings) of the classic cone jobs ([`jobs`]).
const CONE_DIR: &str = "complex-classic-cone";
/// The primary rows again at smaller frames (those smaller than the main classic cone job's).
const CONE_SMALL: [(&str, (u32, u32)); 2] = [("complex-classic-cone-320x240", (320, 240)), ("complex-classic-cone-160x120", (160, 120))];
/// [`cone_size_plot`]'s file, in [`CONE_DIR`].
const CONE_PLOT: &str = "classic-cone-vs-size.png";
const CONE_INTRO: &str = "Classic cone tracing against multires (§6): <code>cone</code> is the same tracer with the point samples disabled, so every cone meets the triangles themselves. The paper measured the classic tracer 2.8× slower on its complex scene with primary cones only (first four rows: with the exact triangle mass, <code>tri=mass</code>, which weighs a thin leaf by its true coverage, and with the default weight), and with secondary cones its run did not finish (last two rows: the classic tracer stops at its time budget, <code>budget=</code> seconds, and leaves the rest of the image black). How much the points save grows with the footprint against the triangles: the next sections repeat the primary rows at smaller frames, and the plot below sets the classic tracer's time against the frame size.";
const CONE_INTRO_SMALL: &str =
    "The primary rows of the classic cone comparison above at a smaller frame: the same triangles under wider footprints.";

/// The rows compared in the classic cone jobs, primary cones only: (triangle weight, the
/// multires spec, the classic cone spec).
const CONE_PAIRS: [(&str, &str, &str); 2] =
    [("exact mass", "multires:primary=1:tri=mass", "cone:primary=1:tri=mass"), ("default weight", "multires:primary=1", "cone:primary=1")];

/// The whole frame (secondary cones too) with the exact triangle mass: the multires spec, and
/// the classic cone spec with its time budget (the paper's run "did not terminate").
fn cone_full_specs(quick: bool) -> (String, String) {
    ("multires:tri=mass".into(), format!("cone:tri=mass:budget={}", if quick { 10 } else { 30 }))
}

/// The `lodtrace bench` run of one demo job.
fn bench_args(a: &DemoArgs, job: &Job) -> BenchArgs {
    BenchArgs {
        scenes: vec![job.scene.to_string()],
        methods: job.methods.clone(),
        reference: job.reference.clone(),
        out: Some(a.out.join(job.dir)),
        width: job.width,
        height: job.height,
        threads: a.threads,
        repeat: 1,
        quiet: a.quiet,
        sweep: job.sweep.clone(),
        // Only a job with a sweep may bound it (bench refuses `--sweep-max-spp` without one).
        sweep_max_spp: (!job.sweep.is_empty()).then_some(if a.quick { 64 } else { 128 }),
        regions: job.regions.clone(),
        sizes: None,
    }
}

pub fn run(a: &DemoArgs) -> Result<()> {
    crate::core::check_threads(a.threads)?;
    // A failed demo removes its output folder again if it created it.
    crate::film::io::discard_dir_on_error(Some(&a.out), || run_in(a))
}

fn run_in(a: &DemoArgs) -> Result<()> {
    // The plots need a font: say so before minutes of rendering, not after.
    super::plot::check_font()?;
    crate::film::io::create_out_dir(&a.out)?;
    crate::film::io::check_writable_dir(&a.out)?;
    // Every job's outputs, and the page's, before the first job renders: a folder where
    // `OUT/complex/bench.json` goes was met only at that job, after the jobs before it.
    let mut names = vec!["targets.md".to_string(), "index.html".to_string()];
    for job in jobs(a.quick) {
        let dir = a.out.join(job.dir);
        if dir.exists() && !dir.is_dir() {
            return Err(Error::Usage(format!(
                "{}: exists and is not a folder (the demo writes its {} outputs there)",
                dir.display(),
                job.dir
            )));
        }
        let outputs = bench::output_names_unloaded(&bench_args(a, &job), &[job.scene.to_string()])?;
        names.extend(outputs.into_iter().map(|n| format!("{}/{n}", job.dir)));
    }
    names.push(format!("{CONE_DIR}/{CONE_PLOT}"));
    crate::film::io::check_out_files(&a.out, &names)?;
    let mut sections = Vec::new();
    // What could not run here (meshes missing): named on the page, not only on stderr.
    let mut skipped = Vec::new();
    for job in jobs(a.quick) {
        if let Err(e) = crate::scene::builtin::get(job.scene) {
            // Named once, however many of its jobs are skipped.
            let what = format!("{} ({e})", job.scene);
            if !skipped.contains(&what) {
                crate::status!("demo: skipping '{}' ({e})", job.scene);
                skipped.push(what);
            }
            continue;
        }
        if !a.quiet {
            crate::status!(
                "demo: {} at {}x{}: {} (reference {})",
                job.dir,
                job.width,
                job.height,
                job.methods,
                job.reference.as_deref().unwrap_or("none")
            );
        }
        let report = bench::bench(&bench_args(a, &job))?;
        bench::print_table(&report)?;
        sections.push((job, report));
    }
    let hier = hierarchy_rows(a)?;
    let (deform, deform_rows) = deform_section(a, &mut skipped)?;
    // The classic cone jobs' rows are judged apart: their multires rows are not the frames
    // the other targets are about.
    let reports: Vec<&BenchReport> = sections.iter().filter(|(j, _)| !j.classic).map(|(_, r)| r).collect();
    let cone: Vec<&BenchReport> = sections.iter().filter(|(j, _)| j.classic).map(|(_, r)| r).collect();
    let mut targets = target_rows(&reports, &cone, a.quick, &deform_rows);
    if let Some(row) = build_row(&hier) {
        // After the other Wand & Straßer rows.
        let at = targets.iter().rposition(|r| r.paper == "Wand & Straßer").map_or(0, |i| i + 1);
        targets.insert(at, row);
    }
    let md = targets_markdown(&targets);
    let p = a.out.join("targets.md");
    crate::film::io::write_atomic(&p, |tmp| std::fs::write(tmp, md).map_err(|e| Error::io(&p, e)))?;
    let mut top = run_line(a);
    if !skipped.is_empty() {
        let _ = write!(top, "<p><b>Not run here</b> (missing meshes: <code>tools/setup</code>): {}.</p>", esc(&skipped.join("; ")));
    }
    top.push_str(&targets_html(&targets));
    // The classic cone plot after the last classic cone section.
    let plot = cone_size_plot(&a.out.join(CONE_DIR), &cone)?;
    let last_cone = sections.iter().rev().find(|(j, _)| j.classic).map(|(j, _)| j.dir);
    let extra: Vec<(&str, String)> = last_cone.into_iter().filter(|_| plot).map(|d| (d, cone_plot_html())).collect();
    let mut html = index_html(&sections, &top, &extra);
    html = html.replace("</body></html>", &format!("{}{deform}</body></html>", hierarchy_html(&hier)));
    let p = a.out.join("index.html");
    crate::film::io::write_atomic(&p, |tmp| std::fs::write(tmp, html).map_err(|e| Error::io(&p, e)))?;
    if !a.quiet {
        crate::status!("demo: open {}", p.display());
    }
    Ok(())
}

/// The paper's Table 1 (preprocessing): its two scenes, the seconds and megabytes of its 2003
/// build (2 GHz Pentium 4).
const TABLE1: [(&str, f64, f64); 2] = [("spheres", 5.7, 2.3), ("complex", 443.0, 106.0)];

/// One scene's point hierarchies built from scratch ([`hierarchy_rows`]).
struct HierRow {
    scene: &'static str,
    /// The paper's seconds and megabytes ([`TABLE1`]).
    paper: (f64, f64),
    stats: super::run::HierarchyStats,
    threads: usize,
}

/// The point hierarchies of the paper's Table 1 scenes built from scratch, the on-disk cache
/// bypassed (the jobs above read them from it), at the paper's default build parameters, on
/// the demo's threads. A scene whose meshes are missing is left out (the jobs name it).
fn hierarchy_rows(a: &DemoArgs) -> Result<Vec<HierRow>> {
    let (bp, _) = crate::multires::MultiresArgs::default().params(true)?;
    let pool = crate::core::thread_pool(a.threads)?;
    let mut rows = Vec::new();
    for (scene, ps, pmb) in TABLE1 {
        let Ok(sc) = crate::scene::builtin::get(scene) else { continue };
        if !a.quiet {
            crate::status!("demo: {scene}: its point hierarchies built from scratch (the paper's Table 1)");
        }
        let (ms, threads) =
            pool.install(|| crate::multires::trace::MultiresScene::build_in(&sc, &bp, None).map(|m| (m, rayon::current_num_threads())))?;
        rows.push(HierRow { scene, paper: (ps, pmb), stats: super::run::hierarchy_stats(&ms), threads });
    }
    Ok(rows)
}

/// The targets row of the hierarchy build: `complex` from scratch in ≤ 60 s.
fn build_row(hier: &[HierRow]) -> Option<TargetRow> {
    let r = hier.iter().find(|r| r.scene == "complex")?;
    let (ps, pmb) = r.paper;
    Some(TargetRow {
        paper: "Wand & Straßer",
        target: "point hierarchy build for complex ≤ 60 s (Table 1: 443 s in 2003)".into(),
        measured: format!(
            "{:.1} s from scratch on {} threads, {:.1} MB ({} hierarchies, {} nodes, {} points; the paper {ps:.0} s, {pmb:.0} MB)",
            r.stats.seconds,
            r.threads,
            r.stats.bytes as f64 / 1e6,
            r.stats.trees,
            r.stats.nodes,
            r.stats.points
        ),
        status: status_of(&[Some(r.stats.seconds <= 60.0)]),
    })
}

/// The page's Table 1 section.
fn hierarchy_html(hier: &[HierRow]) -> String {
    if hier.is_empty() {
        return String::new();
    }
    let mut h = String::from(
        "<h2>Point hierarchies (the paper's Table 1)</h2><p>Each scene's hierarchies (one per mesh and material override; instances share them) built from scratch, the on-disk cache bypassed, with the paper's default build parameters: k³ grid, oversampling c, quantised points. The time and the MB include the instance-level points (never cached); MB counts the nodes with their boxes, the points and the index of the triangles kept in nodes, as the paper's &ldquo;point hierarchy&rdquo; column (the kept triangles' vertices belong to the triangle octree). The paper's &ldquo;triangle octree&rdquo; columns have no counterpart here: <code>--accel octree</code> runs on these same octrees, whose structure the samples decide. The paper's 2003 figures are from a 2 GHz Pentium 4. Same as <code>LODTRACE_CACHE=/tmp/empty lodtrace render SCENE --method multires --stats -</code> (<code>hierarchy</code>).</p><table><tr><th>scene</th><th>hierarchies</th><th>nodes</th><th>points</th><th>triangles kept in nodes</th><th>instance-level points</th><th>MB</th><th>build s (threads)</th><th>paper: s</th><th>paper: MB</th></tr>",
    );
    for r in hier {
        let (ps, pmb) = r.paper;
        let st = &r.stats;
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.2}</td><td>{:.2} ({})</td><td>{ps}</td><td>{pmb}</td></tr>",
            r.scene,
            st.trees,
            st.nodes,
            st.points,
            st.triangles_stored,
            st.group_points,
            st.bytes as f64 / 1e6,
            st.seconds,
            r.threads
        );
    }
    h.push_str("</table>");
    h
}

/// Image size, frames and detail of the demo's deforming sequences.
fn deform_setting(quick: bool) -> (u32, u32, u32, f32) {
    if quick {
        (192, 144, 8, 0.15)
    } else {
        (384, 288, 16, 0.4)
    }
}

/// The update modes the demo runs on each sequence. The last two: the paper's unordered
/// descent without and with the per-ray cache (climbing from the cached leaf to the smallest
/// node that holds a hit, a deviation: the leaf itself misses under this motion), where the
/// cache cuts the tests as in §4.2.2 (BENCHMARKS.md, "Caching (stop 34)" and "Stop 60").
fn deform_specs(quick: bool) -> Result<Vec<super::bench::MethodSpec>> {
    let (_, _, frames, detail) = deform_setting(quick);
    surfel_specs(
        &["naive", "lazy", "lazy-cache", "refit", "lazy:ordered=0", "lazy-cache:ordered=0:climb=1"],
        &format!(":frames={frames}:detail={detail}"),
    )
}

/// `surfel:update=MODE` bench specs, one per mode, each followed by `opts` (`:key=value…`).
fn surfel_specs(modes: &[&str], opts: &str) -> Result<Vec<super::bench::MethodSpec>> {
    modes.iter().map(|m| super::bench::MethodSpec::parse(&format!("surfel:update={m}{opts}"))).collect()
}

/// Adams et al.: every built-in sequence in the four update modes (same recorded motion;
/// [`super::deform_bench`]), the per-frame time curves (the paper's Fig. 5), radius ratios
/// (Fig. 3), test counts with and without the per-ray cache.
fn deform_section(a: &DemoArgs, skipped: &mut Vec<String>) -> Result<(String, Vec<super::deform_bench::DeformRow>)> {
    let (w, h, frames, detail) = deform_setting(a.quick);
    let specs = deform_specs(a.quick)?;
    let dir = a.out.join("deform");
    crate::film::io::create_out_dir(&dir)?;
    let mut rows = Vec::new();
    for seq in crate::deform::Sequence::BUILTIN {
        if !a.quiet {
            // As each triangle scene's section is announced.
            crate::status!("demo: {seq} (deforming sequence) at {w}x{h}, {frames} frames, detail {detail}: {} update modes", specs.len());
        }
        match super::deform_bench::run(&[seq.to_string()], &specs, w, h, a.threads, 1, Some(&dir), a.quiet) {
            Ok(r) => rows.extend(r),
            // A sequence whose mesh is missing is skipped; any other failure (a write, a
            // plot) is the demo's.
            Err(e) if is_missing_asset(&e) => {
                let hint = if e.to_string().contains("tools/setup") { String::new() } else { ": run tools/setup".into() };
                crate::status!("demo: skipping {seq} ({e}{hint})");
                skipped.push(format!("{seq} ({e})"));
            }
            Err(e) => return Err(e),
        }
    }
    if !rows.is_empty() {
        bench::write_report(&dir, &deform_report(w, h, a.threads, rows.clone()))?;
    }
    // Each sequence ran on its own (so that one failing is skipped): the Fig. 3 plot of all.
    super::deform_bench::radius_plot(&dir, &rows)?;
    let mut h_out = format!(
        "<h2>Adams et al.: deforming point-sampled surfaces</h2><p>Each sequence ({frames} frames, {w}×{h}, detail {detail}) rendered with the hierarchy rebuilt every frame (naive), updated lazily (§4.1), lazily with per-ray caching (§4.2.2; under front-to-back traversal the cache is looked up only while at least a quarter of its lookups hit, probed every 8 frames otherwise: <code>--cache-gate</code>, a deviation), and — not in the paper — an obvhs BVH2 refitted every frame; the same recorded motion, so the images must be identical (last column). The last two rows per sequence descend the tree unordered, as the paper does, without and with the cache (climbing from each ray's cached leaf until a node holds a hit, a deviation: the leaf itself moves away within a frame): there the cache cuts the leaf tests, as in the paper; front-to-back traversal (the other rows) cuts more by itself. Per-frame time curves like the paper's Fig. 5. Same as <code>lodtrace bench SEQ --methods surfel:update=naive,surfel:update=lazy,...</code>.</p><table><tr><th>sequence</th><th>update</th><th>surfels</th><th>ms/frame</th><th>vs naive</th><th>BV tests/frame</th><th>leaf tests/frame</th><th>cache hits (all frames)</th><th>MLS iterations</th><th>root radius ratio</th><th>mean radius ratio</th><th>same image</th></tr>"
    );
    for r in &rows {
        let f = |x: Option<f64>| x.map(|v| format!("{v:.2}")).unwrap_or_else(|| super::NA.into());
        let _ = write!(
            h_out,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.1}</td><td>{:.2}×</td><td>{:.0}</td><td>{:.0}</td><td>{}</td><td>{:.2}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            r.scene,
            update_label(&r.update, &r.spec),
            r.surfels,
            r.ms_per_frame,
            r.speedup_vs_first,
            r.sphere_tests_per_frame,
            r.leaf_tests_per_frame,
            if r.cache_lookups > 0 { format!("{}/{}", r.cache_hits, r.cache_lookups) } else { super::NA.into() },
            r.mls_iterations_mean,
            f(r.root_radius_ratio),
            f(r.mean_radius_ratio),
            if r.same_image_as_first { "yes" } else { "NO" },
        );
    }
    h_out.push_str("</table>");
    if dir.join("radius-ratio.png").is_file() {
        h_out.push_str("<p><img src=\"deform/radius-ratio.png\" style=\"max-width:640px\"> (the paper's Fig. 3)</p>");
    }
    for r in rows.iter().filter(|r| r.update == "lazy-cache" && !r.spec.contains("ordered=0")) {
        let seq = &r.scene;
        let _ = write!(
            h_out,
            "<figure><img src=\"deform/{}\"><figcaption>{seq}, last frame</figcaption></figure><figure><img src=\"deform/{seq}-frame-times.png\"><figcaption>{seq}: ms per frame</figcaption></figure><figure><img src=\"deform/{seq}-sphere-tests.png\"><figcaption>{seq}: bounding-volume tests per frame</figcaption></figure>",
            r.image.as_deref().unwrap_or(""),
        );
    }
    if rows.iter().any(|r| r.scene == "elastic-balls") {
        h_out.push_str(&cost_section(a, &dir, (w, h, frames, detail))?);
    }
    if !a.quick {
        let (ph, prows) = paper_setting_section(a, &dir)?;
        h_out.push_str(&ph);
        // After the short run's rows: the targets table judges the speed-up on these.
        rows.extend(prows);
    }
    h_out.push_str(&size_section(a, &dir, detail)?);
    Ok((h_out, rows))
}

/// Width, height and frames of Adams et al.'s setting (§5, 512×384; 90 frames), where the
/// `lazy-cache` ≥ 2× target is judged ([`paper_setting_section`], [`target_rows`]).
const PAPER_SETTING: (u32, u32, u32) = (512, 384, 90);

/// The paper's setting of §5 (Table 1 sizes, 512×384), where the `lazy-cache` ≥ 2× target
/// is judged: naive and lazy-cache over 90 frames at full detail, one repeat — the README's
/// `lodtrace bench SEQ --width 512 --height 384 --methods
/// surfel:update=naive:frames=90,surfel:update=lazy-cache:frames=90` without its repeats
/// (about 1.5 minutes for the four sequences). Full demo only.
fn paper_setting_section(a: &DemoArgs, dir: &Path) -> Result<(String, Vec<super::deform_bench::DeformRow>)> {
    const W: u32 = PAPER_SETTING.0;
    const H: u32 = PAPER_SETTING.1;
    let specs = surfel_specs(&["naive", "lazy-cache"], &format!(":frames={}", PAPER_SETTING.2))?;
    let pdir = dir.join("paper");
    crate::film::io::create_out_dir(&pdir)?;
    let mut rows = Vec::new();
    for seq in crate::deform::Sequence::BUILTIN {
        if !a.quiet {
            crate::status!("demo: {seq} in the paper's setting ({W}x{H}, 90 frames, full detail): naive and lazy-cache");
        }
        rows.extend(run_unless_missing(seq, &specs, (W, H), a.threads, Some(&pdir), a.quiet)?);
    }
    if rows.is_empty() {
        return Ok((String::new(), rows));
    }
    bench::write_report(&pdir, &deform_report(W, H, a.threads, rows.clone()))?;
    let mut h = format!(
        "<h3>In the paper's setting</h3><p>Naive and lazy-cache at {W}×{H} over 90 frames at full detail (the paper's Table 1 sizes), one run each; the targets table above judges the ≥ 2× speed-up on these rows. Same as <code>lodtrace bench SEQ --width {W} --height {H} --methods surfel:update=naive:frames=90,surfel:update=lazy-cache:frames=90</code> (the README's figures are its best of <code>--repeat 3</code>).</p><table><tr><th>sequence</th><th>update</th><th>surfels</th><th>ms/frame</th><th>vs naive</th><th>update ms/frame</th><th>BV tests/frame</th><th>same image</th></tr>"
    );
    for r in &rows {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.1}</td><td>{:.2}×</td><td>{:.1}</td><td>{:.0}</td><td>{}</td></tr>",
            r.scene,
            r.update,
            r.surfels,
            r.ms_per_frame,
            r.speedup_vs_first,
            r.update_ms_per_frame,
            r.sphere_tests_per_frame,
            if r.same_image_as_first { "yes" } else { "NO" },
        );
    }
    h.push_str("</table>");
    for r in rows.iter().filter(|r| r.update == "lazy-cache") {
        let _ = write!(
            h,
            "<figure><img src=\"deform/paper/{seq}-frame-times.png\"><figcaption>{seq}, {W}×{H}: ms per frame (the paper's Fig. 5)</figcaption></figure>",
            seq = r.scene
        );
    }
    Ok((h, rows))
}

/// One sequence's rows of `specs` at `size` (one repeat), none if its mesh is missing (the
/// demo's first Adams run names the skipped sequences once).
fn run_unless_missing(
    seq: &str,
    specs: &[super::bench::MethodSpec],
    (w, h): (u32, u32),
    threads: usize,
    out: Option<&Path>,
    quiet: bool,
) -> Result<Vec<super::deform_bench::DeformRow>> {
    match super::deform_bench::run(&[seq.to_string()], specs, w, h, threads, 1, out, quiet) {
        Err(e) if is_missing_asset(&e) => Ok(Vec::new()),
        r => r,
    }
}

/// Where the rays' work goes in `elastic-balls`' last frame, rebuilt tree against lazy tree:
/// `animate --cost` maps on one scale (loose upper spheres show as halos).
fn cost_section(a: &DemoArgs, dir: &Path, (w, h, frames, detail): (u32, u32, u32, f32)) -> Result<String> {
    let mut maps = Vec::new();
    for update in ["naive", "lazy"] {
        let args = crate::cli::animate::AnimateArgs {
            frames: Some(frames),
            update: update.into(),
            width: w,
            height: h,
            out: Some(dir.join(format!("cost-{update}"))),
            detail,
            threads: a.threads,
            cost: true,
            quiet: true,
            ..crate::cli::animate::AnimateArgs::new("elastic-balls")
        };
        maps.push((update, crate::cli::animate::animate(&args)?.last_cost));
    }
    let max = maps.iter().flat_map(|(_, v)| v.iter().copied()).max().unwrap_or(0);
    let mut out = String::from("<h3>Where the rays' work goes (elastic-balls, last frame)</h3><p>Bounding-volume and ray–surfel tests per pixel, primary and shadow rays, each 4×2 packet's mean (<code>lodtrace animate elastic-balls --update naive|lazy --out D --cost</code>), both maps on one log scale (magma: black none, pale yellow the most of either). Rays that enter a ball's bounding spheres and miss show as a halo around it; the lazy tree keeps the rest pose's topology and bounds its levels above the refitted subtrees by Eq. 9, so its halo can only be wider than the rebuilt tree's (the captions give the mean tests per pixel).</p>");
    for (update, v) in &maps {
        let name = format!("elastic-balls-cost-{update}.png");
        let img = crate::film::metrics::cost_map_to(v, w, h, max)?;
        crate::film::io::write_rgb8_png(&dir.join(&name), &img)?;
        let mean = v.iter().map(|&x| x as f64).sum::<f64>() / v.len().max(1) as f64;
        let _ = write!(
            out,
            "<figure><img src=\"deform/{name}\"><figcaption>{update}: {mean:.0} tests per pixel on average</figcaption></figure>"
        );
    }
    Ok(out)
}

/// The lazy update's speed-up over the rebuild against the image size: naive, lazy-cache and
/// auto (per frame the cheaper of the two) at four sizes (16 frames each), as `lodtrace bench SEQ --sizes ...`. The rebuild's cost
/// does not depend on the rays, the rays' cost does: the speed-up is largest where few rays
/// are traced.
fn size_section(a: &DemoArgs, dir: &Path, detail: f32) -> Result<String> {
    let sizes: &[(u32, u32)] = if a.quick { &[(48, 36), (96, 72), (192, 144)] } else { &[(96, 72), (192, 144), (384, 288), (768, 576)] };
    let specs = surfel_specs(&["naive", "lazy-cache", "auto"], &format!(":frames=16:detail={detail}"))?;
    let sdir = dir.join("sizes");
    crate::film::io::create_out_dir(&sdir)?;
    let mut rows = Vec::new();
    for seq in crate::deform::Sequence::BUILTIN {
        for &(w, h) in sizes {
            rows.extend(run_unless_missing(seq, &specs, (w, h), a.threads, None, true)?);
        }
    }
    if rows.is_empty() {
        return Ok(String::new());
    }
    super::deform_bench::size_plot(&sdir, &rows)?;
    bench::write_report(&sdir, &deform_report(sizes[0].0, sizes[0].1, a.threads, rows.clone()))?;
    let list: Vec<String> = sizes.iter().map(|(w, h)| format!("{w}x{h}")).collect();
    let mut h = format!(
        "<h3>Speed-up against the image size</h3><p>Naive, lazy-cache and auto (per frame a rebuild or the lazy update, whichever was cheaper when last tried: the heuristic the paper's §6 asks for), 16 frames at each size (same detail); speed-ups over naive (16 frames here, so a column at the size of the table above need not match its figure). The rebuild costs the same at every size, the rays do not: the lazy update gains most where few rays are traced; the paper's 2–3× was measured at 512×384 with its 2005 tracer. Same as <code>lodtrace bench SEQ --sizes {} --methods surfel:update=naive,surfel:update=lazy-cache,surfel:update=auto</code>.</p><table><tr><th>sequence</th><th>update</th>",
        list.join(","),
    );
    for (w, hh) in sizes {
        let _ = write!(h, "<th>{w}×{hh}</th>");
    }
    h.push_str("</tr>");
    for seq in crate::deform::Sequence::BUILTIN {
        for upd in ["lazy-cache", "auto"] {
            let _ = write!(h, "<tr><td>{seq}</td><td>{upd}</td>");
            for &(w, hh) in sizes {
                match rows.iter().find(|r| r.scene == *seq && r.update == upd && (r.width, r.height) == (w, hh)) {
                    Some(r) => {
                        let _ = write!(h, "<td>{:.2}× ({:.1} ms)</td>", r.speedup_vs_first, r.ms_per_frame);
                    }
                    None => h.push_str(&format!("<td>{}</td>", super::NA)),
                }
            }
            h.push_str("</tr>");
        }
    }
    h.push_str("</table><p><img src=\"deform/sizes/speedup-vs-size.png\" style=\"max-width:640px\"></p>");
    Ok(h)
}

/// One paper target beside this run's figure: the first table of the page.
#[derive(Debug, Clone, PartialEq)]
struct TargetRow {
    paper: &'static str,
    target: String,
    measured: String,
    /// "met", "not met", "partly" (met on some rows, not on others) or "–" (not measurable
    /// in this run).
    status: &'static str,
}

/// "met" when every verdict is true, "not met" when every one is false, "partly" for a mix,
/// "–" without a verdict. `None` verdicts (not measurable) are left out.
fn status_of(v: &[Option<bool>]) -> &'static str {
    let known: Vec<bool> = v.iter().flatten().copied().collect();
    match (known.iter().any(|&b| b), known.iter().any(|&b| !b)) {
        (true, false) => "met",
        (false, true) => "not met",
        (true, true) => "partly",
        (false, false) => "–",
    }
}

/// The papers' targets (README, "Targets at a glance") with this run's figures: Wand &
/// Straßer's frame time against the octree Whitted frame and its equal-time error on
/// `complex`, Papaioannou et al.'s chessboard savings and pixel difference, Adams et al.'s
/// speed-up, radius ratios, cache cut and MLS iterations. Only what the run measured: a
/// skipped scene or sequence adds no row.
fn target_rows(reports: &[&BenchReport], cone: &[&BenchReport], quick: bool, deform: &[super::deform_bench::DeformRow]) -> Vec<TargetRow> {
    const WS: &str = "Wand & Straßer";
    const PA: &str = "Papaioannou et al.";
    const AD: &str = "Adams et al.";
    let rows: Vec<&bench::BenchRow> = reports.iter().flat_map(|r| r.rows.iter()).collect();
    let mut out = Vec::new();
    // Frame time against the conventional tracer on the same octree.
    let (mut m, mut v) = (Vec::new(), Vec::new());
    let mut small = Vec::new();
    for (scene, paper) in [("spheres", (512, 512)), ("complex", (640, 480))] {
        let Some(oct) = rows.iter().find(|r| r.scene == scene && r.spec == "whitted:octree" && r.sweep.is_none()) else { continue };
        // The frame this scene was benched at: a quick demo's is smaller than the paper's,
        // and wider cones per pixel make multires dearer against Whitted there.
        let size = reports.iter().find(|rep| rep.rows.iter().any(|r| r.scene == scene)).map(|rep| (rep.width, rep.height));
        if let Some((w, h)) = size.filter(|&s| s != paper) {
            small.push(format!("{scene} at {w}×{h}, the paper's {}×{}", paper.0, paper.1));
        }
        for r in rows.iter().filter(|r| r.scene == scene && r.stats.method == "multires" && r.sweep.is_none()) {
            let q = r.stats.render_seconds / oct.stats.render_seconds.max(1e-12);
            m.push(format!(
                "{scene} {}: {q:.2}× ({:.3} s vs {:.3} s){}",
                r.spec,
                r.stats.render_seconds,
                oct.stats.render_seconds,
                if q <= 2.0 { ", within the aim" } else { "" }
            ));
            v.push(Some(q <= 4.0));
        }
    }
    if !m.is_empty() {
        out.push(TargetRow {
            paper: WS,
            target: "multires frame ≤ 4× the octree Whitted frame (paper parity; aim ≤ 2×)".into(),
            measured: if small.is_empty() {
                m.join("; ")
            } else {
                format!(
                    "{} (smaller frames than the paper's: {}; the target is judged at the paper's frames, the README's `lodtrace bench` commands)",
                    m.join("; "),
                    small.join(", ")
                )
            },
            status: status_of(&v),
        });
    }
    // Error at equal time against distributed ray tracing, on complex.
    let (mut m, mut v) = (Vec::new(), Vec::new());
    for r in rows.iter().filter(|r| r.scene == "complex" && r.stats.method == "multires" && r.sweep.is_none()) {
        let Some(f) = r.flip else { continue };
        for e in &r.equal_time {
            match e.sweep_flip_at_equal_time {
                Some(s) => {
                    let le = if e.sweep_beyond { "≤ " } else { "" };
                    m.push(format!("{}: {f:.4} vs {} {le}{s:.4}", r.spec, e.sweep));
                    // Beyond the sweep its figure is a bound: only a loss is certain.
                    v.push(if e.sweep_beyond && f < s { None } else { Some(f < s) });
                }
                None => m.push(format!("{}: {f:.4}, faster than {}'s 1 spp", r.spec, e.sweep)),
            }
        }
    }
    if !m.is_empty() {
        out.push(TargetRow {
            paper: WS,
            target:
                "lower mean FLIP than distributed ray tracing in the same time (complex, §6; the octree sweep is the paper's comparison)"
                    .into(),
            measured: m.join("; "),
            status: status_of(&v),
        });
    }
    if let Some(row) = classic_cone_row(cone, quick) {
        out.push(row);
    }
    // Per-ray LOD on the chessboard (Papaioannou et al. §4).
    let lod: Vec<(&bench::BenchRow, &bench::LodComparison)> =
        rows.iter().filter(|r| r.scene == "chessboard").filter_map(|r| r.lod_vs_full.as_ref().map(|c| (*r, c))).collect();
    if !lod.is_empty() {
        let pct = |x: f64| format!("{:.1} %", 100.0 * x);
        let tests: Vec<String> = lod
            .iter()
            .map(|(r, c)| format!("{}: {}", r.spec, c.triangle_test_reduction.map_or("– (Embree does not count them)".into(), pct)))
            .collect();
        out.push(TargetRow {
            paper: PA,
            target: "chessboard: ≥ 30 % fewer ray–triangle tests than full detail".into(),
            measured: tests.join("; "),
            status: status_of(&lod.iter().map(|(_, c)| c.triangle_test_reduction.map(|x| x >= 0.30)).collect::<Vec<_>>()),
        });
        let time: Vec<String> =
            lod.iter().map(|(r, c)| format!("{}: {} (CPU time {})", r.spec, pct(c.time_reduction), pct(c.cpu_time_reduction))).collect();
        out.push(TargetRow {
            paper: PA,
            target: "chessboard: ≥ 25 % less render time than full detail".into(),
            measured: time.join("; "),
            status: status_of(&lod.iter().map(|(_, c)| Some(c.time_reduction >= 0.25)).collect::<Vec<_>>()),
        });
        let diff: Vec<String> = lod
            .iter()
            .map(|(r, c)| {
                let floor = c
                    .floor
                    .as_ref()
                    .map_or(String::new(), |f| format!(" (two exact back-ends already differ by {})", pct(f.max_pixel_diff)));
                format!("{}: {}{floor}", r.spec, pct(c.max_pixel_diff))
            })
            .collect();
        out.push(TargetRow {
            paper: PA,
            target: "chessboard: largest pixel difference to full detail ≤ 11 %".into(),
            measured: diff.join("; "),
            status: status_of(&lod.iter().map(|(_, c)| Some(c.max_pixel_diff <= 0.11)).collect::<Vec<_>>()),
        });
    }
    // Adams et al.: the ordered lazy-cache row of each sequence against its naive row.
    let plain = |r: &&super::deform_bench::DeformRow| !r.spec.contains("ordered=0") && !r.spec.contains("cache_up=");
    let seqs: Vec<&str> = deform.iter().fold(Vec::new(), |mut v, r| {
        if !v.contains(&r.scene.as_str()) {
            v.push(&r.scene);
        }
        v
    });
    // Judged in the paper's setting where the run has it (the full demo), else on the short run.
    let paper_size = |r: &super::deform_bench::DeformRow| (r.width, r.height, r.frames) == PAPER_SETTING;
    let judged: Vec<&super::deform_bench::DeformRow> =
        if deform.iter().any(paper_size) { deform.iter().filter(|r| paper_size(r)).collect() } else { deform.iter().collect() };
    let (mut m, mut v) = (Vec::new(), Vec::new());
    for seq in &seqs {
        let naive = judged.iter().find(|r| r.scene == *seq && r.update == "naive");
        let lc = judged.iter().filter(|r| plain(r)).find(|r| r.scene == *seq && r.update == "lazy-cache");
        if let (Some(n), Some(l)) = (naive, lc) {
            let q = n.ms_per_frame / l.ms_per_frame.max(1e-12);
            m.push(format!("{seq} {q:.2}×"));
            v.push(Some(q >= 2.0));
        }
    }
    if let Some(r) = judged.first().filter(|_| !m.is_empty()) {
        out.push(TargetRow {
            paper: AD,
            target: "lazy-cache ≥ 2× faster per frame than the rebuild (naive); the paper measured 512×384".into(),
            measured: format!(
                "{} ({}×{}, {} frames{})",
                m.join(", "),
                r.width,
                r.height,
                r.frames,
                // The demo's short run: fewer surfels and frames make the rebuild cheaper against
                // the rays than in the paper's setting, which the README's bench command runs.
                if paper_size(r) {
                    ""
                } else {
                    "; a short run: the target is judged at 512×384 over 90 frames, the README's `lodtrace bench` command"
                }
            ),
            status: status_of(&v),
        });
    }
    let lazy: Vec<&super::deform_bench::DeformRow> = deform.iter().filter(|r| r.root_radius_ratio.is_some()).collect();
    if !lazy.is_empty() {
        let range = |f: &dyn Fn(&super::deform_bench::DeformRow) -> Option<f64>| {
            let v: Vec<f64> = lazy.iter().filter_map(|r| f(r)).collect();
            (v.iter().copied().fold(f64::INFINITY, f64::min), v.iter().copied().fold(f64::NEG_INFINITY, f64::max))
        };
        let (ml, mh) = range(&|r| r.mean_radius_ratio);
        let (rl, rh) = range(&|r| r.root_radius_ratio);
        out.push(TargetRow {
            paper: AD,
            target: "updated / tightest sphere radius: mean ≤ 2, root ≤ 2.5 (lazy update)".into(),
            measured: format!("mean {ml:.2}–{mh:.2}, root {rl:.2}–{rh:.2}"),
            status: status_of(&[Some(mh <= 2.0 && rh <= 2.5)]),
        });
    }
    let (mut m, mut cuts) = (Vec::new(), Vec::new());
    for seq in &seqs {
        let un = |cache: bool| {
            deform.iter().find(|r| r.scene == *seq && r.spec.contains("ordered=0") && r.update == if cache { "lazy-cache" } else { "lazy" })
        };
        if let (Some(a), Some(b)) = (un(false), un(true)) {
            let cut = 1.0 - b.leaf_tests_per_frame / a.leaf_tests_per_frame.max(1e-12);
            m.push(format!("{seq} {:.0} %", 100.0 * cut));
            cuts.push(cut);
        }
    }
    if !m.is_empty() {
        // The paper's 27 % is an average over its sequences, and so is this target.
        let mean = cuts.iter().sum::<f64>() / cuts.len() as f64;
        out.push(TargetRow {
            paper: AD,
            target: "per-ray caching cuts the ray–surfel tests by ≥ 20 % on average over the sequences (paper 27 % on average; unordered descent, the cache climbing from the cached leaf)".into(),
            measured: format!("mean {:.0} % ({})", 100.0 * mean, m.join(", ")),
            status: status_of(&[Some(mean >= 0.20)]),
        });
    }
    if !deform.is_empty() {
        let worst = deform.iter().map(|r| r.mls_iterations_mean).fold(0.0, f64::max);
        out.push(TargetRow {
            paper: AD,
            target: "MLS projection ≤ 4 iterations on average".into(),
            measured: format!("at most {worst:.2} (mean per row)"),
            status: status_of(&[Some(worst <= 4.0)]),
        });
    }
    out
}

/// Classic cone tracing against multires (§6), from the classic cone jobs: primary cones
/// (the paper: 2.8× slower), judged with the exact triangle mass, and the whole frame, which
/// the classic tracer should not finish within its budget where multires does.
fn classic_cone_row(cone: &[&BenchReport], quick: bool) -> Option<TargetRow> {
    let (mut m, mut v) = (Vec::new(), Vec::new());
    let (full, budget) = cone_full_specs(quick);
    for rep in cone {
        let find = |spec: &str| rep.rows.iter().find(|r| r.spec == spec);
        let mut pairs = Vec::new();
        for (weight, ms, cs) in CONE_PAIRS {
            if let (Some(a), Some(b)) = (find(ms), find(cs)) {
                let q = b.stats.render_seconds / a.stats.render_seconds.max(1e-12);
                pairs.push(format!("{weight} {q:.2}×"));
                if weight == CONE_PAIRS[0].0 {
                    v.push(Some(q > 1.0));
                }
            }
        }
        if !pairs.is_empty() {
            m.push(format!("primary cones at {}×{}: {}", rep.width, rep.height, pairs.join(", ")));
        }
        if let (Some(a), Some(b)) = (find(&full), find(&budget)) {
            let pixels = (rep.width as usize * rep.height as usize).max(1);
            let traced = b.stats.cone_profile.as_ref().map_or(pixels, |p| p.pixel_tests.pixels);
            if b.stats.finished {
                m.push(format!(
                    "whole frame at {}×{} (exact mass): cone finished in {:.1} s, multires {:.1} s",
                    rep.width, rep.height, b.stats.render_seconds, a.stats.render_seconds
                ));
            } else {
                m.push(format!(
                    "whole frame at {}×{} (exact mass): cone stopped at its {:.0} s budget with {:.0} % of the pixels traced, multires finished in {:.1} s",
                    rep.width,
                    rep.height,
                    b.stats.render_seconds,
                    100.0 * traced as f64 / pixels as f64,
                    a.stats.render_seconds
                ));
            }
            v.push(Some(!b.stats.finished && a.stats.finished));
        }
    }
    (!m.is_empty()).then(|| TargetRow {
        paper: "Wand & Straßer",
        target: "classic cone tracing (points disabled) slower than multires: 2.8× with primary cones only; with secondary cones it does not finish (§6; judged with the exact triangle mass)".into(),
        measured: m.join("; "),
        status: status_of(&v),
    })
}

/// The classic tracer's time over multires' for primary cones against the frame size, one
/// curve per triangle weight ([`CONE_PAIRS`]), with the paper's 2.8× as a line: written to
/// `dir/`[`CONE_PLOT`] when some frame has a pair; returns whether it was.
fn cone_size_plot(dir: &Path, cone: &[&BenchReport]) -> Result<bool> {
    let series = cone_size_series(cone);
    if series.iter().all(|s| s.1.is_empty()) || !dir.is_dir() {
        return Ok(false);
    }
    super::plot::line_chart_fmt(
        &dir.join(CONE_PLOT),
        "Classic cone tracing against multires, primary cones (complex)",
        "pixels per frame",
        "classic cone time / multires time (x)",
        &series,
        true,
        &|n| if n >= 1e6 { format!("{} M", super::plot::fmt_axis(n / 1e6)) } else { format!("{} k", super::plot::fmt_axis(n / 1e3)) },
        Some((2.8, "paper: 2.8x (primary cones, frame size not given)")),
    )?;
    Ok(true)
}

/// [`cone_size_plot`]'s curves: per weight, (pixels per frame, cone ÷ multires), by size.
fn cone_size_series(cone: &[&BenchReport]) -> Vec<(String, Vec<(f64, f64)>)> {
    CONE_PAIRS
        .iter()
        .map(|(weight, ms, cs)| {
            let mut pts: Vec<(f64, f64)> = cone
                .iter()
                .filter_map(|rep| {
                    let find = |spec: &str| rep.rows.iter().find(|r| r.spec == spec);
                    let (a, b) = (find(ms)?, find(cs)?);
                    Some((rep.width as f64 * rep.height as f64, b.stats.render_seconds / a.stats.render_seconds.max(1e-12)))
                })
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            (weight.to_string(), pts)
        })
        .collect()
}

fn cone_plot_html() -> String {
    format!(
        "<p><img src=\"{CONE_DIR}/{CONE_PLOT}\" style=\"max-width:640px\"></p><p>The classic tracer's time over multires' for primary cones, by frame size: above 1 the points pay. They pay more as the frame shrinks and each footprint covers more triangles.</p>"
    )
}

/// The targets as the page's first table.
fn targets_html(rows: &[TargetRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut h = String::from(
        "<h2>The papers' targets in this run</h2><p>Each target beside what this run measured (one run on this machine; the sections below have the details, the README the history). A quick demo renders smaller images than the papers, and timings on a busy machine move by ±20 %.</p><table><tr><th>paper</th><th>target</th><th>this run</th><th>status</th></tr>",
    );
    for r in rows {
        let _ = write!(
            h,
            "<tr><td style=\"text-align:left\">{}</td><td style=\"text-align:left\">{}</td><td style=\"text-align:left\">{}</td><td>{}</td></tr>",
            r.paper,
            esc(&r.target),
            esc(&r.measured),
            r.status
        );
    }
    h.push_str("</table>");
    h
}

/// The targets as Markdown (`targets.md`, for the README).
fn targets_markdown(rows: &[TargetRow]) -> String {
    let mut s = String::from("| paper | target | this run | status |\n|---|---|---|---|\n");
    for r in rows {
        s.push_str(&format!("| {} | {} | {} | {} |\n", r.paper, r.target, r.measured, r.status));
    }
    s
}

/// An error that means "this scene's or sequence's mesh is not installed" (`tools/setup`):
/// a built-in scene's message, or a mesh file under the assets folder that is not there.
fn is_missing_asset(e: &Error) -> bool {
    match e {
        Error::Scene(m) => m.contains("run tools/setup"),
        Error::Io { path, source } => {
            source.kind() == std::io::ErrorKind::NotFound && path.starts_with(crate::scene::builtin::assets_dir())
        }
        _ => false,
    }
}

/// A report holding deforming-sequence rows only, for `bench.json` and `bench.md`.
fn deform_report(width: u32, height: u32, threads: usize, deform: Vec<super::deform_bench::DeformRow>) -> BenchReport {
    BenchReport {
        width,
        height,
        sizes: Vec::new(),
        simd: crate::core::SIMD_LEVEL,
        repeat: 1,
        threads,
        reference: None,
        rows: Vec::new(),
        deform,
    }
}

/// How this page was made: quick or full, SIMD level, threads (timings depend on all three).
fn run_line(a: &DemoArgs) -> String {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = if a.threads == 0 { format!("{cores} threads (all cores)") } else { format!("{} threads of {cores} cores", a.threads) };
    format!(
        "<p>This run: <code>lodtrace demo{}</code>, lodtrace {}, SIMD {}, {threads} unless a spec says <code>threads=</code>. Each folder has the tables as <code>bench.md</code> and every figure in <code>bench.json</code>; the targets table below is also <code>targets.md</code>.</p>",
        if a.quick { " --quick" } else { "" },
        env!("CARGO_PKG_VERSION"),
        crate::core::SIMD_LEVEL
    )
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// The page: its head, `top` (the targets table), then a section per bench job.
/// `extra`: more of the page after the section of a job's folder (a plot across jobs).
fn index_html(sections: &[(Job, BenchReport)], top: &str, extra: &[(&str, String)]) -> String {
    let mut h = String::new();
    h.push_str("<!doctype html><html><head><meta charset=\"utf-8\"><title>lodtrace demo</title><style>body{font-family:sans-serif;margin:2em;max-width:1400px}table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}td:nth-child(2),th:nth-child(2){text-align:left}figure{display:inline-block;margin:4px}figcaption{font-size:80%;max-width:320px}img{max-width:320px;image-rendering:pixelated}</style></head><body>");
    h.push_str("<h1>lodtrace demo</h1><p>Every method on the built-in paper scenes, rendered one after the other in one process on this machine. Speed-up is the first method's render time divided by each method's. Errors are against the high-sample distributed reference (RMSE and PSNR on the linear, unclamped radiance; mean FLIP on the sRGB display images).</p>");
    h.push_str(top);
    for (job, r) in sections {
        let _ = write!(h, "<h2>{} ({}×{})</h2>", esc(job.dir), job.width, job.height);
        if !job.intro.is_empty() {
            let _ = write!(h, "<p>{}</p>", job.intro);
        }
        h.push_str("<table><tr><th>method</th><th>spec</th><th>threads</th><th>build s</th><th>render s</th><th>Mrays/s</th><th>speed-up</th><th>RMSE</th><th>PSNR dB</th><th>mean FLIP</th></tr>");
        for row in &r.rows {
            let f = |x: Option<f64>, p: usize| x.map(|v| format!("{v:.p$}")).unwrap_or_else(|| super::NA.into());
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.3}</td><td>{:.3}</td><td>{:.2}</td><td>{:.2}×</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                esc(&row.stats.method),
                esc(&row.spec),
                row.stats.threads,
                row.stats.build_seconds,
                row.stats.render_seconds,
                row.stats.mrays_per_second,
                row.speedup_vs_first,
                f(row.rmse, 4),
                f(row.psnr, 2),
                f(row.flip, 4)
            );
        }
        h.push_str("</table>");
        let dir = Path::new(job.dir);
        if let Some(reference) = &job.reference {
            let _ = write!(
                h,
                "<figure><img src=\"{}\"><figcaption>reference: {}</figcaption></figure>",
                dir.join(format!(
                    "{}-reference-{}.png",
                    job.scene,
                    bench::MethodSpec::parse(reference).map(|s| s.slug()).unwrap_or_default()
                ))
                .display(),
                esc(reference)
            );
        }
        // The sweep's images are in the folder; the page shows the curve instead.
        for row in r.rows.iter().filter(|row| row.sweep.is_none()) {
            if let Some(img) = &row.image {
                let _ = write!(
                    h,
                    "<figure><img src=\"{}\"><figcaption>{} — {:.3} s{}</figcaption></figure>",
                    dir.join(img).display(),
                    esc(&row.spec),
                    row.stats.render_seconds,
                    // No reference (the LOD scenes), no FLIP: the caption said "FLIP -".
                    row.flip.map(|v| format!(", FLIP {v:.4}")).unwrap_or_default()
                );
                // Its FLIP map against the reference, written beside it by the bench.
                if let (Some(_), Ok(spec)) = (row.flip, bench::MethodSpec::parse(&row.spec)) {
                    let _ = write!(
                        h,
                        "<figure><img src=\"{}\"><figcaption>{} — FLIP error map against the reference (magma: black 0, pale yellow 1)</figcaption></figure>",
                        dir.join(format!("{}-{}-flip.png", job.scene, spec.slug())).display(),
                        esc(&row.spec)
                    );
                }
            }
        }
        if let Some(first) = r.rows.iter().find(|row| !row.regions.is_empty()) {
            h.push_str("<h3>Where the error sits</h3><p>Mean FLIP against the reference inside each pixel rectangle (x0,y0,x1,y1), from the whole image's FLIP map; in brackets the region's share of the image's FLIP error. Below it the kind of error: the luminance against the reference's, and the part of the squared error at scales of 8 pixels or more (near 100 %: bias that more samples would not remove; near 0 %: aliasing or noise).</p><table><tr><th>method</th><th>spec</th><th>render s</th><th>whole</th>");
            for g in &first.regions {
                let _ = write!(h, "<th>{}</th>", esc(&super::bench::region_heading(&g.name, g.rect)));
            }
            h.push_str("</tr>");
            for row in r.rows.iter().filter(|row| !row.regions.is_empty()) {
                let _ = write!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{:.3}</td><td>{:.4}</td>",
                    esc(&row.stats.method),
                    esc(&row.spec),
                    row.stats.render_seconds,
                    row.flip.unwrap_or(0.0)
                );
                for g in &row.regions {
                    let _ = write!(
                        h,
                        "<td>{:.4} ({:.0} %)<br><small>{} / {} smooth</small></td>",
                        g.figures.flip_mean,
                        100.0 * g.figures.flip_share,
                        crate::cli::compare::luma_bias_text(g.figures.luma_bias, " "),
                        crate::cli::compare::smooth_share_text(g.figures.smooth_share, 0, " ")
                    );
                }
                h.push_str("</tr>");
            }
            h.push_str("</table>");
        }
        for name in &job.sweep {
            let name = bench::MethodSpec::parse(name).map(|s| s.text).unwrap_or_else(|_| name.clone());
            let eq: Vec<_> = r.rows.iter().filter_map(|row| row.equal_time.iter().find(|e| e.sweep == name).map(|e| (row, e))).collect();
            if eq.is_empty() {
                continue;
            }
            let _ = write!(
                h,
                "<h3>Equal time and equal error against {}</h3><p>The sweep renders it at 1, 2, 4, … samples per pixel (the adaptive distributed tracer takes fewer: the samples column gives those taken); its error at each method's time and the time it needs to reach each method's error are interpolated in log time (time ratio &gt; 1: the method reaches that error faster).{}</p><table><tr><th>method</th><th>render s</th><th>mean FLIP</th><th>sweep FLIP at equal time</th><th>sweep samples taken per pixel at equal time</th><th>sweep time to match</th><th>time ratio at equal error</th></tr>",
                esc(&name),
                if name.contains(":octree") { " This is the paper's comparison (§6): the distributed tracer on the same code basis as the multi-resolution tracer." } else { "" }
            );
            for (row, e) in &eq {
                let o = |x: Option<f64>, p: usize| x.map(|v| format!("{v:.p$}")).unwrap_or_else(|| super::NA.into());
                let _ = write!(
                    h,
                    "<tr><td>{}</td><td>{:.3}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                    esc(&row.spec),
                    row.stats.render_seconds,
                    o(row.flip, 4),
                    match e.sweep_flip_at_equal_time {
                        None => "faster than its 1 spp".into(),
                        Some(_) if e.sweep_beyond => format!("&le; {}", o(e.sweep_flip_at_equal_time, 4)),
                        Some(_) => o(e.sweep_flip_at_equal_time, 4),
                    },
                    match e.sweep_spp_at_equal_time {
                        None => "&lt; 1".into(),
                        Some(_) if e.sweep_beyond => format!("{} (its slowest)", o(e.sweep_spp_at_equal_time, 1)),
                        Some(_) => o(e.sweep_spp_at_equal_time, 1),
                    },
                    match e.sweep_seconds_to_match {
                        Some(v) if e.sweep_match_at_most => format!("&le; {v:.3} s (1 spp is better)"),
                        Some(v) => format!("{v:.3} s"),
                        None => format!("&gt; {:.3} s", e.sweep_max_seconds),
                    },
                    if e.sweep_match_at_most {
                        format!("&le; {}", o(e.time_ratio_at_equal_error, 2))
                    } else {
                        o(e.time_ratio_at_equal_error, 2)
                    }
                );
            }
            h.push_str("</table>");
        }
        if r.rows.iter().any(|row| row.sweep.is_some()) {
            let _ =
                write!(h, "<p><img src=\"{}\" style=\"max-width:800px\"></p>", dir.join(format!("{}-equal-time.png", job.scene)).display());
        }
        let lod: Vec<_> = r.rows.iter().filter_map(|row| row.lod_vs_full.as_ref().map(|c| (row, c))).collect();
        if !lod.is_empty() {
            h.push_str("<h3>Per-ray LOD against full detail</h3><p>Difference images are magnified like the paper's Fig. 4e (white = equal, black = the largest difference); the distortion maps show 20·d (refraction d<sub>t</sub>, reflection d<sub>r</sub>) as in Fig. 4c/d. The floor is the full-detail render repeated on the other exact back-end (Embree ↔ CWBVH) with the same samples: what two correct intersectors already differ by in these chaotic glass scenes.</p><table><tr><th>method</th><th>against</th><th>triangle tests saved</th><th>time saved</th><th>CPU time saved</th><th>max pixel diff</th><th>99th pct</th><th>mean diff</th><th>max diff, full-LOD pixels</th><th>floor max / 99th / mean</th><th>LOD pixels above floor max</th></tr>");
            for (row, c) in &lod {
                let _ = write!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.1} %</td><td>{:.1} %</td><td>{:.1} %</td><td>{:.1} %</td><td>{:.2} %</td><td>{:.1} %</td><td>{}</td><td>{}</td></tr>",
                    esc(&row.spec),
                    esc(&c.against),
                    super::bench::pct_or_dash(c.triangle_test_reduction),
                    100.0 * c.time_reduction,
                    100.0 * c.cpu_time_reduction,
                    100.0 * c.max_pixel_diff,
                    100.0 * c.p99_pixel_diff,
                    100.0 * c.mean_pixel_diff,
                    100.0 * c.max_diff_full_lod_pixels,
                    c.floor.as_ref().map_or(super::NA.into(), bench::DiffFloor::summary),
                    c.floor.as_ref().map_or(super::NA.into(), |f| f.lod_pixels_above_floor_max.to_string()),
                );
            }
            h.push_str("</table>");
            for (row, c) in &lod {
                let slug = bench::MethodSpec::parse(&row.spec).map(|s| s.slug()).unwrap_or_default();
                // Each difference image is scaled to its own largest difference: say which.
                let diff = format!("difference to {} (magnified: black = {:.1} %)", esc(&c.against), 100.0 * c.max_pixel_diff);
                for (k, what) in [
                    ("diff", diff.as_str()),
                    ("disparity-t", "refraction disparity (black where no ray refracts)"),
                    ("disparity-r", "reflection disparity (black where no ray reflects)"),
                ] {
                    let _ = write!(
                        h,
                        "<figure><img src=\"{}\"><figcaption>{} — {}</figcaption></figure>",
                        dir.join(format!("{}-{}-{}.png", job.scene, slug, k)).display(),
                        esc(&row.spec),
                        what
                    );
                }
            }
        }
        let prof: Vec<_> = r.rows.iter().filter_map(|row| row.stats.cone_profile.as_ref().map(|p| (row, p))).collect();
        if !prof.is_empty() {
            h.push_str("<h3>Where the cone tracer's work goes</h3><p>Per cone kind: traversal thread-seconds (wall-clock time on each thread, summed over the threads; shading excluded), tests per cone (instance, node, triangle-bound, triangle and surfel tests) and the kind's share of the frame's tests. The heat maps show the tests per pixel, every cone a pixel spawned included (log scale, magma: black none, pale yellow the most in that map; each map has its own scale).</p><table><tr><th>method</th><th>primary</th><th>shadow of primary</th><th>reflected / refracted</th><th>shadow of secondary</th><th>tests per pixel: median / p95 / max</th><th>top 5 % pixels' share</th></tr>");
            for (row, p) in &prof {
                let _ = write!(h, "<tr><td>{}</td>", esc(&row.spec));
                for cell in p.cells() {
                    let _ = write!(h, "<td>{}</td>", esc(&cell));
                }
                h.push_str("</tr>");
            }
            h.push_str("</table>");
            for (row, p) in &prof {
                let slug = bench::MethodSpec::parse(&row.spec).map(|s| s.slug()).unwrap_or_default();
                // Each map is scaled to its own largest count: the colours of two maps differ.
                let _ = write!(
                    h,
                    "<figure><img src=\"{}\"><figcaption>{} — tests per pixel (pale yellow = {}, this map's most)</figcaption></figure>",
                    dir.join(format!("{}-{}-cost.png", job.scene, slug)).display(),
                    esc(&row.spec),
                    p.pixel_tests.max
                );
            }
        }
        let _ = write!(h, "<p><img src=\"{}\" style=\"max-width:640px\"></p>", dir.join("bench-time.png").display());
        for (_, x) in extra.iter().filter(|(d, _)| *d == job.dir) {
            h.push_str(x);
        }
    }
    h.push_str("</body></html>\n");
    h
}

#[cfg(test)]
mod tests {
    /// Every bench run of the demo, quick and full, passes bench's checks (stop 58 refused
    /// `--sweep-max-spp` without a `--sweep`, which the demo passed to every job: `demo`
    /// stopped at its chessboard job until stop 59). Scenes whose meshes are missing are
    /// skipped, as the demo skips them.
    #[test]
    fn every_demo_job_passes_the_bench_checks() {
        for quick in [true, false] {
            let a = DemoArgs { out: std::env::temp_dir().join("lodtrace-demo-plan"), quick, threads: 0, quiet: false };
            for job in jobs(quick) {
                if crate::scene::builtin::get(job.scene).is_err() {
                    continue;
                }
                if let Err(e) = bench::plan(&bench_args(&a, &job)) {
                    panic!("demo{} job '{}': {e}", if quick { " --quick" } else { "" }, job.scene);
                }
            }
            for spec in deform_specs(quick).unwrap() {
                super::super::deform_bench::validate(&spec).unwrap();
            }
        }
    }

    use super::super::deform_bench::DeformRow;
    use super::bench::fixtures::{report, row, stats};
    use super::*;

    fn deform_row(scene: &str, spec: &str, update: &str, ms: f64, leaf: f64, ratios: Option<(f64, f64)>) -> DeformRow {
        DeformRow {
            scene: scene.into(),
            spec: spec.into(),
            width: 192,
            height: 144,
            update: update.into(),
            surfels: 1,
            frames: 8,
            threads: 2,
            build_seconds: 0.0,
            render_seconds: 8e-3 * ms,
            ms_per_frame: ms,
            speedup_vs_first: 1.0,
            per_round_speedups: Vec::new(),
            update_ms_per_frame: 0.0,
            rays_ms_per_frame: None,
            sphere_tests_per_frame: 0.0,
            leaf_tests_per_frame: leaf,
            mls_runs_per_frame: 0.0,
            mls_iterations_mean: 2.5,
            cache_lookups: 0,
            cache_hits: 0,
            inner_nodes_updated_per_frame: 0.0,
            root_radius_ratio: ratios.map(|r| r.0),
            mean_radius_ratio: ratios.map(|r| r.1),
            same_image_as_first: true,
            speedup_vs_naive: None,
            per_round_vs_naive: Vec::new(),
            same_image_as_naive: None,
            per_frame_ms: Vec::new(),
            per_frame_sphere_tests: Vec::new(),
            radius_ratios: Vec::new(),
            image: None,
        }
    }

    /// Only a missing mesh skips a sequence; a failed write stops the demo (it was skipped
    /// too, and the page lost the sequence without an error).
    #[test]
    fn only_missing_meshes_are_skipped() {
        let nf = || std::io::Error::from(std::io::ErrorKind::NotFound);
        assert!(is_missing_asset(&Error::io(crate::scene::builtin::assets_dir().join("armadillo.off"), nf())));
        assert!(is_missing_asset(&Error::Scene("scene 'complex' needs the mesh x (not found): run tools/setup".into())));
        // A sequence's missing mesh too (`animate`'s error; the demo stopped on it, stop 79).
        assert!(is_missing_asset(&crate::cli::animate::missing_sequence_mesh("armadillo-ball", std::path::Path::new("/x/armadillo.off"))));
        assert!(!is_missing_asset(&Error::io("/tmp/out/deform/x.png", nf())));
        let full = std::io::Error::new(std::io::ErrorKind::StorageFull, "disk full");
        assert!(!is_missing_asset(&Error::io(crate::scene::builtin::assets_dir().join("armadillo.off"), full)));
        assert!(!is_missing_asset(&Error::Image("plot: no font".into())));
    }

    #[test]
    fn status_summarises_the_verdicts() {
        assert_eq!(status_of(&[Some(true), Some(true)]), "met");
        assert_eq!(status_of(&[Some(false), None]), "not met");
        assert_eq!(status_of(&[Some(true), Some(false)]), "partly");
        assert_eq!(status_of(&[None]), crate::experiment::NA);
    }

    /// Each paper's target stands beside this run's figure, with a verdict from the figure
    /// (the page gave the figures only, and the speed-up against the first method, Embree,
    /// where the paper's target is against the octree Whitted frame).
    #[test]
    fn targets_stand_beside_the_measured_figures() {
        let sp = report(vec![
            row("spheres", "whitted:embree", stats("whitted", "embree", 0.1, &[])),
            row("spheres", "whitted:octree", stats("whitted", "octree", 1.0, &[])),
            row("spheres", "multires", stats("multires", "octree", 3.5, &[])),
            row("spheres", "multires:clamp2=1:lod=4", stats("multires", "octree", 1.5, &[])),
        ]);
        let mut lod_e = row("chessboard", "lod:embree:spp=4", stats("lod", "embree", 1.0, &[]));
        let mut lod_b = row("chessboard", "lod:bvh:spp=4", stats("lod", "bvh", 1.0, &[]));
        let cmp = |tests: Option<f64>, time: f64, max: f64| bench::LodComparison {
            against: "whitted".into(),
            triangle_test_reduction: tests,
            time_reduction: time,
            cpu_time_reduction: time,
            max_pixel_diff: max,
            max_at: [0, 0],
            p99_pixel_diff: 0.0,
            mean_pixel_diff: 0.0,
            max_diff_full_lod_pixels: 0.0,
            floor: None,
        };
        lod_e.lod_vs_full = Some(cmp(None, 0.3, 0.05));
        lod_b.lod_vs_full = Some(cmp(Some(0.215), 0.1, 0.329));
        let cb = report(vec![lod_e, lod_b]);
        let d = vec![
            deform_row("bend", "surfel:update=naive", "naive", 100.0, 50.0, None),
            deform_row("bend", "surfel:update=lazy-cache", "lazy-cache", 40.0, 50.0, Some((1.2, 1.03))),
            deform_row("bend", "surfel:update=lazy:ordered=0", "lazy", 60.0, 100.0, Some((1.2, 1.03))),
            deform_row("bend", "surfel:update=lazy-cache:ordered=0:climb=1", "lazy-cache", 60.0, 70.0, Some((1.3, 1.05))),
            deform_row("heads", "surfel:update=lazy:ordered=0", "lazy", 60.0, 100.0, Some((1.2, 1.03))),
            deform_row("heads", "surfel:update=lazy-cache:ordered=0:climb=1", "lazy-cache", 60.0, 85.0, Some((1.2, 1.03))),
        ];
        let t = target_rows(&[&sp, &cb], &[], false, &d);
        let find = |p: &str| t.iter().find(|r| r.target.starts_with(p)).unwrap_or_else(|| panic!("no '{p}' in {t:?}"));
        let ws = find("multires frame ≤ 4×");
        assert_eq!(ws.status, "met");
        assert!(ws.measured.contains("spheres multires: 3.50× (3.500 s vs 1.000 s)"), "{}", ws.measured);
        assert!(ws.measured.contains("1.50× (1.500 s vs 1.000 s), within the aim"), "{}", ws.measured);
        // A frame smaller than the paper's is named (a quick demo's); the paper's is not.
        assert!(ws.measured.ends_with("(smaller frames than the paper's: spheres at 4×4, the paper's 512×512; the target is judged at the paper's frames, the README's `lodtrace bench` commands)"), "{}", ws.measured);
        let sp512 = BenchReport { width: 512, height: 512, ..sp.clone() };
        let ws512 = target_rows(&[&sp512], &[], false, &[]).into_iter().find(|r| r.target.starts_with("multires frame ≤ 4×")).unwrap();
        assert!(
            ws512.measured.ends_with("(3.500 s vs 1.000 s); spheres multires:clamp2=1:lod=4: 1.50× (1.500 s vs 1.000 s), within the aim"),
            "{}",
            ws512.measured
        );
        let tests = find("chessboard: ≥ 30 %");
        assert_eq!(tests.status, "not met", "Embree's uncounted tests give no verdict");
        assert!(tests.measured.contains("lod:embree:spp=4: – (Embree"), "{}", tests.measured);
        assert!(tests.measured.contains("lod:bvh:spp=4: 21.5 %"), "{}", tests.measured);
        assert_eq!(find("chessboard: ≥ 25 %").status, "partly");
        assert_eq!(find("chessboard: largest").status, "partly");
        let lc = find("lazy-cache ≥ 2×");
        assert_eq!(lc.status, "met");
        assert!(lc.measured.starts_with("bend 2.50× (192×144, 8 frames; a short run"), "{}", lc.measured);
        // In the paper's setting (the README's bench) the figure stands alone.
        let paper: Vec<_> =
            d.iter().cloned().map(|r| super::super::deform_bench::DeformRow { width: 512, height: 384, frames: 90, ..r }).collect();
        let lc = target_rows(&[], &[], false, &paper).into_iter().find(|r| r.target.starts_with("lazy-cache ≥ 2×")).unwrap();
        assert_eq!(lc.measured, "bend 2.50× (512×384, 90 frames)");
        // The full demo's rows: the short run's and, after them, the paper's setting, where the
        // target is judged (here 1.90× there against 2.50× in the short run: not met).
        let mut both = d.clone();
        both.extend(paper.iter().cloned().map(|r| super::super::deform_bench::DeformRow {
            ms_per_frame: if r.update == "naive" { 95.0 } else { r.ms_per_frame * 1.25 },
            ..r
        }));
        let lc = target_rows(&[], &[], false, &both).into_iter().find(|r| r.target.starts_with("lazy-cache ≥ 2×")).unwrap();
        assert_eq!((lc.measured.as_str(), lc.status), ("bend 1.90× (512×384, 90 frames)", "not met"));
        assert_eq!(find("updated / tightest").measured, "mean 1.03–1.05, root 1.20–1.30");
        let cache = find("per-ray caching");
        // Judged on the mean, as the paper's 27 % (one sequence below 20 % does not fail it).
        assert_eq!((cache.measured.as_str(), cache.status), ("mean 23 % (bend 30 %, heads 15 %)", "met"));
        let low = [d[2].clone(), deform_row("bend", "surfel:update=lazy-cache:ordered=0:climb=1", "lazy-cache", 60.0, 85.0, None)];
        let rows = target_rows(&[], &[], false, &low);
        assert_eq!(rows.iter().find(|r| r.target.starts_with("per-ray caching")).map(|r| r.status), Some("not met"));
        assert_eq!(find("MLS").status, "met");
        // Nothing measured, nothing claimed.
        assert!(target_rows(&[], &[], false, &[]).is_empty());
        let md = targets_markdown(&t);
        assert!(md.lines().count() == t.len() + 2 && md.contains("| Wand & Straßer | multires frame"), "{md}");
    }

    /// The classic cone jobs give their own target row (primary cones judged with the exact
    /// mass, the whole frame by whether the classic tracer ran out of its budget), and their
    /// multires rows stay out of the frame-time row against the octree Whitted frame.
    #[test]
    fn classic_cone_rows_are_judged_apart() {
        let (full, budget) = cone_full_specs(false);
        let mut stopped = stats("cone", "octree", 30.0, &[]);
        stopped.finished = false;
        stopped.cone_profile = Some(crate::experiment::run::ConeProfileStats {
            kinds: Default::default(),
            pixel_tests: crate::experiment::run::PixelTests { pixels: 4, ..Default::default() },
        });
        let big = report(vec![
            row("complex", CONE_PAIRS[0].1, stats("multires", "octree", 4.0, &[])),
            row("complex", CONE_PAIRS[0].2, stats("cone", "octree", 3.6, &[])),
            row("complex", CONE_PAIRS[1].1, stats("multires", "octree", 1.0, &[])),
            row("complex", CONE_PAIRS[1].2, stats("cone", "octree", 0.9, &[])),
            row("complex", &full, stats("multires", "octree", 10.0, &[])),
            row("complex", &budget, stopped),
        ]);
        let small = BenchReport {
            width: 160,
            height: 120,
            ..report(vec![
                row("complex", CONE_PAIRS[0].1, stats("multires", "octree", 1.0, &[])),
                row("complex", CONE_PAIRS[0].2, stats("cone", "octree", 4.4, &[])),
            ])
        };
        let main = report(vec![row("complex", "whitted:octree", stats("whitted", "octree", 1.0, &[]))]);
        let t = target_rows(&[&main], &[&big, &small], false, &[]);
        let cc = t.iter().find(|r| r.target.starts_with("classic cone")).expect("classic cone row");
        assert_eq!(
            cc.measured,
            "primary cones at 4×4: exact mass 0.90×, default weight 0.90×; whole frame at 4×4 (exact mass): cone stopped at its 30 s budget with 25 % of the pixels traced, multires finished in 10.0 s; primary cones at 160×120: exact mass 4.40×"
        );
        assert_eq!(cc.status, "partly", "slower at 160×120 and unfinished, not slower at 4×4");
        // No multires row of these jobs is judged against the octree Whitted frame.
        assert!(t.iter().all(|r| !r.target.starts_with("multires frame")), "{t:?}");
        let mut finished = big.clone();
        finished.rows[5].stats.finished = true;
        let t = target_rows(&[], &[&finished], false, &[]);
        let cc = t.iter().find(|r| r.target.starts_with("classic cone")).unwrap();
        assert!(cc.measured.contains("cone finished in 30.0 s, multires 10.0 s"), "{}", cc.measured);
        assert_eq!(cc.status, "not met");
    }

    /// The classic cone plot's curves: one per weight, the frames in order of size, each
    /// point the classic tracer's time over multires'; a frame without a pair adds nothing.
    #[test]
    fn classic_cone_curves_follow_the_frame_size() {
        let at = |w: u32, h: u32, mass: (f64, f64), default: Option<(f64, f64)>| {
            let mut rows = vec![
                row("complex", CONE_PAIRS[0].1, stats("multires", "octree", mass.0, &[])),
                row("complex", CONE_PAIRS[0].2, stats("cone", "octree", mass.1, &[])),
            ];
            if let Some((m, c)) = default {
                rows.push(row("complex", CONE_PAIRS[1].1, stats("multires", "octree", m, &[])));
                rows.push(row("complex", CONE_PAIRS[1].2, stats("cone", "octree", c, &[])));
            }
            BenchReport { width: w, height: h, ..report(rows) }
        };
        let (big, small) = (at(640, 480, (4.0, 4.8), Some((1.0, 0.8))), at(160, 120, (1.0, 4.4), None));
        let s = cone_size_series(&[&big, &small]);
        assert_eq!(s[0].0, "exact mass");
        assert_eq!(s[0].1.len(), 2);
        assert_eq!(s[0].1[0].0, 19200.0);
        assert!((s[0].1[0].1 - 4.4).abs() < 1e-9 && (s[0].1[1].1 - 1.2).abs() < 1e-9, "{s:?}");
        assert_eq!(s[1].1, vec![(307200.0, 0.8)]);
        assert!(cone_size_series(&[]).iter().all(|c| c.1.is_empty()));
    }

    /// The hierarchy build's row and the Table 1 section: `complex` from scratch against
    /// the 60 s target, beside the paper's 2003 figures.
    #[test]
    fn table_one_gives_the_build_row() {
        let st = |seconds: f64| super::super::run::HierarchyStats {
            trees: 8,
            nodes: 1000,
            points: 2000,
            bytes: 11_400_000,
            seconds,
            ..Default::default()
        };
        assert!(build_row(&[HierRow { scene: "spheres", paper: (5.7, 2.3), stats: st(0.3), threads: 2 }]).is_none(), "no complex, no row");
        let rows = [
            HierRow { scene: "spheres", paper: (5.7, 2.3), stats: st(0.3), threads: 2 },
            HierRow { scene: "complex", paper: (443.0, 106.0), stats: st(2.04), threads: 2 },
        ];
        let r = build_row(&rows).unwrap();
        assert_eq!(
            r.measured,
            "2.0 s from scratch on 2 threads, 11.4 MB (8 hierarchies, 1000 nodes, 2000 points; the paper 443 s, 106 MB)"
        );
        assert_eq!(r.status, "met");
        assert_eq!(
            build_row(&[HierRow { scene: "complex", paper: (443.0, 106.0), stats: st(61.0), threads: 2 }]).unwrap().status,
            "not met"
        );
        let h = hierarchy_html(&rows);
        assert!(h.contains("<tr><td>complex</td><td>8</td><td>1000</td><td>2000</td><td>0</td><td>0</td><td>11.40</td><td>2.04 (2)</td><td>443</td><td>106</td></tr>"), "{h}");
        assert!(hierarchy_html(&[]).is_empty());
    }

    /// The page says what each per-image scale means and gives the CPU time saved (the
    /// one-thread rows' robust figure, in bench.md but missing from the page); a method faster
    /// than the sweep's 1 spp is said so, not "–".
    #[test]
    fn page_states_scales_cpu_time_and_faster_than_one_spp() {
        let job = |scene: &'static str, sweep: Vec<String>| Job {
            scene,
            dir: scene,
            intro: "",
            classic: false,
            width: 4,
            height: 4,
            methods: String::new(),
            reference: None,
            sweep,
            regions: vec![],
        };
        let mut lod = row("chessboard", "lod:bvh:spp=4", stats("lod", "bvh", 1.0, &[]));
        lod.lod_vs_full = Some(bench::LodComparison {
            against: "whitted:bvh:spp=4".into(),
            triangle_test_reduction: Some(0.215),
            time_reduction: 0.151,
            cpu_time_reduction: 0.172,
            max_pixel_diff: 0.329,
            max_at: [0, 0],
            p99_pixel_diff: 0.09,
            mean_pixel_diff: 0.0048,
            max_diff_full_lod_pixels: 0.063,
            floor: None,
        });
        lod.image = Some("chessboard-lod_bvh_spp_4.png".into());
        let mut w = row("spheres", "whitted:embree", stats("whitted", "embree", 0.08, &[]));
        w.flip = Some(0.03);
        w.image = Some("spheres-whitted_embree.png".into());
        w.equal_time.push(bench::equal_time(&[(0.5, 1.0, 0.033), (1.0, 2.0, 0.026)], 0.08, 0.03, "distributed:octree"));
        let h = index_html(
            &[(job("chessboard", vec![]), report(vec![lod])), (job("spheres", vec!["distributed:octree".into()]), report(vec![w]))],
            "",
            &[],
        );
        assert!(h.contains("<th>CPU time saved</th>") && h.contains("<td>17.2 %</td>"), "CPU time column");
        assert!(h.contains("difference to whitted:bvh:spp=4 (magnified: black = 32.9 %)"), "diff caption");
        assert!(h.contains("<td>faster than its 1 spp</td><td>&lt; 1</td>"), "faster than 1 spp");
        // Captions give the FLIP only where there is a reference (they said "FLIP -").
        assert!(h.contains("<figcaption>lod:bvh:spp=4 — 1.000 s</figcaption>"), "caption without a reference");
        assert!(h.contains("<figcaption>whitted:embree — 0.080 s, FLIP 0.0300</figcaption>"), "caption with FLIP");
        assert!(!h.contains("FLIP -"), "no FLIP placeholder");
    }

    #[test]
    fn update_labels_name_the_cache_switches() {
        assert_eq!(update_label("lazy", "surfel:update=lazy:frames=16:detail=0.4"), "lazy");
        assert_eq!(update_label("lazy", "surfel:update=lazy:ordered=0:frames=16"), "lazy, unordered");
        assert_eq!(
            update_label("lazy-cache", "surfel:update=lazy-cache:ordered=0:cache_up=8:frames=16"),
            "lazy-cache, unordered, cache 8 up"
        );
        assert_eq!(
            update_label("lazy-cache", "surfel:update=lazy-cache:ordered=0:climb=1:frames=16"),
            "lazy-cache, unordered, cache climbs"
        );
    }
}
