//! Shared machinery: random numbers, counters, the on-disk cache, small math helpers.
pub mod cache;
pub mod eigen2;
pub mod pack;
pub mod rng;
pub mod stats;

use glam::Vec3;

/// The SIMD level this binary was compiled for (`wide::f32x8` is one AVX register with
/// AVX, two SSE registers otherwise): part of every benchmark's provenance.
pub const SIMD_LEVEL: &str = if cfg!(all(target_feature = "avx2", target_feature = "fma")) {
    "avx2+fma"
} else if cfg!(target_feature = "avx") {
    "avx"
} else if cfg!(target_feature = "sse2") {
    "sse2"
} else {
    "scalar"
};

/// An orthonormal frame (t, b, n) around a unit normal (Duff et al. 2017, branchless ONB).
#[inline]
pub fn onb(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vec3::new(b, sign + n.y * n.y * a, -n.y))
}

/// Luminance of a linear Rec.709 colour.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}
