//! Criterion benchmarks of the Wand & Straßer kernels in `multires` that have a scalar
//! reference beside an `f32x8` version, each group on the same random inputs:
//!
//! - `node_test`: one cone against the 8 child spheres of a node (§4.6) — [`node_test_1`]
//!   (lane by lane) vs [`node_test_x8`]; 512 cones × 8 spheres, throughput in cone–sphere tests.
//! - `tri_bound`: the exact triangle prefilter (a cone against 8 triangle bounding spheres) —
//!   [`tri_bound_1`] lane by lane vs [`tri_bound_x8`]; the same 512 × 8 inputs as `node_test`
//!   (empty lanes r = −∞), throughput in cone–sphere tests.
//! - `point_w_per_box` / `point_w_exact`: the ray–point weight (§4.3) of a node's point block
//!   (exponent, cut-off, normal decode and cosine, cover, e^(−q)), with the node's one
//!   eigen-decomposition (§5.2, the default) or one per point — [`point_w_ref`] (the
//!   reference, point by point) vs [`point_w_x8`] (8 points a step, survivors left-packed);
//!   both write the same list of hits (index, depth, weight) to a [`PointHits`]; 96 blocks of
//!   17–64 points (3 618 in all), throughput in points.
//! - `octree_spheres`: a thin ray against 8 child spheres (`--accel octree`) — [`sphere_1`]
//!   vs [`spheres_x8`]; 64 rays, each against the 8 children of 8 nodes (the per-ray set-up
//!   hoisted on both sides, as in the traversal), throughput in ray–sphere tests.
//! - `cone_sigma`: the squared footprint Σ(t) = a + b·t + c·t² — [`Cone::sigma`] vs
//!   [`Cone::sigma_x8`]; 4 096 depths, throughput in depths.
//! - `tlas_box`: the instance-level box test grown by the cone's reach — [`tlas_box_test_1`]
//!   vs [`tlas_box_test_x8`]; 1 024 random slots, throughput in slots.
//! - `tri_mass`: the Gaussian's mass over a 2-D triangle (`--tri-weight mass`) —
//!   [`gauss_tri_mass`] (six right triangles one by one) vs [`gauss_tri_mass_x8`] (the six
//!   in the lanes of one pass) vs [`gauss_tri_mass_8`] (`x8_batch`: eight triangles per
//!   call, one per lane, as the renderer calls it); 1 024 small triangles and slivers near
//!   the footprint's centre, which all take the full path (the one-edge fast path is not
//!   measured here), throughput in triangles.
//! - `tri_mask`: a triangle's coverage mask over the 64 sub-rays (`--coverage-masks`) —
//!   [`tri_mask_1`] vs [`tri_mask`] (eight sub-rays per step); the same 1 024 triangles,
//!   throughput in triangles.
//!
//! The 2×2 eigen-decomposition, used inside the node test and the exact point test, has its own
//! bench (`benches/eigen.rs`). The `x8` kernels use `wide::f32x8` (two SSE halves without
//! target-cpu flags). Run: `cargo bench --bench multires`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::{Vec2, Vec3};
use lodtrace::core::eigen2::{eigen_1, Eigen2};
use lodtrace::core::rng::Sampler;
use lodtrace::multires::cone::{Cone, Fp};
use lodtrace::multires::mask::{tri_mask, tri_mask_1};
use lodtrace::multires::mass::{gauss_tri_mass, gauss_tri_mass_8, gauss_tri_mass_x8};
use lodtrace::multires::octree_accel::{sphere_1, spheres_x8, RayX8};
use lodtrace::multires::quant::{encode_cover, oct_encode};
use lodtrace::multires::trace::{
    node_test_1, node_test_x8, point_w_ref, point_w_x8, tlas_box_test_1, tlas_box_test_x8, tri_bound_1, tri_bound_x8, BoxReach, PointBlock,
    PointHits, Tlas, R_CUT,
};
use std::hint::black_box;
use wide::f32x8;

const CLAMP: f32 = 0.125;
const FLOOR: f32 = 1e-7;
/// The node and triangle tests at the paper's cut distance (R_CUT), as first benched.
const CUT: f32 = R_CUT;

fn v3(s: &mut Sampler) -> Vec3 {
    Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5)
}

/// A random cone: random direction and origin, an anisotropic footprint 10^U(-4,0) wide (the
/// distribution of the kernel tests in `multires::trace`).
fn rnd_cone(s: &mut Sampler) -> Cone {
    let dir = v3(s).normalize();
    let k = 10f32.powf(s.next() * 4.0 - 4.0);
    let fp = Fp { c0: Vec2::new(s.next(), s.next() - 0.5) * k, c1: Vec2::new(s.next() - 0.5, s.next()) * k * s.next() };
    let fs = Fp { c0: Vec2::new(s.next(), 0.0) * k, c1: Vec2::new(0.0, s.next()) * k };
    let mut c = Cone::new(Vec3::new(s.next(), s.next(), s.next()), dir, &[(fs, fp)]);
    c.tmin = s.next() * 0.5;
    c
}

// ---------------------------------------------------------------------------------------
// Node test: one cone, the 8 child spheres.

struct NodeIn {
    cone: Cone,
    cx: [f32; 8],
    cy: [f32; 8],
    cz: [f32; 8],
    r: [f32; 8],
    /// The node's principal axes (for the triangle prefilter): Σ at a depth mid-range.
    boxe: Eigen2,
}

/// Spheres scattered around the cone axis at depths −2..18 (as in `node_test_x8_matches_scalar`),
/// 10% of them absent (radius −∞, as the missing children of a node).
fn node_inputs(n: usize) -> Vec<NodeIn> {
    let mut s = Sampler::new(21, 0, 0);
    (0..n)
        .map(|_| {
            let cone = rnd_cone(&mut s);
            let boxe = eigen_1(cone.sigma(s.next() * 16.0), CLAMP, FLOOR);
            let mut x = NodeIn { cone, cx: [0.0; 8], cy: [0.0; 8], cz: [0.0; 8], r: [0.0; 8], boxe };
            for l in 0..8 {
                let t = s.next() * 20.0 - 2.0;
                let off = v3(&mut s) * s.next() * 3.0;
                let p = cone.org + cone.dir * t + off;
                (x.cx[l], x.cy[l], x.cz[l]) = (p.x, p.y, p.z);
                x.r[l] = if s.next() < 0.1 { f32::NEG_INFINITY } else { s.next() * 0.5 };
            }
            x
        })
        .collect()
}

fn node_test(cr: &mut Criterion) {
    let inp = node_inputs(512);
    let hits: u32 = inp.iter().map(|x| node_test_x8(&x.cone, &x.cx, &x.cy, &x.cz, &x.r, CLAMP, FLOOR, CUT).mask.count_ones()).sum();
    eprintln!("node_test: {:.1}% of the cone–sphere tests pass", 100.0 * hits as f64 / (8 * inp.len()) as f64);
    let mut g = cr.benchmark_group("node_test");
    g.throughput(Throughput::Elements(8 * inp.len() as u64));
    g.bench_function("scalar", |b| {
        b.iter(|| {
            let mut acc = 0.0f32;
            for x in black_box(&inp) {
                let h = node_test_1(&x.cone, &x.cx, &x.cy, &x.cz, &x.r, CLAMP, FLOOR, CUT);
                acc += h.mask as f32 + h.t_near[0];
            }
            black_box(acc)
        })
    });
    g.bench_function("x8", |b| {
        b.iter(|| {
            let mut acc = 0.0f32;
            for x in black_box(&inp) {
                let h = node_test_x8(&x.cone, &x.cx, &x.cy, &x.cz, &x.r, CLAMP, FLOOR, CUT);
                acc += h.mask as f32 + h.t_near[0];
            }
            black_box(acc)
        })
    });
    g.finish();
}

fn tri_bound(cr: &mut Criterion) {
    let inp = node_inputs(512);
    let hits: u32 = inp.iter().map(|x| tri_bound_x8(&x.cone, &x.cx, &x.cy, &x.cz, &x.r, &x.boxe, CLAMP, FLOOR, CUT).count_ones()).sum();
    eprintln!("tri_bound: {:.1}% of the tests pass", 100.0 * hits as f64 / (8 * inp.len()) as f64);
    let mut g = cr.benchmark_group("tri_bound");
    g.throughput(Throughput::Elements(8 * inp.len() as u64));
    g.bench_function("scalar", |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for x in black_box(&inp) {
                for l in 0..8 {
                    acc += tri_bound_1(&x.cone, x.cx[l], x.cy[l], x.cz[l], x.r[l], &x.boxe, CLAMP, FLOOR, CUT) as u32;
                }
            }
            black_box(acc)
        })
    });
    g.bench_function("x8", |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for x in black_box(&inp) {
                acc += tri_bound_x8(&x.cone, &x.cx, &x.cy, &x.cz, &x.r, &x.boxe, CLAMP, FLOOR, CUT).count_ones();
            }
            black_box(acc)
        })
    });
    g.finish();
}

// ---------------------------------------------------------------------------------------
// Point test: a node's block of quantised points.

struct Block {
    cone: Cone,
    qx: Vec<u8>,
    qy: Vec<u8>,
    qz: Vec<u8>,
    normal: Vec<[u16; 2]>,
    cover: Vec<u8>,
    grid_lo: Vec3,
    h: f32,
    /// The node's footprint at its centre depth (per-box mode, §5.2).
    boxe: Eigen2,
}

impl Block {
    /// The block in ray coordinates, through the constructor [`PointBlock::new`] uses.
    /// As in the tree, the arrays run on past the block (7 more points), so packets load
    /// whole.
    fn view(&self) -> PointBlock<'_> {
        let n = self.qx.len() - 7;
        PointBlock {
            n,
            ..PointBlock::from_grid((&self.qx, &self.qy, &self.qz), &self.normal, &self.cover, self.grid_lo, self.h, &self.cone)
        }
    }
}

/// Blocks as the traversal meets them (k = 4: a 4³ cube of voxels of side h inside an 8³ grid
/// with margin): the node's cube straddles the cone axis at depth T ∈ [2, 8], and the footprint
/// there is 1–2 h wide (the level of detail picks the node whose spacing matches the
/// footprint), with random anisotropy up to 1:4. About 70% of the points pass.
fn point_inputs(n: usize) -> Vec<Block> {
    let mut s = Sampler::new(22, 0, 0);
    let mut s2 = Sampler::new(22, 1, 0);
    (0..n)
        .map(|_| {
            let h = 0.01 * (1.0 + s.next());
            let t = 2.0 + 6.0 * s.next();
            let dir = v3(&mut s).normalize();
            let org = v3(&mut s) * 4.0;
            let w = (1.0 + s.next()) * h / t; // footprint growth per unit t
            let an = 0.25 + 0.75 * s.next();
            let a = s.next() * std::f32::consts::TAU;
            let (cs, sn) = (a.cos(), a.sin());
            let incr = Fp { c0: Vec2::new(cs, sn) * w, c1: Vec2::new(-sn, cs) * (w * an) };
            let cone = Cone::new(org, dir, &[(Fp::ZERO, incr)]);
            // Cube of side 4h centred near the axis at depth t; grid index 0 is 2 voxels below it.
            let centre = org + dir * t + (cone.u * (s.next() - 0.5) + cone.v * (s.next() - 0.5)) * h;
            let grid_lo = centre - Vec3::splat(4.0 * h);
            let np = 17 + (s.next() * 48.0) as usize;
            let mut q = || 2 + (s.next() * 4.0) as u8;
            let (mut qx, mut qy, mut qz) = (vec![], vec![], vec![]);
            for _ in 0..np {
                qx.push(q());
                qy.push(q());
                qz.push(q());
            }
            // The 7 points past the block, random unit normals (cos to the ray anywhere in
            // [0, 1]) and covers of ½–2 h² from a second stream (the blocks' geometry stays
            // that of the first version of this bench).
            for _ in 0..7 {
                qx.push(2 + (s2.next() * 4.0) as u8);
                qy.push(2 + (s2.next() * 4.0) as u8);
                qz.push(2 + (s2.next() * 4.0) as u8);
            }
            let normal = (0..np + 7).map(|_| oct_encode(v3(&mut s2).normalize_or(Vec3::Z))).collect();
            let cover = (0..np + 7).map(|_| encode_cover(0.5 + 1.5 * s2.next())).collect();
            let boxe = eigen_1(cone.sigma(t), CLAMP, FLOOR);
            Block { cone, qx, qy, qz, normal, cover, grid_lo, h, boxe }
        })
        .collect()
}

fn point_w(cr: &mut Criterion) {
    const SCALE: f32 = 1e-4;
    let blocks = point_inputs(96);
    let npts: usize = blocks.iter().map(|b| b.view().n).sum();
    for exact in [false, true] {
        let name = if exact { "point_w_exact" } else { "point_w_per_box" };
        let boxe = |b: &Block| if exact { None } else { Some(b.boxe) };
        let (mut hits, mut out) = (0, PointHits::default());
        for b in &blocks {
            point_w_x8(&b.cone, &b.view(), boxe(b).as_ref(), CLAMP, FLOOR, SCALE, &mut out);
            hits += out.len;
        }
        eprintln!("{name}: {npts} points, {:.1}% pass", 100.0 * hits as f64 / npts as f64);
        let mut g = cr.benchmark_group(name);
        g.throughput(Throughput::Elements(npts as u64));
        g.bench_function("scalar", |bch| {
            bch.iter(|| {
                for b in black_box(&blocks) {
                    point_w_ref(&b.cone, &b.view(), boxe(b).as_ref(), CLAMP, FLOOR, SCALE, &mut out);
                    black_box(&mut out);
                }
            })
        });
        g.bench_function("x8", |bch| {
            bch.iter(|| {
                for b in black_box(&blocks) {
                    point_w_x8(&b.cone, &b.view(), boxe(b).as_ref(), CLAMP, FLOOR, SCALE, &mut out);
                    black_box(&mut out);
                }
            })
        });
        g.finish();
    }
}

// ---------------------------------------------------------------------------------------
// Octree back-end: a thin ray against the 8 child spheres.

struct RayIn {
    o: Vec3,
    d: Vec3,
    /// The child spheres of the nodes this ray meets, 8 per node.
    cx: Vec<[f32; 8]>,
    cy: Vec<[f32; 8]>,
    cz: Vec<[f32; 8]>,
    r: Vec<[f32; 8]>,
}

/// As the traversal meets them: a ray visits several nodes (here 8), each with 8 children
/// in the node's cube [−1, 1]³ (centres at the octant centres, jittered, radii 50–100% of an
/// octant's half-diagonal, 10% absent); rays from 3–5 units away aimed at a random point of
/// the cube, unnormalised directions, t ∈ [0, ∞). The per-ray set-up (1/|d|², the splats)
/// is done once per ray on both sides, as in the tracer.
fn ray_inputs(n: usize, nodes: usize) -> Vec<RayIn> {
    let mut s = Sampler::new(23, 0, 0);
    (0..n)
        .map(|_| {
            let o = v3(&mut s).normalize_or(Vec3::X) * (3.0 + 2.0 * s.next());
            let d = (v3(&mut s) * 1.6 - o) * (0.5 + 1.5 * s.next());
            let mut x = RayIn { o, d, cx: vec![], cy: vec![], cz: vec![], r: vec![] };
            for _ in 0..nodes {
                let (mut cx, mut cy, mut cz, mut r) = ([0.0; 8], [0.0; 8], [0.0; 8], [0.0; 8]);
                for l in 0..8 {
                    let oct = Vec3::new((l & 1) as f32, ((l >> 1) & 1) as f32, ((l >> 2) & 1) as f32) - 0.5;
                    let c = oct + v3(&mut s) * 0.2;
                    (cx[l], cy[l], cz[l]) = (c.x, c.y, c.z);
                    r[l] = if s.next() < 0.1 { f32::NEG_INFINITY } else { 0.866 * (0.5 + 0.5 * s.next()) };
                }
                x.cx.push(cx);
                x.cy.push(cy);
                x.cz.push(cz);
                x.r.push(r);
            }
            x
        })
        .collect()
}

fn octree_spheres(cr: &mut Criterion) {
    const TFAR: f32 = f32::INFINITY;
    let inp = ray_inputs(64, 8);
    let tests = 64 * inp.len() as u64;
    let mut hits = 0u32;
    for x in &inp {
        let r8 = RayX8::new(x.o, x.d);
        for k in 0..x.r.len() {
            hits += spheres_x8(&r8, 0.0, TFAR, &x.cx[k], &x.cy[k], &x.cz[k], &x.r[k]).0.count_ones();
        }
    }
    eprintln!("octree_spheres: {:.1}% of the ray–sphere tests pass", 100.0 * hits as f64 / tests as f64);
    let mut g = cr.benchmark_group("octree_spheres");
    g.throughput(Throughput::Elements(tests));
    g.bench_function("scalar", |b| {
        b.iter(|| {
            let mut acc = 0.0f32;
            for x in black_box(&inp) {
                let inv_dd = 1.0 / x.d.length_squared();
                for k in 0..x.r.len() {
                    for l in 0..8 {
                        let c = Vec3::new(x.cx[k][l], x.cy[k][l], x.cz[k][l]);
                        if let Some(t0) = sphere_1(x.o, x.d, inv_dd, c, x.r[k][l]).filter(|&t0| t0 <= TFAR) {
                            acc += t0;
                        }
                    }
                }
            }
            black_box(acc)
        })
    });
    g.bench_function("x8", |b| {
        b.iter(|| {
            let mut acc = 0.0f32;
            for x in black_box(&inp) {
                let r8 = RayX8::new(x.o, x.d);
                for k in 0..x.r.len() {
                    let (m, t) = spheres_x8(&r8, 0.0, TFAR, &x.cx[k], &x.cy[k], &x.cz[k], &x.r[k]);
                    acc += m as f32 + t[0];
                }
            }
            black_box(acc)
        })
    });
    g.finish();
}

// ---------------------------------------------------------------------------------------
// Σ(t) of a cone.

fn cone_sigma(cr: &mut Criterion) {
    const N: usize = 4096;
    let mut s = Sampler::new(24, 0, 0);
    let cone = rnd_cone(&mut s);
    let t: Vec<f32> = (0..N).map(|_| s.next() * 20.0).collect();
    let (mut a, mut b, mut c) = (vec![0.0f32; N], vec![0.0f32; N], vec![0.0f32; N]);
    let mut g = cr.benchmark_group("cone_sigma");
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("scalar", |bch| {
        bch.iter(|| {
            let (cone, t) = (black_box(&cone), black_box(&t));
            for i in 0..N {
                let m = cone.sigma(t[i]);
                (a[i], b[i], c[i]) = (m.a, m.b, m.c);
            }
            black_box((&mut a, &mut b, &mut c));
        })
    });
    g.bench_function("x8", |bch| {
        bch.iter(|| {
            let (cone, t) = (black_box(&cone), black_box(&t));
            for i in (0..N).step_by(8) {
                let (sa, sb, sc) = cone.sigma_x8(f32x8::from(&t[i..i + 8]));
                a[i..i + 8].copy_from_slice(&sa.to_array());
                b[i..i + 8].copy_from_slice(&sb.to_array());
                c[i..i + 8].copy_from_slice(&sc.to_array());
            }
            black_box((&mut a, &mut b, &mut c));
        })
    });
    g.finish();
}

/// 1 024 small triangles and slivers near the footprint's centre.
fn centre_triangles() -> Vec<[Vec2; 3]> {
    const N: usize = 1024;
    let mut s = Sampler::new(25, 0, 0);
    (0..N)
        .map(|i| {
            let c = Vec2::new(s.next() - 0.5, s.next() - 0.5) * 1.5;
            if i % 2 == 0 {
                std::array::from_fn(|_| c + Vec2::new(s.next() - 0.5, s.next() - 0.5) * 2.0)
            } else {
                let dir = Vec2::from_angle(s.next() * std::f32::consts::TAU);
                [c - dir * 1.5, c + dir * 1.5, c + dir * 1.2 + dir.perp() * (0.05 + 0.2 * s.next())]
            }
        })
        .collect()
}

/// Benchmarks `f` applied to each triangle in turn, results into `out`.
fn per_triangle<T>(
    g: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>,
    name: &str,
    tris: &[[Vec2; 3]],
    out: &mut [T],
    f: impl Fn([Vec2; 3]) -> T,
) {
    g.bench_function(name, |bch| {
        bch.iter(|| {
            for (o, q) in out.iter_mut().zip(black_box(tris)) {
                *o = f(*q);
            }
            black_box(&mut *out);
        })
    });
}

fn tri_mass(cr: &mut Criterion) {
    const N: usize = 1024;
    let tris = centre_triangles();
    let mut out = vec![0.0f32; N];
    let mut g = cr.benchmark_group("tri_mass");
    g.throughput(Throughput::Elements(N as u64));
    per_triangle(&mut g, "scalar", &tris, &mut out, gauss_tri_mass);
    per_triangle(&mut g, "x8", &tris, &mut out, gauss_tri_mass_x8);
    g.bench_function("x8_batch", |bch| {
        bch.iter(|| {
            for (o, q) in out.chunks_exact_mut(8).zip(black_box(&tris).chunks_exact(8)) {
                o.copy_from_slice(&gauss_tri_mass_8(q.try_into().expect("8 triangles")));
            }
            black_box(&mut out);
        })
    });
    g.finish();
}

fn tri_mask_bench(cr: &mut Criterion) {
    let tris = centre_triangles();
    let mut out = vec![0u64; tris.len()];
    let mut g = cr.benchmark_group("tri_mask");
    g.throughput(Throughput::Elements(tris.len() as u64));
    per_triangle(&mut g, "scalar", &tris, &mut out, tri_mask_1);
    per_triangle(&mut g, "x8", &tris, &mut out, tri_mask);
    g.finish();
}

/// 1 024 random instance slots (boxes near the cone, flat ones included, spheres around them)
/// in groups of 8, one random cone per group.
fn tlas_box(cr: &mut Criterion) {
    const N: usize = 1024;
    let mut s = Sampler::new(26, 0, 0);
    let mut tl = Tlas::default();
    let mut reach = Vec::new();
    for _ in 0..N / 8 {
        let cone = rnd_cone(&mut s);
        reach.push(BoxReach::cone(&cone, R_CUT, FLOOR));
        for _ in 0..8 {
            let c = cone.org + cone.dir * (s.next() * 12.0 - 2.0) + v3(&mut s) * 2.0;
            let h = Vec3::new(s.next(), s.next() * s.next(), s.next()) * 0.8;
            tl.cx.push(c.x);
            tl.cy.push(c.y);
            tl.cz.push(c.z);
            tl.r.push(h.length() * (1.0 + s.next()));
            for k in 0..3 {
                tl.lo[k].push(c[k] - h[k]);
                tl.hi[k].push(c[k] + h[k]);
            }
            tl.child.push(0);
        }
    }
    let mut g = cr.benchmark_group("tlas_box");
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("scalar", |bch| {
        bch.iter(|| {
            let mut hits = 0u32;
            for (i, rc) in black_box(&reach).iter().enumerate() {
                for l in 0..8 {
                    hits += tlas_box_test_1(rc, &tl, i * 8 + l).is_some() as u32;
                }
            }
            black_box(hits)
        })
    });
    g.bench_function("x8", |bch| {
        bch.iter(|| {
            let mut hits = 0u32;
            for (i, rc) in black_box(&reach).iter().enumerate() {
                hits += tlas_box_test_x8(rc, &tl, i * 8).0.count_ones();
            }
            black_box(hits)
        })
    });
    g.finish();
}

criterion_group!(benches, node_test, tri_bound, point_w, octree_spheres, cone_sigma, tri_mass, tri_mask_bench, tlas_box);
criterion_main!(benches);
