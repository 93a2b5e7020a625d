//! Criterion benchmark of the Adams et al. bounding-sphere test (`deform::tree`): 4096 random
//! (ray, sphere) pairs, as
//!
//! - `scalar`: [`sphere_test_1`] per pair (the reference),
//! - `x8_spheres`: one ray against 8 spheres per [`sphere_test_x8_spheres`] step,
//! - `x8_rays`: 8 rays (SoA) against one sphere per [`sphere_test_x8_rays`] step.
//!
//! Throughput is in ray–sphere tests per second. Run: `cargo bench --bench deform`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::Vec3;
use lodtrace::core::rng::Sampler;
use lodtrace::deform::tree::{sphere_test_1, sphere_test_x8_rays, sphere_test_x8_spheres};
use std::hint::black_box;

const N: usize = 4096;

struct Input {
    o: Vec<Vec3>,
    d: Vec<Vec3>,
    c: Vec<Vec3>,
    r: Vec<f32>,
}

/// Rays from around the unit cube toward it, spheres inside it: about half the tests hit.
fn inputs() -> Input {
    let mut s = Sampler::new(5, 0, 0);
    let mut v = |k: f32| Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * k;
    let mut inp = Input { o: vec![], d: vec![], c: vec![], r: vec![] };
    for _ in 0..N {
        let o = v(6.0);
        let target = v(1.0);
        inp.o.push(o);
        inp.d.push((target - o).normalize());
        inp.c.push(v(1.0));
        inp.r.push(0.05 + 0.3 * v(1.0).x.abs());
    }
    inp
}

fn bench(cr: &mut Criterion) {
    let inp = inputs();
    let mut g = cr.benchmark_group("sphere_test");
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("scalar", |b| {
        b.iter(|| {
            let mut hits = 0u32;
            for i in 0..N {
                hits += sphere_test_1(inp.o[i], inp.d[i], inp.c[i], inp.r[i], 0.0, f32::INFINITY).is_some() as u32;
            }
            black_box(hits)
        })
    });
    // SoA copies for the packet kernels.
    let soa = |f: &dyn Fn(usize) -> f32| -> Vec<[f32; 8]> { (0..N / 8).map(|k| std::array::from_fn(|l| f(8 * k + l))).collect() };
    let (cx, cy, cz, r) = (soa(&|i| inp.c[i].x), soa(&|i| inp.c[i].y), soa(&|i| inp.c[i].z), soa(&|i| inp.r[i]));
    g.bench_function("x8_spheres", |b| {
        b.iter(|| {
            let mut hits = 0u32;
            for k in 0..N / 8 {
                // Ray 8k against spheres 8k..8k+8 (same number of tests as the reference).
                let (m, _) = sphere_test_x8_spheres(inp.o[8 * k], inp.d[8 * k], &cx[k], &cy[k], &cz[k], &r[k], 0.0, f32::INFINITY);
                hits += m.count_ones();
            }
            black_box(hits)
        })
    });
    let (ox, oy, oz) = (soa(&|i| inp.o[i].x), soa(&|i| inp.o[i].y), soa(&|i| inp.o[i].z));
    let (dx, dy, dz) = (soa(&|i| inp.d[i].x), soa(&|i| inp.d[i].y), soa(&|i| inp.d[i].z));
    let (tn, tf) = ([0.0f32; 8], [f32::INFINITY; 8]);
    g.bench_function("x8_rays", |b| {
        b.iter(|| {
            let mut hits = 0u32;
            for k in 0..N / 8 {
                let (m, _) = sphere_test_x8_rays(&[ox[k], oy[k], oz[k]], &[dx[k], dy[k], dz[k]], inp.c[8 * k], inp.r[8 * k], &tn, &tf);
                hits += m.count_ones();
            }
            black_box(hits)
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
