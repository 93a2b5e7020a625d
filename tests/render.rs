//! Integrator tests: known-answer shading, determinism across thread counts, packet widths
//! agree, distributed convergence, and the `render` command's outputs.

use glam::Vec3;
use lodtrace::baseline::accel::{self, AccelKind};
use lodtrace::baseline::render::{render, Integrator, RenderOpts};
use lodtrace::baseline::shade::TraceCtx;
use lodtrace::film::Film;
use lodtrace::scene::{builtin, Scene};

fn accels() -> Vec<AccelKind> {
    let mut v = vec![AccelKind::Bvh];
    if cfg!(feature = "embree") {
        v.push(AccelKind::Embree);
    }
    v
}

fn render_scene(scene: &Scene, kind: AccelKind, opts: &RenderOpts) -> Film {
    let leaves = scene.leaf_instances().unwrap();
    let acc = accel::build(kind, scene).unwrap();
    let ctx = TraceCtx { scene, leaves: &leaves, accel: acc.as_ref(), max_depth: scene.max_depth };
    let cam = scene.camera.frame(opts.width, opts.height);
    render(&ctx, &cam, opts).unwrap().film
}

fn rmse(a: &Film, b: &Film) -> f64 {
    let s: f64 = a.color.iter().zip(&b.color).map(|(x, y)| (*x - *y).length_squared() as f64 / 3.0).sum();
    (s / a.color.len() as f64).sqrt()
}

#[test]
fn diffuse_plane_under_point_light_has_analytic_radiance() {
    let mut scene = builtin::plane();
    scene.validate().unwrap();
    for kind in accels() {
        let opts = RenderOpts { width: 65, height: 65, ..Default::default() };
        let film = render_scene(&scene, kind, &opts);
        // Centre pixel: the point straight below the light, d = 2, cosθ = 1.
        let expect = 0.5 / std::f32::consts::PI * 10.0 / 4.0;
        let c = film.color[film.index(32, 32)];
        assert!((c.x - expect).abs() < 1e-4 * expect.max(1.0), "{kind:?}: {c} vs {expect}");
        assert!((film.depth[film.index(32, 32)] - 3.0).abs() < 1e-4);
        assert!((film.normal[film.index(32, 32)] - Vec3::Y).length() < 1e-5);
        // Off centre, the inverse-square and cosine laws: pixel (i,j) hits point p on y = 0.
        let cam = scene.camera.frame(65, 65);
        for (i, j) in [(10, 32), (50, 12), (5, 60)] {
            let d = cam.pixel_center_dir(i, j);
            let t = -cam.eye.y / d.y;
            let p = cam.eye + d * t;
            if p.x.abs() > 1.0 || p.z.abs() > 1.0 {
                continue;
            }
            let l = Vec3::new(0.0, 2.0, 0.0) - p;
            let e = 10.0 * (l.normalize().y) / l.length_squared();
            let expect = 0.5 / std::f32::consts::PI * e;
            let c = film.color[film.index(i, j)];
            assert!((c.x - expect).abs() < 1e-4, "{kind:?} pixel ({i},{j}): {} vs {expect}", c.x);
            assert!((film.depth[film.index(i, j)] - t).abs() < 1e-3 * t);
        }
    }
}

#[test]
fn images_are_identical_for_any_thread_count() {
    let mut scene = builtin::spheres();
    scene.validate().unwrap();
    for integrator in [Integrator::Whitted, Integrator::Distributed] {
        let o1 = RenderOpts { integrator, width: 48, height: 36, spp: 6, threads: 1, ..Default::default() };
        let o2 = RenderOpts { threads: 2, ..o1.clone() };
        let a = render_scene(&scene, AccelKind::Bvh, &o1);
        let b = render_scene(&scene, AccelKind::Bvh, &o2);
        assert!(a.color == b.color, "{integrator:?}: images differ between 1 and 2 threads");
        let o3 = RenderOpts { seed: 7, ..o1.clone() };
        let c = render_scene(&scene, AccelKind::Bvh, &o3);
        assert!(a.color != c.color, "{integrator:?}: the seed changes nothing");
    }
}

#[test]
fn packet_and_single_ray_primary_paths_agree() {
    let mut scene = builtin::spheres();
    scene.validate().unwrap();
    for kind in accels() {
        let o8 = RenderOpts { width: 61, height: 37, packet: 8, ..Default::default() };
        let o1 = RenderOpts { packet: 1, ..o8.clone() };
        let a = render_scene(&scene, kind, &o8);
        let b = render_scene(&scene, kind, &o1);
        let differ = a.color.iter().zip(&b.color).filter(|(x, y)| (**x - **y).abs().max_element() > 1e-5).count();
        assert_eq!(differ, 0, "{kind:?}: {differ} pixels differ between packet widths 1 and 8");
    }
}

#[cfg(feature = "embree")]
#[test]
fn bvh_and_embree_render_the_same_image() {
    let mut scene = builtin::spheres();
    scene.validate().unwrap();
    let o = RenderOpts { width: 80, height: 60, ..Default::default() };
    let a = render_scene(&scene, AccelKind::Bvh, &o);
    let b = render_scene(&scene, AccelKind::Embree, &o);
    let differ = a.color.iter().zip(&b.color).filter(|(x, y)| (**x - **y).abs().max_element() > 1e-3).count();
    // Edge pixels may differ where the two intersectors pick different triangles of a shared edge.
    assert!(differ <= a.color.len() / 200, "{differ} of {} pixels differ", a.color.len());
}

#[test]
fn distributed_converges_to_its_reference() {
    let mut scene = builtin::spheres();
    scene.validate().unwrap();
    let base = RenderOpts { integrator: Integrator::Distributed, width: 40, height: 30, variance_threshold: 0.0, ..Default::default() };
    let reference = render_scene(&scene, AccelKind::Bvh, &RenderOpts { spp: 402, seed: 99, ..base.clone() });
    let e4 = rmse(&render_scene(&scene, AccelKind::Bvh, &RenderOpts { spp: 6, ..base.clone() }), &reference);
    let e64 = rmse(&render_scene(&scene, AccelKind::Bvh, &RenderOpts { spp: 66, ..base.clone() }), &reference);
    // Monte Carlo error falls roughly as 1/sqrt(n): 16× the samples, about 1/4 the error.
    assert!(e64 < e4 * 0.5, "rmse 6 spp {e4}, 66 spp {e64}");
    // And the Whitted image (point-light shadows, no anti-aliasing) is farther away than 66 spp.
    let w = rmse(&render_scene(&scene, AccelKind::Bvh, &RenderOpts { integrator: Integrator::Whitted, ..base.clone() }), &reference);
    assert!(w > e64, "whitted {w} vs distributed {e64}");
}

#[test]
fn adaptive_pass_refines_only_high_variance_pixels() {
    let mut scene = builtin::spheres();
    scene.validate().unwrap();
    let leaves = scene.leaf_instances().unwrap();
    let acc = accel::build(AccelKind::Bvh, &scene).unwrap();
    let ctx = TraceCtx { scene: &scene, leaves: &leaves, accel: acc.as_ref(), max_depth: scene.max_depth };
    let cam = scene.camera.frame(64, 48);
    let o = RenderOpts { integrator: Integrator::Distributed, width: 64, height: 48, spp: 18, ..Default::default() };
    let adaptive = render(&ctx, &cam, &o).unwrap();
    let all = render(&ctx, &cam, &RenderOpts { variance_threshold: 0.0, ..o.clone() }).unwrap();
    use lodtrace::core::stats::Counter;
    let refined = adaptive.counters.get(Counter::pixels_refined);
    assert!(refined > 0 && refined < 64 * 48, "refined {refined}");
    assert_eq!(all.counters.get(Counter::pixels_refined), 64 * 48);
    // 2 first-pass samples + 4×4 in refined pixels.
    assert_eq!(adaptive.counters.get(Counter::samples), 64 * 48 * 2 + refined * 16);
}

#[test]
fn render_command_writes_png_and_stats() {
    let dir = std::env::temp_dir().join(format!("lodtrace-render-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("a.png");
    let json = dir.join("a.json");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_lodtrace"))
        .args(["render", "spheres", "--accel", "bvh", "--width", "32", "--height", "24", "--quiet", "--out"])
        .arg(&png)
        .arg("--stats")
        .arg(&json)
        .status()
        .unwrap();
    assert!(st.success());
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (32, 24));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for k in ["method", "accel", "width", "height", "spp", "build_seconds", "render_seconds", "counters"] {
        assert!(v.get(k).is_some(), "stats lack {k}");
    }
    assert_eq!(v["counters"]["rays_primary"], 32 * 24);
    assert!(v["counters"]["triangle_tests"].as_u64().unwrap() > 0);
    std::fs::remove_dir_all(&dir).ok();
}

/// The same scene shrunk by 1e-4, moved 1e3 from the origin, or seen from 100× farther
/// through a 100× narrower lens renders as at unit scale with the Whitted, LOD and multires
/// tracers (mean FLIP against the unit-scale frame). Until stop 77 secondary rays left a hit
/// at 1e-4·(1 + |p|): at scale 1e-4 that is the balls' size (shadows gone, FLIP 0.11 for
/// Whitted and LOD, 0.02 for multires), and Whitted's and LOD's hit point ray.org + t·dir
/// carried the camera distance's rounding (precision review).
#[test]
fn a_scene_renders_alike_at_any_scale_and_distance() {
    use lodtrace::baseline::accel::AccelKind;
    use lodtrace::baseline::render::RenderOpts;
    use lodtrace::cli::Method;
    use lodtrace::experiment::run;
    use lodtrace::lod::LodArgs;
    use lodtrace::multires::MultiresArgs;
    // (scale S, translation T, camera distance factor K): eye = look + K·(eye₀ − look₀),
    // the field of view narrowed so the framing stays.
    let toml = |s: f32, t: [f32; 3], k: f32| -> String {
        let v = |x: [f32; 3]| format!("[{}, {}, {}]", x[0] * s + t[0], x[1] * s + t[1], x[2] * s + t[2]);
        let (eye0, look0) = ([0.5f32, 3.2, 8.5], [0.0f32, 0.8, 0.0]);
        let eye = std::array::from_fn(|i| look0[i] + k * (eye0[i] - look0[i]));
        let fovy = 2.0 * ((22.5f32).to_radians().tan() / k).atan().to_degrees();
        format!(
            r#"name = "scaled"
background = [0.45, 0.55, 0.75]
ambient = 0.08
max_depth = 4
[camera]
eye = {eye}
look = {look}
fovy = {fovy}
[materials.white]
color = 0.8
[materials.black]
color = 0.05
[materials.red]
color = [0.7, 0.05, 0.05]
reflect = 0.45
[materials.glass]
color = 1
kd = 0.05
ks = 0.8
reflect = 0.08
transmit = 0.88
ior = 1.5
[meshes.board]
generator = "checkerboard"
n = 8
size = 12.0
material = "white"
material_b = "black"
[meshes.ball]
generator = "sphere"
stacks = 21
slices = 23
[[groups.world.instances]]
target = "board"
[[groups.world.instances]]
target = "ball"
translate = [-1.6, 1.3, -1.0]
scale = 1.3
material = "red"
[[groups.world.instances]]
target = "ball"
translate = [1.4, 1.1, 1.2]
scale = 1.1
material = "glass"
[[instances]]
target = "world"
translate = [{}, {}, {}]
scale = {s}
[[lights]]
type = "point"
pos = {light}
intensity = {int}
"#,
            t[0],
            t[1],
            t[2],
            eye = v(eye),
            look = v(look0),
            light = v([5.0, 4.0, 6.0]),
            int = 15.0 * s * s,
        )
    };
    let dir = std::env::temp_dir().join(format!("lodtrace-scaled-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let render = |name: &str, text: String, m: Method| {
        let p = dir.join(format!("{name}.toml"));
        std::fs::write(&p, text).unwrap();
        let scene = lodtrace::scene::load::load_scene(p.to_str().unwrap()).unwrap();
        let o = RenderOpts { width: 80, height: 60, spp: 1, threads: 2, ..Default::default() };
        run::run(&scene, m, AccelKind::Bvh, &o, &MultiresArgs::default(), &LodArgs::default()).unwrap().out.film.color
    };
    for m in [Method::Whitted, Method::Lod, Method::Multires] {
        let unit = render("unit", toml(1.0, [0.0; 3], 1.0), m);
        for (name, s, t, tol) in [("small", 1e-4f32, [0.0f32; 3], 0.002), ("moved", 1.0, [1e3, 5e2, -7e2], 0.005)] {
            let img = render(name, toml(s, t, 1.0), m);
            let (flip, _) = lodtrace::film::metrics::flip_mean(&unit, &img, 80, 60).unwrap();
            assert!(flip < tol, "{m:?}, {name}: mean FLIP {flip} against unit scale");
        }
        // A far camera: 1,000 against 10,000 times as far (both nearly orthographic).
        let (a, b) = (render("far3", toml(1.0, [0.0; 3], 1e3), m), render("far4", toml(1.0, [0.0; 3], 1e4), m));
        let (flip, _) = lodtrace::film::metrics::flip_mean(&a, &b, 80, 60).unwrap();
        assert!(flip < 0.02, "{m:?}: mean FLIP {flip} between cameras 1e3 and 1e4 times as far");
    }
    std::fs::remove_dir_all(&dir).ok();
}
