//! Quantisation of the point samples (Wand & Straßer §3.2, last paragraph: "all point
//! properties are quantized to small integer values (8 bit for material properties and
//! position, 16 bit for differential properties)").
//!
//! - Position: the representative sits at the mean of its voxel's samples (a deviation from
//!   the paper's voxel centre, see [`super::build`]), stored as an 8-bit code per axis over
//!   the node's grid with its margin: 256 codes over the 2k voxels of a row, m = 128/k codes
//!   per voxel side ([`super::build::codes_per_voxel`]). [`encode_pos`] takes the sub-cell
//!   of the voxel that holds the mean, [`decode_pos`] returns that sub-cell's centre, so the
//!   decoded position is within half a code step (h/2m) of the mean per axis; a mean outside
//!   its voxel (samples clamped into a border cell) is held to the voxel's nearest sub-cell.
//! - Material properties: 8 bit each, linear over a per-hierarchy range `[lo, hi]`
//!   ([`Range8`]); colour channels use a square-root curve so dark colours keep precision.
//! - Differential properties: the normal as a 2×16-bit octahedral code ([`oct_encode`]),
//!   the normal derivatives ∇n as four IEEE half floats (16 bit each), in units of the
//!   hierarchy's root side ([`encode_grad`]), so that the code's range does not depend on the
//!   model's units.
//!
//! Every encoder has a round-trip test: the decoded value is within one quantisation step.

use glam::{Vec2, Vec3};
use half::f16;

/// 8-bit position code (per axis) of a point at `p` in voxel `cell` of the grid with lower
/// corner `grid_lo`, voxel side `h` and `m` codes per voxel side (the module notes): the
/// sub-cell of the voxel that holds `p`, clamped to the voxel (NaN to its first sub-cell).
/// The grid has at most 256/m voxels per axis (2k for `m` = 128/k), so the code fits 8 bits.
#[inline]
pub fn encode_pos(p: Vec3, grid_lo: Vec3, cell: [u32; 3], h: f32, m: u32) -> [u8; 3] {
    let cell_lo = grid_lo + Vec3::new(cell[0] as f32, cell[1] as f32, cell[2] as f32) * h;
    let sub = (((p - cell_lo) / h) * m as f32).floor().clamp(Vec3::ZERO, Vec3::splat((m - 1) as f32));
    [(cell[0] * m + sub.x as u32) as u8, (cell[1] * m + sub.y as u32) as u8, (cell[2] * m + sub.z as u32) as u8]
}
/// The position of code `q` ([`encode_pos`]): the centre of its sub-cell, `grid_lo + (q + ½)·step`
/// with `step` = h/m.
#[inline]
pub fn decode_pos(q: [u8; 3], grid_lo: Vec3, step: f32) -> Vec3 {
    grid_lo + (Vec3::new(q[0] as f32, q[1] as f32, q[2] as f32) + 0.5) * step
}

/// 8-bit code over `[lo, hi]`: linear, or with `log` linear in ln v (for a positive range
/// spanning decades, [`Range8::for_exponent`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Range8 {
    pub lo: f32,
    pub hi: f32,
    pub log: bool,
}

impl Range8 {
    pub fn new(lo: f32, hi: f32) -> Self {
        Range8 { lo, hi: if hi > lo { hi } else { lo }, log: false }
    }
    /// A Phong exponent's range: logarithmic when it is positive and spans more than a factor
    /// 16, so small exponents keep their steps (linear over 1–1000, 2 decoded as 1; review
    /// finding, stop 77); [`Range8::new`] otherwise.
    pub fn for_exponent(lo: f32, hi: f32) -> Self {
        let r = Self::new(lo, hi);
        Range8 { log: lo > 0.0 && r.hi > 16.0 * lo && r.hi.is_finite(), ..r }
    }
    /// One quantisation step of a linear range (a `log` range's steps are relative:
    /// (hi/lo)^(1/255) each).
    pub fn step(&self) -> f32 {
        (self.hi - self.lo) / 255.0
    }
    #[inline]
    pub fn encode(&self, v: f32) -> u8 {
        if self.hi <= self.lo || !v.is_finite() {
            return 0;
        }
        let x = if self.log {
            (v.max(self.lo).ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        };
        (x.clamp(0.0, 1.0) * 255.0).round() as u8
    }
    #[inline]
    pub fn decode(&self, q: u8) -> f32 {
        let x = q as f32 / 255.0;
        if self.log {
            (self.lo.ln() + (self.hi.ln() - self.lo.ln()) * x).exp().clamp(self.lo, self.hi)
        } else {
            self.lo + (self.hi - self.lo) * x
        }
    }
}

/// Colour channel in [0, hi]: square-root curve (finer steps near black).
#[inline]
pub fn encode_color(v: f32, hi: f32) -> u8 {
    if !(hi > 0.0) || !v.is_finite() {
        return 0;
    }
    ((v / hi).clamp(0.0, 1.0).sqrt() * 255.0).round() as u8
}
#[inline]
pub fn decode_color(q: u8, hi: f32) -> f32 {
    let x = q as f32 / 255.0;
    x * x * hi
}

/// Octahedral normal encoding (Meyer et al. 2010) with 16 bits per component (codes 0..=65534, so 0 is exact).
#[inline]
pub fn oct_encode(n: Vec3) -> [u16; 2] {
    let n = if n.is_finite() && n.length_squared() > 0.0 { n } else { Vec3::Z };
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    let mut p = Vec2::new(n.x, n.y) / l1;
    if n.z < 0.0 {
        p = Vec2::new((1.0 - p.y.abs()) * p.x.signum(), (1.0 - p.x.abs()) * p.y.signum());
    }
    let q = |x: f32| ((x.clamp(-1.0, 1.0) * 0.5 + 0.5) * 65534.0).round() as u16;
    [q(p.x), q(p.y)]
}
#[inline]
pub fn oct_decode(c: [u16; 2]) -> Vec3 {
    let x = c[0] as f32 / 65534.0 * 2.0 - 1.0;
    let y = c[1] as f32 / 65534.0 * 2.0 - 1.0;
    let z = 1.0 - x.abs() - y.abs();
    let t = (-z).max(0.0);
    let xx = x + if x >= 0.0 { -t } else { t };
    let yy = y + if y >= 0.0 { -t } else { t };
    Vec3::new(xx, yy, z).normalize()
}

/// A value in [0, 1], 8 bit linear.
#[inline]
pub fn encode_unit(v: f32) -> u8 {
    if !v.is_finite() {
        return 0;
    }
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}
#[inline]
pub fn decode_unit(c: u8) -> f32 {
    c as f32 * (1.0 / 255.0)
}

/// Largest surface area a point can stand for, in voxel faces h² (foliage folds several
/// leaves into one voxel; a plane cuts at most √2·h²): 255/64, so the step is 1/64 and a
/// cover of 1 (every point under `--point-weights voxel`, the paper's) codes exactly. (Until
/// stop 77 it was 4: step 4/255, and 1 came back as 1.0039; review finding.)
pub const COVER_MAX: f32 = 255.0 / 64.0;

/// Surface area per point in units of h², 8 bit linear over [0, `COVER_MAX`] (step 1/64).
#[inline]
pub fn encode_cover(a: f32) -> u8 {
    if !a.is_finite() {
        return 0;
    }
    (a / COVER_MAX * 255.0).round().clamp(0.0, 255.0) as u8
}
#[inline]
pub fn decode_cover(c: u8) -> f32 {
    c as f32 * (COVER_MAX / 255.0)
}

/// [`encode_cover`] without dropping small areas: an area below half a step (1/128 h²: a
/// voxel the surface only grazes, or one small leaf in a coarse voxel) codes 1 with
/// probability a/step and 0 otherwise, `u` ∈ \[0, 1) being a hash of the point, so the
/// covers keep their expected sum. Rounding made every such point weightless: from
/// `--oversampling` 129 on, a voxel holding one sample (1/c h²) coded 0, at c = 10⁴ any
/// voxel with fewer than 79 (review finding, stop 91). At the default c = 100 one sample
/// already codes 1, so the default trees do not change.
#[inline]
pub fn encode_cover_dithered(a: f32, u: f32) -> u8 {
    let c = encode_cover(a);
    if c == 0 && a > 0.0 && a.is_finite() {
        (u * (COVER_MAX / 255.0) < a) as u8
    } else {
        c
    }
}

/// A hash as a uniform number in \[0, 1) (its top 24 bits).
#[inline]
pub fn unit_of_hash(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// ∇n = (∂n/∂u, ∂n/∂v), each a 2-vector in the point's tangent frame (per unit length), as
/// four halves of ∇n·`len`, `len` being the hierarchy's root side: a curvature relative to
/// the model's size, about 1 for a sphere that fills it whatever its units. (Until stop 77 the
/// halves held ∇n per unit length, so a sphere of radius 1e-5 came back with 0.65 of its
/// curvature, clamped at ±65,000, and one of radius 1e7 with 1.19, in the halves'
/// subnormals; review finding.)
#[inline]
pub fn encode_grad(gu: Vec2, gv: Vec2, len: f32) -> [u16; 4] {
    let h = |x: f32| {
        let x = x * len;
        f16::from_f32(if x.is_finite() { x.clamp(-65000.0, 65000.0) } else { 0.0 }).to_bits()
    };
    [h(gu.x), h(gu.y), h(gv.x), h(gv.y)]
}
/// ∇n per unit length from [`encode_grad`]'s code with the same `len`.
#[inline]
pub fn decode_grad(g: [u16; 4], len: f32) -> (Vec2, Vec2) {
    let inv = 1.0 / len;
    let f = |b: u16| f16::from_bits(b).to_f32() * inv;
    (Vec2::new(f(g[0]), f(g[1])), Vec2::new(f(g[2]), f(g[3])))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn range8_round_trip(lo in -10.0f32..10.0, span in 0.001f32..100.0, x in 0.0f32..1.0) {
            let r = Range8::new(lo, lo + span);
            let v = lo + x * span;
            let d = r.decode(r.encode(v));
            prop_assert!((d - v).abs() <= r.step() * 0.5 + 1e-5 * span);
        }
        #[test]
        fn color_round_trip(hi in 0.01f32..4.0, x in 0.0f32..1.0) {
            let v = x * hi;
            let d = decode_color(encode_color(v, hi), hi);
            // One step of the square-root curve at this value.
            let s = x.sqrt();
            let step = ((s + 1.0 / 255.0).powi(2) - s * s) * hi;
            prop_assert!((d - v).abs() <= step * 0.5 + 1e-6);
        }
        #[test]
        fn oct_round_trip(x in -1.0f32..1.0, y in -1.0f32..1.0, z in -1.0f32..1.0) {
            let n = Vec3::new(x, y, z);
            prop_assume!(n.length() > 1e-3);
            let n = n.normalize();
            let d = oct_decode(oct_encode(n));
            // One 16-bit step of the octahedral map is at most ~2/65535·2 rad.
            // (sin of the angle: acos is too coarse in f32 near 1.)
            prop_assert!(d.cross(n).length() < 1e-4, "{n} -> {d}");
        }
        #[test]
        fn grad_round_trip(a in -100.0f32..100.0, b in -100.0f32..100.0, c in -1.0f32..1.0, d in -1.0f32..1.0, e in -7i32..8) {
            // Curvatures of models of any size: a value κ at root side L has κ·L in the
            // code's normal range as long as κ·L is (here 1e-3..100 of the root's scale).
            let len = 10f32.powi(e);
            let (a, b, c, d) = (a / len, b / len, c / len, d / len);
            let (gu, gv) = decode_grad(encode_grad(Vec2::new(a, b), Vec2::new(c, d), len), len);
            for (x, y) in [(gu.x, a), (gu.y, b), (gv.x, c), (gv.y, d)] {
                // Half floats keep 11 significant bits: one step is 2^-10 relative (plus
                // subnormals, below 6e-5 of the root's scale).
                prop_assert!((x - y).abs() <= y.abs() * 1.0 / 1024.0 + 1e-7 / len, "{y} at root side {len}: {x}");
            }
        }
    }

    /// Values on a fine grid over [lo, hi], random ones, and the edge values of a linear
    /// 8-bit code over [lo, hi] (the ends, the code boundaries (c + ½)·step, the smallest
    /// positive floats, the float just below the top).
    fn linear_values(lo: f32, hi: f32, seed: u32) -> Vec<f32> {
        let step = (hi - lo) / 255.0;
        let mut s = crate::core::rng::Sampler::new(seed, 0, 0);
        let mut v: Vec<f32> = (0..=100_000).map(|i| lo + (hi - lo) * (i as f32 / 100_000.0)).collect();
        v.extend((0..100_000).map(|_| lo + (hi - lo) * s.next()));
        v.extend([lo, -0.0, 1e-45, f32::MIN_POSITIVE, hi, hi - hi * f32::EPSILON, hi * (1.0 - 1e-7)]);
        for c in 0..255 {
            let b = lo + (c as f32 + 0.5) * step;
            v.extend([b, f32::from_bits(b.to_bits() - 1), f32::from_bits(b.to_bits() + 1)]);
        }
        v
    }

    /// The unit code ([`encode_unit`], rounding): within half a step (1/510) on [0, 1] (slack
    /// 10⁻⁴ step for the f32 rounding of v·255 and c/255, at most 255·2⁻²⁴ codes); outside
    /// the range the nearest end; non-finite input code 0; every code re-encodes to itself.
    #[test]
    fn unit_round_trip() {
        let step = 1.0 / 255.0;
        for v in linear_values(0.0, 1.0, 1) {
            let d = decode_unit(encode_unit(v));
            assert!((d - v).abs() <= 0.5 * step + 1e-4 * step, "{v} -> {} -> {d}", encode_unit(v));
        }
        for (v, want) in [(-1e-7f32, 0.0f32), (-1.0, 0.0), (f32::MIN, 0.0), (1.0 + f32::EPSILON, 1.0), (2.0, 1.0), (f32::MAX, 1.0)] {
            assert_eq!(decode_unit(encode_unit(v)), want, "{v}");
        }
        for v in [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(encode_unit(v), 0, "{v}");
        }
        for c in 0..=255u8 {
            assert_eq!(encode_unit(decode_unit(c)), c);
        }
        assert_eq!((decode_unit(0), decode_unit(255)), (0.0, 1.0));
    }

    /// The cover code ([`encode_cover`], rounding, step `COVER_MAX`/255 = 1/64 h²):
    /// within half a step on [0, `COVER_MAX`]; beyond it (foliage folds more area into a
    /// voxel) `COVER_MAX`, below 0 zero; non-finite input code 0.
    /// [`encode_cover_dithered`]: the code of [`encode_cover`] from half a step up; below,
    /// 0 or 1 with the area's mean over uniform `u`, and 0 for no area.
    #[test]
    fn dithered_cover_keeps_small_areas_on_average() {
        let step = COVER_MAX / 255.0;
        for a in [0.5 * step, step, 0.9, 2.0, COVER_MAX, 9.0, 0.0, -1.0, f32::NAN] {
            for u in [0.0, 0.3, 0.999_999] {
                assert_eq!(encode_cover_dithered(a, u), encode_cover(a), "{a} at {u}");
            }
        }
        const N: u32 = 4096;
        for a in [1.0 / 129.0, 1.0 / 1000.0, 1.0 / 10_000.0, 0.3 * step] {
            let mean = (0..N).map(|i| decode_cover(encode_cover_dithered(a, (i as f32 + 0.5) / N as f32))).sum::<f32>() / N as f32;
            assert!((mean - a).abs() <= 2.0 * step / N as f32, "area {a}: mean code {mean}");
        }
        assert!((0..1000u32).all(|i| (0.0..1.0).contains(&unit_of_hash(crate::core::rng::pcg_hash(i)))));
        assert_eq!(unit_of_hash(u32::MAX), 1.0 - 1.0 / 16_777_216.0);
    }

    #[test]
    fn cover_round_trip() {
        let step = COVER_MAX / 255.0;
        for v in linear_values(0.0, COVER_MAX, 2) {
            let d = decode_cover(encode_cover(v));
            assert!((d - v).abs() <= 0.5 * step + 1e-4 * step, "{v} -> {} -> {d}", encode_cover(v));
        }
        for (v, want) in [(-1e-7f32, 0u8), (-3.0, 0), (f32::MIN, 0), (COVER_MAX * (1.0 + f32::EPSILON), 255), (9.0, 255), (f32::MAX, 255)] {
            assert_eq!(encode_cover(v), want, "{v}");
        }
        assert!((decode_cover(255) - COVER_MAX).abs() <= 1e-6 && decode_cover(0) == 0.0);
        for v in [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(encode_cover(v), 0, "{v}");
        }
        for c in 0..=255u8 {
            assert_eq!(encode_cover(decode_cover(c)), c);
        }
        // The paper's weight of a point (`--point-weights voxel`) comes back exactly.
        assert_eq!(decode_cover(encode_cover(1.0)), 1.0);
    }

    /// The 8-bit position code ([`encode_pos`] / [`decode_pos`], as the build stores a
    /// representative at its samples' mean): for every k of the build (2..=64, m = 128/k codes
    /// per voxel side), random grids (voxel sides 10⁻³..10³, origins up to ±100 voxels or 50
    /// units off) and points in a random voxel — random, on the voxel's faces and corners,
    /// on the sub-cell boundaries and centres — the code stays in the voxel and decodes within
    /// half a code step h/2m per axis (the sub-cell centre). Slack: 8 ulp of the coordinates'
    /// magnitude (the f32 sums cell_lo = grid_lo + cell·h, p − cell_lo and the decode). A point
    /// just outside its voxel (samples clamped into a border cell) decodes to the voxel's
    /// nearest sub-cell; NaN to a sub-cell of the voxel.
    #[test]
    fn position_round_trip() {
        let mut s = crate::core::rng::Sampler::new(3, 0, 0);
        let mut worst = 0.0f32;
        for k in 2..=64u32 {
            let m = super::super::build::codes_per_voxel(k);
            let g = 2 * k;
            assert!(g * m <= 256, "k {k}: {g} voxels × {m} codes do not fit 8 bits");
            for _ in 0..60 {
                let h = 10f32.powf(s.next() * 6.0 - 3.0);
                let off = if s.next() < 0.5 { 100.0 * h } else { 50.0 };
                let grid_lo = Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 2.0 * off;
                let cell = [0, 1, 2].map(|_| ((s.next() * g as f32) as u32).min(g - 1));
                let cell_lo = grid_lo + Vec3::new(cell[0] as f32, cell[1] as f32, cell[2] as f32) * h;
                let step = h / m as f32;
                let slack = 8.0 * f32::EPSILON * (grid_lo.abs().max_element() + g as f32 * h);
                let mut pts = vec![cell_lo, cell_lo + Vec3::splat(h), cell_lo + Vec3::new(h, 0.0, 0.5 * h)];
                for _ in 0..20 {
                    pts.push(cell_lo + Vec3::new(s.next(), s.next(), s.next()) * h);
                }
                for j in 0..m {
                    pts.push(cell_lo + Vec3::splat(j as f32 * step));
                    pts.push(cell_lo + Vec3::splat((j as f32 + 0.5) * step));
                }
                // Just outside the voxel, and far outside: held to its nearest sub-cell.
                let out = [cell_lo - Vec3::splat(0.01 * step), cell_lo + Vec3::splat(h + 0.01 * step), cell_lo - Vec3::splat(5.0 * h)];
                for (i, &p) in pts.iter().chain(&out).enumerate() {
                    let q = encode_pos(p, grid_lo, cell, h, m);
                    for a in 0..3 {
                        assert_eq!(q[a] as u32 / m, cell[a], "k {k}: {p} in voxel {cell:?} coded {q:?}");
                    }
                    let d = decode_pos(q, grid_lo, step);
                    // Outside points: the distance to the voxel's nearest point.
                    let want = if i < pts.len() { p } else { p.clamp(cell_lo, cell_lo + Vec3::splat(h)) };
                    let err = (d - want).abs().max_element();
                    assert!(err <= 0.5 * step + slack, "k {k}, h {h}: {p} -> {q:?} -> {d}: error {err} > half step {}", 0.5 * step);
                    worst = worst.max((err - slack) / step);
                }
                let q = encode_pos(Vec3::NAN, grid_lo, cell, h, m);
                assert!((0..3).all(|a| q[a] as u32 / m == cell[a]) && decode_pos(q, grid_lo, step).is_finite(), "NaN -> {q:?}");
            }
        }
        // The bound is reached (not loose by a factor): the faces are half a step off.
        assert!(worst > 0.45, "largest error {worst} steps");
    }

    #[test]
    fn degenerate_inputs() {
        assert_eq!(oct_decode(oct_encode(Vec3::ZERO)), Vec3::Z);
        assert!(oct_decode(oct_encode(Vec3::NAN)).is_finite());
        // A Phong exponent over 1–1000: logarithmic, each code within 1.4 % (half a step of
        // 1000^(1/255)) and 2 no longer decoded as 1.
        let e = Range8::for_exponent(1.0, 1000.0);
        assert!(e.log && !Range8::for_exponent(0.0, 1000.0).log && !Range8::for_exponent(10.0, 100.0).log);
        for v in [1.0f32, 2.0, 3.5, 10.0, 60.0, 120.0, 999.0, 1000.0] {
            let d = e.decode(e.encode(v));
            assert!((d / v - 1.0).abs() < 0.014, "{v} -> {d}");
        }
        assert_eq!((e.decode(0), e.decode(255)), (1.0, 1000.0));
        let r = Range8::new(1.0, 1.0);
        assert_eq!(r.decode(r.encode(1.0)), 1.0);
        assert_eq!(Range8::new(0.0, 1.0).encode(f32::NAN), 0);
        let (gu, _) = decode_grad(encode_grad(Vec2::new(f32::NAN, 1e9), Vec2::ZERO, 1.0), 1.0);
        assert!(gu.is_finite());
    }
}
