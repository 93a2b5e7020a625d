//! `lodtrace demo`: the main job. Renders the built-in paper scenes with every method that
//! exists, side by side through [`super::bench`], cross-checks the intersectors against
//! Embree, and writes images, tables, plots and an `index.html` a person can open.

use super::bench::{self, BenchArgs, BenchReport};
use crate::error::{Error, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug, Clone)]
pub struct DemoArgs {
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Smaller images and fewer reference samples (a minute instead of several).
    #[arg(long)]
    pub quick: bool,
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

struct Job {
    scene: &'static str,
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
    vec![
        Job { scene: "spheres", width: swd, height: sh, methods: methods.clone(), reference: r(sref), sweep: sw.clone(), regions: vec![] },
        Job { scene: "complex", width: cw, height: ch, methods, reference: r(cref), sweep: sw.clone(), regions: complex_regions(cw, ch) },
        // Fig. 8: soft shadows, depth of field, blurry reflections at three roughnesses.
        Job { scene: "effects", width: swd, height: sh, methods: fx, reference: r(sref), sweep: sw[..1].to_vec(), regions: vec![] },
        Job { scene: "chessboard", width: lw, height: lh, methods: lod_cb, reference: None, sweep: vec![], regions: vec![] },
        Job { scene: "cabinet", width: lw, height: lh, methods: lod.clone(), reference: None, sweep: vec![], regions: vec![] },
        Job { scene: "reflector", width: lw, height: lh, methods: lod, reference: None, sweep: vec![], regions: vec![] },
    ]
}

pub fn run(a: &DemoArgs) -> Result<()> {
    crate::core::check_threads(a.threads)?;
    // A failed demo removes its output folder again if it created it.
    crate::film::io::discard_dir_on_error(Some(&a.out), || run_in(a))
}

fn run_in(a: &DemoArgs) -> Result<()> {
    crate::film::io::create_out_dir(&a.out)?;
    crate::film::io::check_writable_dir(&a.out)?;
    let mut sections = Vec::new();
    for job in jobs(a.quick) {
        if crate::scene::builtin::get(job.scene).is_err() {
            eprintln!("demo: skipping '{}' (not available: run tools/setup for its meshes)", job.scene);
            continue;
        }
        eprintln!(
            "demo: {} at {}x{}: {} (reference {})",
            job.scene,
            job.width,
            job.height,
            job.methods,
            job.reference.as_deref().unwrap_or("none")
        );
        let dir = a.out.join(job.scene);
        let args = BenchArgs {
            scenes: vec![job.scene.to_string()],
            methods: job.methods.clone(),
            reference: job.reference.clone(),
            out: Some(dir.clone()),
            width: job.width,
            height: job.height,
            threads: a.threads,
            repeat: 1,
            quiet: false,
            sweep: job.sweep.clone(),
            sweep_max_spp: if a.quick { 64 } else { 128 },
            regions: job.regions.clone(),
            sizes: None,
        };
        let report = bench::bench(&args)?;
        bench::print_table(&report)?;
        sections.push((job, report));
    }
    let deform = deform_section(a)?;
    let mut html = index_html(&sections);
    html = html.replace("</body></html>", &format!("{deform}</body></html>"));
    let p = a.out.join("index.html");
    crate::film::io::write_atomic(&p, |tmp| std::fs::write(tmp, html).map_err(|e| Error::io(&p, e)))?;
    eprintln!("demo: open {}", p.display());
    Ok(())
}

/// Adams et al.: every built-in sequence in the four update modes (same recorded motion;
/// [`super::deform_bench`]), the per-frame time curves (the paper's Fig. 5), radius ratios
/// (Fig. 3), test counts with and without the per-ray cache.
fn deform_section(a: &DemoArgs) -> Result<String> {
    let (w, h, frames, detail) = if a.quick { (192, 144, 8, 0.15) } else { (384, 288, 16, 0.4) };
    // The last two: the paper's unordered descent without and with the per-ray cache (of an
    // ancestor 8 levels above the hit leaf; the leaf itself misses under this motion), where
    // the cache cuts the tests as in §4.2.2 (BENCHMARKS.md, "Caching (stop 34)").
    let specs: Vec<super::bench::MethodSpec> =
        ["naive", "lazy", "lazy-cache", "refit", "lazy:ordered=0", "lazy-cache:ordered=0:cache_up=8"]
            .iter()
            .map(|m| super::bench::MethodSpec::parse(&format!("surfel:update={m}:frames={frames}:detail={detail}")))
            .collect::<Result<_>>()?;
    let dir = a.out.join("deform");
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut rows = Vec::new();
    for seq in crate::deform::Sequence::BUILTIN {
        match super::deform_bench::run(&[seq.to_string()], &specs, w, h, a.threads, 1, Some(&dir), false) {
            Ok(r) => rows.extend(r),
            Err(e) => eprintln!("demo: skipping {seq} ({e})"),
        }
    }
    // Each sequence ran on its own (so that one failing is skipped): the Fig. 3 plot of all.
    super::deform_bench::radius_plot(&dir, &rows)?;
    let mut h_out = format!(
        "<h2>Adams et al.: deforming point-sampled surfaces</h2><p>Each sequence ({frames} frames, {w}×{h}, detail {detail}) rendered with the hierarchy rebuilt every frame (naive), updated lazily (§4.1), lazily with per-ray caching (§4.2.2), and — not in the paper — an obvhs BVH2 refitted every frame; the same recorded motion, so the images must be identical (last column). The last two rows per sequence descend the tree unordered, as the paper does, without and with the cache (of the ancestor 8 levels above each ray's hit leaf, a deviation: the leaf itself moves away within a frame): there the cache cuts the leaf tests, as in the paper; front-to-back traversal (the other rows) cuts more by itself. Per-frame time curves like the paper's Fig. 5. Same as <code>lodtrace bench SEQ --methods surfel:update=naive,surfel:update=lazy,...</code>.</p><table><tr><th>sequence</th><th>update</th><th>surfels</th><th>ms/frame</th><th>vs naive</th><th>BV tests/frame</th><th>leaf tests/frame</th><th>cache hits</th><th>MLS iterations</th><th>root radius ratio</th><th>mean radius ratio</th><th>same image</th></tr>"
    );
    for r in &rows {
        let f = |x: Option<f64>| x.map(|v| format!("{v:.2}")).unwrap_or_else(|| "-".into());
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
            if r.cache_lookups > 0 { format!("{}/{}", r.cache_hits, r.cache_lookups) } else { "-".into() },
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
    h_out.push_str(&size_section(a, &dir, detail)?);
    Ok(h_out)
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
    let specs: Vec<super::bench::MethodSpec> = ["naive", "lazy-cache", "auto"]
        .iter()
        .map(|m| super::bench::MethodSpec::parse(&format!("surfel:update={m}:frames=16:detail={detail}")))
        .collect::<Result<_>>()?;
    let sdir = dir.join("sizes");
    std::fs::create_dir_all(&sdir).map_err(|e| Error::io(&sdir, e))?;
    let mut rows = Vec::new();
    for seq in crate::deform::Sequence::BUILTIN {
        for &(w, h) in sizes {
            match super::deform_bench::run(&[seq.to_string()], &specs, w, h, a.threads, 1, None, true) {
                Ok(r) => rows.extend(r),
                Err(e) => eprintln!("demo: skipping {seq} at {w}x{h} ({e})"),
            }
        }
    }
    if rows.is_empty() {
        return Ok(String::new());
    }
    super::deform_bench::size_plot(&sdir, &rows)?;
    let mut h = String::from(
        "<h3>Speed-up against the image size</h3><p>Naive, lazy-cache and auto (per frame a rebuild or the lazy update, whichever was cheaper when last tried: the heuristic the paper's §6 asks for), 16 frames at each size (same detail); speed-ups over naive. The rebuild costs the same at every size, the rays do not: the lazy update gains most where few rays are traced, and the paper's 2–3× (at 512×384 with its 2005 tracer) is reached here only at small images. Same as <code>lodtrace bench SEQ --sizes 96x72,192x144,... --methods surfel:update=naive,surfel:update=lazy-cache,surfel:update=auto</code>.</p><table><tr><th>sequence</th><th>update</th>",
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
                    None => h.push_str("<td>-</td>"),
                }
            }
            h.push_str("</tr>");
        }
    }
    h.push_str("</table><p><img src=\"deform/sizes/speedup-vs-size.png\" style=\"max-width:640px\"></p>");
    Ok(h)
}

/// The demo table's "update" cell: the mode, and the cache ablation switches of its spec.
fn update_label(update: &str, spec: &str) -> String {
    let mut l = update.to_string();
    if spec.contains("ordered=0") {
        l.push_str(", unordered");
    }
    if let Some(n) = spec.split(':').find_map(|k| k.strip_prefix("cache_up=")) {
        let _ = write!(l, ", cache {n} up");
    }
    l
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

fn index_html(sections: &[(Job, BenchReport)]) -> String {
    let mut h = String::new();
    h.push_str("<!doctype html><html><head><meta charset=\"utf-8\"><title>lodtrace demo</title><style>body{font-family:sans-serif;margin:2em;max-width:1400px}table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}td:nth-child(2),th:nth-child(2){text-align:left}figure{display:inline-block;margin:4px}figcaption{font-size:80%;max-width:320px}img{max-width:320px;image-rendering:pixelated}</style></head><body>");
    h.push_str("<h1>lodtrace demo</h1><p>Every method on the built-in paper scenes, rendered one after the other in one process on this machine. Speed-up is the first method's render time divided by each method's. Errors are against the high-sample distributed reference (RMSE and PSNR on the linear, unclamped radiance; mean FLIP on the sRGB display images).</p>");
    for (job, r) in sections {
        let _ = write!(h, "<h2>{} ({}×{})</h2><table><tr><th>method</th><th>spec</th><th>threads</th><th>build s</th><th>render s</th><th>Mrays/s</th><th>speed-up</th><th>RMSE</th><th>PSNR dB</th><th>mean FLIP</th></tr>", esc(job.scene), job.width, job.height);
        for row in &r.rows {
            let f = |x: Option<f64>, p: usize| x.map(|v| format!("{v:.p$}")).unwrap_or_else(|| "-".into());
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
        let dir = Path::new(job.scene);
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
                    "<figure><img src=\"{}\"><figcaption>{} — {:.3} s, FLIP {}</figcaption></figure>",
                    dir.join(img).display(),
                    esc(&row.spec),
                    row.stats.render_seconds,
                    row.flip.map(|v| format!("{v:.4}")).unwrap_or("-".into())
                );
            }
        }
        if let Some(first) = r.rows.iter().find(|row| !row.regions.is_empty()) {
            h.push_str("<h3>Where the error sits</h3><p>Mean FLIP against the reference inside each pixel rectangle (x0,y0,x1,y1), from the whole image's FLIP map; in brackets the region's share of the image's FLIP error. Below it the kind of error: the luminance against the reference's, and the part of the squared error at scales of 8 pixels or more (near 100 %: bias that more samples would not remove; near 0 %: aliasing or noise).</p><table><tr><th>method</th><th>spec</th><th>render s</th><th>whole</th>");
            for g in &first.regions {
                let _ = write!(h, "<th>{} {},{},{},{}</th>", esc(&g.name), g.rect[0], g.rect[1], g.rect[2], g.rect[3]);
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
                        "<td>{:.4} ({:.0} %)<br><small>{:+.1} % / {:.0} % smooth</small></td>",
                        g.figures.flip_mean,
                        100.0 * g.figures.flip_share,
                        100.0 * g.figures.luma_bias,
                        100.0 * g.figures.smooth_share
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
                "<h3>Equal time and equal error against {}</h3><p>The sweep renders it at 1, 2, 4, … samples per pixel; its error at each method's time and the time it needs to reach each method's error are interpolated in log time (time ratio &gt; 1: the method reaches that error faster).{}</p><table><tr><th>method</th><th>render s</th><th>mean FLIP</th><th>sweep FLIP at equal time</th><th>sweep samples per pixel at equal time</th><th>sweep time to match</th><th>time ratio at equal error</th></tr>",
                esc(&name),
                if name.contains(":octree") { " This is the paper's comparison (§6): the distributed tracer on the same code basis as the multi-resolution tracer." } else { "" }
            );
            for (row, e) in &eq {
                let o = |x: Option<f64>, p: usize| x.map(|v| format!("{v:.p$}")).unwrap_or_else(|| "-".into());
                let _ = write!(
                    h,
                    "<tr><td>{}</td><td>{:.3}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                    esc(&row.spec),
                    row.stats.render_seconds,
                    o(row.flip, 4),
                    if e.sweep_beyond { format!("&le; {}", o(e.sweep_flip_at_equal_time, 4)) } else { o(e.sweep_flip_at_equal_time, 4) },
                    if e.sweep_beyond {
                        format!("{} (its slowest)", o(e.sweep_spp_at_equal_time, 1))
                    } else {
                        o(e.sweep_spp_at_equal_time, 1)
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
            h.push_str("<h3>Per-ray LOD against full detail</h3><p>Difference images are magnified like the paper's Fig. 4e (white = equal, black = the largest difference); the distortion maps show 20·d (refraction d<sub>t</sub>, reflection d<sub>r</sub>) as in Fig. 4c/d. The floor is the full-detail render repeated on the other exact back-end (Embree ↔ CWBVH) with the same samples: what two correct intersectors already differ by in these chaotic glass scenes.</p><table><tr><th>method</th><th>against</th><th>triangle tests saved</th><th>time saved</th><th>max pixel diff</th><th>99th pct</th><th>mean diff</th><th>max diff, full-LOD pixels</th><th>floor max / 99th / mean</th><th>LOD pixels above floor max</th></tr>");
            for (row, c) in &lod {
                let _ = write!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.1} %</td><td>{:.1} %</td><td>{:.1} %</td><td>{:.2} %</td><td>{:.1} %</td><td>{}</td><td>{}</td></tr>",
                    esc(&row.spec),
                    esc(&c.against),
                    super::bench::pct_or_dash(c.triangle_test_reduction),
                    100.0 * c.time_reduction,
                    100.0 * c.max_pixel_diff,
                    100.0 * c.p99_pixel_diff,
                    100.0 * c.mean_pixel_diff,
                    100.0 * c.max_diff_full_lod_pixels,
                    c.floor.as_ref().map_or("–".into(), bench::DiffFloor::summary),
                    c.floor.as_ref().map_or("–".into(), |f| f.lod_pixels_above_floor_max.to_string()),
                );
            }
            h.push_str("</table>");
            for (row, _) in &lod {
                let slug = bench::MethodSpec::parse(&row.spec).map(|s| s.slug()).unwrap_or_default();
                for (k, what) in
                    [("diff", "difference (magnified)"), ("disparity-t", "refraction disparity"), ("disparity-r", "reflection disparity")]
                {
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
            h.push_str("<h3>Where the cone tracer's work goes</h3><p>Per cone kind: traversal thread-seconds (wall-clock time on each thread, summed over the threads; shading excluded), tests per cone (instance, node, triangle-bound, triangle and surfel tests) and the kind's share of the frame's tests. The heat maps show the tests per pixel, every cone a pixel spawned included (log scale, magma: black none, pale yellow the most).</p><table><tr><th>method</th><th>primary</th><th>shadow of primary</th><th>reflected / refracted</th><th>shadow of secondary</th><th>tests per pixel: median / p95 / max</th><th>top 5 % pixels' share</th></tr>");
            for (row, p) in &prof {
                let _ = write!(h, "<tr><td>{}</td>", esc(&row.spec));
                for cell in p.cells() {
                    let _ = write!(h, "<td>{}</td>", esc(&cell));
                }
                h.push_str("</tr>");
            }
            h.push_str("</table>");
            for (row, _) in &prof {
                let slug = bench::MethodSpec::parse(&row.spec).map(|s| s.slug()).unwrap_or_default();
                let _ = write!(
                    h,
                    "<figure><img src=\"{}\"><figcaption>{} — tests per pixel</figcaption></figure>",
                    dir.join(format!("{}-{}-cost.png", job.scene, slug)).display(),
                    esc(&row.spec)
                );
            }
        }
        let _ = write!(h, "<p><img src=\"{}\" style=\"max-width:640px\"></p>", dir.join("bench-time.png").display());
    }
    h.push_str("</body></html>\n");
    h
}

#[cfg(test)]
mod tests {
    use super::update_label;

    #[test]
    fn update_labels_name_the_cache_switches() {
        assert_eq!(update_label("lazy", "surfel:update=lazy:frames=16:detail=0.4"), "lazy");
        assert_eq!(update_label("lazy", "surfel:update=lazy:ordered=0:frames=16"), "lazy, unordered");
        assert_eq!(
            update_label("lazy-cache", "surfel:update=lazy-cache:ordered=0:cache_up=8:frames=16"),
            "lazy-cache, unordered, cache 8 up"
        );
    }
}
