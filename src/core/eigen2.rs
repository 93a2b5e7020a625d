//! Symmetric 2×2 eigen-decomposition of ray-cone footprints: Wand & Straßer 2003, §4.1 eq. 3,
//! needed by every intersection test (§5.2) and for the anisotropy limit and the minimum
//! footprint diameter of the traversal (§5.1).
//!
//! **Convention.** A footprint is stored as the symmetric covariance Σ = fp·fpᵀ = [a b; b c] in
//! the ray's (u, v) coordinates, so fp⁻² of eq. 2 is Σ⁻¹. The eigenvalues λ₁ ≥ λ₂ of Σ are the
//! squared semi-axes of the footprint ellipse; we return the semi-axes s₁ = √λ₁ ≥ s₂ = √λ₂
//! and the major axis e₁ = (cos, sin) (minor axis e₂ = (−sin, cos)), so
//! Σ⁻¹ = Uᵀ diag(1/s₁², 1/s₂²) U with U = [e₁ e₂]ᵀ: the paper's λᵢ of eq. 3 are our 1/sᵢ.
//! The Gaussian exponent of eq. 2 is [`Eigen2::q`].
//!
//! **Algorithm.** m = (a+c)/2, h = (a−c)/2, d = √(h² + b²), λ₁ = m + d, λ₂ = max(m − d, 0)
//! (rounding can make m − d slightly negative; an indefinite Σ with a + c ≥ 0 also gets
//! λ₂ = 0). The eigenvector of λ₁ is the longer of (λ₁ − c, b) = (d + h, b) and
//! (b, λ₁ − a) = (b, d − h): the first if h ≥ 0, else the second; its long component is formed
//! as d + |h| (no cancellation) and its squared norm 2d(d + |h|) ≥ 2d², so it is well
//! conditioned. It is normalised, unless its length is ≤ 10⁻⁶·λ₁ (isotropic to rounding:
//! d ≲ 5–7·10⁻⁷ λ₁), in which case the axis is (1, 0). To stay finite over the whole f32 range,
//! Σ is first scaled by 2⁻⁸⁰ when its largest entry exceeds 2⁶⁰ (by 2⁸⁰ when it is below
//! 2⁻⁴⁰) and the semi-axes are scaled back by 2⁴⁰ (2⁻⁴⁰): powers of two, so no extra rounding
//! unless a much smaller entry underflows. (Unscaled, h² + b² overflows for entries ≳ 1.3·10¹⁹;
//! and h² + b² must stay normal for h, b down to 2⁻²⁴ of the largest entry: until the f64
//! reference test, Σ was scaled up only below 2⁻⁶⁰, and between 2⁻⁶⁰ and ≈ 2⁻⁵⁰ the squares of
//! a small anisotropy underflowed: up to 3.6·10⁻⁵·λ₁ eigenvalue error, ≈ 300 ε, and a round
//! footprint with axis (1, 0) for anisotropies below ≈ 10⁻⁴. Without effect on renders:
//! their floor, 10⁻⁷, is above such semi-axes, ≤ 3·10⁻⁸.)
//!
//! **Clamp and floor (§5.1).** The paper bounds the minimum eigenvalue to a fraction
//! (1/4–1/16) of the maximum. We apply the fraction `clamp` ∈ (0, 1] to the *semi-axes*
//! (s₂ ≥ clamp·s₁, i.e. to the λᵢ of eq. 3, which are 1/sᵢ); pass `clamp²` to bound the
//! ratio of Σ's eigenvalues instead. Then both axes are raised to at least `floor` > 0, so
//! zero and rank-1 footprints stay invertible.
//!
//! **Degenerate input.** Any non-finite entry or a negative trace (a + c < 0) gives the floor
//! circle: cos = 1, sin = 0, s₁ = s₂ = `floor`; the zero matrix gives the same. No input gives
//! NaN or ∞ out; s₁ ≥ s₂ ≥ `floor` and s₂ ≥ clamp·s₁ always (for clamp ≤ 1).
//!
//! **Kernels.** [`eigen_1`] is the scalar reference. [`eigen_x4`] / [`eigen_x8`] run the same
//! IEEE operations in the same order lane-wise on `wide` vectors with masks and selects (no
//! per-lane fallback), so they reproduce [`eigen_1`] bit for bit. Without `-C target-cpu`,
//! `wide::f32x8` is two SSE halves; [`eigen_x8_avx2`] is the same kernel on 256-bit AVX
//! registers for callers that are themselves compiled with AVX2 (also bit-identical: the
//! compiler never contracts to FMA), and [`eigen_soa`] decomposes a struct-of-arrays batch,
//! choosing AVX2 once at run time (scalar with the `scalar` feature).
//!
//! **Measured** (`CARGO_TARGET_DIR=/work/target-eigen cargo bench --bench eigen`: 4096 random
//! Σ = F Fᵀ stored SoA, clamp 1/8, outputs written to four Vecs; 2-vCPU AMD EPYC (Zen 3) VM,
//! no target-cpu flags), million footprints/s and the ratio to the scalar reference. Other
//! jobs kept the load average at ≈ 4 on the 2 vCPUs throughout, so criterion's wall-clock
//! figures are depressed and noisy; the second column is a stand-alone copy of these kernels
//! timed as the best of 30 batches of 200 runs, which filters out part of that interference.
//!
//! | kernel                          | criterion (median) | stand-alone, best of 30 |
//! |---------------------------------|--------------------|-------------------------|
//! | `eigen_1` (scalar)              |  34.7              |  43.5                   |
//! | `eigen_x4` (SSE2)               | 159   (4.6×)       | 265   (6.1×)            |
//! | `eigen_x8` (2 × SSE2)           | 216   (6.2×)       | 330   (7.6×)            |
//! | `eigen_soa` → `eigen_x8_avx2`   | 338   (9.7×)       | 570   (13×)             |
//!
//! The packets beat their lane count. Most likely the scalar loop is latency-bound (this VM
//! has no hardware counters to confirm it): each element is a dependent chain
//! sqrt → add → mul → add → sqrt → div → mul of ~50 cycles, close to what one element costs
//! (23 ns ≈ 56 cycles at the nominal 2.45 GHz), and the out-of-order window overlaps little of
//! the next element; a packet pays that latency once per 4 or 8 lanes. It is not the
//! data-dependent h ≥ 0 branch: a branch-free (bit-mask) scalar select measured the same.
//!
//! Tried (stand-alone timings per 4096 footprints):
//! - choosing the eigenvector by comparing the squared norms (λ₁ − c)² + b² ≥ b² + (λ₁ − a)²
//!   and a mask of |x| ≤ f32::MAX tests, as first written: `eigen_x8` 16.0 µs; the sign of h
//!   and the x − x finiteness mask: 12.3 µs (kept);
//! - the `wide` f32x8 code inlined into an AVX2 function (VEX-encoded, still 2 × 128 bit):
//!   12.0 µs, no gain, hence the 256-bit intrinsics version (7.2 µs);
//! - `_mm256_rsqrt_ps` + one Newton–Raphson step instead of sqrt and div in the AVX2 version:
//!   8.0–9.2 µs against 7.1–8.5 µs, no gain and no longer bit-identical (rejected);
//! - `eigen_soa` copying each chunk with a run-time length: 12 µs (memcpy calls); fixed-size
//!   chunks and one zero-padded tail packet: 7.8 µs (kept).

use wide::{f32x4, f32x8};

#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Sym2 {
    pub a: f32,
    pub b: f32,
    pub c: f32,
}

impl Sym2 {
    /// Entry-wise sum.
    #[allow(clippy::should_implement_trait)]
    #[inline]
    pub fn add(self, o: Sym2) -> Sym2 {
        Sym2 { a: self.a + o.a, b: self.b + o.b, c: self.c + o.c }
    }
    #[inline]
    pub fn scale(self, k: f32) -> Sym2 {
        Sym2 { a: self.a * k, b: self.b * k, c: self.c * k }
    }
    #[inline]
    pub fn is_finite(self) -> bool {
        self.a.is_finite() && self.b.is_finite() && self.c.is_finite()
    }
}

/// Major axis e1 = (cos, sin), minor axis e2 = (−sin, cos); s1 ≥ s2 > 0 are the semi-axes
/// (square roots of the eigenvalues of Σ, after the clamp and the floor).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Eigen2 {
    pub cos: f32,
    pub sin: f32,
    pub s1: f32,
    pub s2: f32,
}

impl Eigen2 {
    /// Quadratic form q = (e1·p)²/s1² + (e2·p)²/s2² of a point p = (x, y): the exponent of the
    /// Gaussian weight exp(−q) (eq. 2).
    #[inline]
    pub fn q(&self, x: f32, y: f32) -> f32 {
        let p1 = self.cos * x + self.sin * y;
        let p2 = self.cos * y - self.sin * x;
        p1 * p1 / (self.s1 * self.s1) + p2 * p2 / (self.s2 * self.s2)
    }
    /// Σ back from the (clamped) decomposition: s1² e1e1ᵀ + s2² e2e2ᵀ.
    #[inline]
    pub fn to_sym(&self) -> Sym2 {
        let (l1, l2) = (self.s1 * self.s1, self.s2 * self.s2);
        let (c, s) = (self.cos, self.sin);
        Sym2 { a: l1 * c * c + l2 * s * s, b: (l1 - l2) * c * s, c: l1 * s * s + l2 * c * c }
    }
}

/// Eight decompositions, lane by lane (see [`Eigen2`]).
#[derive(Clone, Copy, Debug)]
pub struct Eigen2x8 {
    pub cos: f32x8,
    pub sin: f32x8,
    pub s1: f32x8,
    pub s2: f32x8,
}

/// Four decompositions, lane by lane (see [`Eigen2`]).
#[derive(Clone, Copy, Debug)]
pub struct Eigen2x4 {
    pub cos: f32x4,
    pub sin: f32x4,
    pub s1: f32x4,
    pub s2: f32x4,
}

/// Range scaling: entries above `BIG` are scaled by `DOWN` (semi-axes back by `DOWN_S⁻¹`),
/// below `TINY` by `UP`. After scaling the largest entry t ∈ [2⁻⁶⁹, 2⁶⁰] (at least 2⁻⁴⁰ for
/// entries from 2⁻¹²⁰ on), so every square below (≤ 10 t²) is finite, and the squares of
/// entries down to 2⁻²³·t are normal.
const BIG: f32 = (1u64 << 60) as f32;
const TINY: f32 = 1.0 / (1u64 << 40) as f32;
const DOWN: f32 = 1.0 / (1u128 << 80) as f32;
const UP: f32 = (1u128 << 80) as f32;
/// √DOWN⁻¹ and √UP⁻¹: multiply the semi-axes of the scaled Σ by these.
const DOWN_S: f32 = (1u64 << 40) as f32;
const UP_S: f32 = 1.0 / (1u64 << 40) as f32;
/// The eigenvector is replaced by (1, 0) when its squared norm is ≤ ISO·λ₁² (isotropic).
const ISO: f32 = 1.0e-12;

/// Scalar reference. `clamp` in (0,1]: anisotropy limit (§5.1: the minor axis is raised to at
/// least clamp·major, typical 1/4..1/16); `floor` > 0: both axes are at least `floor`.
#[inline]
pub fn eigen_1(m: Sym2, clamp: f32, floor: f32) -> Eigen2 {
    let Sym2 { a, b, c } = m;
    if !(a.is_finite() && b.is_finite() && c.is_finite() && a + c >= 0.0) {
        return Eigen2 { cos: 1.0, sin: 0.0, s1: floor, s2: floor };
    }
    let t = a.abs().max(b.abs()).max(c.abs());
    let (k, ks) = if t > BIG {
        (DOWN, DOWN_S)
    } else if t < TINY {
        (UP, UP_S)
    } else {
        (1.0, 1.0)
    };
    let (a, b, c) = (a * k, b * k, c * k);
    let mean = 0.5 * (a + c);
    let h = 0.5 * (a - c);
    let d = (h * h + b * b).sqrt();
    let l1 = mean + d;
    let l2 = (mean - d).max(0.0);
    // Eigenvector of l1: (l1 − c, b) = (d + h, b) if a ≥ c, else (b, l1 − a) = (b, d − h): the
    // longer of the two, with its long component d + |h| formed without cancellation.
    let p = d + h.abs();
    let (vx, vy) = if h >= 0.0 { (p, b) } else { (b, p) };
    let nn = p * p + b * b;
    let (cos, sin) = if nn > (ISO * (l1 * l1)).max(f32::MIN_POSITIVE) {
        let inv = 1.0 / nn.sqrt();
        (vx * inv, vy * inv)
    } else {
        (1.0, 0.0)
    };
    let s1 = l1.max(0.0).sqrt() * ks;
    let s2 = (l2.sqrt() * ks).max(clamp * s1);
    Eigen2 { cos, sin, s1: s1.max(floor), s2: s2.max(floor) }
}

macro_rules! eigen_wide {
    ($name:ident, $v:ident, $out:ident, $doc:literal) => {
        #[doc = $doc]
        #[inline]
        pub fn $name(a: $v, b: $v, c: $v, clamp: f32, floor: f32) -> $out {
            let zero = $v::splat(0.0);
            let one = $v::splat(1.0);
            // Finite entries and a non-negative trace: x − x is +0 for finite x and NaN for ±∞
            // and NaN, and NaN compares false. Other lanes become the zero matrix, which yields
            // the floor circle below, as in `eigen_1`.
            let ok = ((a + c) + ((a - a) + (b - b) + (c - c))).simd_ge(zero);
            let (a, b, c) = (a & ok, b & ok, c & ok);
            let t = a.abs().fast_max(b.abs()).fast_max(c.abs());
            let big = t.simd_gt($v::splat(BIG));
            let tiny = t.simd_lt($v::splat(TINY));
            let (a, b, c, ks) = if (big | tiny).any() {
                let k = big.select($v::splat(DOWN), tiny.select($v::splat(UP), one));
                (a * k, b * k, c * k, big.select($v::splat(DOWN_S), tiny.select($v::splat(UP_S), one)))
            } else {
                (a, b, c, one)
            };
            let half = $v::splat(0.5);
            let mean = half * (a + c);
            let h = half * (a - c);
            let d = (h * h + b * b).sqrt();
            let l1 = mean + d;
            let l2 = (mean - d).fast_max(zero);
            let p = d + h.abs();
            let hpos = h.simd_ge(zero);
            let vx = hpos.select(p, b);
            let vy = hpos.select(b, p);
            let nn = p * p + b * b;
            let aniso = nn.simd_gt(($v::splat(ISO) * (l1 * l1)).fast_max($v::splat(f32::MIN_POSITIVE)));
            let inv = one / aniso.select(nn, one).sqrt();
            let cos = aniso.select(vx * inv, one);
            let sin = (vy * inv) & aniso;
            let s1 = l1.fast_max(zero).sqrt() * ks;
            let s2 = (l2.sqrt() * ks).fast_max($v::splat(clamp) * s1);
            let fl = $v::splat(floor);
            $out { cos, sin, s1: s1.fast_max(fl), s2: s2.fast_max(fl) }
        }
    };
}

eigen_wide!(eigen_x8, f32x8, Eigen2x8, "[`eigen_1`] on 8 lanes (masks and selects; same operations, same results bit for bit).");
eigen_wide!(eigen_x4, f32x4, Eigen2x4, "[`eigen_1`] on 4 lanes (masks and selects; same operations, same results bit for bit).");

/// [`eigen_x8`] on 256-bit AVX registers, for callers compiled with AVX2 (a `#[target_feature]`
/// function, where this inlines). Same operations in the same order as [`eigen_1`], so the same
/// bits.
///
/// # Safety
/// The CPU must support AVX2 and FMA (`is_x86_feature_detected!`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub unsafe fn eigen_x8_avx2(a: f32x8, b: f32x8, c: f32x8, clamp: f32, floor: f32) -> Eigen2x8 {
    use std::arch::x86_64::*;
    let (a, b, c): (__m256, __m256, __m256) = (a.into(), b.into(), c.into());
    let set = |x: f32| _mm256_set1_ps(x);
    let sel = |m: __m256, t: __m256, f: __m256| _mm256_blendv_ps(f, t, m);
    let (zero, one) = (_mm256_setzero_ps(), set(1.0));
    let abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX));
    let abs = |x: __m256| _mm256_and_ps(x, abs_mask);
    let zz = _mm256_add_ps(_mm256_add_ps(_mm256_sub_ps(a, a), _mm256_sub_ps(b, b)), _mm256_sub_ps(c, c));
    let ok = _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_add_ps(_mm256_add_ps(a, c), zz), zero);
    let (mut a, mut b, mut c) = (_mm256_and_ps(a, ok), _mm256_and_ps(b, ok), _mm256_and_ps(c, ok));
    let t = _mm256_max_ps(_mm256_max_ps(abs(a), abs(b)), abs(c));
    let big = _mm256_cmp_ps::<_CMP_GT_OQ>(t, set(BIG));
    let tiny = _mm256_cmp_ps::<_CMP_LT_OQ>(t, set(TINY));
    let mut ks = one;
    if _mm256_movemask_ps(_mm256_or_ps(big, tiny)) != 0 {
        let k = sel(big, set(DOWN), sel(tiny, set(UP), one));
        (a, b, c) = (_mm256_mul_ps(a, k), _mm256_mul_ps(b, k), _mm256_mul_ps(c, k));
        ks = sel(big, set(DOWN_S), sel(tiny, set(UP_S), one));
    }
    let half = set(0.5);
    let mean = _mm256_mul_ps(half, _mm256_add_ps(a, c));
    let h = _mm256_mul_ps(half, _mm256_sub_ps(a, c));
    let bb = _mm256_mul_ps(b, b);
    let d = _mm256_sqrt_ps(_mm256_add_ps(_mm256_mul_ps(h, h), bb));
    let l1 = _mm256_add_ps(mean, d);
    let l2 = _mm256_max_ps(_mm256_sub_ps(mean, d), zero);
    let p = _mm256_add_ps(d, abs(h));
    let hpos = _mm256_cmp_ps::<_CMP_GE_OQ>(h, zero);
    let vx = sel(hpos, p, b);
    let vy = sel(hpos, b, p);
    let nn = _mm256_add_ps(_mm256_mul_ps(p, p), bb);
    let tol = _mm256_max_ps(_mm256_mul_ps(set(ISO), _mm256_mul_ps(l1, l1)), set(f32::MIN_POSITIVE));
    let aniso = _mm256_cmp_ps::<_CMP_GT_OQ>(nn, tol);
    let inv = _mm256_div_ps(one, _mm256_sqrt_ps(sel(aniso, nn, one)));
    let cos = sel(aniso, _mm256_mul_ps(vx, inv), one);
    let sin = _mm256_and_ps(_mm256_mul_ps(vy, inv), aniso);
    let s1 = _mm256_mul_ps(_mm256_sqrt_ps(_mm256_max_ps(l1, zero)), ks);
    let s2 = _mm256_max_ps(_mm256_mul_ps(_mm256_sqrt_ps(l2), ks), _mm256_mul_ps(set(clamp), s1));
    let fl = set(floor);
    Eigen2x8 { cos: cos.into(), sin: sin.into(), s1: _mm256_max_ps(s1, fl).into(), s2: _mm256_max_ps(s2, fl).into() }
}

/// Whether [`eigen_x8_avx2`] may be called on this CPU.
#[inline]
pub fn avx2_fma_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Output slices of [`eigen_soa`], one entry per input footprint.
pub struct Eigen2Out<'a> {
    pub cos: &'a mut [f32],
    pub sin: &'a mut [f32],
    pub s1: &'a mut [f32],
    pub s2: &'a mut [f32],
}

/// Decomposes the footprints (`a[i]`, `b[i]`, `c[i]`) stored as struct-of-arrays into `out`: 8 at a
/// time with [`eigen_x8_avx2`] when the CPU has AVX2 and FMA (checked once per call), else
/// [`eigen_x8`]; the tail is zero-padded into one more packet. With the `scalar` feature,
/// [`eigen_1`] per element. All paths give the same bits.
///
/// # Panics
/// If the slices differ in length.
pub fn eigen_soa(a: &[f32], b: &[f32], c: &[f32], clamp: f32, floor: f32, out: Eigen2Out) {
    let n = a.len();
    assert!(b.len() == n && c.len() == n, "eigen_soa: input lengths differ");
    assert!(out.cos.len() == n && out.sin.len() == n && out.s1.len() == n && out.s2.len() == n, "eigen_soa: output lengths differ");
    if cfg!(feature = "scalar") {
        for i in 0..n {
            let e = eigen_1(Sym2 { a: a[i], b: b[i], c: c[i] }, clamp, floor);
            (out.cos[i], out.sin[i], out.s1[i], out.s2[i]) = (e.cos, e.sin, e.s1, e.s2);
        }
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if avx2_fma_available() {
        // SAFETY: AVX2 and FMA were just detected.
        unsafe { soa_avx2(a, b, c, clamp, floor, out) };
        return;
    }
    soa_with(a, b, c, clamp, floor, out, eigen_x8);
}

#[inline(always)]
fn soa_with(
    a: &[f32],
    b: &[f32],
    c: &[f32],
    clamp: f32,
    floor: f32,
    out: Eigen2Out,
    f: impl Fn(f32x8, f32x8, f32x8, f32, f32) -> Eigen2x8,
) {
    let n = a.len();
    let mut store = |i: usize, m: usize, e: Eigen2x8| {
        out.cos[i..i + m].copy_from_slice(&e.cos.to_array()[..m]);
        out.sin[i..i + m].copy_from_slice(&e.sin.to_array()[..m]);
        out.s1[i..i + m].copy_from_slice(&e.s1.to_array()[..m]);
        out.s2[i..i + m].copy_from_slice(&e.s2.to_array()[..m]);
    };
    let full = n - n % 8;
    for i in (0..full).step_by(8) {
        let v = |s: &[f32]| f32x8::from(<[f32; 8]>::try_from(&s[i..i + 8]).unwrap());
        store(i, 8, f(v(a), v(b), v(c), clamp, floor));
    }
    if full < n {
        let v = |s: &[f32]| {
            let mut t = [0.0f32; 8];
            t[..n - full].copy_from_slice(&s[full..]);
            f32x8::from(t)
        };
        store(full, n - full, f(v(a), v(b), v(c), clamp, floor));
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn soa_avx2(a: &[f32], b: &[f32], c: &[f32], clamp: f32, floor: f32, out: Eigen2Out) {
    // SAFETY: the caller checked AVX2 and FMA.
    soa_with(a, b, c, clamp, floor, out, |a, b, c, cl, fl| unsafe { eigen_x8_avx2(a, b, c, cl, fl) });
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Σ = F Fᵀ with F = [f0 f1; f2 f3].
    fn from_f(f: [f32; 4]) -> Sym2 {
        Sym2 { a: f[0] * f[0] + f[1] * f[1], b: f[0] * f[2] + f[1] * f[3], c: f[2] * f[2] + f[3] * f[3] }
    }

    fn frob(m: Sym2) -> f32 {
        let (a, b, c) = (m.a as f64, m.b as f64, m.c as f64);
        (a * a + 2.0 * b * b + c * c).sqrt() as f32
    }

    fn degenerate() -> Vec<Sym2> {
        vec![
            Sym2 { a: 0.0, b: 0.0, c: 0.0 },
            Sym2 { a: -0.0, b: -0.0, c: 0.0 },
            from_f([1.0, 2.0, 2.0, 4.0]),   // rank 1: colinear columns
            from_f([3.0, -1.5, -6.0, 3.0]), // rank 1, negative b
            from_f([1.0, 2.0, 1.0, 2.0 + 1e-6]),
            from_f([1e-3, 1e3, 1e-3, 1e3]),
            Sym2 { a: 3.0, b: 0.0, c: 3.0 }, // isotropic
            Sym2 { a: 3.0, b: 1e-7, c: 3.0 + 1e-7 },
            Sym2 { a: 1.0, b: 1.0 + 1e-7, c: 1.0 }, // negative λ₂ by rounding
            Sym2 { a: 1e-8, b: 1.0, c: 1e-8 },
            Sym2 { a: 2.0, b: 0.0, c: -1.0 },  // indefinite, positive trace
            Sym2 { a: 1.0, b: 0.0, c: -1.0 },  // zero trace
            Sym2 { a: -1.0, b: 0.0, c: -1.0 }, // negative trace
            Sym2 { a: f32::NAN, b: 0.0, c: 1.0 },
            Sym2 { a: 1.0, b: f32::NAN, c: 1.0 },
            Sym2 { a: 1.0, b: 0.0, c: f32::NEG_INFINITY },
            Sym2 { a: f32::INFINITY, b: 0.0, c: 1.0 },
            Sym2 { a: 1.0, b: f32::INFINITY, c: 1.0 },
            Sym2 { a: 1e18, b: 1e18, c: 1e18 },
            Sym2 { a: 1e18, b: -1e18, c: 1e18 },
            Sym2 { a: f32::MAX, b: f32::MAX, c: f32::MAX },
            Sym2 { a: f32::MAX, b: 0.0, c: -f32::MAX },
            Sym2 { a: 3e38, b: -1e38, c: 1.0 },
            Sym2 { a: 1e-30, b: 0.0, c: 0.0 },
            Sym2 { a: 1e-30, b: 1e-30, c: 1e-30 },
            Sym2 { a: 1e-45, b: 1e-45, c: 0.0 },
        ]
    }

    fn check_valid(m: Sym2, e: Eigen2, clamp: f32, floor: f32) {
        assert!(e.cos.is_finite() && e.sin.is_finite() && e.s1.is_finite() && e.s2.is_finite(), "{m:?} -> {e:?}");
        assert!((e.cos * e.cos + e.sin * e.sin - 1.0).abs() < 1e-5, "{m:?} -> {e:?}");
        assert!(e.s1 >= e.s2 && e.s2 >= floor, "{m:?} -> {e:?}");
        assert!(e.s2 >= clamp * e.s1, "{m:?} -> {e:?}");
    }

    fn any_sym() -> impl Strategy<Value = Sym2> {
        let random = (prop::array::uniform4(-10.0f32..10.0), prop::sample::select(vec![1e-6f32, 1e-3, 1.0, 1e3, 1e6]))
            .prop_map(|(f, s)| from_f(f.map(|x| x * s)));
        prop_oneof![3 => random, 1 => prop::sample::select(degenerate())]
    }

    proptest! {
        /// (1) Σ = F Fᵀ is reproduced, e1 is a unit eigenvector of λ1 = s1².
        #[test]
        fn reconstructs(f in prop::array::uniform4(-10.0f32..10.0), scale in prop::sample::select(vec![1e-6f32, 1.0, 1e6])) {
            let m = from_f(f.map(|x| x * scale));
            let norm = frob(m);
            prop_assume!(norm > 0.0);
            let e = eigen_1(m, 1e-9, 1e-30);
            let r = e.to_sym();
            for (x, y) in [(r.a, m.a), (r.b, m.b), (r.c, m.c)] {
                prop_assert!((x - y).abs() <= 1e-4 * norm, "{:?} -> {:?} -> {:?}", m, e, r);
            }
            prop_assert!((e.cos * e.cos + e.sin * e.sin - 1.0).abs() < 1e-5);
            let l1 = e.s1 * e.s1;
            let (rx, ry) = (m.a * e.cos + m.b * e.sin - l1 * e.cos, m.b * e.cos + m.c * e.sin - l1 * e.sin);
            prop_assert!((rx * rx + ry * ry).sqrt() <= 1e-4 * norm, "{:?} -> {:?}: residual ({}, {})", m, e, rx, ry);
            prop_assert!(e.s1 >= e.s2);
        }

        /// (2) Arbitrary bit patterns (NaN, ±∞, subnormals, huge) never give NaN or ∞.
        #[test]
        fn any_input_is_finite(a in any::<f32>(), b in any::<f32>(), c in any::<f32>(), clamp in 1e-9f32..=1.0, floor in 1e-30f32..1.0) {
            let m = Sym2 { a, b, c };
            check_valid(m, eigen_1(m, clamp, floor), clamp, floor);
        }

        /// (3) The anisotropy clamp: s2 ≥ clamp·s1, and the major axis is untouched by it.
        #[test]
        fn clamp_holds(m in any_sym(), clamp in prop::sample::select(vec![1.0f32, 0.5, 0.25, 0.125, 1.0 / 16.0, 1e-3])) {
            let e = eigen_1(m, clamp, 1e-30);
            check_valid(m, e, clamp, 1e-30);
            let free = eigen_1(m, 1e-9, 1e-30);
            prop_assert_eq!(e.s1, free.s1);
            prop_assert_eq!((e.cos, e.sin), (free.cos, free.sin));
        }

        /// (4) x4, x8 (and AVX2) agree with the scalar reference lane by lane, random and
        /// degenerate inputs mixed.
        #[test]
        fn packets_agree_with_scalar(ms in prop::array::uniform8(any_sym()), clamp in prop::sample::select(vec![1e-9f32, 0.25, 1.0 / 16.0]), floor in prop::sample::select(vec![1e-30f32, 1e-6, 1e-2])) {
            let (a, b, c) = (ms.map(|m| m.a), ms.map(|m| m.b), ms.map(|m| m.c));
            let e8 = eigen_x8(f32x8::from(a), f32x8::from(b), f32x8::from(c), clamp, floor);
            let lanes8 = unpack(e8.cos.to_array(), e8.sin.to_array(), e8.s1.to_array(), e8.s2.to_array());
            let mut lanes4 = Vec::new();
            for h in 0..2 {
                let q = |v: [f32; 8]| f32x4::from([v[4 * h], v[4 * h + 1], v[4 * h + 2], v[4 * h + 3]]);
                let e4 = eigen_x4(q(a), q(b), q(c), clamp, floor);
                lanes4.extend(unpack(e4.cos.to_array(), e4.sin.to_array(), e4.s1.to_array(), e4.s2.to_array()));
            }
            for l in 0..8 {
                let e = eigen_1(ms[l], clamp, floor);
                agree(ms[l], e, lanes8[l]);
                agree(ms[l], e, lanes4[l]);
                // Same operations in the same order: the same bits.
                prop_assert_eq!(bits(e), bits(lanes8[l]));
                prop_assert_eq!(bits(e), bits(lanes4[l]));
            }
            #[cfg(target_arch = "x86_64")]
            if avx2_fma_available() {
                let ea = unsafe { eigen_x8_avx2(f32x8::from(a), f32x8::from(b), f32x8::from(c), clamp, floor) };
                let la = unpack(ea.cos.to_array(), ea.sin.to_array(), ea.s1.to_array(), ea.s2.to_array());
                for l in 0..8 {
                    prop_assert_eq!(bits(la[l]), bits(lanes8[l]));
                }
            }
        }
    }

    fn unpack<const N: usize>(co: [f32; N], si: [f32; N], s1: [f32; N], s2: [f32; N]) -> Vec<Eigen2> {
        (0..N).map(|l| Eigen2 { cos: co[l], sin: si[l], s1: s1[l], s2: s2[l] }).collect()
    }

    fn bits(e: Eigen2) -> [u32; 4] {
        [e.cos.to_bits(), e.sin.to_bits(), e.s1.to_bits(), e.s2.to_bits()]
    }

    /// The brief's tolerance: s1, s2 relative 1e-5; the axis up to sign unless isotropic.
    fn agree(m: Sym2, e: Eigen2, x: Eigen2) {
        assert!((x.s1 - e.s1).abs() <= 1e-5 * e.s1, "{m:?}: s1 {x:?} vs {e:?}");
        assert!((x.s2 - e.s2).abs() <= 1e-5 * e.s2, "{m:?}: s2 {x:?} vs {e:?}");
        let (mean, h) = (0.5 * (m.a as f64 + m.c as f64), 0.5 * (m.a as f64 - m.c as f64));
        let iso = !m.is_finite() || (h * h + m.b as f64 * m.b as f64).sqrt() <= 1e-5 * mean.abs();
        if !iso {
            assert!((x.cos * e.cos + x.sin * e.sin).abs() > 1.0 - 1e-4, "{m:?}: axis {x:?} vs {e:?}");
        }
    }

    /// Independent reference: nalgebra's `SymmetricEigen` in f64 on the same (f32) entries.
    /// Returns λ₁ ≥ λ₂ and the unit eigenvector of λ₁.
    fn reference(m: Sym2) -> (f64, f64, [f64; 2]) {
        let (a, b, c) = (m.a as f64, m.b as f64, m.c as f64);
        let e = nalgebra::Matrix2::new(a, b, b, c).symmetric_eigen();
        let (i, j) = if e.eigenvalues[0] >= e.eigenvalues[1] { (0, 1) } else { (1, 0) };
        let v = e.eigenvectors.column(i);
        (e.eigenvalues[i], e.eigenvalues[j], [v[0], v[1]])
    }

    /// Footprints of the hard kinds, entries from 10⁻³⁰ to 10³⁰ (both range scalings):
    /// exactly rank 1 (colinear footprint columns: Σ = s·(cos², cos·sin, sin²)), near-singular
    /// (λ₂/λ₁ from 10⁻¹ to 10⁻¹⁴), nearly isotropic ((λ₁ − λ₂)/λ₁ from 10⁻¹ to 10⁻⁹), and
    /// axis-aligned and exactly isotropic ones; Σ is formed in f64 and rounded to f32 (the
    /// reference decomposes the rounded entries).
    fn hard_footprints() -> Vec<Sym2> {
        let mut r = crate::core::rng::Sampler::new(17, 0, 0);
        let mut out = vec![];
        let sym = |l1: f64, l2: f64, phi: f64| {
            let (co, si) = (phi.cos(), phi.sin());
            Sym2 { a: (l1 * co * co + l2 * si * si) as f32, b: ((l1 - l2) * co * si) as f32, c: (l1 * si * si + l2 * co * co) as f32 }
        };
        for i in 0..6000 {
            let scale = 10f64.powf(r.next() as f64 * 60.0 - 30.0);
            let phi = r.next() as f64 * std::f64::consts::TAU;
            let rel = match i % 3 {
                0 => 0.0,
                1 => 10f64.powf(-1.0 - 13.0 * r.next() as f64),
                _ => 1.0 - 10f64.powf(-1.0 - 8.0 * r.next() as f64),
            };
            out.push(sym(scale, scale * rel, phi));
        }
        for phi in [0.0, std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_4, std::f64::consts::PI] {
            for (l1, l2) in [(1.0, 0.0), (4.0, 1.0), (1.0, 1.0), (1e20, 1e-20), (1e-20, 0.0)] {
                out.push(sym(l1, l2, phi));
            }
        }
        // Small footprints, 10⁻⁵ anisotropic, in the range (2⁻⁶⁰ to 2⁻⁴⁰) that was not scaled
        // until this test: (a − c)² and b² underflowed, and the decomposition came out round.
        for e in [-59, -55, -50, -45, -41] {
            let l = 2f64.powi(e);
            out.push(sym(l, l * (1.0 - 1e-5), 0.3));
            out.push(sym(l, l * (1.0 - 1e-3), 1.1));
        }
        out
    }

    /// `kernel`'s decomposition `e` of `m` against the reference; `worst`: the largest relative
    /// errors seen (eigenvalues, axis angle).
    fn against_reference(kernel: &str, m: Sym2, e: Eigen2, worst: &mut (f64, f64)) {
        // Tolerances (f32 ε = 1.2·10⁻⁷), relative to the largest eigenvalue λ₁: both λᵢ within
        // 4ε·λ₁ (mean, h, d, λ = mean ± d, √λ and the reference's s² each round once, by at
        // most ε/2 of λ₁: measured 1.8ε); the major axis (up to sign) within 4ε rad (measured
        // 0.7ε), wherever λ₁ − λ₂ > 2·10⁻⁶·λ₁: the axis is formed from (d + |h|, b) without
        // cancellation (h = (a − c)/2 is exact for close a, c), so it is accurate in absolute
        // terms however small the gap; at gaps ≤ 1.42·10⁻⁶·λ₁ (the vector's squared norm
        // ≤ 10⁻¹²·λ₁²) the decomposition treats Σ as isotropic (axis (1, 0), module docs).
        const TOL: f64 = 4.0 * f32::EPSILON as f64;
        let (l1, l2, v) = reference(m);
        let (s1, s2) = (e.s1 as f64, e.s2 as f64);
        let (d1, d2) = ((s1 * s1 - l1).abs() / l1, (s2 * s2 - l2.max(0.0)).abs() / l1);
        assert!(d1 <= TOL && d2 <= TOL, "{kernel} {m:?}: s² = ({}, {}) vs λ = ({l1}, {l2}) (relative {d1:e}, {d2:e})", s1 * s1, s2 * s2);
        worst.0 = worst.0.max(d1).max(d2);
        if l1 - l2 > 2e-6 * l1 {
            let sin = (e.cos as f64 * v[1] - e.sin as f64 * v[0]).abs();
            assert!(
                sin <= TOL,
                "{kernel} {m:?}: axis ({}, {}) vs ({}, {}): {sin:e} rad, gap {:e}",
                e.cos,
                e.sin,
                v[0],
                v[1],
                (l1 - l2) / l1
            );
            worst.1 = worst.1.max(sin);
        }
    }

    /// The scalar decomposition and the 4- and 8-wide packets (and the AVX2 kernel where the
    /// CPU has it) against an independent f64 reference on rank-1, near-singular and nearly
    /// isotropic footprints (the "eigen-decomposition against a reference").
    #[test]
    fn matches_f64_reference_on_hard_footprints() {
        let ms = hard_footprints();
        let (clamp, floor) = (1e-9f32, 1e-37f32);
        let mut worst = [(0.0, 0.0); 4];
        for chunk in ms.chunks(8) {
            let mut m8 = [Sym2::default(); 8];
            m8[..chunk.len()].copy_from_slice(chunk);
            let (a, b, c) = (m8.map(|m| m.a), m8.map(|m| m.b), m8.map(|m| m.c));
            let e8 = eigen_x8(f32x8::from(a), f32x8::from(b), f32x8::from(c), clamp, floor);
            let x8 = unpack(e8.cos.to_array(), e8.sin.to_array(), e8.s1.to_array(), e8.s2.to_array());
            let mut x4 = vec![];
            for h in 0..2 {
                let q = |v: [f32; 8]| f32x4::from([v[4 * h], v[4 * h + 1], v[4 * h + 2], v[4 * h + 3]]);
                let e4 = eigen_x4(q(a), q(b), q(c), clamp, floor);
                x4.extend(unpack(e4.cos.to_array(), e4.sin.to_array(), e4.s1.to_array(), e4.s2.to_array()));
            }
            #[cfg(target_arch = "x86_64")]
            let avx = avx2_fma_available().then(|| {
                // SAFETY: AVX2 and FMA were just detected.
                let e = unsafe { eigen_x8_avx2(f32x8::from(a), f32x8::from(b), f32x8::from(c), clamp, floor) };
                unpack(e.cos.to_array(), e.sin.to_array(), e.s1.to_array(), e.s2.to_array())
            });
            #[cfg(not(target_arch = "x86_64"))]
            let avx: Option<Vec<Eigen2>> = None;
            for (l, &m) in chunk.iter().enumerate() {
                against_reference("eigen_1", m, eigen_1(m, clamp, floor), &mut worst[0]);
                against_reference("eigen_x4", m, x4[l], &mut worst[1]);
                against_reference("eigen_x8", m, x8[l], &mut worst[2]);
                if let Some(x) = &avx {
                    against_reference("eigen_x8_avx2", m, x[l], &mut worst[3]);
                }
            }
        }
        eprintln!("worst relative errors (eigenvalues, axis) scalar/x4/x8/avx2: {worst:?}");
    }

    #[test]
    fn degenerate_inputs() {
        for &(clamp, floor) in &[(1e-9f32, 1e-30f32), (0.125, 1e-6), (1.0, 0.5)] {
            for m in degenerate() {
                let e = eigen_1(m, clamp, floor);
                check_valid(m, e, clamp, floor);
                if !m.is_finite() || m.a + m.c < 0.0 || m == Sym2::default() {
                    assert_eq!(e, Eigen2 { cos: 1.0, sin: 0.0, s1: floor, s2: floor }, "{m:?}");
                }
            }
        }
        // Rank 1: the minor axis is the floor (or the clamp), the major axis is the column.
        let e = eigen_1(from_f([1.0, 2.0, 2.0, 4.0]), 1e-9, 1e-6);
        assert!((e.s1 - 5.0).abs() < 1e-5 && e.s2 == 1e-6, "{e:?}");
        assert!((e.cos - 1.0 / 5f32.sqrt()).abs() < 1e-6 && (e.sin - 2.0 / 5f32.sqrt()).abs() < 1e-6, "{e:?}");
        // Isotropic: axis (1, 0).
        let e = eigen_1(Sym2 { a: 4.0, b: 0.0, c: 4.0 }, 1e-9, 1e-6);
        assert_eq!(e, Eigen2 { cos: 1.0, sin: 0.0, s1: 2.0, s2: 2.0 });
        // Huge but finite: scaled, exact for a power-of-two diagonal.
        let e = eigen_1(Sym2 { a: 2f32.powi(120), b: 0.0, c: 2f32.powi(100) }, 1e-9, 1e-6);
        assert_eq!((e.s1, e.s2, e.cos, e.sin), (2f32.powi(60), 2f32.powi(50), 1.0, 0.0));
        let e = eigen_1(Sym2 { a: 2f32.powi(-100), b: 0.0, c: 2f32.powi(-120) }, 1e-9, 1e-40);
        assert_eq!((e.s1, e.s2, e.cos, e.sin), (2f32.powi(-50), 2f32.powi(-60), 1.0, 0.0));
    }

    /// (5) A point on the major axis at distance s1 (and on the minor one at s2) has q = 1.
    #[test]
    fn q_on_axes_is_one() {
        for f in [[3.0, 0.5, -1.0, 2.0], [0.1, -4.0, 0.3, 1.0], [2.0, 0.0, 0.0, 1.0]] {
            let e = eigen_1(from_f(f), 1e-9, 1e-30);
            assert!((e.q(e.cos * e.s1, e.sin * e.s1) - 1.0).abs() < 1e-5, "{e:?}");
            assert!((e.q(-e.sin * e.s2, e.cos * e.s2) - 1.0).abs() < 1e-5, "{e:?}");
            assert!(e.q(0.0, 0.0) == 0.0);
        }
    }

    #[test]
    fn soa_batch_matches_scalar() {
        let mut r = crate::core::rng::Sampler::new(7, 0, 0);
        let mut ms = degenerate();
        for _ in 0..61 {
            let s = 10f32.powf(r.next() * 12.0 - 6.0);
            ms.push(from_f([r.next() - 0.5, r.next() - 0.5, r.next() - 0.5, r.next() - 0.5].map(|x| x * s)));
        }
        let n = ms.len();
        assert!(!n.is_multiple_of(8));
        let (a, b, c): (Vec<f32>, Vec<f32>, Vec<f32>) =
            (ms.iter().map(|m| m.a).collect(), ms.iter().map(|m| m.b).collect(), ms.iter().map(|m| m.c).collect());
        let (mut co, mut si, mut s1, mut s2) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        eigen_soa(&a, &b, &c, 0.25, 1e-6, Eigen2Out { cos: &mut co, sin: &mut si, s1: &mut s1, s2: &mut s2 });
        for i in 0..n {
            assert_eq!(bits(eigen_1(ms[i], 0.25, 1e-6)), bits(Eigen2 { cos: co[i], sin: si[i], s1: s1[i], s2: s2[i] }), "{:?}", ms[i]);
        }
    }

    #[test]
    fn sym2_helpers() {
        let (p, q) = (Sym2 { a: 1.0, b: 2.0, c: 3.0 }, Sym2 { a: 0.5, b: -1.0, c: 1.0 });
        assert_eq!(p.add(q), Sym2 { a: 1.5, b: 1.0, c: 4.0 });
        assert_eq!(p.scale(2.0), Sym2 { a: 2.0, b: 4.0, c: 6.0 });
        assert!(p.is_finite() && !Sym2 { a: f32::NAN, ..p }.is_finite() && !Sym2 { c: f32::INFINITY, ..p }.is_finite());
    }
}
