//! Criterion benchmark of the 2×2 footprint eigen-decomposition (`core::eigen2`, Wand & Straßer
//! §4.1 eq. 3): the same 4096 random Σ = F Fᵀ, stored SoA, through
//!
//! - `scalar`: [`eigen_1`] in a loop (the reference),
//! - `x4`: [`eigen_x4`] over chunks of 4,
//! - `x8`: [`eigen_x8`] over chunks of 8 (`wide::f32x8`: two SSE halves without target-cpu flags),
//! - `x8_avx2`: [`eigen_soa`], i.e. `eigen_x8_avx2` over chunks of 8 in an AVX2 function chosen at
//!   run time (falls back to `x8` on CPUs without AVX2/FMA),
//!
//! each writing cos, sin, s1, s2 to output Vecs. Throughput is in footprints (elements) per second.
//!
//! Run: `cargo bench --bench eigen`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lodtrace::core::eigen2::{eigen_1, eigen_soa, eigen_x4, eigen_x8, Eigen2Out, Sym2};
use lodtrace::core::rng::Sampler;
use std::hint::black_box;
use wide::{f32x4, f32x8};

const N: usize = 4096;
const CLAMP: f32 = 0.125;
const FLOOR: f32 = 1e-6;

struct Soa {
    a: Vec<f32>,
    b: Vec<f32>,
    c: Vec<f32>,
}

/// Σ = F Fᵀ with F's entries uniform in [-1, 1) times a scale 10^U(-3, 3).
fn inputs() -> Soa {
    let mut s = Sampler::new(11, 0, 0);
    let mut m = Soa { a: Vec::with_capacity(N), b: Vec::with_capacity(N), c: Vec::with_capacity(N) };
    for _ in 0..N {
        let k = 10f32.powf(s.next() * 6.0 - 3.0);
        let f = [s.next(), s.next(), s.next(), s.next()].map(|x| (2.0 * x - 1.0) * k);
        m.a.push(f[0] * f[0] + f[1] * f[1]);
        m.b.push(f[0] * f[2] + f[1] * f[3]);
        m.c.push(f[2] * f[2] + f[3] * f[3]);
    }
    m
}

struct Out {
    cos: Vec<f32>,
    sin: Vec<f32>,
    s1: Vec<f32>,
    s2: Vec<f32>,
}

impl Out {
    fn new() -> Self {
        Out { cos: vec![0.0; N], sin: vec![0.0; N], s1: vec![0.0; N], s2: vec![0.0; N] }
    }
}

fn eigen(c: &mut Criterion) {
    let m = inputs();
    let mut o = Out::new();
    let mut g = c.benchmark_group("eigen2");
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("scalar", |bch| {
        bch.iter(|| {
            let (a, b, cc) = (black_box(&m.a), black_box(&m.b), black_box(&m.c));
            for i in 0..N {
                let e = eigen_1(Sym2 { a: a[i], b: b[i], c: cc[i] }, CLAMP, FLOOR);
                (o.cos[i], o.sin[i], o.s1[i], o.s2[i]) = (e.cos, e.sin, e.s1, e.s2);
            }
            black_box(&mut o);
        })
    });
    g.bench_function("x4", |bch| {
        bch.iter(|| {
            let (a, b, cc) = (black_box(&m.a), black_box(&m.b), black_box(&m.c));
            for i in (0..N).step_by(4) {
                let v = |s: &Vec<f32>| f32x4::from(&s[i..i + 4]);
                let e = eigen_x4(v(a), v(b), v(cc), CLAMP, FLOOR);
                o.cos[i..i + 4].copy_from_slice(&e.cos.to_array());
                o.sin[i..i + 4].copy_from_slice(&e.sin.to_array());
                o.s1[i..i + 4].copy_from_slice(&e.s1.to_array());
                o.s2[i..i + 4].copy_from_slice(&e.s2.to_array());
            }
            black_box(&mut o);
        })
    });
    g.bench_function("x8", |bch| {
        bch.iter(|| {
            let (a, b, cc) = (black_box(&m.a), black_box(&m.b), black_box(&m.c));
            for i in (0..N).step_by(8) {
                let v = |s: &Vec<f32>| f32x8::from(&s[i..i + 8]);
                let e = eigen_x8(v(a), v(b), v(cc), CLAMP, FLOOR);
                o.cos[i..i + 8].copy_from_slice(&e.cos.to_array());
                o.sin[i..i + 8].copy_from_slice(&e.sin.to_array());
                o.s1[i..i + 8].copy_from_slice(&e.s1.to_array());
                o.s2[i..i + 8].copy_from_slice(&e.s2.to_array());
            }
            black_box(&mut o);
        })
    });
    g.bench_function("x8_avx2", |bch| {
        bch.iter(|| {
            let out = Eigen2Out { cos: &mut o.cos, sin: &mut o.sin, s1: &mut o.s1, s2: &mut o.s2 };
            eigen_soa(black_box(&m.a), black_box(&m.b), black_box(&m.c), CLAMP, FLOOR, out);
            black_box(&mut o);
        })
    });
    g.finish();
}

criterion_group!(benches, eigen);
criterion_main!(benches);
