//! Criterion benchmarks of the intersection kernels and of primary-ray throughput:
//!
//! - `node8`: one CWBVH node (8 quantised child boxes) against one ray — our SSE2 test (`wide::f32x8` off x86-64)
//!   test, obvhs' SSE test and obvhs' scalar reference;
//! - `triangle`: the watertight test (Woop et al.) against Möller–Trumbore;
//! - `primary/<scene>` (spheres, complex, armadillo): the DESIGN.md camera's primary rays (160×120) through each back-end:
//!   bvh single rays, Embree single rays, Embree 8-wide packets, Embree streams.
//!
//! Run: `cargo bench --bench traversal` (add `-- primary` to pick a group).

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::{Vec3, Vec3A};
use lodtrace::baseline::accel::{self, Accel, AccelKind, Ray, K};
use lodtrace::baseline::bvh::intersect_node;
use lodtrace::baseline::tri::{intersect_moller_trumbore, intersect_watertight, RayShear};
use lodtrace::core::rng::Sampler;
use lodtrace::core::stats::Counters;
use obvhs::{aabb::Aabb, cwbvh::node::CwBvhNode, BvhBuildParams};

fn rnd3(s: &mut Sampler) -> Vec3 {
    Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5)
}

fn node8(c: &mut Criterion) {
    let mesh = lodtrace::scene::builtin::icosphere(5, 0);
    let aabbs: Vec<Aabb> = (0..mesh.tri_count())
        .map(|t| {
            let [a, b, c] = mesh.tri_verts(t);
            Aabb::new(Vec3A::from(a.min(b).min(c)), Vec3A::from(a.max(b).max(c)))
        })
        .collect();
    let bvh = obvhs::cwbvh::builder::build_cwbvh(&aabbs, BvhBuildParams::medium_build(), &mut Default::default());
    let mut s = Sampler::new(1, 0, 0);
    let rays: Vec<(obvhs::ray::Ray, u32)> = (0..256)
        .map(|_| {
            let o = Vec3A::from(rnd3(&mut s) * 4.0);
            let d = Vec3A::from(rnd3(&mut s));
            (obvhs::ray::Ray::new(o, d, 1e-4, 1e30), bvh.new_traversal(d).oct_inv4)
        })
        .collect();
    let nodes = &bvh.nodes[..bvh.nodes.len().min(64)];
    let mut g = c.benchmark_group("node8");
    g.throughput(Throughput::Elements((rays.len() * nodes.len()) as u64));
    type NodeTest = fn(&CwBvhNode, &obvhs::ray::Ray, u32) -> u32;
    let mut kernels: Vec<(&str, NodeTest)> = vec![
        ("lodtrace_simd", intersect_node),
        ("obvhs_sse", |n, r, o| n.intersect_ray(r, o)),
        ("obvhs_scalar", |n, r, o| n.intersect_ray_basic(r, o)),
    ];
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 checked just above.
        kernels.insert(1, ("lodtrace_avx2", |n, r, o| unsafe { lodtrace::baseline::bvh::intersect_node_avx2(n, r, o) }));
    }
    for (name, test) in kernels {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut acc = 0u32;
                for (r, oct) in &rays {
                    for n in nodes {
                        acc ^= test(black_box(n), r, *oct);
                    }
                }
                acc
            })
        });
    }
    g.finish();
}

fn triangle(c: &mut Criterion) {
    let mut s = Sampler::new(2, 0, 0);
    let tris: Vec<[Vec3; 3]> = (0..1024).map(|_| [rnd3(&mut s), rnd3(&mut s), rnd3(&mut s)]).collect();
    let rays: Vec<(Vec3, Vec3)> = (0..64).map(|_| (rnd3(&mut s) * 4.0, rnd3(&mut s))).collect();
    let mut g = c.benchmark_group("triangle");
    g.throughput(Throughput::Elements((tris.len() * rays.len()) as u64));
    g.bench_function("watertight", |b| {
        b.iter(|| {
            let mut n = 0u32;
            for (o, d) in &rays {
                let sh = RayShear::new(*o, *d);
                for t in &tris {
                    n += intersect_watertight(&sh, t[0], t[1], t[2], 0.0, f32::INFINITY).is_some() as u32;
                }
            }
            n
        })
    });
    g.bench_function("moller_trumbore", |b| {
        b.iter(|| {
            let mut n = 0u32;
            for (o, d) in &rays {
                for t in &tris {
                    n += intersect_moller_trumbore(*o, *d, t[0], t[1], t[2]).is_some() as u32;
                }
            }
            n
        })
    });
    g.finish();
}

fn primary(c: &mut Criterion) {
    for name in ["spheres", "complex", "assets/armadillo.off"] {
        let mut scene = lodtrace::scene::load::load_scene(name).expect("scene (run tools/setup)");
        scene.validate().unwrap();
        let (w, h) = (160u32, 120u32);
        let fr = scene.camera.frame(w, h);
        let rays: Vec<Ray> =
            (0..h).flat_map(|j| (0..w).map(move |i| (i, j))).map(|(i, j)| Ray::new(fr.eye, fr.pixel_center_dir(i, j))).collect();
        let label = name.trim_start_matches("assets/").trim_end_matches(".off");
        let mut g = c.benchmark_group(format!("primary/{label}"));
        g.throughput(Throughput::Elements(rays.len() as u64));
        g.sample_size(20);
        let bvh = accel::build(AccelKind::Bvh, &scene).unwrap();
        let emb = lodtrace::baseline::embree::EmbreeAccel::build(&scene).unwrap();
        for (label, be) in [("bvh", bvh.as_ref()), ("embree", &emb as &dyn Accel)] {
            g.bench_with_input(BenchmarkId::new("single", label), &rays, |b, rays| {
                b.iter(|| {
                    let mut cn = Counters::default();
                    rays.iter().filter(|r| be.intersect1(r, &mut cn).is_some()).count()
                })
            });
        }
        // Packets of 8 along image rows (coherent, as the Whitted tracer issues them).
        g.bench_with_input(BenchmarkId::new("packet8", "embree"), &rays, |b, rays| {
            b.iter(|| {
                let mut cn = Counters::default();
                let mut out = [None; K];
                let mut n = 0;
                for ch in rays.chunks_exact(K) {
                    emb.intersect8(ch.try_into().unwrap(), 0xff, &mut out, &mut cn);
                    n += out.iter().filter(|h| h.is_some()).count();
                }
                n
            })
        });
        g.bench_with_input(BenchmarkId::new("stream", "embree"), &rays, |b, rays| {
            let mut out = vec![None; rays.len()];
            b.iter(|| {
                let mut cn = Counters::default();
                emb.intersect_stream(rays, &mut out, &mut cn);
                out.iter().filter(|h| h.is_some()).count()
            })
        });
        g.finish();
    }
}

criterion_group!(benches, node8, triangle, primary);
criterion_main!(benches);
