//! `lodtrace bench SCENE... --methods LIST [--reference SPEC] [--out DIR]`: every method on
//! the same scene in one process, one after the other on the same machine, so the ratios
//! are comparable. Prints a table (build time, render time, Mrays/s, ratio to the first
//! method, error against the reference) and writes `bench.json`, a plot and the images.
//!
//! A method spec is `METHOD[:ACCEL][:key=value...]`, keys: `spp`, `threads`, `packet`,
//! `fps` (distributed first-pass spp), `vt` (distributed variance threshold), `depth`; for
//! the cone tracers (`multires`, `cone`): `k`, `c` (oversampling), `clamp`, `lod`, `dtol`,
//! `cs` (cone scale), `mip=0`, `primary=1`, `budget` (seconds), `eigen=per-box|exact`, `tri=paper|coverage`.
//! Examples: `whitted:embree`, `whitted:bvh:threads=1`, `distributed:embree:spp=64`.

use super::run;
use crate::baseline::accel::AccelKind;
use crate::baseline::render::RenderOpts;
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
    /// Comma-separated method specs, e.g. `whitted:embree,whitted:bvh,distributed:embree:spp=16`.
    #[arg(long, required = true)]
    pub methods: String,
    /// Reference spec for the error columns, e.g. `distributed:embree:spp=256:vt=0`.
    #[arg(long)]
    pub reference: Option<String>,
    /// Output folder for bench.json, the plot and the images (created if missing).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// Default thread count for methods that don't set `threads=` (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Repeat each render this many times and keep the fastest (rendering only).
    #[arg(long, default_value_t = 1)]
    pub repeat: u32,
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
}

impl MethodSpec {
    pub fn parse(s: &str) -> Result<Self> {
        let bad = |m: String| Error::Usage(format!("method spec '{s}': {m}"));
        let mut parts = s.trim().split(':');
        let m = parts.next().unwrap_or("");
        let method = Method::from_str(m, true)
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
        };
        for p in parts {
            if let Some((k, v)) = p.split_once('=') {
                let num = |v: &str| {
                    v.parse::<f64>().ok().filter(|x| x.is_finite() && *x >= 0.0).ok_or_else(|| bad(format!("bad value '{v}' for {k}")))
                };
                match k {
                    "spp" => spec.spp = num(v)? as u32,
                    "threads" => spec.threads = Some(num(v)? as usize),
                    "packet" => spec.packet = num(v)? as u32,
                    "fps" => spec.first_pass_spp = num(v)? as u32,
                    "vt" => spec.variance_threshold = num(v)? as f32,
                    "depth" => spec.max_depth = Some(num(v)? as u32),
                    "k" => spec.multires.k = num(v)? as u32,
                    "c" => spec.multires.oversampling = num(v)? as f32,
                    "clamp" => spec.multires.anisotropy_clamp = num(v)? as f32,
                    "lod" => spec.multires.lod_scale = num(v)? as f32,
                    "dtol" => spec.multires.depth_tolerance = num(v)? as f32,
                    "cs" => spec.multires.cone_scale = num(v)? as f32,
                    "mip" => spec.multires.no_mipmap = num(v)? == 0.0,
                    "primary" => spec.multires.primary_only = num(v)? != 0.0,
                    "budget" => spec.multires.time_budget = Some(num(v)?),
                    "tri" => {
                        spec.multires.tri_weight = crate::multires::trace::TriWeight::from_str(v, true)
                            .map_err(|_| bad(format!("tri={v}: paper or coverage")))?
                    }
                    "eigen" => {
                        spec.multires.eigen = crate::multires::trace::EigenMode::from_str(v, true)
                            .map_err(|_| bad(format!("eigen={v}: per-box or exact")))?
                    }
                    _ => {
                        return Err(bad(format!(
                            "unknown key '{k}' (spp, threads, packet, fps, vt, depth; cone tracers: k, c, clamp, lod, dtol, cs, mip, primary, budget, eigen, tri)"
                        )))
                    }
                }
            } else {
                spec.accel = AccelKind::from_str(p, true).map_err(|_| bad(format!("unknown accel '{p}' (embree, bvh, octree)")))?;
            }
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
        self.text.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect()
    }
}

pub fn parse_list(s: &str) -> Result<Vec<MethodSpec>> {
    let v: Vec<MethodSpec> = s.split(',').filter(|p| !p.trim().is_empty()).map(MethodSpec::parse).collect::<Result<_>>()?;
    if v.is_empty() {
        return Err(Error::Usage("--methods is empty".into()));
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
    pub rmse: Option<f64>,
    pub psnr: Option<f64>,
    pub flip: Option<f64>,
    pub image: Option<String>,
}

#[derive(Serialize, Debug, Clone)]
pub struct BenchReport {
    pub width: u32,
    pub height: u32,
    pub reference: Option<String>,
    pub rows: Vec<BenchRow>,
}

/// Renders `spec` on `scene` (best of `repeat` renders).
pub fn run_spec(
    scene: &Scene,
    spec: &MethodSpec,
    width: u32,
    height: u32,
    threads: usize,
    repeat: u32,
    quiet: bool,
) -> Result<(Film, run::Stats)> {
    let mut sc;
    let scene = if let Some(d) = spec.max_depth {
        sc = scene.clone();
        sc.max_depth = d;
        &sc
    } else {
        scene
    };
    let opts = spec.opts(width, height, threads, quiet);
    let mut best: Option<run::RunResult> = None;
    for _ in 0..repeat.max(1) {
        let r = run::run(scene, spec.method, spec.accel, &opts, &spec.multires)?;
        if best.as_ref().is_none_or(|b| r.out.seconds < b.out.seconds) {
            best = Some(r);
        }
    }
    let r = best.expect("at least one run");
    let stats = r.stats(scene, spec.method, spec.accel, &opts);
    Ok((r.out.film, stats))
}

/// Errors of `film` against `reference`: (RMSE, PSNR dB, mean FLIP) and the FLIP error map.
pub fn errors(film: &Film, reference: &Film) -> Result<(f64, f64, f64, image::RgbImage)> {
    use crate::film::metrics;
    let (w, h) = (film.width, film.height);
    if (w, h) != (reference.width, reference.height) {
        return Err(Error::Usage(format!("image {w}x{h} and reference {}x{} differ in size", reference.width, reference.height)));
    }
    let rmse = metrics::rmse(&reference.color, &film.color, w, h);
    let psnr = metrics::psnr(&reference.color, &film.color, w, h);
    let (flip, map) = metrics::flip_mean(&reference.color, &film.color, w, h)?;
    Ok((rmse, psnr, flip, map))
}

pub fn run(a: &BenchArgs) -> Result<()> {
    let report = bench(a)?;
    print_table(&report);
    Ok(())
}

/// Runs the whole bench and writes its outputs; returns the report.
pub fn bench(a: &BenchArgs) -> Result<BenchReport> {
    let specs = parse_list(&a.methods)?;
    let reference = a.reference.as_deref().map(MethodSpec::parse).transpose()?;
    // Validate everything before the first (possibly long) render.
    for s in specs.iter().chain(reference.iter()) {
        s.opts(a.width, a.height, a.threads, true).validate()?;
    }
    if let Some(out) = &a.out {
        std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    }
    let scenes: Vec<Scene> = a.scenes.iter().map(|s| crate::scene::load::load_scene(s)).collect::<Result<_>>()?;
    let mut rows = Vec::new();
    for scene in &scenes {
        let ref_film = match &reference {
            Some(r) => {
                let (film, _) = run_spec(scene, r, a.width, a.height, a.threads, 1, a.quiet)?;
                if let Some(out) = &a.out {
                    crate::film::io::write_png(&out.join(format!("{}-reference-{}.png", scene.name, r.slug())), &film)?;
                }
                Some(film)
            }
            None => None,
        };
        let mut first_time = None;
        for spec in &specs {
            let (film, stats) = run_spec(scene, spec, a.width, a.height, a.threads, a.repeat, a.quiet)?;
            let t0 = *first_time.get_or_insert(stats.render_seconds);
            let (rmse, psnr, flip) = match &ref_film {
                Some(r) => {
                    let (x, y, z, map) = errors(&film, r)?;
                    if let Some(out) = &a.out {
                        crate::film::io::write_rgb8_png(&out.join(format!("{}-{}-flip.png", scene.name, spec.slug())), &map)?;
                    }
                    // PSNR is +inf for an identical image; JSON has no infinity.
                    (Some(x), y.is_finite().then_some(y), Some(z))
                }
                None => (None, None, None),
            };
            let image = match &a.out {
                Some(out) => {
                    let name = format!("{}-{}.png", scene.name, spec.slug());
                    crate::film::io::write_png(&out.join(&name), &film)?;
                    Some(name)
                }
                None => None,
            };
            if !a.quiet {
                eprintln!("  {} {}: render {:.3} s", scene.name, spec.text, stats.render_seconds);
            }
            rows.push(BenchRow {
                scene: scene.name.clone(),
                spec: spec.text.clone(),
                speedup_vs_first: t0 / stats.render_seconds.max(1e-12),
                stats,
                rmse,
                psnr,
                flip,
                image,
            });
        }
    }
    let report = BenchReport { width: a.width, height: a.height, reference: a.reference.clone(), rows };
    if let Some(out) = &a.out {
        write_outputs(out, &report)?;
    }
    Ok(report)
}

fn write_outputs(out: &Path, report: &BenchReport) -> Result<()> {
    let json = serde_json::to_string_pretty(report).expect("report serialises");
    let p = out.join("bench.json");
    crate::film::io::write_atomic(&p, |tmp| std::fs::write(tmp, json).map_err(|e| Error::io(&p, e)))?;
    let p = out.join("bench.md");
    let md = table_string(report);
    crate::film::io::write_atomic(&p, |tmp| std::fs::write(tmp, md).map_err(|e| Error::io(&p, e)))?;
    let bars: Vec<(String, f64)> = report.rows.iter().map(|r| (format!("{} {}", r.scene, r.spec), r.stats.render_seconds)).collect();
    super::plot::bar_chart(&out.join("bench-time.png"), &format!("Render time, {}x{}", report.width, report.height), "seconds", &bars)?;
    // Error against the reference versus time, one curve per scene: the trade-off a
    // multi-resolution method is meant to win.
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for r in &report.rows {
        if let Some(flip) = r.flip {
            match series.iter_mut().find(|(n, _)| *n == r.scene) {
                Some((_, v)) => v.push((r.stats.render_seconds, flip)),
                None => series.push((r.scene.clone(), vec![(r.stats.render_seconds, flip)])),
            }
        }
    }
    if !series.is_empty() {
        for (_, v) in &mut series {
            v.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
        super::plot::line_chart(
            &out.join("bench-error.png"),
            "Error against the reference vs render time",
            "render time (s)",
            "mean FLIP",
            &series,
        )?;
    }
    Ok(())
}

/// The table as Markdown (printed to stdout and written to bench.md).
pub fn table_string(report: &BenchReport) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "{}x{}{}\n\n",
        report.width,
        report.height,
        report.reference.as_ref().map(|r| format!(", errors against {r}")).unwrap_or_default()
    ));
    s.push_str("| scene | method | thr | build s | render s | Mrays/s | speed-up vs first | RMSE | PSNR dB | FLIP | triangle tests | node tests |\n");
    s.push_str("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in &report.rows {
        let f = |x: Option<f64>, p: usize| x.map(|v| format!("{v:.p$}")).unwrap_or_else(|| "-".into());
        s.push_str(&format!(
            "| {} | {} | {} | {:.3} | {:.3} | {:.2} | {:.2}x | {} | {} | {} | {} | {} |\n",
            r.scene,
            r.spec,
            r.stats.threads,
            r.stats.build_seconds,
            r.stats.render_seconds,
            r.stats.mrays_per_second,
            r.speedup_vs_first,
            f(r.rmse, 4),
            f(r.psnr, 2),
            f(r.flip, 4),
            r.stats.counters.get("triangle_tests").copied().unwrap_or(0),
            r.stats.counters.get("node_tests").copied().unwrap_or(0),
        ));
    }
    s
}

pub fn print_table(report: &BenchReport) {
    print!("{}", table_string(report));
}

#[cfg(test)]
mod tests {
    use super::*;
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
        assert!(parse_list("whitted:gpu").is_err());
        assert!(parse_list("whitted:spp=x").is_err());
    }
}
