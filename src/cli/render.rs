//! `lodtrace render`: one method on one scene → PNG, optional EXR AOVs and `--stats` JSON.
use super::{CameraArgs, RenderArgs};
use crate::baseline::render::RenderOpts;
use crate::error::{Error, Result};
use crate::experiment::run;
use crate::film::io;
use crate::scene::Scene;
use std::path::{Path, PathBuf};

/// Applies `--eye/--look/--up/--fovy`; a bare mesh keeps its automatic framing otherwise.
pub fn apply_camera(scene: &mut Scene, c: &CameraArgs) -> Result<()> {
    if let Some(v) = c.eye {
        scene.camera.eye = v;
    }
    if let Some(v) = c.look {
        scene.camera.look = v;
    }
    if let Some(v) = c.up {
        scene.camera.up = v;
    }
    if let Some(v) = c.fovy {
        scene.camera.fovy = v;
    }
    scene.camera.validate()?;
    // A moved eye can carry the rays beyond Embree's range in a small instance's space.
    scene.check_ray_reach()
}

/// Fails early (before any work) when an output's folder does not exist.
/// A JSON output (`--stats`, `--json`) named like an image is a slip of the keyboard
/// (`--stats s.png` beside `--out s.exr`): refused.
pub fn check_json_path(p: &Path, option: &str) -> Result<()> {
    if is_stdout(p) {
        return Ok(());
    }
    const IMAGES: [&str; 5] = ["png", "exr", "jpg", "jpeg", "ppm"];
    if p.extension().is_some_and(|e| IMAGES.iter().any(|x| e.eq_ignore_ascii_case(x))) {
        return Err(Error::Usage(format!("{}: {option} writes JSON; name it .json", p.display())));
    }
    check_out_path(p)
}

/// `--stats -`: the JSON goes to standard output, which the commands leave to it (their
/// summaries and progress go to standard error). Until stop 80 it was a file named `-`.
pub fn is_stdout(p: &Path) -> bool {
    p.as_os_str() == "-"
}

/// Writes `json` to `p` (atomically), or to standard output for `-` ([`is_stdout`]).
pub fn write_json(p: &Path, json: &str) -> Result<()> {
    if is_stdout(p) {
        use std::io::Write as _;
        let mut o = std::io::stdout().lock();
        return o.write_all(json.as_bytes()).and_then(|_| o.flush()).map_err(|e| Error::io(p, e));
    }
    io::write_atomic(p, |tmp| std::fs::write(tmp, json.as_bytes()).map_err(|e| Error::io(p, e)))
}

pub fn check_out_path(p: &Path) -> Result<()> {
    let dir = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        // Name the culprit when a file stands where a folder should (`--out a.png/x.png`).
        if let Some(f) = dir.ancestors().find(|a| !a.as_os_str().is_empty() && a.exists()) {
            if !f.is_dir() {
                return Err(Error::Usage(format!("{}: {} is a file, not a folder", p.display(), f.display())));
            }
        }
        return Err(Error::Usage(format!("{}: output folder does not exist", p.display())));
    }
    // Outputs are written to a temporary file and renamed over the target: that would
    // replace a device or pipe (`/dev/full`) with a plain file.
    io::check_not_special(p)?;
    io::check_writable_dir(dir)
}

pub fn opts_from(a: &RenderArgs) -> RenderOpts {
    RenderOpts {
        width: a.width,
        height: a.height,
        spp: a.spp,
        seed: a.seed,
        threads: a.threads,
        packet: a.packet,
        first_pass_spp: a.first_pass_spp,
        variance_threshold: a.variance_threshold,
        aov: !a.aov.is_empty(),
        quiet: a.quiet,
        label: format!("{} {}", a.method.name(), accel_name(a.method, a.accel.unwrap_or(crate::baseline::accel::AccelKind::Embree))),
        ..Default::default()
    }
}

/// The hierarchy a method traces, as reported in labels and stats: the cone tracers trace
/// their own octree and the surfel tracer its sphere tree, whatever `--accel` says.
pub fn accel_name(m: crate::cli::Method, a: crate::baseline::accel::AccelKind) -> &'static str {
    use crate::cli::Method::*;
    match m {
        Multires | Cone => "octree",
        Surfel => "sphere-tree",
        _ => a.name(),
    }
}

/// Refuses options the chosen method would silently ignore (`--k 0` with `--method
/// whitted`, `--time-budget` with anything but the cone tracers): a researcher who passes
/// one believes it took effect.
pub fn check_method_options(a: &RenderArgs) -> Result<()> {
    use crate::baseline::accel::AccelKind;
    use crate::cli::Method::*;
    let m = a.method;
    let cone = matches!(m, Multires | Cone);
    let octree = matches!(m, Whitted | Distributed) && a.accel == Some(AccelKind::Octree);
    let (build, trace) = a.multires.changed();
    let mut wrong: Vec<(&str, &str)> = Vec::new();
    if !cone && !octree {
        wrong.extend(build.iter().map(|o| (*o, "--method multires and cone, and of --accel octree")));
    }
    if !cone {
        wrong.extend(trace.iter().map(|o| (*o, "--method multires and cone")));
    }
    if m != Lod {
        wrong.extend(a.lod.changed().into_iter().map(|o| (o, "--method lod")));
    }
    // The cone tracers trace one deterministic cone per pixel (the octree's surface samples
    // take a fixed seed, part of the cache key): no packets, no random numbers while tracing.
    if cone && a.packet != 8 {
        wrong.push(("--packet", "the ray tracers (whitted, distributed, lod)"));
    }
    if (cone || m == Surfel) && a.seed != 0 {
        wrong.push(("--seed", "the ray tracers' sampling (the cone and surfel tracers are deterministic)"));
    }
    // Whitted and lod draw random numbers only to jitter several samples per pixel: at one
    // they render the same image whatever the seed (taken without a word until stop 80).
    if matches!(m, Whitted | Lod) && a.spp == 1 && a.seed != 0 {
        return Err(Error::Usage(format!(
            "--seed has no effect on --method {} at --spp 1 (no jitter, nothing random): give --spp N",
            m.name()
        )));
    }
    // The cone tracers trace their own octree, surfel its sphere tree: only the default
    // (which they do not use) passes unremarked.
    if matches!(m, Multires | Cone | Surfel) && a.accel.is_some() {
        return Err(Error::Usage(format!(
            "--accel picks the triangle tracers' structure ({}); --method {} traces its own {}",
            crate::baseline::accel::ACCEL_USE,
            m.name(),
            if m == Surfel { "sphere tree" } else { "multi-resolution octree" }
        )));
    }
    // Options of cones or rays that are not traced (stop 80: they were ignored without a
    // word). `MultiresArgs::params` refuses the shadow and secondary cones' options beside
    // `--primary-only`, for bench specs too.
    if cone && a.no_shadows {
        if let Some(o) = trace.iter().find(|o| crate::multires::MultiresArgs::SHADOW.contains(o)) {
            return Err(Error::Usage(format!("{o} has no effect beside --no-shadows (no shadow cones)")));
        }
    }
    if cone && a.multires.primary_only && a.max_depth.is_some() {
        return Err(Error::Usage("--max-depth has no effect beside --primary-only (no reflected or refracted cones)".into()));
    }
    let d = crate::baseline::render::RenderOpts::default();
    if m != Distributed && a.first_pass_spp != d.first_pass_spp {
        wrong.push(("--first-pass-spp", "--method distributed"));
    }
    if m == Distributed && a.first_pass_spp != d.first_pass_spp && a.first_pass_spp > a.spp {
        return Err(Error::Usage(format!(
            "--first-pass-spp {} exceeds --spp {} (the per-pixel maximum, which caps it): raise --spp",
            a.first_pass_spp, a.spp
        )));
    }
    if m == Distributed && a.spp == 1 {
        crate::error::warn(
            "--method distributed with --spp 1 takes one sample per pixel (no supersampling, soft shadows or depth of field to speak of): give --spp N",
        );
    }
    if m != Distributed && a.variance_threshold != d.variance_threshold {
        wrong.push(("--variance-threshold", "--method distributed"));
    }
    // The threshold picks the pixels of the second pass; there is none when the first pass
    // takes every sample --spp allows (taken without effect until stop 80).
    if m == Distributed && a.variance_threshold != d.variance_threshold && a.first_pass_spp >= a.spp {
        return Err(Error::Usage(format!(
            "--variance-threshold has no effect at --spp {} with --first-pass-spp {}: the first pass takes every sample, there is no second pass",
            a.spp,
            a.first_pass_spp.min(a.spp)
        )));
    }
    if m == Surfel {
        // The sequence brings its own camera and has no recursion.
        let c = &a.camera;
        let set = [(c.eye.is_some(), "--eye"), (c.look.is_some(), "--look"), (c.up.is_some(), "--up"), (c.fovy.is_some(), "--fovy")];
        if let Some((_, o)) = set.iter().find(|(s, _)| *s) {
            return Err(Error::Usage(format!("{o}: --method surfel renders with the sequence's own camera")));
        }
        if a.max_depth.is_some() {
            wrong.push(("--max-depth", "the methods with reflection and refraction"));
        }
    }
    match wrong.first() {
        Some((o, of)) => Err(Error::Usage(format!("{o} is an option of {of}; --method {} would ignore it", m.name()))),
        None => Ok(()),
    }
}

/// Checks the options of a `render` run before the scene is loaded; the beauty image's path.
pub(crate) fn check(a: &RenderArgs) -> Result<PathBuf> {
    let opts = opts_from(a);
    opts.validate()?;
    check_method_options(a)?;
    let out = a.out.clone().unwrap_or_else(|| "render.png".into());
    if out.as_os_str().is_empty() {
        return Err(Error::Usage("--out needs a file name".into()));
    }
    check_out_path(&out)?;
    io::check_beauty_ext(&out)?;
    for (i, (k, p)) in a.aov.iter().enumerate() {
        // The cost AOV comes as a heat map (.png) and as counts (.exr): one of each.
        let ext_of = |p: &Path| p.extension().map(|e| e.to_ascii_lowercase());
        if a.aov[..i].iter().any(|(o, q)| o == k && ext_of(q) == ext_of(p)) {
            return Err(Error::Usage(format!("--aov {k} given twice")));
        }
        check_out_path(p)?;
        let ext = p.extension().map(|e| e.to_ascii_lowercase());
        if k == "cost" {
            // The cone tracers' tests per pixel: a heat map (.png) or the counts (.exr).
            if ext != Some("png".into()) && ext != Some("exr".into()) {
                return Err(Error::Usage(format!(
                    "{}: the cost AOV is written as .png (log-scale heat map) or .exr (tests per pixel)",
                    p.display()
                )));
            }
            if !matches!(a.method, crate::cli::Method::Multires | crate::cli::Method::Cone) {
                return Err(Error::Usage("the cost AOV exists for --method multires and cone only".into()));
            }
            continue;
        }
        let png = k.starts_with("disparity") || k.starts_with("lod");
        let want = if png { "png" } else { "exr" };
        if ext != Some(want.into()) {
            return Err(Error::Usage(format!("{}: the {k} AOV is written as .{want}", p.display())));
        }
        if png && a.method != crate::cli::Method::Lod {
            return Err(Error::Usage(format!("the {k} AOV exists for --method lod only")));
        }
    }
    if let Some(p) = &a.stats {
        check_json_path(p, "--stats")?;
    }
    let mut paths: Vec<&Path> = vec![&out];
    paths.extend(a.aov.iter().map(|(_, p)| p.as_path()));
    paths.extend(a.stats.as_deref());
    io::check_outputs_apart_from_scene(&a.scene, &paths)?;
    if a.debug_pixel.is_some() && !matches!(a.method, crate::cli::Method::Multires | crate::cli::Method::Cone) {
        return Err(Error::Usage("--debug-pixel explains a cone: --method multires or cone".into()));
    }
    if a.method == crate::cli::Method::Surfel {
        return Ok(out);
    }
    if a.debug_pixel.is_some() {
        if a.out.is_some() || !a.aov.is_empty() || a.stats.is_some() {
            return Err(Error::Usage("--debug-pixel writes no image, AOV or stats".into()));
        }
        if a.spp != 1 {
            return Err(Error::Usage("the cone tracers shoot one cone per pixel: use --spp 1".into()));
        }
        // One cone, traced on this thread, to the end: these would be ignored.
        let d = crate::multires::MultiresArgs::default();
        let ignored = [(a.multires.time_budget != d.time_budget, "--time-budget"), (a.threads != 0, "--threads")];
        if let Some((_, o)) = ignored.iter().find(|(set, _)| *set) {
            return Err(Error::Usage(format!("{o}: --debug-pixel traces one cone alone, to the end")));
        }
    }
    if a.method == crate::cli::Method::Lod && a.accel == Some(crate::baseline::accel::AccelKind::Octree) {
        // Before loading, so that the error is the only line (no mesh warnings first).
        return Err(Error::Usage("--method lod runs on --accel bvh or embree; the octree serves whitted and distributed".into()));
    }
    Ok(out)
}

pub fn run(a: &RenderArgs) -> Result<()> {
    let out = check(a)?;
    if a.method == crate::cli::Method::Surfel {
        return render_surfel(a, &out);
    }
    let opts = opts_from(a);
    let mut scene = crate::scene::load::load_scene(&a.scene)?;
    apply_camera(&mut scene, &a.camera)?;
    if let Some(d) = a.max_depth {
        if d > crate::scene::MAX_DEPTH {
            return Err(Error::Usage(format!("--max-depth {d} is absurd (max {})", crate::scene::MAX_DEPTH)));
        }
        scene.max_depth = d;
    }
    scene.shadows = !a.no_shadows;
    if let Some(px) = a.debug_pixel {
        crate::error::print_stdout(&run::explain_cone(&scene, a.method, &opts, &a.multires, px)?)?;
        return Ok(());
    }
    let r = run::run(&scene, a.method, a.accel.unwrap_or(crate::baseline::accel::AccelKind::Embree), &opts, &a.multires, &a.lod)?;
    // A failed write removes the outputs written before it.
    let mut outs = io::Outputs::default();
    outs.wrote(&out, io::write_beauty(&out, &r.out.film))?;
    for (kind, p) in &a.aov {
        let w = match kind.as_str() {
            "depth" => io::write_exr_depth(p, &r.out.film),
            "normal" => io::write_exr_normal(p, &r.out.film),
            "color" => io::write_film_exr(p, &r.out.film),
            "cost" => {
                let c = r.cones.as_ref().expect("cone method");
                if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
                    crate::film::metrics::cost_map(&c.pixel_tests, opts.width, opts.height).and_then(|img| io::write_rgb8_png(p, &img))
                } else {
                    let v: Vec<f32> = c.pixel_tests.iter().map(|&x| x as f32).collect();
                    io::write_exr_scalar(p, opts.width, opts.height, &v)
                }
            }
            k @ ("disparity-r" | "disparity-t" | "lod-r" | "lod-t") => {
                let m = &r.lod.as_ref().expect("lod method").maps;
                io::write_rgb8_png(p, &crate::lod::maps_image(m, k))
            }
            other => Err(Error::Usage(format!("--aov {other}: unknown AOV"))),
        };
        outs.wrote(p, w)?;
    }
    let stats = r.stats(&scene, a.method, a.accel.unwrap_or(crate::baseline::accel::AccelKind::Embree), &opts);
    if let Some(p) = &a.stats {
        let json = serde_json::to_string_pretty(&stats).expect("stats serialise") + "\n";
        if is_stdout(p) {
            write_json(p, &json)?;
        } else {
            outs.wrote(p, write_json(p, &json))?;
        }
    }
    outs.keep();
    if !r.finished {
        crate::status!("lodtrace: warning: the time budget ran out; the image is incomplete");
    }
    crate::status!(
        "{}: {} {} {}x{} spp {}{}: build {:.3} s{}, render {:.3} s, {:.2} Mrays/s -> {}",
        scene.name,
        stats.method,
        stats.accel,
        stats.width,
        stats.height,
        stats.spp,
        samples_taken(&stats),
        stats.build_seconds,
        crate::experiment::bench::cache_note(&stats),
        stats.render_seconds,
        stats.mrays_per_second,
        out.display()
    );
    Ok(())
}

/// " (at most; 7.3 taken per pixel)" where the adaptive distributed tracer took fewer samples
/// than `--spp` allows (its first pass, then more only where the variance asks), as the
/// stats' `samples` counter and bench's "samples per pixel" column say; else nothing.
fn samples_taken(st: &crate::experiment::run::Stats) -> String {
    let px = st.width as f64 * st.height as f64;
    match st.counters.get("samples") {
        Some(&n) if px > 0.0 && (n as f64) < st.spp as f64 * px => format!(" (at most; {:.1} taken per pixel)", n as f64 / px),
        _ => String::new(),
    }
}

/// `--method surfel` (Adams et al.): the first frame of a deforming sequence (or a mesh file
/// sampled into surfels), with the sequence's own camera and light; `lodtrace animate` renders
/// whole sequences.
fn render_surfel(a: &RenderArgs, out: &Path) -> Result<()> {
    if !a.aov.is_empty() || a.spp != 1 {
        return Err(Error::Usage("--method surfel renders one ray per pixel and no AOVs (use --spp 1, no --aov)".into()));
    }
    let args = super::animate::AnimateArgs {
        frames: Some(1),
        update: "lazy".into(),
        width: a.width,
        height: a.height,
        stats: a.stats.clone(),
        threads: a.threads,
        packet: a.packet,
        // As `animate --no-shadows` (once refused here, though the tracer had it).
        no_shadows: a.no_shadows,
        quiet: a.quiet,
        ..super::animate::AnimateArgs::new(&a.scene)
    };
    let st = super::animate::animate(&args)?;
    io::write_beauty(out, &st.last_frame)?;
    crate::status!(
        // The stats JSON's two fields by their names (the line gave their sum as "build").
        "{}: surfel {}x{}: {} surfels, setup {:.3} s, build {:.3} s, render {:.3} s -> {}",
        st.scene,
        st.width,
        st.height,
        st.surfels,
        st.setup_seconds,
        st.build_seconds,
        st.render_seconds,
        out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    /// Every `lodtrace render` command in the README passes render's option checks (as
    /// `bench::tests::the_readmes_bench_commands_pass_the_checks` does for bench); commands
    /// naming a mesh that `tools/setup` has not fetched are skipped.
    #[test]
    fn the_readmes_render_commands_pass_the_checks() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut checked = 0;
        for (cmd, mut a) in crate::cli::readme_commands::<super::RenderArgs>("render") {
            if a.scene.contains('/') {
                if !root.join(&a.scene).exists() {
                    continue;
                }
                a.scene = root.join(&a.scene).to_string_lossy().into_owned();
            }
            if let Err(e) = super::check(&a) {
                panic!("README: {cmd}\n{e}");
            }
            checked += 1;
        }
        assert!(checked >= 8, "only {checked} render commands found in the README");
    }
}
