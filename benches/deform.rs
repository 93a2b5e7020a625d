//! Criterion benchmarks of the Adams et al. kernels with a scalar reference beside an f32x8
//! version. Run: `cargo bench --bench deform`.
//!
//! `sphere_test`: the bounding-sphere test (`deform::tree`) on 4096 random (ray, sphere)
//! pairs, throughput in ray–sphere tests:
//! - `scalar`: [`sphere_test_1`] per pair (the reference),
//! - `x8_spheres`: one ray against 8 spheres per [`sphere_test_x8_spheres`] step,
//! - `x8_rays`: 8 rays (SoA) against one sphere per [`sphere_test_x8_rays`] step.
//!
//! `packet_nodes`: what the packet traversal does per node — 512 packets of 8 rays, each
//! meeting 16 spheres with its own per-ray `tfar`: [`sphere_test_1`] ray by ray against
//! [`RayPacketX8::test`] (the packet built once, as in `intersect_x8`); throughput in
//! ray–sphere tests.
//!
//! `packet_ellipse`: what the packet traversal does per leaf — 512 packets of 8 rays, each
//! meeting 16 surfel ellipses: `mls::ellipse_hit` ray by ray against
//! [`RayPacketX8::ellipse`]; throughput in ray–ellipse tests.
//!
//! `mls`: the MLS iteration (§4.2.1) from a surfel-ellipse start on 1024 noisy 16-surfel
//! neighbourhoods of a sphere — [`mls_intersect`] vs [`mls_intersect_x8`]; throughput in
//! intersections.
//!
//! `deform_point`: Eq. 1 for 6000 surfels of a sphere, 16 of 500 simulation nodes each,
//! under a random non-rigid motion (what a lazy refit of one `elastic-balls` ball does per
//! surfel before it stores it); throughput in surfels.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::Vec3;
use lodtrace::core::rng::Sampler;
use lodtrace::deform::displace::{deform_point, NodeWeights};
use lodtrace::deform::mls::{ellipse_hit, mls_intersect, mls_intersect_x8, MlsNbr, MlsParams};
use lodtrace::deform::tree::{sphere_test_1, sphere_test_x8_rays, sphere_test_x8_spheres, RayPacketX8};
use lodtrace::deform::{DeformField, SimNodes};
use std::hint::black_box;
use wide::f32x8;

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

/// One packet's rays in struct-of-arrays form: (origins, directions), each `[axis][lane]`.
type PacketSoa = ([[f32; 8]; 3], [[f32; 8]; 3]);

/// The rays `8k .. 8k + 8` of `inp` in struct-of-arrays form (origins, directions) for
/// packet k < `p`; the benches build each `RayPacketX8` in the timed loop, as `intersect_x8`
/// builds one per packet.
fn packets(inp: &Input, p: usize) -> Vec<PacketSoa> {
    let soa = |v: &[Vec3]| -> [[f32; 8]; 3] { std::array::from_fn(|a| std::array::from_fn(|l| v[l][a])) };
    (0..p).map(|k| (soa(&inp.o[8 * k..8 * k + 8]), soa(&inp.d[8 * k..8 * k + 8]))).collect()
}

/// Packets per run and node (or surfel) visits per packet of the packet benches.
const P: usize = N / 8;
const S: usize = 16;

/// A packet bench: for each of the `P` packets of `inp` and each of its `S` visits `j`,
/// `scalar(k, j, i, l)` tests ray i (lane l) alone and `x8(pk, k, j)` the whole packet (built
/// in the timed loop, once per packet as in `intersect_x8`), returning the hits.
fn packet_group(
    cr: &mut Criterion,
    name: &str,
    inp: &Input,
    scalar: impl Fn(usize, usize, usize, usize) -> bool,
    x8: impl Fn(&RayPacketX8, usize, usize) -> u32,
) {
    let pks = packets(inp, P);
    let mut g = cr.benchmark_group(name);
    g.throughput(Throughput::Elements((P * S * 8) as u64));
    g.bench_function("scalar", |b| {
        b.iter(|| {
            let mut hits = 0u32;
            for k in 0..P {
                for j in 0..S {
                    for l in 0..8 {
                        hits += scalar(k, j, 8 * k + l, l) as u32;
                    }
                }
            }
            black_box(hits)
        })
    });
    g.bench_function("x8", |b| {
        b.iter(|| {
            let mut hits = 0u32;
            for (k, (o, d)) in pks.iter().enumerate() {
                let pk = RayPacketX8::new(o, d, &[0.0; 8]);
                for j in 0..S {
                    hits += x8(&pk, k, j);
                }
            }
            black_box(hits)
        })
    });
    g.finish();
}

fn packet_nodes(cr: &mut Criterion) {
    let inp = inputs();
    let tfar: Vec<[f32; 8]> = (0..P).map(|k| std::array::from_fn(|l| 4.0 + ((k * 8 + l) % 7) as f32)).collect();
    let tf8: Vec<f32x8> = tfar.iter().map(|t| f32x8::from(*t)).collect();
    let sphere = |k: usize, j: usize| (inp.c[(k * S + j) % N], inp.r[(k * S + j) % N]);
    packet_group(
        cr,
        "packet_nodes",
        &inp,
        |k, j, i, l| {
            let (c, r) = sphere(k, j);
            sphere_test_1(inp.o[i], inp.d[i], c, r, 0.0, tfar[k][l]).is_some()
        },
        |pk, k, j| {
            let (c, r) = sphere(k, j);
            pk.test(c, r, tf8[k]).0.count_ones()
        },
    );
}

fn packet_ellipse(cr: &mut Criterion) {
    let inp = inputs();
    let mut s = Sampler::new(6, 0, 0);
    let mut axis = || Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.6;
    let axes: Vec<(Vec3, Vec3)> = (0..N).map(|_| (axis(), axis())).collect();
    let surfel = |k: usize, j: usize| (inp.c[(k * S + j) % N], axes[(k * S + j) % N]);
    let tf = f32x8::splat(100.0);
    packet_group(
        cr,
        "packet_ellipse",
        &inp,
        |k, j, i, _| {
            let (c, (u, v)) = surfel(k, j);
            ellipse_hit(inp.o[i], inp.d[i], c, u, v, 0.0, 100.0).is_some()
        },
        |pk, k, j| {
            let (c, (u, v)) = surfel(k, j);
            pk.ellipse(c, u, v, tf).0.count_ones()
        },
    );
}

fn mls(cr: &mut Criterion) {
    const M: usize = 1024;
    let mut s = Sampler::new(9, 0, 0);
    let mut cases = Vec::with_capacity(M);
    for _ in 0..M {
        let dir0 = Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5).normalize_or(Vec3::Z);
        let mut nb = Vec::new();
        let mut nbx = MlsNbr::default();
        for _ in 0..16 {
            let q = (dir0 + Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.3).normalize_or(Vec3::Z);
            let p = q * (1.0 + 0.01 * (s.next() - 0.5));
            nb.push((p, q));
            nbx.push(p, q);
        }
        let x0 = dir0;
        let o = x0 * 4.0 + Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.3;
        let d = (x0 - o).normalize();
        let t0 = (x0 - o).length();
        cases.push((o, d, t0, x0, nb, nbx));
    }
    let prm = MlsParams::default();
    let mut g = cr.benchmark_group("mls");
    g.throughput(Throughput::Elements(M as u64));
    g.bench_function("scalar", |b| {
        b.iter(|| {
            for (o, d, t0, x0, nb, _) in black_box(&cases) {
                black_box(mls_intersect(*o, *d, *t0, *x0, nb, 0.35, *x0, 0.5, 0.0, 100.0, &prm));
            }
        })
    });
    g.bench_function("x8", |b| {
        b.iter(|| {
            for (o, d, t0, x0, _, nbx) in black_box(&cases) {
                black_box(mls_intersect_x8(*o, *d, *t0, *x0, nbx, 0.35, *x0, 0.5, 0.0, 100.0, &prm));
            }
        })
    });
    g.finish();
}

fn deform(cr: &mut Criterion) {
    let mut s = Sampler::new(11, 0, 0);
    let mut unit = || Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5).normalize_or(Vec3::Z);
    let rest: Vec<Vec3> = (0..500).map(|_| unit() * 0.9).collect();
    let pts: Vec<Vec3> = (0..6000).map(|_| unit()).collect();
    let axes: Vec<(Vec3, Vec3)> =
        pts.iter().map(|p| (p.any_orthonormal_vector() * 0.02, p.cross(p.any_orthonormal_vector()) * 0.02)).collect();
    let nodes = SimNodes::new(rest.clone(), vec![1.0; rest.len()], 8).unwrap();
    let q = glam::Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), 0.7);
    let def: Vec<Vec3> = rest.iter().map(|x| q * (*x * Vec3::new(1.2, 0.8, 1.0) + 0.05 * Vec3::new(x.y, x.z, x.x) * x.x)).collect();
    let f = DeformField::compute(&nodes, &def, true).unwrap();
    let w = NodeWeights::new(&pts, &nodes, 16);
    let k = w.k;
    let mut g = cr.benchmark_group("deform_point");
    g.throughput(Throughput::Elements(pts.len() as u64));
    g.bench_function("eq1", |b| {
        b.iter(|| {
            for (i, (p, a)) in black_box(&pts).iter().zip(&axes).enumerate() {
                black_box(deform_point(&f, *p, *a, &w.idx[i * k..i * k + k], &w.w[i * k..i * k + k]));
            }
        })
    });
    g.finish();
}

criterion_group!(benches, bench, packet_nodes, packet_ellipse, mls, deform);
criterion_main!(benches);
