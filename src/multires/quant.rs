//! Quantisation of the point samples (Wand & Straßer §3.2, last paragraph: "all point
//! properties are quantized to small integer values (8 bit for material properties and
//! position, 16 bit for differential properties)").
//!
//! - Position: the representative sits at the centre of its voxel, so its 8-bit grid index
//!   per axis *is* the position, exactly (no rounding error at all).
//! - Material properties: 8 bit each, linear over a per-hierarchy range `[lo, hi]`
//!   ([`Range8`]); colour channels use a square-root curve so dark colours keep precision.
//! - Differential properties: the normal as a 2×16-bit octahedral code ([`oct_encode`]),
//!   the normal derivatives ∇n as four IEEE half floats (16 bit each).
//!
//! Every encoder has a round-trip test: the decoded value is within one quantisation step.

use glam::{Vec2, Vec3};
use half::f16;

/// Linear 8-bit code over `[lo, hi]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Range8 {
    pub lo: f32,
    pub hi: f32,
}

impl Range8 {
    pub fn new(lo: f32, hi: f32) -> Self {
        Range8 { lo, hi: if hi > lo { hi } else { lo } }
    }
    /// One quantisation step.
    pub fn step(&self) -> f32 {
        (self.hi - self.lo) / 255.0
    }
    #[inline]
    pub fn encode(&self, v: f32) -> u8 {
        if self.hi <= self.lo || !v.is_finite() {
            return 0;
        }
        (((v - self.lo) / (self.hi - self.lo)).clamp(0.0, 1.0) * 255.0).round() as u8
    }
    #[inline]
    pub fn decode(&self, q: u8) -> f32 {
        self.lo + (self.hi - self.lo) * (q as f32 / 255.0)
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
/// leaves into one voxel; a plane cuts at most √2·h²).
pub const COVER_MAX: f32 = 4.0;

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

/// ∇n = (∂n/∂u, ∂n/∂v), each a 2-vector in the point's tangent frame, as four halves.
#[inline]
pub fn encode_grad(gu: Vec2, gv: Vec2) -> [u16; 4] {
    let h = |x: f32| f16::from_f32(if x.is_finite() { x.clamp(-65000.0, 65000.0) } else { 0.0 }).to_bits();
    [h(gu.x), h(gu.y), h(gv.x), h(gv.y)]
}
#[inline]
pub fn decode_grad(g: [u16; 4]) -> (Vec2, Vec2) {
    let f = |b: u16| f16::from_bits(b).to_f32();
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
        fn grad_round_trip(a in -100.0f32..100.0, b in -100.0f32..100.0, c in -1.0f32..1.0, d in -1.0f32..1.0) {
            let (gu, gv) = decode_grad(encode_grad(Vec2::new(a, b), Vec2::new(c, d)));
            for (x, y) in [(gu.x, a), (gu.y, b), (gv.x, c), (gv.y, d)] {
                // Half floats keep 11 significant bits: one step is 2^-10 relative (plus subnormals).
                prop_assert!((x - y).abs() <= y.abs() * 1.0 / 1024.0 + 1e-7);
            }
        }
    }

    #[test]
    fn degenerate_inputs() {
        assert_eq!(oct_decode(oct_encode(Vec3::ZERO)), Vec3::Z);
        assert!(oct_decode(oct_encode(Vec3::NAN)).is_finite());
        let r = Range8::new(1.0, 1.0);
        assert_eq!(r.decode(r.encode(1.0)), 1.0);
        assert_eq!(Range8::new(0.0, 1.0).encode(f32::NAN), 0);
        let (gu, _) = decode_grad(encode_grad(Vec2::new(f32::NAN, 1e9), Vec2::ZERO));
        assert!(gu.is_finite());
    }
}
