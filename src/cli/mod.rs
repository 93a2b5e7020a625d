//! The command line of DESIGN.md (a contract). One file per subcommand; `main.rs` is thin.
//! Every error is printed as one line; bad input or usage exits 2, a failed check exits 1.

pub mod animate;
pub mod compare;
pub mod render;
pub mod scenes;
pub mod verify;

use crate::baseline::accel::AccelKind;
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

#[derive(Parser, Debug)]
#[command(name = "lodtrace", version, about = "Multi-resolution ray tracing research tool: render, verify against Embree, compare, bench")]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a scene with one method.
    // Negative numbers are values (`--fovy -1` gets its range error, not "unexpected argument").
    #[command(allow_negative_numbers = true)]
    Render(RenderArgs),
    /// Cross-check an intersector against Embree on camera and random rays (exit 1 on disagreement).
    #[command(allow_negative_numbers = true)]
    Verify(verify::VerifyArgs),
    /// Compare two images: RMSE, PSNR, mean FLIP, SSIM.
    #[command(allow_negative_numbers = true)]
    Compare(compare::CompareArgs),
    /// Run several methods on the same scenes and print a side-by-side table.
    #[command(allow_negative_numbers = true)]
    Bench(crate::experiment::bench::BenchArgs),
    /// Ray trace a deforming point-sampled scene frame by frame (Adams et al.): a built-in sequence or a mesh dropped onto a floor.
    #[command(allow_negative_numbers = true)]
    Animate(animate::AnimateArgs),
    /// List the built-in scenes.
    Scenes,
    /// The main job: render the built-in scenes with every method, write images, tables, plots and an index page.
    #[command(allow_negative_numbers = true)]
    Demo(crate::experiment::demo::DemoArgs),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Conventional ray tracing, one ray per sample (the baselines).
    Whitted,
    /// Distributed ray tracing: adaptive supersampling, soft shadows, glossy, depth of field.
    Distributed,
    /// Wand & Straßer's multi-resolution point-sample cone tracer.
    Multires,
    /// Classic cone tracing: the multires tracer without its points.
    Cone,
    /// Papaioannou et al.'s per-ray level of detail from ray disparity.
    Lod,
    /// Adams et al.'s surfel ray tracer: the first frame of a deforming sequence, or of a mesh
    /// (.obj/.off) or point file (.ply) sampled into surfels (`lodtrace animate` renders all frames).
    Surfel,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Whitted => "whitted",
            Method::Distributed => "distributed",
            Method::Multires => "multires",
            Method::Cone => "cone",
            Method::Lod => "lod",
            Method::Surfel => "surfel",
        }
    }
}

/// Camera overrides, shared by the commands that render.
#[derive(Args, Debug, Clone, Default)]
pub struct CameraArgs {
    /// Camera position `X,Y,Z` (default: the scene's).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<glam::Vec3>,
    /// Point the camera looks at, `X,Y,Z` (default: the scene's).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub look: Option<glam::Vec3>,
    /// Camera up vector, `X,Y,Z` (default: the scene's).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<glam::Vec3>,
    /// Vertical field of view in degrees, in (0, 180) (default: the scene's).
    #[arg(long)]
    pub fovy: Option<f32>,
}

#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// Built-in scene name, .obj/.off mesh, or .toml scene file; with `--method surfel`, a
    /// built-in sequence (`lodtrace animate --help`), a mesh or a .ply point file.
    pub scene: String,
    #[arg(long, value_enum, default_value = "whitted")]
    pub method: Method,
    /// Triangle tracers' acceleration structure [default: embree]: whitted and distributed
    /// take embree, bvh or octree (the cone tracers' octree without points), lod embree or
    /// bvh; multires and cone trace their own octree, surfel its sphere tree, and refuse it.
    #[arg(long, value_enum)]
    pub accel: Option<AccelKind>,
    #[arg(long, default_value_t = 640, value_parser = clap::value_parser!(u32).range(1..=32768))]
    pub width: u32,
    #[arg(long, default_value_t = 480, value_parser = clap::value_parser!(u32).range(1..=32768))]
    pub height: u32,
    /// Samples per pixel (whitted: jittered when > 1; distributed: the maximum per pixel).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Output image (default render.png): `.png` is 8-bit sRGB, `.exr` linear float.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// AOV output (repeatable): `depth=`, `normal=`, `color=FILE.exr`; `disparity-r|t=`,
    /// `lod-r|t=FILE.png` (--method lod); `cost=FILE.png|.exr` (--method multires, cone: tests
    /// per pixel, log-scale heat map or counts).
    #[arg(long, value_parser = parse_aov)]
    pub aov: Vec<(String, PathBuf)>,
    /// Statistics as JSON: times, counters, hierarchy and per-cone-kind profile (`-`: to
    /// standard output; `none`: not written).
    #[arg(long)]
    pub stats: Option<PathBuf>,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Seed of the random sampling (jitter, distributed rays): same seed, same image.
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// Packet width for primary rays: 1 (single rays) or 8.
    #[arg(long, default_value_t = 8)]
    pub packet: u32,
    /// Distributed: samples per pixel of the first (fixed, jittered) pass.
    #[arg(long, default_value_t = 2)]
    pub first_pass_spp: u32,
    /// Distributed: luminance variance (over 5×5 pixels) above which a pixel gets the second pass.
    #[arg(long, default_value_t = 0.001)]
    pub variance_threshold: f32,
    /// Recursion depth limit for reflection/refraction (default: the scene's).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Every light counts as visible: no shadow rays or cones (a diagnostic, to split shading
    /// from visibility; every method: whitted, distributed, lod, multires, cone and surfel).
    #[arg(long)]
    pub no_shadows: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Explain one pixel instead of rendering (--method multires, cone): its primary cone's
    /// A-buffer, front to back (depth interval, weights, mesh, alpha, share of the pixel,
    /// colour), and the tests it took. X,Y from the top left; writes no image.
    #[arg(long, value_parser = parse_pixel, allow_hyphen_values = true)]
    pub debug_pixel: Option<(u32, u32)>,
    #[command(flatten)]
    pub multires: crate::multires::MultiresArgs,
    #[command(flatten)]
    pub lod: crate::lod::LodArgs,
}

fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    let v: Vec<u32> = s.split(',').map(|x| x.trim().parse::<u32>()).collect::<Result<_, _>>().map_err(|e| format!("'{s}': {e}"))?;
    match v[..] {
        [x, y] => Ok((x, y)),
        _ => Err(format!("'{s}': expected a pixel x,y")),
    }
}

pub fn parse_vec3(s: &str) -> Result<glam::Vec3, String> {
    let v: Vec<f32> = s.split(',').map(|x| x.trim().parse::<f32>()).collect::<Result<_, _>>().map_err(|e| format!("'{s}': {e}"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("'{s}': expected three finite numbers x,y,z"));
    }
    Ok(glam::Vec3::new(v[0], v[1], v[2]))
}

/// AOV names: EXR depth, normal, colour; PNG maps of `--method lod` (disparities d_r, d_t
/// ×20, and the level-1 LOD of the reflected / transmitted rays); `cost`, the cone tracers'
/// tests per pixel (PNG heat map or EXR counts).
pub const AOVS: &[&str] = &["depth", "normal", "color", "disparity-r", "disparity-t", "lod-r", "lod-t", "cost"];

fn parse_aov(s: &str) -> Result<(String, PathBuf), String> {
    let (k, v) = s.split_once('=').ok_or_else(|| format!("'{s}': expected KIND=FILE, KIND one of {}", AOVS.join(", ")))?;
    if !AOVS.contains(&k) {
        return Err(format!("unknown AOV '{k}' ({})", AOVS.join(", ")));
    }
    if v.is_empty() {
        return Err(format!("AOV '{k}' needs a file name"));
    }
    Ok((k.to_string(), PathBuf::from(v)))
}

/// `none` for an optional output (`--stats none`, `bench --out none`, `verify --json none`)
/// means no output, as `animate --out none` does ([`animate::none_outputs`]); until stop 82
/// these wrote a file or folder named `none`.
pub(crate) fn none_is_absent(p: &mut Option<PathBuf>) {
    if p.as_deref().is_some_and(|p| p.as_os_str() == "none") {
        *p = None;
    }
}

/// Runs a parsed command; returns the process exit code.
pub fn run(cli: Cli) -> i32 {
    let mut cmd = cli.cmd;
    match &mut cmd {
        Command::Render(a) => none_is_absent(&mut a.stats),
        Command::Bench(a) => none_is_absent(&mut a.out),
        Command::Verify(a) => none_is_absent(&mut a.json),
        _ => {}
    }
    // Before any thread pool is made (rayon reads the variables when it builds one).
    let r = crate::core::check_thread_env().and_then(|()| match cmd {
        Command::Render(a) => render::run(&a).map(|_| 0),
        Command::Verify(a) => verify::run(&a),
        Command::Compare(a) => compare::run(&a),
        Command::Bench(a) => crate::experiment::bench::run(&a).map(|_| 0),
        Command::Animate(a) => animate::run(&a).map(|_| 0),
        Command::Scenes => scenes::run().map(|_| 0),
        Command::Demo(a) => crate::experiment::demo::run(&a).map(|_| 0),
    });
    match r {
        Ok(code) => {
            crate::error::flush_warnings();
            code
        }
        Err(e) => {
            crate::error::discard_warnings();
            // An error caused by an interrupt's clean-up (its folder removed under a writer)
            // is not reported: the signal thread reports the interrupt and ends the process.
            crate::film::io::halt_if_interrupted();
            crate::status!("lodtrace: error: {}", crate::error::one_line(&e.to_string()));
            2
        }
    }
}

/// Test support: every `lodtrace SUB …` line of the README (shell continuation lines joined as
/// the shell joins them, `#` comments dropped) with its arguments parsed by clap into `A`;
/// panics naming the line if clap refuses one. The README-command tests of bench, render and
/// animate check these against their subcommand's option checks.
#[cfg(test)]
pub(crate) fn readme_commands<A: clap::Args>(sub: &str) -> Vec<(String, A)> {
    let readme = std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap().replace("\\\n", "");
    let prefix = format!("lodtrace {sub} ");
    readme
        .lines()
        .filter_map(|line| line.trim().strip_prefix(prefix.as_str()))
        .map(|cmd| {
            // A comment, or a pipe into another program (`--stats - | jq`), ends the command.
            let words = std::iter::once(sub).chain(cmd.split('#').next().unwrap().split(" | ").next().unwrap().split_whitespace());
            let parsed = A::augment_args(clap::Command::new("lodtrace"))
                .try_get_matches_from(words)
                .map_err(|e| e.to_string())
                .and_then(|m| A::from_arg_matches(&m).map_err(|e| e.to_string()));
            match parsed {
                Ok(a) => (format!("lodtrace {sub} {cmd}"), a),
                Err(e) => panic!("README: lodtrace {sub} {cmd}\n{e}"),
            }
        })
        .collect()
}
