//! Coverage masks for the A-buffer's fragments (*deviation* from Wand & Straßer §4.4,
//! `--coverage-masks`; the remedy of Carpenter's original A-buffer, 1984).
//!
//! The paper composites a ray's fragments front to back by their alpha alone, which is
//! right when the pieces in successive fragments sit at independent places in the footprint.
//! Foliage breaks that: leaves growing from one stem cover the *same* part of the footprint
//! (their coverage is correlated), so alpha compositing counts the overlap twice and a plant
//! comes out 1.2–1.5× too opaque at a distance (BENCHMARKS.md, the README record, stops 19–20).
//!
//! A mask has one bit per *sub-ray* of the cone: 64 fixed offsets in whitened footprint
//! coordinates (the Gaussian's own units, weight e^{−|m|²}), spread with the truncated
//! Gaussian's density (equal mass per bit, within the 2 % cut-off) on a golden-angle spiral.
//! A triangle sets the bits of the sub-rays that pass through it: its vertices, mapped to the
//! footprint coordinates at its depth, and a point-in-triangle test per offset (eight at a
//! time in [`tri_mask`], [`tri_mask_1`] the scalar reference). Since the whitening scales with
//! the footprint, an offset names the same sub-ray at every depth. Triangles smaller than a
//! bit carry no mask (0) and composite as in the paper.
//!
//! Points carry no mask either. Tried (stop 21): each point as a disc of its projected area
//! (its weight over the Gaussian there). A point set is a sampling, not a tiling, so the
//! union of its discs falls short of their summed area (1 − e^{−A} for random places), and
//! far foliage turned transparent: `complex` mean FLIP 0.0865 → 0.0964 (`tri=mass`,
//! 320×240), with 60 % more time.
//!
//! The masks only *correct* the paper's weights and compositing; the weights still give the
//! coverage. Within a fragment, the share of a piece's sub-rays that earlier pieces already
//! cover is not counted as coverage ([`super::abuffer::Frag::hidden`]; leaves of one plant
//! mostly meet in one fragment). Across fragments ([`super::abuffer::Over`]), the share a
//! fragment gets of what is left in front of it is scaled by how much of its mask is still
//! uncovered, relative to the uncovered share of all bits: a surface behind that covers the
//! whole footprint fills exactly what is left (no seams or halos from the 64-sample
//! discretisation), a leaf behind the same spot of a leaf in front gets nothing. Early ray
//! termination ([`super::abuffer::ABuffer::opaque`]) sees the corrected fragment alphas but
//! composites them as the paper does.

use super::cone::Cone;
use super::trace::MASS_IN_CUT;
use glam::{Vec2, Vec3};
use std::sync::OnceLock;
use wide::f32x8;

/// Sub-rays per mask.
pub const BITS: usize = 64;

struct Offsets {
    x: [f32x8; BITS / 8],
    y: [f32x8; BITS / 8],
    xs: [f32; BITS],
    ys: [f32; BITS],
}

fn offsets() -> &'static Offsets {
    static O: OnceLock<Offsets> = OnceLock::new();
    O.get_or_init(|| {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        let mut xs = [0.0; BITS];
        let mut ys = [0.0; BITS];
        for k in 0..BITS {
            // Equal Gaussian mass per bit: the radial CDF of e^{-r²} is 1 − e^{-r²}, truncated
            // at the cut-off (mass MASS_IN_CUT).
            let u = MASS_IN_CUT * (k as f32 + 0.5) / BITS as f32;
            let r = (-(1.0 - u).ln()).sqrt();
            let a = golden * k as f32;
            xs[k] = r * a.cos();
            ys[k] = r * a.sin();
        }
        let chunk = |s: &[f32; BITS], c: usize| f32x8::from(<[f32; 8]>::try_from(&s[8 * c..8 * c + 8]).unwrap());
        Offsets { x: std::array::from_fn(|c| chunk(&xs, c)), y: std::array::from_fn(|c| chunk(&ys, c)), xs, ys }
    })
}

/// The sub-ray offsets (whitened footprint units), for tests and plots.
pub fn offset(k: usize) -> Vec2 {
    let o = offsets();
    Vec2::new(o.xs[k], o.ys[k])
}

/// The map from the cone's (x, y) at depth t to whitened footprint coordinates: L⁻¹ with
/// Σ(t) = L Lᵀ (Cholesky), so that the weight is e^{−|m|²}; the minor factor is kept ≥
/// `clamp` times the major and both ≥ `floor`, as the footprint itself (§4.2).
#[derive(Clone, Copy, Debug)]
pub struct Whitening {
    i11: f32,
    l21: f32,
    i22: f32,
}

impl Whitening {
    pub fn new(lc: &Cone, t: f32, clamp: f32, floor: f32) -> Self {
        let s = lc.sigma(t.max(lc.tmin).max(0.0));
        let l11 = s.a.max(0.0).sqrt().max(floor);
        let l21 = s.b / l11;
        let l22 = (s.c - l21 * l21).max(0.0).sqrt().max(clamp * l11).max(floor);
        Whitening { i11: 1.0 / l11, l21, i22: 1.0 / l22 }
    }
    #[inline]
    pub fn apply(&self, x: f32, y: f32) -> Vec2 {
        let m1 = x * self.i11;
        Vec2::new(m1, (y - self.l21 * m1) * self.i22)
    }
}

/// World (or object) points in whitened footprint coordinates of `lc` at depth `t`
/// ([`Whitening`]).
pub fn whiten<const N: usize>(lc: &Cone, p: [Vec3; N], t: f32, clamp: f32, floor: f32) -> [Vec2; N] {
    let wh = Whitening::new(lc, t, clamp, floor);
    p.map(|p| {
        let d = p - lc.org;
        wh.apply(d.dot(lc.u), d.dot(lc.v))
    })
}

/// Scalar reference: bit k is set when sub-ray k passes through the 2-D triangle `q`
/// (whitened footprint coordinates; either orientation). Degenerate or non-finite
/// triangles set none.
pub fn tri_mask_1(q: [Vec2; 3]) -> u64 {
    let Some(Edges { e, sum }) = edge_functions(q) else {
        return 0;
    };
    let mut m = 0u64;
    for k in 0..BITS {
        let s = offset(k);
        let d0 = e[0].0.mul_add(s.x, e[0].1.mul_add(s.y, e[0].2));
        if d0 >= 0.0 && {
            let d1 = e[1].0.mul_add(s.x, e[1].1.mul_add(s.y, e[1].2));
            d1 >= 0.0 && d0 + d1 <= sum
        } {
            m |= 1 << k;
        }
    }
    m
}

/// Two of a triangle's edge functions a·x + b·y + c, oriented so that the inside is ≥ 0,
/// and the constant sum of all three. Both kernels evaluate an edge function as
/// `a.mul_add(x, b.mul_add(y, c))` and test the third edge as `d0 + d1 ≤ sum` (the three
/// add up to twice the triangle's area anywhere), in the same operations, so the masks are
/// bit-identical. Stop 83: fused multiply-adds and the sum took the x8 kernel from 3.1× to
/// 4.3× its scalar reference (BENCHMARKS.md).
struct Edges {
    e: [(f32, f32, f32); 2],
    sum: f32,
}

/// [`Edges`]; None for a degenerate or non-finite triangle.
#[inline]
fn edge_functions(q: [Vec2; 3]) -> Option<Edges> {
    let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
    // Finite and non-zero (a finite area also means finite corners).
    if !(area.is_finite() && area != 0.0) {
        return None;
    }
    let sg = area.signum();
    let e = std::array::from_fn(|i| {
        let (p, e) = (q[i], q[i + 1] - q[i]);
        // perp_dot(e, s − p) = e.x (s.y − p.y) − e.y (s.x − p.x)
        (-sg * e.y, sg * e.x, sg * (e.y * p.x - e.x * p.y))
    });
    Some(Edges { e, sum: area.abs() })
}

/// [`tri_mask_1`], eight sub-rays per `f32x8` step (bit-identical: the same operations in
/// the same order).
pub fn tri_mask(q: [Vec2; 3]) -> u64 {
    // Outside the offsets' disc: nothing to test.
    let lo = q[0].min(q[1]).min(q[2]);
    let hi = q[0].max(q[1]).max(q[2]);
    const R: f32 = 2.0;
    if lo.x > R || lo.y > R || hi.x < -R || hi.y < -R {
        return 0;
    }
    let Some(Edges { e, sum }) = edge_functions(q) else {
        return 0;
    };
    let o = offsets();
    let z = f32x8::splat(0.0);
    let sum = f32x8::splat(sum);
    let [(a0, b0, c0), (a1, b1, c1)] = e.map(|(a, b, c)| (f32x8::splat(a), f32x8::splat(b), f32x8::splat(c)));
    let mut m = 0u64;
    for k in 0..BITS / 8 {
        let (sx, sy) = (o.x[k], o.y[k]);
        let d0 = a0.mul_add(sx, b0.mul_add(sy, c0));
        let d1 = a1.mul_add(sx, b1.mul_add(sy, c1));
        let inside = d0.simd_ge(z) & d1.simd_ge(z) & (d0 + d1).simd_le(sum);
        m |= (inside.to_bitmask() as u64 & 0xff) << (8 * k);
    }
    m
}

/// Share of all sub-rays a mask holds.
#[inline]
pub fn share(m: u64) -> f32 {
    m.count_ones() as f32 * (1.0 / BITS as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rng(seed: &mut u64) -> f32 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }

    #[test]
    fn offsets_have_the_gaussian_mass_per_bit() {
        // Radii increase with k; the share of offsets within radius r is the truncated
        // Gaussian's mass there.
        for k in 1..BITS {
            assert!(offset(k).length() > offset(k - 1).length());
        }
        for r in [0.5f32, 1.0, 1.5] {
            let inside = (0..BITS).filter(|&k| offset(k).length() < r).count() as f32 / BITS as f32;
            let mass = (1.0 - (-r * r).exp()) / MASS_IN_CUT;
            assert!((inside - mass).abs() <= 1.0 / BITS as f32, "r {r}: {inside} vs {mass}");
        }
        assert!(offset(BITS - 1).length() < super::super::trace::POINT_CUT);
        // Balanced: the mean offset is near the centre.
        let mean = (0..BITS).map(offset).sum::<Vec2>() / BITS as f32;
        assert!(mean.length() < 0.1, "{mean}");
    }

    #[test]
    fn packet_mask_equals_scalar_on_random_and_degenerate_triangles() {
        let mut seed = 7u64;
        let mut bits = 0;
        for i in 0..20_000 {
            let s = [0.3f32, 1.5, 4.0][i % 3];
            let q: [Vec2; 3] = std::array::from_fn(|_| Vec2::new(rng(&mut seed), rng(&mut seed)) * s);
            let m = tri_mask(q);
            assert_eq!(m, tri_mask_1(q), "{q:?}");
            bits += m.count_ones();
        }
        assert!(bits > 100_000, "the random triangles cover something: {bits}");
        let p = Vec2::new(0.2, 0.3);
        for q in
            [[p, p, p], [Vec2::ZERO, Vec2::X, Vec2::X * 2.0], [Vec2::NAN, Vec2::X, Vec2::Y], [Vec2::splat(f32::INFINITY), Vec2::X, Vec2::Y]]
        {
            assert_eq!(tri_mask(q), 0);
            assert_eq!(tri_mask_1(q), 0);
        }
    }

    #[test]
    fn a_covering_triangle_sets_every_bit_and_halves_set_complements() {
        let big = [Vec2::new(-10.0, -10.0), Vec2::new(30.0, -10.0), Vec2::new(-10.0, 30.0)];
        assert_eq!(tri_mask(big), u64::MAX);
        // The two halves of a square split along a diagonal through the centre: disjoint
        // masks (up to an offset on the diagonal itself), together every bit.
        let (a, b, c, d) = (Vec2::new(-5.0, -5.0), Vec2::new(5.0, -5.0), Vec2::new(5.0, 5.0), Vec2::new(-5.0, 5.0));
        let (m1, m2) = (tri_mask([a, b, c]), tri_mask([a, c, d]));
        assert_eq!(m1 | m2, u64::MAX);
        assert!((m1 & m2).count_ones() <= 1);
        assert!((share(m1) - 0.5).abs() < 0.1, "{}", share(m1));
    }
}
