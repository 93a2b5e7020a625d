//! Wand & Straßer cone tracers: the tests. Known answers (an opaque plane composites
//! to alpha 1 and its exact colour), the weight-sum invariant of the point hierarchy,
//! anti-aliasing against a 256-spp reference, silhouettes against Embree's, degenerate input,
//! and packet width 1 vs 8 of the conventional tracer on the same octree.

use glam::{Affine3A, Mat3, Vec3};
use lodtrace::baseline::accel::{self, AccelKind};
use lodtrace::baseline::render::{render, Integrator, RenderOpts};
use lodtrace::baseline::shade::TraceCtx;
use lodtrace::core::eigen2::eigen_1;
use lodtrace::core::stats::Counters;
use lodtrace::film::Film;
use lodtrace::multires::abuffer::{ABuffer, Elem};
use lodtrace::multires::build::BuildParams;
use lodtrace::multires::cone::{self, Cone, Fp, Outgoing};
use lodtrace::multires::render::render as cone_render;
use lodtrace::multires::trace::{Collect, MultiresScene, Scratch, ShadeScratch, Termination, TraceParams, Tracer, TriWeight};
use lodtrace::scene::{builtin, Camera, Light, Material, Mesh, Scene, Target};
use std::sync::atomic::AtomicBool;

fn reference_accel() -> AccelKind {
    if cfg!(feature = "embree") {
        AccelKind::Embree
    } else {
        AccelKind::Bvh
    }
}

fn conventional(scene: &Scene, kind: AccelKind, opts: &RenderOpts) -> Film {
    let leaves = scene.leaf_instances().unwrap();
    let acc = accel::build(kind, scene).unwrap();
    let ctx = TraceCtx { scene, leaves: &leaves, accel: acc.as_ref(), max_depth: scene.max_depth };
    render(&ctx, &scene.camera.frame(opts.width, opts.height), opts).unwrap().film
}

fn cones(scene: &Scene, tp: &TraceParams, w: u32, h: u32) -> Film {
    let ms = MultiresScene::build(scene, &BuildParams::default()).unwrap();
    let opts = RenderOpts { width: w, height: h, ..Default::default() };
    cone_render(&ms, tp, &scene.camera.frame(w, h), &opts).unwrap().out.film
}

/// The distributed reference at 64 spp, every pixel fully sampled.
fn distributed_64(scene: &Scene, w: u32, h: u32) -> Film {
    conventional(
        scene,
        reference_accel(),
        &RenderOpts { integrator: Integrator::Distributed, width: w, height: h, spp: 64, variance_threshold: 0.0, ..Default::default() },
    )
}

/// A scene file shipped in `scenes/`.
fn shipped_scene(name: &str) -> Scene {
    lodtrace::scene::tomlscene::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("scenes/{name}.toml"))).unwrap()
}

fn rmse(a: &Film, b: &Film) -> f64 {
    let s: f64 = a.color.iter().zip(&b.color).map(|(x, y)| (*x - *y).length_squared() as f64 / 3.0).sum();
    (s / a.color.len() as f64).sqrt()
}

/// A 2×2 square in z = 0 facing +z, of colour `col`, seen head-on from z = `dist`.
fn square_scene(col: Vec3, dist: f32) -> Scene {
    let mut s = Scene::empty("square");
    s.materials[0] = Material::diffuse("c", col);
    // A finely tessellated square (so that the hierarchy has point levels), one colour.
    let id = s.add_mesh(builtin::checkerboard(64, 2.0, 0, 0));
    s.instance(Target::Mesh(id), Affine3A::from_rotation_x(std::f32::consts::FRAC_PI_2), None);
    s.camera = Camera { eye: Vec3::new(0.0, 0.0, dist), look: Vec3::ZERO, up: Vec3::Y, fovy: 30.0, aperture: 0.0, focal_dist: dist };
    s.lights.push(Light::Point { pos: Vec3::new(0.0, 0.0, dist), intensity: Vec3::splat(dist * dist) });
    s.ambient = Vec3::ZERO;
    s.background = Vec3::ZERO;
    s.validate().unwrap();
    s
}

/// Issue test: an opaque plane seen head-on composites to alpha 1 and to its exact colour,
/// both where the leaves' triangles are used (close) and where points are (far).
#[test]
fn opaque_plane_head_on_is_opaque_and_exact() {
    // Eye and light in front (+z) and behind (−z); cone scales where leaves' triangles
    // are used (0.5) and where points are (8, 16).
    for (dist, cone_scale) in [(4.0f32, 0.5f32), (4.0, 8.0), (4.0, 16.0), (-4.0, 8.0), (-4.0, 16.0)] {
        let mut scene = square_scene(Vec3::new(0.8, 0.4, 0.2), dist.abs());
        scene.camera.eye = Vec3::new(0.0, 0.0, dist);
        scene.lights[0] = Light::Point { pos: Vec3::new(0.0, 0.0, dist), intensity: Vec3::splat(dist * dist) };
        let ms = MultiresScene::build(&scene, &BuildParams::default()).unwrap();
        let tp = TraceParams { cone_scale, ..Default::default() };
        let abort = AtomicBool::new(false);
        let tr = Tracer::new(&ms, &tp, 1e-7, &abort, None);
        let cam = scene.camera.frame(64, 64);
        let mut ss = ShadeScratch::new(16, scene.max_depth);
        let mut c = Counters::default();
        // Expected: albedo/π · I·cosθ/d² with I = d² (light at the eye): albedo/π.
        let expect = Vec3::new(0.8, 0.4, 0.2) / std::f32::consts::PI;
        for (i, j) in [(32, 32), (28, 35), (36, 30)] {
            let r = tr.radiance(&Cone::primary(&cam, i, j, cone_scale, 1.0), 0, 1.0, &mut ss, &mut c);
            assert!(r.alpha >= 0.999, "alpha {} at ({i},{j}), cone scale {cone_scale}", r.alpha);
            // Exact up to 2%, triangles and points alike: the points sit at their samples'
            // mean, on the plane (at their voxel centres, h/2 off it on one side, the light
            // distance made the colour 7% / 14% too bright from the front at cone scale 8 /
            // 16, and 7% / 11% too dark from behind).
            let tol = 0.02;
            let err = (r.color - expect).abs().max_element() / expect.max_element();
            assert!(err < tol, "colour {} vs {expect} at ({i},{j}), cone scale {cone_scale}", r.color);
        }
        if cone_scale > 1.0 {
            assert!(c.get(lodtrace::core::stats::Counter::surfel_tests) > 0, "the far case must use points");
        }
    }
}

/// Instance-level points (`multires::group`, a completion of the paper for instanced
/// scenes): a floor of 24×24 instanced tiles seen head-on by cones several tiles wide is
/// still opaque and exactly coloured when the cones stop at slots of the instance tree, the
/// traversal visits far fewer nodes than instance by instance, and the two images agree.
#[test]
fn instance_level_points_keep_a_tiled_floor_opaque_and_exact() {
    let dist = 40.0f32;
    let mut scene = Scene::empty("tiled floor");
    scene.materials[0] = Material::diffuse("c", Vec3::new(0.8, 0.4, 0.2));
    let tile = scene.add_mesh(builtin::checkerboard(8, 1.0, 0, 0));
    for i in -12..12 {
        for j in -12..12 {
            let xf = Affine3A::from_translation(Vec3::new(i as f32 + 0.5, j as f32 + 0.5, 0.0))
                * Affine3A::from_rotation_x(std::f32::consts::FRAC_PI_2);
            scene.instance(Target::Mesh(tile), xf, None);
        }
    }
    scene.camera = Camera { eye: Vec3::new(0.0, 0.0, dist), look: Vec3::ZERO, up: Vec3::Y, fovy: 30.0, aperture: 0.0, focal_dist: dist };
    scene.lights.push(Light::Point { pos: Vec3::new(0.0, 0.0, dist), intensity: Vec3::splat(dist * dist) });
    scene.ambient = Vec3::ZERO;
    scene.background = Vec3::ZERO;
    scene.validate().unwrap();
    let ms = MultiresScene::build(&scene, &BuildParams::default()).unwrap();
    assert!(!ms.groups.points.is_empty());
    let abort = AtomicBool::new(false);
    let cam = scene.camera.frame(64, 64);
    let expect = Vec3::new(0.8, 0.4, 0.2) / std::f32::consts::PI;
    let cone_scale = 12.0;
    let mut node_tests = vec![];
    let mut colours = vec![];
    for group_points in [true, false] {
        let tp = TraceParams { cone_scale, group_points, ..Default::default() };
        let tr = Tracer::new(&ms, &tp, 1e-7, &abort, None);
        let mut ss = ShadeScratch::new(16, scene.max_depth);
        let mut c = Counters::default();
        let mut cols = vec![];
        for (i, j) in [(32, 32), (26, 35), (38, 29), (30, 24), (35, 40)] {
            let r = tr.radiance(&Cone::primary(&cam, i, j, cone_scale, 1.0), 0, 1.0, &mut ss, &mut c);
            assert!(r.alpha >= 0.999, "alpha {} at ({i},{j}), group points {group_points}", r.alpha);
            let err = (r.color - expect).abs().max_element() / expect.max_element();
            assert!(err < 0.05, "colour {} vs {expect} at ({i},{j}), group points {group_points}", r.color);
            cols.push(r.color);
        }
        node_tests.push(c.get(lodtrace::core::stats::Counter::node_tests) + c.get(lodtrace::core::stats::Counter::instance_tests));
        colours.push(cols);
    }
    assert!(node_tests[0] * 3 < node_tests[1], "node + instance tests with / without group points: {node_tests:?}");
    for (a, b) in colours[0].iter().zip(&colours[1]) {
        assert!((*a - *b).abs().max_element() < 0.03 * expect.max_element(), "{a} vs {b}");
    }
}

/// An 8×8 plane (128×128 cells, one colour) through the origin with unit normal `n`, seen
/// from 4 units away along `n` turned by `view` radians, in mesh space (the hierarchy is
/// built there, so the plane is tilted against the octree's axes).
fn tilted_plane_scene(n: Vec3, view: f32) -> Scene {
    let mut scene = square_scene(Vec3::splat(0.5), 4.0);
    scene.meshes[0] = builtin::checkerboard(128, 8.0, 0, 0);
    let r = glam::Quat::from_rotation_arc(Vec3::Y, n);
    let m = &mut scene.meshes[0];
    for v in 0..m.px.len() {
        let p = r * Vec3::new(m.px[v], m.py[v], m.pz[v]);
        (m.px[v], m.py[v], m.pz[v]) = (p.x, p.y, p.z);
        let q = r * Vec3::new(m.nx[v], m.ny[v], m.nz[v]);
        (m.nx[v], m.ny[v], m.nz[v]) = (q.x, q.y, q.z);
    }
    let root = scene.root as usize;
    scene.groups[root].children[0].xform = Affine3A::IDENTITY;
    let side = n.cross(if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Z }).normalize();
    scene.camera.eye = glam::Quat::from_axis_angle(side, view) * n * 4.0;
    scene.camera.up = side;
    scene.validate().unwrap();
    scene
}

/// Issue test: weight sums ≥ 1 inside a surface at the point levels (§4.3: "the weights of
/// overlapping points sum to at least one inside the surface"), on a sphere and on tilted
/// planes (normal (1, 1, 1) seen head-on; 30° off the y axis, seen 60° off its normal), many
/// footprint sizes (cone scales 3, 6, 12: points, with triangles at the finest), the whole
/// footprint inside the surface (the planes are 8 units wide, the footprints' 2% ellipses at
/// most 1.6). The sums are Monte-Carlo estimates (the voxel occupancy and the area per point
/// come from random samples), held above 1 by the point weights' 10% margin
/// (`POINT_MARGIN`) and by the mipmap blend (with `mipmap: false` a footprint down to half
/// the spacing, where λ = 2 lets the points in, samples the grid too coarsely: sums 0.74–0.85
/// on these planes). Measured minima: 1.023 (sphere), 1.036 and 1.026 (planes); typical
/// sums 1.05–1.2, about 2 where coverage-weighted triangles join the points (the (1, 1, 1)
/// plane at scale 3) or the footprint spans the whole sphere (scale 12: front and back
/// merge). (Until the test review the bound was 0.9 and only the sphere was tested.)
#[test]
fn point_weight_sums_cover_the_surface() {
    let mut ball = Scene::empty("ball");
    let mut m = builtin::uv_sphere(64, 128, 0);
    m.compute_normals();
    let id = ball.add_mesh(m);
    ball.instance(Target::Mesh(id), Affine3A::IDENTITY, None);
    ball.camera = Camera { eye: Vec3::new(0.3, 0.2, 6.0), look: Vec3::ZERO, up: Vec3::Y, fovy: 30.0, aperture: 0.0, focal_dist: 6.0 };
    ball.validate().unwrap();
    // Pixels well inside the sphere's disc (radius ≈ 15 pixels around the centre); a 3×3
    // grid 4 pixels apart on the planes.
    let ball_px = vec![(32, 32), (28, 30), (36, 34), (30, 36), (34, 27)];
    let grid: Vec<(u32, u32)> = (0..9).map(|k| (28 + 4 * (k % 3), 28 + 4 * (k / 3))).collect();
    let cases = [
        ("sphere", ball, ball_px),
        ("plane (1,1,1) head-on", tilted_plane_scene(Vec3::ONE.normalize(), 0.0), grid.clone()),
        ("plane 30° seen at 60°", tilted_plane_scene(glam::Quat::from_rotation_x(30f32.to_radians()) * Vec3::Y, 60f32.to_radians()), grid),
    ];
    for (name, scene, pixels) in cases {
        let ms = MultiresScene::build(&scene, &BuildParams::default()).unwrap();
        let abort = AtomicBool::new(false);
        let cam = scene.camera.frame(64, 64);
        let mut sc = Scratch::default();
        let mut c = Counters::default();
        let mut sums = vec![];
        for cone_scale in [3.0f32, 6.0, 12.0] {
            // The whole footprint's sum: no early termination at alpha 1 inside a fragment.
            let tp = TraceParams { cone_scale, termination: Termination::Final, ..Default::default() };
            let tr = Tracer::new(&ms, &tp, 1e-7, &abort, None);
            for &(i, j) in &pixels {
                let mut ab = ABuffer::new(16);
                tr.traverse(&Cone::primary(&cam, i, j, cone_scale, 1.0), &mut ab, Collect::Alpha, &mut sc, &mut c);
                // The front fragment (the sphere's far side is a second one).
                assert!(!ab.frags.is_empty() && (ab.frags.len() == 1 || name == "sphere"), "{name}: {} fragments", ab.frags.len());
                sums.push(ab.frags[0].w);
            }
        }
        assert!(c.get(lodtrace::core::stats::Counter::surfel_tests) > 0, "{name}: no point level reached");
        let min = sums.iter().cloned().fold(f32::INFINITY, f32::min);
        assert!(min >= 1.0, "{name}: a weight sum of {min} inside the surface ({sums:?})");
    }
}

/// Area point weights (the default; a documented deviation): a diagonal plane's interior
/// sums to ≈ 1 like an axis-aligned one, where the paper's whole-voxel weights give about
/// |n_x| + |n_y| + |n_z| or more (measured: 1.09 against 2.65 on the (1, 1, 1) plane).
#[test]
fn area_point_weights_sum_to_one_at_any_orientation() {
    use lodtrace::multires::build::PointWeights;
    let mean_sum = |weights: PointWeights, tilt: bool| {
        let mut scene = square_scene(Vec3::splat(0.5), 4.0);
        if tilt {
            // The hierarchy is built in mesh space, so turn the vertices themselves: normal
            // (1, 1, 1)/√3, the worst case for whole-voxel weights (√3). The square's
            // instance turns +y to +z; undo that here and aim the camera along the normal.
            let n = Vec3::ONE.normalize();
            let r = glam::Quat::from_rotation_arc(Vec3::Y, n);
            let m = &mut scene.meshes[0];
            for v in 0..m.px.len() {
                let p = r * Vec3::new(m.px[v], m.py[v], m.pz[v]);
                (m.px[v], m.py[v], m.pz[v]) = (p.x, p.y, p.z);
                let q = r * Vec3::new(m.nx[v], m.ny[v], m.nz[v]);
                (m.nx[v], m.ny[v], m.nz[v]) = (q.x, q.y, q.z);
            }
            let root = scene.root as usize;
            scene.groups[root].children[0].xform = Affine3A::IDENTITY;
            scene.camera.eye = n * 4.0;
            scene.camera.up = Vec3::Z;
        }
        let ms = MultiresScene::build(&scene, &BuildParams { weights, ..Default::default() }).unwrap();
        let tp = TraceParams { cone_scale: 6.0, termination: Termination::Final, ..Default::default() };
        let abort = AtomicBool::new(false);
        let tr = Tracer::new(&ms, &tp, 1e-7, &abort, None);
        let cam = scene.camera.frame(64, 64);
        let (mut sc, mut c) = (Scratch::default(), Counters::default());
        let mut sums = vec![];
        for (i, j) in [(32, 32), (29, 30), (35, 34), (30, 35), (34, 29)] {
            let mut ab = ABuffer::new(16);
            tr.traverse(&Cone::primary(&cam, i, j, 6.0, 1.0), &mut ab, Collect::Alpha, &mut sc, &mut c);
            sums.push(ab.frags.first().map(|f| f.w).unwrap_or(0.0));
        }
        assert!(c.get(lodtrace::core::stats::Counter::surfel_tests) > 0);
        sums.iter().sum::<f32>() / sums.len() as f32
    };
    let (flat, diag) = (mean_sum(PointWeights::Area, false), mean_sum(PointWeights::Area, true));
    let (vflat, vdiag) = (mean_sum(PointWeights::Voxel, false), mean_sum(PointWeights::Voxel, true));
    for s in [flat, diag, vflat] {
        assert!((1.0..1.3).contains(&s), "area {flat} / {diag}, voxel {vflat} / {vdiag}");
    }
    assert!(vdiag > 1.3 * diag, "area {flat} / {diag}, voxel {vflat} / {vdiag}");
}

/// Normal spread (the default; a documented deviation): a cloud of small, randomly turned
/// facets (foliage) seen from far, lit from the side. Its true mean diffuse cosine, normals
/// flipped to the viewer and spread over that hemisphere, is (1 + v·l)/4 = 1/4; the paper's
/// single averaged normal lights the aggregate like one surface. Local shading
/// (`primary_only`, no shadows), so the answer is known.
#[test]
fn normal_spread_shades_aggregates_by_their_mean_cosine() {
    // Light from the side (l ⊥ v), far, irradiance 1 at the cloud.
    let s = foliage_scene(Vec3::new(1000.0, 0.0, 0.0));
    let ms = MultiresScene::build(&s, &BuildParams::default()).unwrap();
    let cam = s.camera.frame(32, 32);
    let shade = |normal_spread: bool| {
        let tp = TraceParams { cone_scale: 6.0, primary_only: true, normal_spread, ..Default::default() };
        let abort = AtomicBool::new(false);
        let tr = Tracer::new(&ms, &tp, 1e-7, &abort, None);
        let mut ss = ShadeScratch::new(16, s.max_depth);
        let mut c = Counters::default();
        let mut sum = 0.0;
        let mut n = 0;
        for j in 12..20 {
            for i in 12..20 {
                let r = tr.radiance(&Cone::primary(&cam, i, j, 6.0, 1.0), 0, 1.0, &mut ss, &mut c);
                if r.alpha > 0.9 {
                    sum += r.color.x / r.alpha;
                    n += 1;
                }
            }
        }
        assert!(n > 40 && c.get(lodtrace::core::stats::Counter::surfel_tests) > 0);
        // Mean cosine: radiance = albedo/π · E · cos.
        sum / n as f32 / (0.8 / std::f32::consts::PI)
    };
    let (on, off) = (shade(true), shade(false));
    assert!((on - 0.25).abs() < 0.08, "mean cosine with spread {on}, without {off}, expected 0.25");
    assert!((on - 0.25).abs() < (off - 0.25).abs(), "mean cosine with spread {on}, without {off}, expected 0.25");
}

/// A cloud of 6,000 small, randomly facing triangles in [−1, 1]³ (the test's foliage),
/// lit by `light`, seen from z = 12.
fn foliage_scene(light: Vec3) -> Scene {
    let mut s = Scene::empty("foliage");
    s.materials[0] = Material::diffuse("leaf", Vec3::splat(0.8));
    let mut m = Mesh::new("cloud");
    let mut h = 0x9e37_79b9u32;
    let mut rnd = || {
        h ^= h << 13;
        h ^= h >> 17;
        h ^= h << 5;
        h as f32 / u32::MAX as f32
    };
    for _ in 0..6000 {
        let c = Vec3::new(rnd(), rnd(), rnd()) * 2.0 - Vec3::ONE;
        let a = Vec3::new(rnd(), rnd(), rnd()) * 2.0 - Vec3::ONE;
        let b = Vec3::new(rnd(), rnd(), rnd()) * 2.0 - Vec3::ONE;
        let (i, j, k) = (m.push_vertex(c), m.push_vertex(c + a * 0.08), m.push_vertex(c + b * 0.08));
        m.push_tri(i, j, k, 0);
    }
    m.compute_normals();
    let id = s.add_mesh(m);
    s.instance(Target::Mesh(id), Affine3A::IDENTITY, None);
    let d = 12.0;
    s.camera = Camera { eye: Vec3::new(0.0, 0.0, d), look: Vec3::ZERO, up: Vec3::Y, fovy: 20.0, aperture: 0.0, focal_dist: d };
    s.lights.push(Light::Point { pos: light, intensity: Vec3::splat(light.length_squared()) });
    s.ambient = Vec3::ZERO;
    s.background = Vec3::ZERO;
    s.validate().unwrap();
    s
}

/// Foliage shadows itself (`aggregate_shadow`, a deviation from the paper): a fragment of a
/// leaf cloud starts its shadow cones past its own thickness, not past its footprint (the
/// surface rule, which skips the leaves within the footprint that shadow it), with the
/// cone's own cross-section. Seen from the side and lit from above, the cloud gets darker
/// (its self-shadowing) and stays about as close to the reference as the surface rule, with
/// either triangle weight; with the exact mass its brightness is near the reference's. A
/// smooth surface is not touched.
///
/// Until stop 31 the rule also had to be *closer* than the surface rule here (coverage
/// RMSE 0.0194 against 0.0205, mass 0.0158 against 0.0166). Then the surface rule's shadow
/// footprint was corrected to the paper's (the incoming footprint on the tangent plane, not
/// a projection along the light), which brought the surface rule itself to 0.0192 and
/// 0.0158 on this cloud: the rule's gain now shows on `complex` (320×240 mean FLIP 0.1255
/// against 0.1380 without it, README stop 31), not on this isolated cloud.
///
/// Stop 39's facing rule ([`lodtrace::multires::abuffer::Frag::alpha`]) takes the larger of
/// the weights facing either way instead of their sum, which for randomly facing leaves is
/// about half the sum. The cloud's shadow cones were too opaque, so it moves every variant
/// towards the reference (measured, RMSE with / without the rule: coverage 0.0175 / 0.0182,
/// mass 0.0138 / 0.0135; before it 0.0194 / 0.0192 and 0.0158 / 0.0158); with the coverage
/// weight the aggregate rule then darkens the cloud by under 1 % (0.00716 against 0.00709,
/// 0.00663 against 0.00700 before), so the darkening is asserted with the exact mass only.
#[test]
fn foliage_shadows_itself() {
    let scene = foliage_scene(Vec3::new(0.0, 1000.0, 300.0));
    let (w, h) = (48, 48);
    let reference = conventional(&scene, reference_accel(), &RenderOpts { width: w, height: h, spp: 64, ..Default::default() });
    let mean = |f: &Film| f.color.iter().map(|c| c.x as f64).sum::<f64>() / f.color.len() as f64;
    let want = mean(&reference);
    for tw in [TriWeight::Coverage, TriWeight::Mass] {
        let [(m_on, e_on), (m_off, e_off), (_, e_paper)] =
            [(true, true), (false, true), (true, false)].map(|(aggregate_shadow, facing)| {
                let f = cones(&scene, &TraceParams { aggregate_shadow, facing, tri_weight: tw, ..Default::default() }, w, h);
                (mean(&f), rmse(&f, &reference))
            });
        let msg = format!(
            "{tw:?}: mean {m_on} / RMSE {e_on} with, {m_off} / {e_off} without; RMSE {e_paper} without facing; reference mean {want}"
        );
        assert!(e_on < 1.05 * e_off, "{msg}");
        assert!(e_on < 0.95 * e_paper, "the facing rule should bring the cloud closer: {msg}");
        // With the exact triangle mass the cloud's coverage is near right, and the
        // brightness lands near the reference's (measured: 6 % darker with, 13 % brighter
        // without; before the facing rule 12 % and 4 %. The coverage weight's too opaque
        // leaves make the cloud 21 % too dark with or without).
        if tw == TriWeight::Mass {
            assert!(m_on < m_off && (m_on - want).abs() < 0.15 * want, "{msg}");
        }
    }
    // A plane, head-on and at a distance where points are used: the same image either way.
    let plane = square_scene(Vec3::splat(0.7), 40.0);
    let a = cones(&plane, &TraceParams::default(), 32, 32);
    let b = cones(&plane, &TraceParams { aggregate_shadow: false, ..Default::default() }, 32, 32);
    assert_eq!(a.color, b.color);
}

/// Shadow cones to an elliptical light (§4.2, squared footprints added): a 2×2 occluder
/// (finely tessellated, so its octree has point levels) hangs between a floor and a small
/// elliptical light. Where the distributed reference has the umbra, the cone tracer's
/// visibility (its image over its own unshadowed image) is zero; where the reference is
/// fully lit, it is near one. Measured: 0 and 0.935 (the Gaussian cone's penumbra reaches a
/// little past the exact one). A coarser level for the shadow cones (λ = 4 instead of 2,
/// tried at stop 23) let 6 % of the light into the umbra and took 7 % more from the lit
/// floor; this test fails for it.
/// An elliptical light 3 units above the origin, the camera `eye_y` high and 3 units back
/// looking at the origin, no ambient light or background: the set-up of the umbra tests.
fn light_above_camera_below(s: &mut Scene, eye_y: f32) {
    s.lights.push(Light::Ellipse {
        center: Vec3::new(0.0, 3.0, 0.0),
        axis_a: Vec3::X * 0.4,
        axis_b: Vec3::Z * 0.4,
        intensity: Vec3::splat(9.0),
    });
    s.camera = Camera { eye: Vec3::new(0.0, eye_y, 3.0), look: Vec3::ZERO, up: Vec3::Y, fovy: 50.0, aperture: 0.0, focal_dist: 3.0 };
    s.ambient = Vec3::ZERO;
    s.background = Vec3::ZERO;
    s.validate().unwrap();
}

#[test]
fn shadow_cones_give_a_dark_umbra_and_a_lit_floor() {
    let mut s = Scene::empty("umbra");
    s.materials[0] = Material::diffuse("white", Vec3::splat(0.8));
    let floor = s.add_mesh(builtin::checkerboard(32, 16.0, 0, 0));
    s.instance(Target::Mesh(floor), Affine3A::IDENTITY, None);
    let occ = s.add_mesh(builtin::checkerboard(64, 2.0, 0, 0));
    s.instance(Target::Mesh(occ), Affine3A::from_translation(Vec3::new(0.0, 1.0, 0.0)), None);
    // Low, looking at the floor under the occluder.
    light_above_camera_below(&mut s, 0.9);
    let mut open = s.clone();
    open.shadows = false;
    let (w, h) = (48, 48);
    let reference = distributed_64(&s, w, h);
    let unshadowed = conventional(&open, reference_accel(), &RenderOpts { width: w, height: h, spp: 16, ..Default::default() });
    let lum = |f: &Film| f.color.iter().map(|c| c.x).collect::<Vec<f32>>();
    let (r, ro) = (lum(&reference), lum(&unshadowed));
    let top = ro.iter().cloned().fold(0.0f32, f32::max);
    let floor: Vec<usize> = (0..r.len()).filter(|&i| ro[i] > 0.05 * top).collect();
    let umbra: Vec<usize> = floor.iter().cloned().filter(|&i| r[i] < 0.005 * ro[i]).collect();
    let lit: Vec<usize> = floor.iter().cloned().filter(|&i| r[i] > 0.99 * ro[i]).collect();
    assert!(umbra.len() > 100 && lit.len() > 100, "{} umbra and {} lit pixels", umbra.len(), lit.len());
    let mean = |v: &[f32], ix: &[usize]| ix.iter().map(|&i| v[i] as f64).sum::<f64>() / ix.len() as f64;
    let m = lum(&cones(&s, &TraceParams::default(), w, h));
    let mo = lum(&cones(&open, &TraceParams::default(), w, h));
    let (u, l) = (mean(&m, &umbra) / mean(&mo, &umbra), mean(&m, &lit) / mean(&mo, &lit));
    assert!(u < 0.01 && l > 0.9, "visibility in the umbra {u}, on the lit floor {l}");
    assert!(m.iter().all(|v| v.is_finite()));
}

/// Shadow cones leaving a flat floor skip every instance on its plane (`multires::plane`):
/// the tiles of a floor share one plane, an occluder above it has its own, and the skip
/// leaves the image (umbra included) as the start distance made it while the primary hits'
/// shadow cones do fewer node tests. A light below the floor's lit side is never skipped.
#[test]
fn flat_floors_skip_their_own_shadow_cones_and_keep_the_image() {
    use lodtrace::multires::plane::NONE;
    use lodtrace::multires::trace::ConeKind;
    let mut s = Scene::empty("tiled umbra");
    s.materials[0] = Material::diffuse("white", Vec3::splat(0.8));
    let tile = s.add_mesh(builtin::checkerboard(8, 2.0, 0, 0));
    for i in -4..4 {
        for j in -4..4 {
            s.instance(Target::Mesh(tile), Affine3A::from_translation(Vec3::new(2.0 * i as f32 + 1.0, 0.0, 2.0 * j as f32 + 1.0)), None);
        }
    }
    let occ = s.add_mesh(builtin::checkerboard(16, 1.0, 0, 0));
    s.instance(Target::Mesh(occ), Affine3A::from_translation(Vec3::new(0.0, 0.8, 0.0)), None);
    let ball = s.add_mesh(builtin::uv_sphere(8, 12, 0));
    s.instance(
        Target::Mesh(ball),
        Affine3A::from_scale_rotation_translation(Vec3::splat(0.3), glam::Quat::IDENTITY, Vec3::new(1.5, 0.3, 0.5)),
        None,
    );
    // Below the occluder, looking at the floor under it.
    light_above_camera_below(&mut s, 0.5);
    let ms = MultiresScene::build(&s, &BuildParams::default()).unwrap();
    let floor = ms.flat.leaf[0];
    assert_ne!(floor, NONE);
    assert!(ms.flat.leaf[..64].iter().all(|&k| k == floor), "the tiles share a plane");
    assert!(ms.flat.leaf[64] != NONE && ms.flat.leaf[64] != floor, "the occluder has its own");
    assert_eq!(ms.flat.leaf[65], NONE, "a sphere is not flat");
    assert_eq!(ms.flat.slot[0], NONE, "the root holds several planes");
    assert!(ms.flat.slot.iter().filter(|&&k| k == floor).count() > 64, "inner slots of tiles only carry the plane");
    let (w, h) = (48, 48);
    let opts = RenderOpts { width: w, height: h, ..Default::default() };
    let cam = s.camera.frame(w, h);
    let run = |plane_skip: bool| {
        let tp = TraceParams { plane_skip, ..Default::default() };
        let r = cone_render(&ms, &tp, &cam, &opts).unwrap();
        let k = ConeKind::PrimaryShadow as usize;
        (r.out.film, r.profile.work[k].iter().sum::<u64>(), r.profile.cones[k])
    };
    let (on, tests_on, cones_on) = run(true);
    let (off, tests_off, cones_off) = run(false);
    assert_eq!(cones_on, cones_off);
    assert!(cones_on > 1000, "{cones_on} shadow cones");
    assert!((tests_on as f64) < 0.8 * tests_off as f64, "primary shadow cones' work with / without the skip: {tests_on} / {tests_off}");
    let e = rmse(&on, &off);
    assert!(e < 1e-3, "RMSE {e} between the skip and the paper's start distance");
    // The umbra stays: the occluder is on another plane.
    let mut open = s.clone();
    open.shadows = false;
    let lit = cone_render(&MultiresScene::build(&open, &BuildParams::default()).unwrap(), &TraceParams::default(), &cam, &opts).unwrap();
    let top = lit.out.film.color.iter().map(|c| c.x).fold(0.0f32, f32::max);
    let umbra = on.color.iter().zip(&lit.out.film.color).filter(|(c, o)| o.x > 0.2 * top && c.x < 0.05 * o.x).count();
    assert!(umbra > 50, "{umbra} umbra pixels");
    assert!(on.color.iter().all(|c| c.is_finite()));
    // A light that reaches below the floor's plane: the floor must not skip itself (the
    // occluder, the other flat instance, is left out here).
    let mut under = s.clone();
    let root = under.root as usize;
    under.groups[root].children.retain(|i| i.target != Target::Mesh(occ));
    under.lights = vec![Light::Ellipse {
        center: Vec3::new(0.0, 0.3, -1.0),
        axis_a: Vec3::Y * 0.5,
        axis_b: Vec3::X * 0.5,
        intensity: Vec3::splat(9.0),
    }];
    under.validate().unwrap();
    let msu = MultiresScene::build(&under, &BuildParams::default()).unwrap();
    let tp = TraceParams::default();
    let r = cone_render(&msu, &tp, &cam, &opts).unwrap();
    assert!(r.out.film.color.iter().all(|c| c.is_finite()));
    let tpo = TraceParams { plane_skip: false, ..Default::default() };
    let ro = cone_render(&msu, &tpo, &cam, &opts).unwrap();
    assert!(r.profile.cones[ConeKind::PrimaryShadow as usize] > 1000);
    assert_eq!(r.profile.work, ro.profile.work, "no skip for a light that reaches below the plane");
}

/// A black-and-white checkerboard seen at a grazing angle: high-contrast edges everywhere.
fn edge_scene() -> Scene {
    let mut s = Scene::empty("edges");
    s.materials[0] = Material::diffuse("white", Vec3::splat(0.9));
    let b = s.add_material(Material::diffuse("black", Vec3::splat(0.02)));
    let id = s.add_mesh(builtin::checkerboard(24, 12.0, 0, b));
    s.instance(Target::Mesh(id), Affine3A::IDENTITY, None);
    s.camera =
        Camera { eye: Vec3::new(0.0, 1.2, 6.0), look: Vec3::new(0.0, 0.0, -2.0), up: Vec3::Y, fovy: 40.0, aperture: 0.0, focal_dist: 6.0 };
    s.lights.push(Light::Point { pos: Vec3::new(0.0, 8.0, 4.0), intensity: Vec3::splat(80.0) });
    s.ambient = Vec3::splat(0.2);
    s.validate().unwrap();
    s
}

/// Issue test: on a high-contrast edge image the multires image is closer to a 256-spp
/// reference than the 1-spp image.
#[test]
fn multires_is_closer_to_the_reference_than_one_sample() {
    let scene = edge_scene();
    let (w, h) = (48, 48);
    let reference = conventional(&scene, reference_accel(), &RenderOpts { width: w, height: h, spp: 256, ..Default::default() });
    let one = conventional(&scene, reference_accel(), &RenderOpts { width: w, height: h, ..Default::default() });
    let mr = cones(&scene, &TraceParams::default(), w, h);
    let (e1, em) = (rmse(&one, &reference), rmse(&mr, &reference));
    assert!(em < 0.8 * e1, "multires RMSE {em} vs 1 spp {e1}");
    assert!(mr.color.iter().all(|c| c.is_finite()));
}

/// §4.4 early ray termination: the paper's rule (whole-ray alpha at each intersection event)
/// stops grazing cones on the board before they sweep their whole footprint, so it does
/// less work than waiting for fragments to lie behind the traversal front. The price is a
/// bias towards the near part of a straddling fragment's footprint (measured here: RMSE
/// against 256 spp 0.032 vs 0.024), bounded by the asserts below.
#[test]
fn paper_termination_cuts_work_on_grazing_cones() {
    let scene = edge_scene();
    let (w, h) = (48, 48);
    let ms = MultiresScene::build(&scene, &BuildParams::default()).unwrap();
    let opts = RenderOpts { width: w, height: h, ..Default::default() };
    let run = |termination| {
        let tp = TraceParams { termination, ..Default::default() };
        cone_render(&ms, &tp, &scene.camera.frame(w, h), &opts).unwrap().out
    };
    let (paper, fin) = (run(Termination::Paper), run(Termination::Final));
    let work = |o: &lodtrace::baseline::render::RenderOutput| {
        use lodtrace::core::stats::Counter::*;
        o.counters.get(surfel_tests) + o.counters.get(triangle_tests)
    };
    let (wp, wf) = (work(&paper), work(&fin));
    assert!((wp as f64) < 0.9 * wf as f64, "paper rule {wp} tests vs final {wf}");
    assert!(paper.film.color.iter().all(|c| c.is_finite()));
    let reference = conventional(&scene, reference_accel(), &RenderOpts { width: w, height: h, spp: 256, ..Default::default() });
    let (ep, ef) = (rmse(&paper.film, &reference), rmse(&fin.film, &reference));
    let d = rmse(&paper.film, &fin.film);
    assert!(ep < 1.5 * ef && d < 0.05, "RMSE paper {ep}, final {ef}, between {d}");
}

/// Occlusion, §4.4: a small cube standing on a large floor. The floor's root node is
/// entered at the eye and hands out its big triangles before the cube's nodes are visited;
/// an opaque floor fragment behind the cube must not end the ray (the first version of the
/// paper's early termination did, and the floor showed through most of the cube). Wherever
/// Embree's pixel-centre ray hits the cube, away from its outline, both cone tracers see the
/// cube first.
#[test]
fn floor_behind_an_object_does_not_hide_it() {
    let mut scene = Scene::empty("cube-on-floor");
    scene.materials[0] = Material::diffuse("white", Vec3::splat(0.8));
    let black = scene.add_material(Material::diffuse("black", Vec3::splat(0.15)));
    let red = scene.add_material(Material::diffuse("red", Vec3::new(0.8, 0.08, 0.06)));
    let board = scene.add_mesh(builtin::checkerboard(32, 32.0, 0, black));
    scene.instance(Target::Mesh(board), Affine3A::from_translation(Vec3::new(0.0, 0.0, -8.0)), None);
    let cube = scene.add_mesh(builtin::cube_mesh(red));
    scene.instance(
        Target::Mesh(cube),
        Affine3A::from_scale_rotation_translation(Vec3::splat(0.3), glam::Quat::from_rotation_y(0.6), Vec3::new(-1.1, 0.3, 3.3)),
        None,
    );
    let (eye, look) = (Vec3::new(0.0, 4.2, 8.2), Vec3::new(-1.1, 0.3, 3.3));
    scene.camera = Camera { eye, look, up: Vec3::Y, fovy: 20.0, aperture: 0.0, focal_dist: (look - eye).length() };
    scene.lights.push(Light::Point { pos: Vec3::new(2.0, 8.0, 6.0), intensity: Vec3::splat(60.0) });
    scene.validate().unwrap();
    let (w, h) = (40, 40);
    let reference = conventional(&scene, reference_accel(), &RenderOpts { width: w, height: h, ..Default::default() });
    // The cube's pixels: nearer than 7 units (the floor around it is farther).
    let on_cube = |f: &Film, i: i32, j: i32| f.depth[(j as u32 * w + i as u32) as usize] < 7.0;
    for points in [true, false] {
        let film = cones(&scene, &TraceParams { points, ..Default::default() }, w, h);
        let (mut inside, mut seen) = (0, 0);
        for j in 1..h as i32 - 1 {
            for i in 1..w as i32 - 1 {
                let interior = [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)].iter().all(|&(di, dj)| on_cube(&reference, i + di, j + dj));
                if interior {
                    inside += 1;
                    seen += on_cube(&film, i, j) as u32;
                }
            }
        }
        assert!(inside > 100, "the cube covers {inside} interior pixels");
        assert_eq!(seen, inside, "points={points}: the cube is seen in {seen} of its {inside} interior pixels");
    }
}

/// A mirror ball standing on a green checkerboard floor under a blue sky.
fn mirror_on_floor() -> Scene {
    let mut scene = Scene::empty("mirror-on-floor");
    scene.materials[0] = Material::diffuse("green", Vec3::new(0.1, 0.7, 0.1));
    let mirror = scene.add_material(Material { name: "mirror".into(), color: Vec3::ZERO, kd: 0.0, reflect: 1.0, ..Default::default() });
    let board = scene.add_mesh(builtin::checkerboard(16, 16.0, 0, 0));
    scene.instance(Target::Mesh(board), Affine3A::IDENTITY, None);
    let mut ball = builtin::icosphere(4, mirror);
    ball.compute_normals();
    let ball = scene.add_mesh(ball);
    scene.instance(Target::Mesh(ball), Affine3A::from_translation(Vec3::new(0.0, 1.0, 0.0)), None);
    scene.camera =
        Camera { eye: Vec3::new(0.0, 1.6, 6.0), look: Vec3::new(0.0, 0.8, 0.0), up: Vec3::Y, fovy: 30.0, aperture: 0.0, focal_dist: 6.0 };
    scene.lights.push(Light::Point { pos: Vec3::new(3.0, 8.0, 6.0), intensity: Vec3::splat(60.0) });
    scene.background = Vec3::new(0.1, 0.2, 0.9);
    scene.ambient = Vec3::splat(0.3);
    scene.validate().unwrap();
    scene
}

/// Self-exclusion of secondary cones is per instance: a mirror sphere standing on a green
/// floor under a blue sky. Near its bottom the mirror reflects the floor a short way off; the
/// first version skipped the whole scene up to the sphere's self-intersection threshold,
/// so those reflected cones started below the floor and saw the sky (a blue rim where Embree
/// sees green). Wherever Embree's pixel is clearly floor-coloured inside the sphere, the
/// multires pixel must be too.
#[test]
fn reflections_of_a_touching_floor_are_not_skipped() {
    let scene = mirror_on_floor();
    let (w, h) = (48, 48);
    let reference = conventional(&scene, reference_accel(), &RenderOpts { width: w, height: h, ..Default::default() });
    let on_ball = |f: &Film, i: i32, j: i32| f.depth[(j as u32 * w + i as u32) as usize] < 6.5;
    let greenish = |c: Vec3| c.y > 2.0 * c.z;
    let film = cones(&scene, &TraceParams::default(), w, h);
    let (mut floor_seen, mut sky_instead) = (0, 0);
    for j in 1..h as i32 - 1 {
        for i in 1..w as i32 - 1 {
            let interior = [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)].iter().all(|&(di, dj)| on_ball(&reference, i + di, j + dj));
            let k = (j as u32 * w + i as u32) as usize;
            if interior && greenish(reference.color[k]) {
                floor_seen += 1;
                sky_instead += !greenish(film.color[k]) as u32;
            }
        }
    }
    assert!(floor_seen > 30, "the mirror shows the floor in {floor_seen} interior pixels");
    assert!(sky_instead <= floor_seen / 20, "{sky_instead} of {floor_seen} pixels reflecting the floor show the sky instead");
}

/// `--secondary-clamp` changes the cones below the first surface only: unset or equal to
/// `--anisotropy-clamp` it renders the paper's image bit for bit; at 1 (round secondary
/// cones) the pixels away from the mirror are unchanged, those on it change, and the mirror
/// still shows the floor.
#[test]
fn secondary_clamp_changes_secondary_cones_only() {
    let scene = mirror_on_floor();
    let (w, h) = (48, 48);
    let paper = TraceParams::default();
    let base = cones(&scene, &paper, w, h);
    let same = cones(&scene, &TraceParams { secondary_clamp: Some(paper.clamp), ..paper.clone() }, w, h);
    assert!(base.color == same.color && base.depth == same.depth, "an explicit clamp equal to the primary one changed the image");
    let round = cones(&scene, &TraceParams { secondary_clamp: Some(1.0), ..paper.clone() }, w, h);
    // The ball's pixels: a surface not facing straight up (the floor does).
    let ball = |k: usize| base.depth[k].is_finite() && base.normal[k].y < 0.999;
    let near_ball = |i: i32, j: i32| {
        (-1..=1).any(|dj| {
            (-1..=1).any(|di| {
                let (x, y) = (i + di, j + dj);
                x >= 0 && y >= 0 && x < w as i32 && y < h as i32 && ball((y as u32 * w + x as u32) as usize)
            })
        })
    };
    let greenish = |c: Vec3| c.y > 2.0 * c.z;
    let (mut off_ball, mut on_ball, mut changed, mut floor_b, mut floor_r) = (0, 0, 0, 0, 0);
    for j in 0..h as i32 {
        for i in 0..w as i32 {
            let k = (j as u32 * w + i as u32) as usize;
            if ball(k) {
                on_ball += 1;
                changed += (round.color[k] != base.color[k]) as u32;
                floor_b += greenish(base.color[k]) as u32;
                floor_r += greenish(round.color[k]) as u32;
            } else if !near_ball(i, j) {
                off_ball += 1;
                assert_eq!(round.color[k], base.color[k], "pixel {i},{j} away from the mirror changed");
            }
        }
    }
    assert!(on_ball > 100 && off_ball > 100, "{on_ball} / {off_ball} pixels on / away from the ball");
    assert!(changed > on_ball / 10, "only {changed} of {on_ball} mirror pixels changed with round secondary cones");
    // Round cones blur the reflected horizon across the narrow direction of the reflection
    // (floor pixels at 1/4, 1/2, 1: 337, 320, 307 of the paper's 371), but keep the floor.
    assert!(floor_b > 30 && floor_r * 5 >= floor_b * 4, "round cones show the floor in {floor_r} mirror pixels, the paper's in {floor_b}");
    assert!(TraceParams { secondary_clamp: Some(0.0), ..paper.clone() }.validate().is_err());
    assert!(TraceParams { secondary_clamp: Some(f32::NAN), ..paper }.validate().is_err());
}

/// Issue test: a mesh seen through `cone` and `multires` at close range (leaves reached)
/// matches Embree's silhouette: coverage ≥ 50% exactly where Embree's pixel-centre ray hits,
/// except in pixels next to the silhouette.
#[test]
fn close_up_silhouette_matches_the_reference() {
    let mut scene = Scene::empty("bunny-ish");
    let mut m = builtin::icosphere(3, 0);
    m.compute_normals();
    let id = scene.add_mesh(m);
    scene.instance(Target::Mesh(id), Affine3A::from_scale(Vec3::new(1.0, 0.6, 0.8)), None);
    scene.camera = Camera { eye: Vec3::new(0.4, 0.3, 3.0), look: Vec3::ZERO, up: Vec3::Y, fovy: 45.0, aperture: 0.0, focal_dist: 3.0 };
    scene.lights.push(Light::Point { pos: Vec3::new(2.0, 3.0, 4.0), intensity: Vec3::splat(30.0) });
    scene.validate().unwrap();
    let (w, h) = (48, 48);
    let reference = conventional(&scene, reference_accel(), &RenderOpts { width: w, height: h, ..Default::default() });
    for points in [true, false] {
        let tp = TraceParams { points, ..Default::default() };
        let film = cones(&scene, &tp, w, h);
        let hit = |f: &Film, i: i32, j: i32| f.depth[(j as u32 * w + i as u32) as usize].is_finite();
        let mut bad = 0;
        for j in 0..h as i32 {
            for i in 0..w as i32 {
                if hit(&film, i, j) == hit(&reference, i, j) {
                    continue;
                }
                // Next to the reference silhouette?
                let mut edge = false;
                for (di, dj) in [(-1, 0), (1, 0), (0, -1), (0, 1)] {
                    let (x, y) = (i + di, j + dj);
                    if x >= 0 && y >= 0 && x < w as i32 && y < h as i32 && hit(&reference, x, y) != hit(&reference, i, j) {
                        edge = true;
                    }
                }
                if !edge {
                    bad += 1;
                }
            }
        }
        assert_eq!(bad, 0, "points={points}: {bad} pixels disagree with the reference away from the silhouette");
    }
}

/// Degenerate input: zero-area and NaN triangles, a zero footprint (cone scale tiny), no panic
/// and no NaN pixel; the conventional tracer on the octree agrees at packet widths 1 and 8.
#[test]
fn degenerate_geometry_and_octree_packets() {
    let mut scene = edge_scene();
    let mut bad = Mesh::new("bad");
    let a = bad.push_vertex(Vec3::new(0.0, 0.5, 0.0));
    let b = bad.push_vertex(Vec3::new(1.0, 0.5, 0.0));
    let c = bad.push_vertex(Vec3::new(2.0, 0.5, 0.0));
    let d = bad.push_vertex(Vec3::new(0.5, 1.0, 0.0));
    bad.push_tri(a, b, c, 0); // colinear
    bad.push_tri(a, a, d, 0); // repeated vertex
    bad.push_tri(a, b, d, 0); // a real one
    bad.compute_normals();
    let id = scene.add_mesh(bad);
    scene.instance(Target::Mesh(id), Affine3A::IDENTITY, None);
    scene.validate().unwrap();
    for tp in [
        TraceParams::default(),
        TraceParams { cone_scale: 1e-6, ..Default::default() },
        TraceParams { points: false, ..Default::default() },
    ] {
        let f = cones(&scene, &tp, 24, 24);
        assert!(f.color.iter().all(|c| c.is_finite()), "NaN pixel");
    }
    let one = conventional(&scene, AccelKind::Octree, &RenderOpts { width: 24, height: 24, packet: 1, ..Default::default() });
    let eight = conventional(&scene, AccelKind::Octree, &RenderOpts { width: 24, height: 24, packet: 8, ..Default::default() });
    assert_eq!(one.color, eight.color);
    let _ = Integrator::Whitted;
}

/// §5.2: the per-box decomposition is the fast approximation of the exact one (each point at
/// its own depth, each triangle at its own), so the two render `spheres` — a floor seen at a
/// grazing angle, a mirror and a glass ball — nearly alike. Until stop 38 exact mode gave each
/// triangle vertex its own footprint, which distorted the floor's large triangles into streaks
/// of false shadow (RMSE 0.157 against the reference, per-box 0.041).
#[test]
fn exact_and_per_box_decompositions_render_alike() {
    use lodtrace::multires::trace::EigenMode;
    let s = builtin::get("spheres").unwrap();
    let (w, h) = (96, 96);
    let per_box = cones(&s, &TraceParams::default(), w, h);
    let exact = cones(&s, &TraceParams { eigen: EigenMode::Exact, ..Default::default() }, w, h);
    let e = rmse(&per_box, &exact);
    assert!(e < 0.012, "RMSE {e} between the exact and the per-box decomposition");
    assert!(exact.color.iter().all(|c| c.is_finite()));
}

/// A sphere of radius `r` at `c` (smooth normals) alone, as a hierarchy to trace cones in.
fn lone_sphere(c: Vec3, r: f32) -> Scene {
    let mut s = Scene::empty("sphere");
    let m = s.add_mesh(builtin::uv_sphere(41, 43, 0));
    s.instance(Target::Mesh(m), Affine3A::from_scale_rotation_translation(Vec3::splat(r), glam::Quat::IDENTITY, c), None);
    s.camera = Camera { eye: c + Vec3::new(0.0, 2.0, 8.0), look: c, up: Vec3::Y, fovy: 45.0, aperture: 0.0, focal_dist: 8.0 };
    s.validate().unwrap();
    s
}

/// Whether the segment from `p` to `q` passes through the sphere (c, r).
fn blocked(p: Vec3, q: Vec3, c: Vec3, r: f32) -> bool {
    let d = (q - p).normalize();
    let (b, cc) = ((p - c).dot(d), (p - c).length_squared() - r * r);
    let disc = b * b - cc;
    disc > 0.0 && -b - disc.sqrt() > 0.0
}

/// Soft shadows (`--no-facing` ablation; Wand & Straßer §4.2 shadow cones, §7 "the shadow
/// region is overestimated"): along a line out of a sphere's shadow on the floor, the
/// shadow cone's alpha follows the occluded share of the light's Gaussian (the filter the
/// cone stands for, sampled here against the analytic sphere) once the sphere's near and far
/// sides count once and its triangles by their mass; the paper's sum counts both sides and
/// stays at alpha 1 deep into the penumbra.
#[test]
fn soft_shadow_penumbra_follows_the_light() {
    let (c, r) = (Vec3::new(0.0, 0.75, 0.0), 0.75);
    let scene = lone_sphere(c, r);
    let ms = MultiresScene::build(&scene, &BuildParams::default()).unwrap();
    let (lc, la, lb) = (Vec3::new(-7.0, 9.0, -6.0), Vec3::new(2.8, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.7));
    let abort = AtomicBool::new(false);
    let alphas = |facing: bool| -> Vec<(f32, f32)> {
        let tp = TraceParams { tri_weight: TriWeight::Mass, facing, ..Default::default() };
        let tr = Tracer::new(&ms, &tp, 1e-7, &abort, None);
        let (mut sc, mut cn) = (Scratch::default(), Counters::default());
        let away = Vec3::new(7.0, 0.0, 6.0).normalize();
        (0..12)
            .map(|k| {
                let p = away * (1.75 + 0.07 * k as f32) + Vec3::Y * 1e-3;
                // The light's Gaussian e^(−x²−y²) in its axes, cut at 2 %, by inverse CDF.
                let n = 2000;
                let hidden = (0..n)
                    .filter(|&i| {
                        let u = (i as f32 + 0.5) / n as f32;
                        let rr = (-(1.0 - 0.98 * u).ln()).sqrt();
                        let th = i as f32 * 2.399_963;
                        blocked(p, lc + la * (rr * th.cos()) + lb * (rr * th.sin()), c, r)
                    })
                    .count();
                let (mut sh, dist) = cone::shadow(p, Vec3::X * 0.01, Vec3::Z * 0.01, lc, la, lb);
                sh.tmin = 1e-3;
                sh.tmax = dist * 0.9999;
                let mut ab = ABuffer::new(16);
                tr.traverse(&sh, &mut ab, Collect::Alpha, &mut sc, &mut cn);
                (hidden as f32 / n as f32, ab.alpha())
            })
            .collect()
    };
    let penumbra = |v: &[(f32, f32)]| v.iter().cloned().filter(|&(g, _)| (0.2..0.85).contains(&g)).collect::<Vec<_>>();
    let (with, paper) = (alphas(true), alphas(false));
    let (pw, pp) = (penumbra(&with), penumbra(&paper));
    assert!(pw.len() >= 4, "penumbra samples {with:?}");
    for &(g, a) in &pw {
        assert!((a - g).abs() < 0.08, "alpha {a} against the light's occluded share {g}: {with:?}");
    }
    let worst = pp.iter().map(|&(g, a)| a - g).fold(0.0f32, f32::max);
    assert!(worst > 0.3, "the paper's sum should overestimate the penumbra: {paper:?}");
}

/// A cone leaving a closed surface from inside (a glass sphere's inner wall towards its
/// light) meets the far wall: all its weight faces away from the cone's origin, points and
/// triangles alike (their facing comes from the same normals), and it is opaque.
#[test]
fn a_closed_surface_seen_from_inside_faces_away() {
    let (c, r) = (Vec3::new(1.4, 1.1, 1.2), 1.1);
    let scene = lone_sphere(c, r);
    let ms = MultiresScene::build(&scene, &BuildParams::default()).unwrap();
    let abort = AtomicBool::new(false);
    let tp = TraceParams { tri_weight: TriWeight::Mass, ..Default::default() };
    let tr = Tracer::new(&ms, &tp, 1e-7, &abort, None);
    let (mut sc, mut cn) = (Scratch::default(), Counters::default());
    let (lc, la, lb) = (Vec3::new(-4.0, 8.0, 5.0), Vec3::X * 0.8, Vec3::Z * 0.8);
    let l = (lc - c).normalize();
    let (u, v) = (l.any_orthonormal_vector(), l.cross(l.any_orthonormal_vector()));
    for k in 0..8 {
        let a = k as f32 * 0.8;
        let n = (-l * 0.6 + (u * a.cos() + v * a.sin()) * 0.8).normalize();
        let (mut sh, dist) = cone::shadow(c + n * (r * 0.999), u * 0.05, v * 0.05, lc, la, lb);
        sh.tmin = 0.3; // past the wall it starts from
        sh.tmax = dist * 0.9999;
        let mut ab = ABuffer::new(16);
        tr.traverse(&sh, &mut ab, Collect::Alpha, &mut sc, &mut cn);
        let f = ab.frags.first().expect("the far wall");
        assert!(f.wb > 0.97 * f.w, "far wall: {} of weight {} faces away", f.wb, f.w);
        assert!(ab.alpha() > 0.99, "alpha {}", ab.alpha());
    }
    assert!(cn.get(lodtrace::core::stats::Counter::surfel_tests) > 0 && cn.get(lodtrace::core::stats::Counter::triangle_tests) > 0);
}

/// A defocused cube on a floor (`scenes/dof-cube.toml`; the paper's §7 "merges the floor
/// and the base of the bunny into a single fragment"): with the pieces of the two meshes
/// composited by depth (`split_meshes`) and each fragment shaded by the side of the cube
/// that shows (`facing`), the cone tracer comes much closer to the distributed reference
/// than with the paper's sums, where the floor behind the cube's base averages into its
/// faces and a face's normal averages with the far side's. Measured at 160×120 against 64
/// spp: mean FLIP 0.199, against 0.358 with the paper's sums and 0.244 without the split
/// (stop 39). At 400×300 against 128 spp after stop 40's fixes below: 0.147 (0.154 before
/// the near side's own depth, 0.175 with the lens radius, 0.191 before all three).
#[test]
fn a_defocused_cube_keeps_its_faces() {
    let scene = shipped_scene("dof-cube");
    let (w, h) = (160, 120);
    let reference = distributed_64(&scene, w, h);
    let flip = |tp: TraceParams| {
        let f = cones(&scene, &tp, w, h);
        lodtrace::film::metrics::flip_mean(&reference.color, &f.color, w, h).unwrap().0
    };
    let now = flip(TraceParams::default());
    let paper = flip(TraceParams { split_meshes: false, facing: false, ..Default::default() });
    let no_split = flip(TraceParams { split_meshes: false, ..Default::default() });
    assert!(
        now < 0.7 * paper && now < 0.9 * no_split,
        "mean FLIP {now} against {paper} with the paper's sums, {no_split} without the split"
    );
    // The lens footprint with the thin lens's variance (`--lens-scale`, default 1/√2) blurs
    // the cube as wide as the distributed reference's lens samples do; the lens radius
    // itself blurs it √2 times wider.
    let radius = flip(TraceParams { lens_scale: 1.0, ..Default::default() });
    assert!(now < 0.95 * radius, "mean FLIP {now} with the lens's variance, {radius} with its radius");
    // Where the reference sees the lit top, the cone tracer must not put the far side's
    // darkness: a fragment merging the top with the cube's far side is shaded at the near
    // side's own depth (at the whole fragment's, a point inside the cube, the cube itself
    // shadowed it: dark hooks on the top until stop 40).
    let f = cones(&scene, &TraceParams::default(), w, h);
    let lum = |c: Vec3| c.dot(Vec3::new(0.2126, 0.7152, 0.0722));
    let dark = reference.color.iter().zip(&f.color).filter(|(r, m)| lum(**r) > 0.16 && lum(**m) < 0.03).count();
    assert!(dark < 30, "{dark} pixels dark where the reference's top is lit (8 measured; 105 at the fragment's depth)");
    // A solid and a floor hold no aggregate (foliage): the aggregates' shadow rule must
    // leave the image alone. Until stop 40 a blurred edge's fragment, top and side face
    // merged (|mean normal| ≤ 0.95), counted as one, and its shadow cones put sharp-edged
    // dark patches on the cube's lit top.
    let with = cones(&scene, &TraceParams::default(), w, h);
    let without = cones(&scene, &TraceParams { aggregate_shadow: false, ..Default::default() }, w, h);
    let differ = with.color.iter().zip(&without.color).filter(|(a, b)| (**a - **b).abs().max_element() > 1e-4).count();
    assert_eq!(differ, 0, "{differ} pixels change with the aggregate shadow rule on a solid");
}

/// `scenes/dof-ball.toml` (stop 40): a defocused ball in front of a floor. Its silhouette's
/// edge-on triangles reach deep in depth, and the floor behind joins their fragment; the
/// paper's early termination counted the floor from where the ball's first piece begins and
/// ended the cones before the ball's nearer pieces were found, leaving shards and bites in
/// the blurred silhouette. Each mesh of a fragment now counts from its own beginning. With
/// the exact triangle mass, measured at 160×120 against 64 spp: mean FLIP 0.059 (0.124
/// before); at 400×300 against 128 spp 0.058 (0.119).
#[test]
fn a_defocused_ball_keeps_a_soft_silhouette() {
    let scene = shipped_scene("dof-ball");
    let (w, h) = (160, 120);
    let reference = distributed_64(&scene, w, h);
    let f = cones(&scene, &TraceParams { tri_weight: TriWeight::Mass, ..Default::default() }, w, h);
    let flip = lodtrace::film::metrics::flip_mean(&reference.color, &f.color, w, h).unwrap().0;
    assert!(flip < 0.09, "mean FLIP {flip} against the distributed reference");
}

/// A red cube on a large floor of two triangles, seen at a grazing angle: every pixel inside
/// the cube's image in the conventional render is red in the cone tracer's too, under the
/// paper's termination, with per-box and exact decompositions. The floor's triangles are
/// stored in the floor's root node, whose box reaches far down the ray; until stop 49 their
/// fragments took the depth interval from the footprint at the box's centre depth (hundreds
/// of footprints at the hit), and the cone ended on the floor before the cube in front of the
/// floor's hit was reached (11 % of the cube's pixels showed floor; review finding).
#[test]
fn grazing_floor_fragment_does_not_hide_what_stands_on_it() {
    let mut scene = Scene::empty("cube-on-big-floor");
    scene.materials[0] = Material::diffuse("green", Vec3::new(0.1, 0.6, 0.1));
    let red = scene.add_material(Material::diffuse("red", Vec3::new(0.8, 0.05, 0.05)));
    let floor = scene.add_mesh(builtin::checkerboard(1, 400.0, 0, 0));
    scene.instance(Target::Mesh(floor), Affine3A::from_translation(Vec3::new(0.0, 0.0, -150.0)), None);
    let cube = scene.add_mesh(builtin::cube_mesh(red));
    scene.instance(
        Target::Mesh(cube),
        Affine3A::from_scale_rotation_translation(Vec3::splat(0.3), glam::Quat::IDENTITY, Vec3::new(0.0, 0.3, -10.0)),
        None,
    );
    scene.camera = Camera {
        eye: Vec3::new(0.0, 0.35, 0.0),
        look: Vec3::new(0.0, 0.2, -10.0),
        up: Vec3::Y,
        fovy: 6.0,
        aperture: 0.0,
        focal_dist: 10.0,
    };
    scene.lights.push(Light::Point { pos: Vec3::new(0.0, 50.0, 0.0), intensity: Vec3::splat(2500.0) });
    scene.ambient = Vec3::splat(0.2);
    scene.validate().unwrap();
    let (w, h) = (48u32, 48u32);
    let reference = conventional(&scene, reference_accel(), &RenderOpts { width: w, height: h, ..Default::default() });
    let red_px = |f: &Film, i: i32, j: i32| {
        let c = f.color[(j as u32 * w + i as u32) as usize];
        c.x > 2.0 * c.y
    };
    for eigen in [lodtrace::multires::trace::EigenMode::PerBox, lodtrace::multires::trace::EigenMode::Exact] {
        let film = cones(&scene, &TraceParams { termination: Termination::Paper, eigen, ..Default::default() }, w, h);
        let (mut inside, mut lost) = (0, Vec::new());
        for j in 1..h as i32 - 1 {
            for i in 1..w as i32 - 1 {
                if [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)].iter().all(|&(di, dj)| red_px(&reference, i + di, j + dj)) {
                    inside += 1;
                    if !red_px(&film, i, j) {
                        lost.push((i, j));
                    }
                }
            }
        }
        assert!(inside > 300, "{eigen:?}: the cube covers {inside} interior pixels");
        assert!(lost.is_empty(), "{eigen:?}: {} of {inside} cube pixels show the floor, e.g. {:?}", lost.len(), &lost[..lost.len().min(6)]);
    }
}

/// ∇n of a triangle (for reflected and refracted cones, §4.2) is the derivative of the
/// *normalised* interpolated normal, the one that shades: on a coarse mesh the interpolated
/// normal is markedly shorter than 1 inside a triangle (0.79 at an icosahedron's face
/// centres), and forgetting the normalisation's 1/|n| underestimates the curvature as much.
#[test]
fn triangle_normal_derivative_is_that_of_the_unit_normal() {
    let mut mesh = builtin::icosphere(0, 0);
    mesh.compute_normals();
    let mut scene = Scene::empty("ico");
    let id = scene.add_mesh(mesh.clone());
    scene.instance(Target::Mesh(id), Affine3A::from_scale(Vec3::splat(2.0)), None);
    scene.validate().unwrap();
    let ms = MultiresScene::build(&scene, &BuildParams::default()).unwrap();
    let p = TraceParams::default();
    let abort = AtomicBool::new(false);
    let tr = Tracer::new(&ms, &p, 1e-7, &abort, None);
    let m = &scene.meshes[id as usize];
    let mut worst = 0.0f32;
    for tri in 0..20u32 {
        let [i0, i1, i2] = m.tris[tri as usize];
        let at = |b1: f32, b2: f32| {
            let b0 = 1.0 - b1 - b2;
            let po = m.pos(i0) * b0 + m.pos(i1) * b1 + m.pos(i2) * b2;
            let no = m.normal(i0) * b0 + m.normal(i1) * b1 + m.normal(i2) * b2;
            (po * 2.0, no.normalize())
        };
        let (b1, b2) = (1.0 / 3.0, 1.0 / 3.0);
        let w = tr.shape_operator(Elem::Tri { leaf: 0, tri, b1, b2 });
        let (p0, n0) = at(b1, b2);
        for (d1, d2) in [(1e-3, 0.0), (0.0, 1e-3)] {
            let (p1, n1) = at(b1 + d1, b2 + d2);
            let fd = n1 - n0;
            worst = worst.max((fd - w * (p1 - p0)).length() / fd.length());
        }
    }
    assert!(worst < 0.02, "relative error of W·δ against the unit normal's finite difference: {worst}");
}

/// §4.2, transmitted rays: the centre ray decides between refraction and total reflection;
/// a refracted cone is then built like a reflected one, from the directions of the rays
/// through the footprint's axis ends. Near the critical angle the refracted directions fan
/// out fastest (dθₜ/dθᵢ = η·cosθᵢ/cosθₜ, here 4.1), so the cone's spread must be largest
/// there; an axis end whose own ray is totally reflected must not make it zero. (Until this
/// review that axis got the centre direction, no spread at all.)
#[test]
fn refracted_cone_near_the_critical_angle_keeps_its_spread() {
    let eta = 1.5f32; // glass to air: critical sin θ = 1/1.5
    let sin_i = 0.64f32;
    let cos_i = (1.0 - sin_i * sin_i).sqrt();
    let sin_t = eta * sin_i;
    let cos_t = (1.0 - sin_t * sin_t).sqrt();
    let gain = eta * cos_i / cos_t;
    for sx in [1.0f32, -1.0] {
        let dir = Vec3::new(sx * sin_i, -cos_i, 0.0);
        let along = Vec3::new(sx * cos_i, sin_i, 0.0); // ⟂ dir, in the plane of incidence
        let spread_for = |k: f32| {
            let mut c = Cone::new(-dir, dir, &[]);
            let incr = c.fp_of(along * k, Vec3::Z * 0.01);
            c.add_pair(Fp::ZERO, incr);
            let fs = c.footprint_and_spread(1.0, 1e-9, 1e-30);
            let out = cone::secondary(Vec3::ZERO, dir, Vec3::Y, &Mat3::ZERO, fs, Outgoing::Refract(eta), 0.0).unwrap();
            // The spread in the plane of incidence: √(eᵀ·C·e), e the outgoing in-plane axis.
            let e = Vec3::Z.cross(out.dir).normalize();
            let (x, y) = (e.dot(out.u), e.dot(out.v));
            (out.c.a * x * x + 2.0 * out.c.b * x * y + out.c.c * y * y).max(0.0).sqrt()
        };
        // Small spread: every ray of the cone refracts, first order holds.
        let small = spread_for(0.002);
        assert!((small - 0.002 * gain).abs() < 0.1 * 0.002 * gain, "side {sx}: spread {small}, first order {}", 0.002 * gain);
        // 0.05 rad: the rays on one side pass the critical angle (2.0° away).
        let wide = spread_for(0.05);
        assert!(wide > 0.5 * 0.05 * gain, "side {sx}: spread {wide}, first order {}, the small cone's × 25 {}", 0.05 * gain, small * 25.0);
    }
}

/// Semi-axes (major, minor) of a cone's footprint at t, unclamped.
fn axes_at(c: &Cone, t: f32) -> (f32, f32) {
    let e = eigen_1(c.sigma(t), 1e-9, 1e-30);
    (e.s1, e.s2)
}

/// §4.2, reflected rays: a flat mirror reflects every ray of the incoming cone, so the
/// reflected cone is the mirror image of the incoming one continued through the mirror; its
/// footprint `t'` past the mirror is the incoming cone's at `t_hit + t'`. A depth-of-field
/// cone (the pixel cone plus the lens cone, §4.2 "Primary Rays") meeting a mirror at the
/// focal plane carries the lens cone's rays, which cross there and diverge again: a mirror
/// in focus shows the objects it reflects as blurred as the lens blurs them at that
/// distance. (Until this review the reflected cone kept only the growth rate of the
/// footprint's semi-axes, which at the focal plane is the pixel cone's: the lens spread was
/// lost and a mirror in focus reflected everything in focus.)
#[test]
fn flat_mirror_in_focus_keeps_the_lens_blur() {
    let cam = Camera { eye: Vec3::ZERO, look: Vec3::new(0.0, 0.0, -1.0), up: Vec3::Y, fovy: 40.0, aperture: 0.2, focal_dist: 5.0 };
    let fr = cam.frame(64, 64);
    for (i, j, tilt) in [(32u32, 32u32, 0.0f32), (32, 32, 0.4), (9, 51, 0.25), (50, 20, 0.0)] {
        let c = Cone::primary(&fr, i, j, 1.0, std::f32::consts::FRAC_1_SQRT_2);
        for t_hit in [5.0 / c.dir.dot(fr.f), 3.0] {
            let p = c.org + c.dir * t_hit;
            let n = (-c.dir + Vec3::new(0.3, 1.0, 0.2).normalize() * tilt).normalize();
            let fs = c.footprint_and_spread(t_hit, 1e-9, 1e-30);
            let r = cone::secondary(p, c.dir, n, &Mat3::ZERO, fs, Outgoing::Reflect, 0.0).unwrap();
            for tp in [0.5f32, 2.0, 10.0] {
                let (got, want) = (axes_at(&r, tp), axes_at(&c, t_hit + tp));
                let err = ((got.0 - want.0) / want.0).abs().max(((got.1 - want.1) / want.1).abs());
                assert!(
                    err < 0.01,
                    "pixel ({i},{j}) tilt {tilt} hit at {t_hit}: {tp} past the mirror, axes {got:?}, mirror image {want:?}"
                );
            }
        }
    }
    // The same for a footprint that does not grow (startDev only) plus a rough reflection's
    // blur (a second cone, added in quadrature, §6): a flat mirror further on keeps the blur.
    let c = Cone::new(Vec3::new(0.0, 0.0, 10.0), Vec3::NEG_Z, &[(Fp::diag(0.5), Fp::ZERO), (Fp::ZERO, Fp::diag(0.1))]);
    let fs = c.footprint_and_spread(1.0, 1e-9, 1e-30);
    let r = cone::secondary(Vec3::new(0.0, 0.0, 9.0), Vec3::NEG_Z, Vec3::Z, &Mat3::ZERO, fs, Outgoing::Reflect, 0.0).unwrap();
    for tp in [1.0f32, 10.0] {
        let (got, want) = (axes_at(&r, tp), axes_at(&c, 1.0 + tp));
        assert!((got.0 - want.0).abs() < 0.01 * want.0, "rough then flat: {tp} past the mirror, axes {got:?}, mirror image {want:?}");
    }
}

/// The cones of a blurry reflection and of an elliptical light have the variance of what
/// the distributed reference samples there (a uniform cap of half-angle `roughness`, a
/// uniform ellipse), at the default `--rough-scale` and `--light-scale`. A Gaussian
/// exp(−x²/a²) has variance a²/2 per axis, a uniform disk of radius R has R²/4: with the
/// scales at 1 (the paper's tan(roughness) and the light's axes) the cones were √2 too wide,
/// blurrier reflections and wider penumbrae than the reference (stop 51).
#[test]
fn glossy_and_light_cones_have_the_reference_samplers_variance() {
    use lodtrace::baseline::shade::sample_cone;
    let tp = TraceParams::default();
    let n = 200;
    let grid = || (0..n * n).map(move |k| (((k % n) as f32 + 0.5) / n as f32, ((k / n) as f32 + 0.5) / n as f32));
    for roughness in [0.03f32, 0.1, 0.25] {
        // Per axis, in the plane at unit distance along the mirror direction.
        let var_ref = grid()
            .map(|(u, v)| {
                let d = sample_cone(Vec3::Z, roughness, u, v);
                (((d.x / d.z).powi(2) + (d.y / d.z).powi(2)) / 2.0) as f64
            })
            .sum::<f64>()
            / (n * n) as f64;
        let a = cone::rough_spread(roughness, tp.rough_scale) as f64;
        let ratio = a * a / 2.0 / var_ref;
        assert!((ratio - 1.0).abs() < 0.03, "roughness {roughness}: cone variance ÷ the reference's {ratio}");
        // And the reflected cone carries it: a mirror hit by a negligible footprint.
        let incoming = Cone::new(Vec3::new(0.0, 0.0, 10.0), Vec3::new(0.0, 0.0, -1.0), &[(Fp::ZERO, Fp::diag(1e-6))]);
        let fs = incoming.footprint_and_spread(10.0, 1e-9, 1e-30);
        let rc = cone::secondary(Vec3::ZERO, incoming.dir, Vec3::Z, &Mat3::ZERO, fs, Outgoing::Reflect, a as f32).unwrap();
        let e = eigen_1(rc.sigma(3.0), 1e-9, 1e-30);
        assert!(((e.s1 / 3.0) as f64 / a - 1.0).abs() < 1e-3 && ((e.s2 / 3.0) as f64 / a - 1.0).abs() < 1e-3);
    }
    // An ellipse facing the shading point, 9 units away: the shadow cone at the light.
    let (c, axis_a, axis_b) = (Vec3::new(0.0, 9.0, 0.0), Vec3::new(2.8, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.7));
    let light = Light::Ellipse { center: c, axis_a, axis_b, intensity: Vec3::ONE };
    let var_along = |axis: Vec3| {
        let u = axis.normalize();
        grid().map(|(s, t)| ((light.sample(s, t) - c).dot(u) as f64).powi(2)).sum::<f64>() / (n * n) as f64
    };
    let (la, lb) = cone::light_axes(axis_a, axis_b, tp.light_scale);
    let (sh, dist) = cone::shadow(Vec3::ZERO, Vec3::X * 1e-6, Vec3::Z * 1e-6, c, la, lb);
    let e = eigen_1(sh.sigma(dist), 1e-9, 1e-30);
    for (semi, axis) in [(e.s1, axis_a), (e.s2, axis_b)] {
        let ratio = (semi as f64).powi(2) / 2.0 / var_along(axis);
        assert!((ratio - 1.0).abs() < 0.03, "light axis {axis}: cone variance ÷ the reference's {ratio}");
    }
}
