//! The pure-Rust back-end (`--accel bvh`): obvhs' compressed wide BVH8 (CWBVH, Ylitie et al.
//! 2017) over each unique mesh (BLAS) and over the leaf instances (TLAS). Node traversal is
//! obvhs' own `traverse!` with our node test ([`intersect_node`]); the triangle test is the watertight test of
//! [`super::tri`], so `verify` can compare it with Embree's robust mode.
//!
//! Layout: each BLAS keeps its triangles' vertices re-ordered into the BVH's primitive order
//! (`verts[3·i..3·i+3]`), so a leaf reads one contiguous run; `prim_ids` maps back to the
//! mesh's triangle index for shading.
//!
//! Node test: our own 8-child SIMD slab test over obvhs' quantised CWBVH nodes,
//! [`intersect_node`] (SSE2 on x86-64, `wide::f32x8` elsewhere). obvhs' own `intersect_ray` clamps the entry
//! distance at a fixed 1e-4 instead of the ray's `tmin`, which loses hits closer than 1e-4
//! ray units (found by `lodtrace verify`: origins within 1e-4 of a surface missed it).
//! Ours also widens every slab by its rounding error (`slab_tol`), so that no box a ray
//! passes through is culled (rays through a box's edge were, and escaped closed meshes).
//! The node-test ray is built by `ob_ray`, which scales the direction by a power of two
//! (obvhs' `safe_inverse` clamps components below f32::EPSILON in absolute terms, which broke
//! short direction vectors and instances under large scales).
//!
//! Packets: obvhs has no packet traversal; [`Accel::intersect8`] here is the default loop of
//! single rays over the CWBVH (the coherent-packet path is Embree's `rtcIntersect8`).

use super::accel::{Accel, Hit, InstFilter, Ray};
use super::tri::{intersect_watertight, RayShear};
use crate::core::stats::{Counter, Counters};
use crate::error::{Error, Result};
use crate::scene::Scene;
use glam::{Affine3A, UVec2, Vec3, Vec3A};
use obvhs::{aabb::Aabb, cwbvh::node::CwBvhNode, cwbvh::CwBvh, BvhBuildParams};
use rayon::prelude::*;
use std::time::Duration;
#[cfg(not(target_arch = "x86_64"))]
use wide::f32x8;

struct Blas {
    bvh: CwBvh,
    /// Triangle vertices in BVH primitive order.
    verts: Vec<Vec3>,
    /// Mesh triangle index of each BVH primitive.
    prim_ids: Vec<u32>,
}

struct TlasInst {
    inv: Affine3A,
    blas: u32,
}

pub struct BvhAccel {
    tlas: CwBvh,
    /// Leaf instances in TLAS primitive order; `inst_ids` maps back to the scene's order.
    insts: Vec<TlasInst>,
    inst_ids: Vec<u32>,
    blas: Vec<Blas>,
    /// Run the AVX2 build of the traversal (detected at run time; see [`BvhAccel::trace`]).
    avx2: bool,
}

/// Build quality for the BLAS and the TLAS: obvhs' `slow_build` preset (PLOC with the high
/// search distance, reinsertion of 20 % of the nodes, up to 3 triangles a leaf). Measured on
/// `complex` (640×480 Whitted, one run each, same binary): node tests 14.10 M with
/// `medium_build` → 12.73 M (−10 %), primary-ray kernel bench 2.44 → 2.66 M rays/s, at
/// 0.04 → 0.06 s of build. `very_slow_build` (full reinsertion) gave 12.91 M; obvhs'
/// `pre_split` of large triangles −6 % triangle tests but no fewer node tests and no time.
fn params() -> BvhBuildParams {
    BvhBuildParams::slow_build()
}

fn build_blas(mesh: &crate::scene::Mesh) -> Blas {
    let aabbs: Vec<Aabb> = (0..mesh.tri_count())
        .map(|t| {
            let [a, b, c] = mesh.tri_verts(t);
            let lo = a.min(b).min(c);
            let hi = a.max(b).max(c);
            Aabb::new(Vec3A::from(lo), Vec3A::from(hi))
        })
        .collect();
    let bvh = obvhs::cwbvh::builder::build_cwbvh(&aabbs, params(), &mut Duration::default());
    let mut verts = Vec::with_capacity(bvh.primitive_indices.len() * 3);
    for &p in &bvh.primitive_indices {
        verts.extend_from_slice(&mesh.tri_verts(p as usize));
    }
    let prim_ids = bvh.primitive_indices.clone();
    Blas { bvh, verts, prim_ids }
}

/// Ray against the 8 quantised child boxes of a CWBVH node; returns obvhs' hit mask (child
/// bits shifted to their traversal-order positions). Boxes are clipped to the ray's
/// [tmin, tmax].
///
/// x86-64 path: SSE2, two 4-wide halves. Each axis is one 16-byte load (obvhs stores
/// `child_min_a[8]` and `child_max_a[8]` back to back), widened u8 → u16 → i32 → f32 with
/// unpacks against zero — the per-byte scalar conversions were the cost of obvhs' own test.
/// Other targets use the portable `wide::f32x8` version, one lane per child.
#[inline(always)]
pub fn intersect_node(node: &CwBvhNode, ray: &obvhs::ray::Ray, oct_inv4: u32) -> u32 {
    let idir = node.compute_extent() * ray.inv_direction;
    let orig = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    let m = slab_mask(node, ray, idir, orig);
    hit_bits(node, m, oct_inv4)
}

/// As [`intersect_node`], 8 lanes at once with AVX2 (`vpmovzxbd` widening, 256-bit slab
/// test); same IEEE operations in the same order, so the same mask bit for bit.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub unsafe fn intersect_node_avx2(node: &CwBvhNode, ray: &obvhs::ray::Ray, oct_inv4: u32) -> u32 {
    use std::arch::x86_64::*;
    let idir = node.compute_extent() * ray.inv_direction;
    let orig = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    #[inline(always)]
    unsafe fn q(v: &[u8; 8], a: __m256, b: __m256) -> __m256 {
        let w = _mm256_cvtepu8_epi32(_mm_loadl_epi64(v.as_ptr() as *const __m128i));
        _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(w), a), b)
    }
    #[inline(always)]
    unsafe fn axis(lo: &[u8; 8], hi: &[u8; 8], neg: bool, a: f32, b: f32) -> (__m256, __m256) {
        let t = slab_tol(a, b);
        let (a, bn, bf) = (_mm256_set1_ps(a), _mm256_set1_ps(b - t), _mm256_set1_ps(b + t));
        let (near, far) = if neg { (hi, lo) } else { (lo, hi) };
        (q(near, a, bn), q(far, a, bf))
    }
    let (xn, xf) = axis(&node.child_min_x, &node.child_max_x, ray.direction.x < 0.0, idir.x, orig.x);
    let (yn, yf) = axis(&node.child_min_y, &node.child_max_y, ray.direction.y < 0.0, idir.y, orig.y);
    let (zn, zf) = axis(&node.child_min_z, &node.child_max_z, ray.direction.z < 0.0, idir.z, orig.z);
    let n = _mm256_max_ps(_mm256_max_ps(xn, yn), _mm256_max_ps(zn, _mm256_set1_ps(ray.tmin)));
    let f = _mm256_min_ps(_mm256_min_ps(xf, yf), _mm256_min_ps(zf, _mm256_set1_ps(ray.tmax)));
    let m = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(n, f)) as u32;
    hit_bits(node, m, oct_inv4)
}

/// The obvhs ray for the node tests, and the factor `k` that converts a ray distance `t` into
/// the node ray's (`t·k`). Two repairs of obvhs' `Ray::new`:
///
/// - −0.0 direction components are made +0.0. obvhs inverts a zero component to ±1/ε by its
///   sign bit (−0.0 → negative) but picks the ray octant, and the node tests their near and
///   far planes, by `d < 0` (−0.0 → positive): with −0.0 the two disagree, the slab comes out
///   inverted, and every box is missed (`lodtrace verify cube --rays 100000000` found a ray
///   along (0, −0, 1) through a face's interior that the BVH missed).
/// - The direction is scaled by a power of two `1/k` so that its largest component lies in
///   [1, 2) (the interval by `k`, both exact). obvhs' `safe_inverse` replaces every component
///   with |d| ≤ f32::EPSILON by ±1/EPSILON, an absolute threshold: a short direction vector
///   (the `Ray` contract allows any length) or an instance-space one under a large scale
///   (a unit mesh scaled by 1e9 gives |d| ~ 1e-9) got all its inverses clamped, the slabs
///   came out wrong, and hits far from any edge were missed (`spheres`' camera rays scaled by
///   1e-9: 3,938 of 15,360 rays changed). After the scaling the clamp only touches components
///   below 1.2e-7 of the largest one. The triangle test keeps the unscaled ray.
#[inline(always)]
fn ob_ray(o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> (obvhs::ray::Ray, f32) {
    // x + 0.0 is x except that −0.0 becomes +0.0 (IEEE 754, round to nearest).
    let d = Vec3A::from(d) + Vec3A::ZERO;
    // 2^−e for the largest component's exponent e, kept inside the normal range.
    let e = ((d.abs().max_element().to_bits() >> 23) as i32 - 127).clamp(-126, 126);
    let k = f32::from_bits(((127 - e) as u32) << 23);
    let ik = f32::from_bits(((127 + e) as u32) << 23);
    (obvhs::ray::Ray::new(Vec3A::from(o), d * k, tmin * ik, tmax * ik), ik)
}

/// How far the node test widens every slab (near planes lowered, far planes raised by this
/// much), so that it is conservative: a slab distance is computed as `q·a + b` with
/// `a = extent·inv_dir` (exact: the extent is a power of two), `b = (p − o)·inv_dir` and
/// `q ≤ 255`, and its rounding error, with that of `inv_dir` itself, stays below
/// 3u·255|a| + 4u|b| (u = 2⁻²⁴); this is 8u·(255|a| + |b|). Without it the rounding put a
/// box's far plane before its near one for rays through a box's edge, and the box was
/// culled: rays from inside `cube` aimed at its edges escaped the closed mesh (8,356 of
/// 200,000), where Embree lost none (review, base79; test
/// `no_ray_escapes_a_closed_mesh_through_its_edges`).
#[inline(always)]
fn slab_tol(a: f32, b: f32) -> f32 {
    4.0 * f32::EPSILON * (255.0 * a.abs() + b.abs())
}

#[inline(always)]
fn hit_bits(node: &CwBvhNode, mut m: u32, oct_inv4: u32) -> u32 {
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mut hit = 0u32;
    while m != 0 {
        let i = m.trailing_zeros() as u64 * 8;
        m &= m - 1;
        hit |= (((child_bits8 >> i) & 0xff) as u32) << (((bit_index8 >> i) & 0xff) as u32);
    }
    hit
}

#[cfg(target_arch = "x86_64")]
const _: () = {
    use std::mem::offset_of;
    assert!(offset_of!(CwBvhNode, child_max_x) == offset_of!(CwBvhNode, child_min_x) + 8);
    assert!(offset_of!(CwBvhNode, child_max_y) == offset_of!(CwBvhNode, child_min_y) + 8);
    assert!(offset_of!(CwBvhNode, child_max_z) == offset_of!(CwBvhNode, child_min_z) + 8);
};

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn slab_mask(node: &CwBvhNode, ray: &obvhs::ray::Ray, idir: Vec3A, orig: Vec3A) -> u32 {
    use std::arch::x86_64::*;
    /// (near[0..4], near[4..8], far[0..4], far[4..8]) distances of one axis.
    #[inline(always)]
    unsafe fn axis(minmax: *const [u8; 8], neg: bool, a: f32, b: f32) -> (__m128, __m128, __m128, __m128) {
        let z = _mm_setzero_si128();
        let v = _mm_loadu_si128(minmax as *const __m128i);
        let lo = _mm_unpacklo_epi8(v, z); // the 8 minima as u16
        let hi = _mm_unpackhi_epi8(v, z); // the 8 maxima
        let t = slab_tol(a, b);
        let (a, bn, bf) = (_mm_set1_ps(a), _mm_set1_ps(b - t), _mm_set1_ps(b + t));
        let f = |q: __m128i, b: __m128| _mm_add_ps(_mm_mul_ps(_mm_cvtepi32_ps(q), a), b);
        // Near planes with the lowered offset, far planes with the raised one.
        let (near, far) = if neg { (hi, lo) } else { (lo, hi) };
        (
            f(_mm_unpacklo_epi16(near, z), bn),
            f(_mm_unpackhi_epi16(near, z), bn),
            f(_mm_unpacklo_epi16(far, z), bf),
            f(_mm_unpackhi_epi16(far, z), bf),
        )
    }
    // SAFETY: SSE2 is part of x86-64; each load reads child_min_a and child_max_a, which are
    // contiguous (checked by the const assertions above) inside the node.
    unsafe {
        let (xn0, xn1, xf0, xf1) = axis(&node.child_min_x, ray.direction.x < 0.0, idir.x, orig.x);
        let (yn0, yn1, yf0, yf1) = axis(&node.child_min_y, ray.direction.y < 0.0, idir.y, orig.y);
        let (zn0, zn1, zf0, zf1) = axis(&node.child_min_z, ray.direction.z < 0.0, idir.z, orig.z);
        let (t0, t1) = (_mm_set1_ps(ray.tmin), _mm_set1_ps(ray.tmax));
        let n0 = _mm_max_ps(_mm_max_ps(xn0, yn0), _mm_max_ps(zn0, t0));
        let n1 = _mm_max_ps(_mm_max_ps(xn1, yn1), _mm_max_ps(zn1, t0));
        let f0 = _mm_min_ps(_mm_min_ps(xf0, yf0), _mm_min_ps(zf0, t1));
        let f1 = _mm_min_ps(_mm_min_ps(xf1, yf1), _mm_min_ps(zf1, t1));
        (_mm_movemask_ps(_mm_cmple_ps(n0, f0)) | (_mm_movemask_ps(_mm_cmple_ps(n1, f1)) << 4)) as u32
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn slab_mask(node: &CwBvhNode, ray: &obvhs::ray::Ray, idir: Vec3A, orig: Vec3A) -> u32 {
    #[inline(always)]
    fn q(v: &[u8; 8]) -> f32x8 {
        f32x8::from(v.map(|x| x as f32))
    }
    #[inline(always)]
    fn slab(lo: &[u8; 8], hi: &[u8; 8], neg: bool, idir: f32, orig: f32) -> (f32x8, f32x8) {
        let (near, far) = if neg { (hi, lo) } else { (lo, hi) };
        let t = slab_tol(idir, orig);
        let (a, bn, bf) = (f32x8::splat(idir), f32x8::splat(orig - t), f32x8::splat(orig + t));
        (q(near) * a + bn, q(far) * a + bf)
    }
    let (x0, x1) = slab(&node.child_min_x, &node.child_max_x, ray.direction.x < 0.0, idir.x, orig.x);
    let (y0, y1) = slab(&node.child_min_y, &node.child_max_y, ray.direction.y < 0.0, idir.y, orig.y);
    let (z0, z1) = slab(&node.child_min_z, &node.child_max_z, ray.direction.z < 0.0, idir.z, orig.z);
    let tmin = x0.max(y0).max(z0).max(f32x8::splat(ray.tmin));
    let tmax = x1.min(y1).min(z1).min(f32x8::splat(ray.tmax));
    tmin.simd_le(tmax).to_bitmask() as u32
}

fn avx2_available() -> bool {
    if std::env::var("LODTRACE_BVH_ISA").map(|v| v.eq_ignore_ascii_case("sse2")).unwrap_or(false) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("lzcnt")
            && std::arch::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

impl BvhAccel {
    pub fn build(scene: &Scene) -> Result<Self> {
        let leaves = scene.leaf_instances()?;
        if leaves.is_empty() {
            return Err(Error::Scene("nothing to build a BVH over".into()));
        }
        let blas: Vec<Blas> = scene.meshes.par_iter().map(build_blas).collect();
        let aabbs: Vec<Aabb> = leaves
            .iter()
            .map(|l| {
                let b = &blas[l.mesh as usize].bvh.total_aabb;
                let mut out = Aabb::empty();
                for i in 0..8 {
                    let c = Vec3A::new(
                        if i & 1 == 0 { b.min.x } else { b.max.x },
                        if i & 2 == 0 { b.min.y } else { b.max.y },
                        if i & 4 == 0 { b.min.z } else { b.max.z },
                    );
                    out.extend(l.xform.transform_point3a(c));
                }
                out
            })
            .collect();
        let tlas = obvhs::cwbvh::builder::build_cwbvh(&aabbs, params(), &mut Duration::default());
        let inst_ids = tlas.primitive_indices.clone();
        let insts = inst_ids.iter().map(|&i| TlasInst { inv: leaves[i as usize].inv, blas: leaves[i as usize].mesh }).collect();
        Ok(BvhAccel { tlas, insts, inst_ids, blas, avx2: avx2_available() })
    }

    /// Whether this structure traverses with the AVX2 code path.
    pub fn uses_avx2(&self) -> bool {
        self.avx2
    }

    /// Chooses the code path: `false` forces the baseline build; `true` takes AVX2 only where
    /// the CPU has it. For comparing the two (they must agree bit for bit).
    pub fn set_avx2(&mut self, on: bool) {
        self.avx2 = on && avx2_available();
    }

    /// Closest hit (`ANY = false`) or any hit (`ANY = true`). The same traversal is compiled
    /// twice — for the baseline x86-64 target and with AVX2/BMI enabled — and picked at run
    /// time, as Embree picks its kernels; `LODTRACE_BVH_ISA=sse2` forces the baseline. Both
    /// give bit-identical results (no FMA contraction: the arithmetic is the same IEEE ops).
    #[inline(always)]
    fn trace<const ANY: bool>(&self, ray: &Ray, f: InstFilter, c: &mut Counters) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the CPU reports AVX2, BMI1/2, LZCNT and POPCNT.
            return unsafe { self.trace_avx2::<ANY>(ray, f, c) };
        }
        self.trace_impl::<ANY, false>(ray, f, c)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn trace_avx2<const ANY: bool>(&self, ray: &Ray, f: InstFilter, c: &mut Counters) -> Option<Hit> {
        self.trace_impl::<ANY, true>(ray, f, c)
    }

    /// `filter` is tested once per visited instance, before its BLAS.
    #[inline(always)]
    fn trace_impl<const ANY: bool, const AVX: bool>(&self, ray: &Ray, filter: InstFilter, c: &mut Counters) -> Option<Hit> {
        #[inline(always)]
        fn node_test<const AVX: bool>(n: &CwBvhNode, r: &obvhs::ray::Ray, oct: u32) -> u32 {
            #[cfg(target_arch = "x86_64")]
            if AVX {
                // SAFETY: AVX = true only inside `trace_avx2`, reached only with AVX2 present.
                return unsafe { intersect_node_avx2(n, r, oct) };
            }
            intersect_node(n, r, oct)
        }
        if !ray.is_valid() {
            return None;
        }
        let mut tfar = ray.tfar;
        let mut best: Option<Hit> = None;
        let tnear = ray.tnear.max(0.0).min(tfar);
        let (world, tl_k) = ob_ray(ray.org, ray.dir, tnear, tfar);
        let mut tl_ray = world;
        let mut state = self.tlas.new_traversal(world.direction);
        let mut node;
        let (mut n_nodes, mut n_inst, mut n_tris) = (0u64, 0u64, 0u64);
        'tlas: {
            obvhs::traverse!(
                self.tlas,
                node,
                state,
                {
                    n_nodes += 1;
                    node_test::<AVX>(node, &tl_ray, state.oct_inv4)
                },
                {
                    let ti = state.primitive_id as usize;
                    if !filter.admits(self.inst_ids[ti]) {
                        continue;
                    }
                    n_inst += 1;
                    let inst = &self.insts[ti];
                    let blas = &self.blas[inst.blas as usize];
                    let lo = inst.inv.transform_point3(ray.org);
                    let ld = inst.inv.transform_vector3(ray.dir);
                    let (mut bl_ray, bl_k) = ob_ray(lo, ld, tnear, tfar);
                    let shear = RayShear::new(lo, ld);
                    let mut bstate = blas.bvh.new_traversal(bl_ray.direction);
                    let mut bnode;
                    'blas: {
                        obvhs::traverse!(
                            blas.bvh,
                            bnode,
                            bstate,
                            {
                                n_nodes += 1;
                                node_test::<AVX>(bnode, &bl_ray, bstate.oct_inv4)
                            },
                            {
                                n_tris += 1;
                                let p = bstate.primitive_id as usize;
                                let v = &blas.verts[3 * p..3 * p + 3];
                                if let Some((t, u, vv)) = intersect_watertight(&shear, v[0], v[1], v[2], tnear, tfar) {
                                    tfar = t;
                                    bl_ray.tmax = t * bl_k;
                                    best = Some(Hit { t, u, v: vv, prim: blas.prim_ids[p], inst: self.inst_ids[ti] });
                                    if ANY {
                                        break 'blas;
                                    }
                                }
                            }
                        );
                    }
                    if ANY && best.is_some() {
                        break 'tlas;
                    }
                    tl_ray.tmax = tfar * tl_k;
                }
            );
        }
        c.add(Counter::node_tests, n_nodes);
        c.add(Counter::instance_tests, n_inst);
        c.add(Counter::triangle_tests, n_tris);
        best
    }
}

impl Accel for BvhAccel {
    fn name(&self) -> &'static str {
        "bvh"
    }
    fn intersect1(&self, ray: &Ray, c: &mut Counters) -> Option<Hit> {
        self.trace::<false>(ray, InstFilter::All, c)
    }
    fn occluded1(&self, ray: &Ray, c: &mut Counters) -> bool {
        self.trace::<true>(ray, InstFilter::All, c).is_some()
    }
    fn intersect1_filtered(&self, ray: &Ray, filter: InstFilter, c: &mut Counters) -> Option<Hit> {
        self.trace::<false>(ray, filter, c)
    }
    fn memory_bytes(&self) -> usize {
        let node = std::mem::size_of::<obvhs::cwbvh::node::CwBvhNode>();
        let tl = self.tlas.nodes.len() * node + self.insts.len() * (std::mem::size_of::<TlasInst>() + 8);
        let bl: usize = self.blas.iter().map(|b| b.bvh.nodes.len() * node + b.verts.len() * 12 + b.prim_ids.len() * 8).sum();
        tl + bl
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler;

    /// The 8-wide node test against obvhs' scalar reference (`intersect_ray_basic`, which
    /// clamps entry at 1e-4): a superset of its masks (ours widens the slabs by their
    /// rounding error), and strictly more when tmin is 0 (ours keeps boxes starting closer
    /// than 1e-4).
    #[test]
    fn node_test_matches_scalar_reference() {
        let mesh = crate::scene::builtin::icosphere(3, 0);
        let blas = build_blas(&mesh);
        let mut differ_at_zero = 0;
        for k in 0..500u32 {
            let mut s = Sampler::new(5, k, 0);
            let o = Vec3A::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 3.0;
            let mut d = Vec3A::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5);
            if k % 10 == 0 {
                // Long direction vectors: boxes end within t < 1e-4, where obvhs' clamp bites.
                d *= 1e5;
            }
            let oct = blas.bvh.new_traversal(d).oct_inv4;
            for tmin in [1e-4f32, 0.0] {
                let r = obvhs::ray::Ray::new(o, d, tmin, 1e30);
                for n in &blas.bvh.nodes {
                    let ours = intersect_node(n, &r, oct);
                    #[cfg(target_arch = "x86_64")]
                    if std::arch::is_x86_feature_detected!("avx2") {
                        // SAFETY: checked just above.
                        assert_eq!(unsafe { intersect_node_avx2(n, &r, oct) }, ours, "AVX2 and SSE2 node tests differ");
                    }
                    let reference = n.intersect_ray_basic(&r, oct);
                    // Ours widens the slabs by their rounding error (`slab_tol`): a superset.
                    assert_eq!(ours & reference, reference, "lost a box at tmin {tmin}: ray {o:?} {d:?}");
                    if tmin == 0.0 {
                        differ_at_zero += (ours != reference) as u32;
                    }
                }
            }
        }
        // The long-direction rays make the difference show up.
        assert!(differ_at_zero > 0);
    }
}
