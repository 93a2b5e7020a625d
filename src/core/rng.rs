//! Counter-based random numbers: a hash of (seed, pixel, sample, dimension), so an image is
//! bit-identical for any thread count and tile order (DESIGN.md, Determinism).

/// PCG-style 32-bit integer hash (Jarzynski & Olano, "Hash Functions for GPU Rendering", 2020).
#[inline(always)]
pub fn pcg_hash(x: u32) -> u32 {
    let state = x.wrapping_mul(747796405).wrapping_add(2891336453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277803737);
    (word >> 22) ^ word
}

/// A sampler for one (seed, pixel, sample) triple; each call to [`Sampler::next`] draws the
/// next dimension.
#[derive(Clone, Copy, Debug)]
pub struct Sampler {
    key: u32,
    dim: u32,
}

impl Sampler {
    #[inline]
    pub fn new(seed: u32, pixel: u32, sample: u32) -> Self {
        let key = pcg_hash(seed ^ pcg_hash(pixel ^ pcg_hash(sample.wrapping_add(0x9e37_79b9))));
        Sampler { key, dim: 0 }
    }
    /// Uniform in [0, 1).
    // Not an `Iterator`: the sampler never ends, and `next` draws the next dimension's value
    // (the name every sampler call site uses).
    #[allow(clippy::should_implement_trait)]
    #[inline]
    pub fn next(&mut self) -> f32 {
        let h = pcg_hash(self.key ^ pcg_hash(self.dim.wrapping_mul(0x85eb_ca6b)));
        self.dim += 1;
        (h >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
    #[inline]
    pub fn next2(&mut self) -> (f32, f32) {
        (self.next(), self.next())
    }
}

/// Uniform point on the unit disk (concentric mapping, Shirley & Chiu 1997).
pub fn concentric_disk(u: f32, v: f32) -> (f32, f32) {
    let a = 2.0 * u - 1.0;
    let b = 2.0 * v - 1.0;
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, std::f32::consts::FRAC_PI_4 * (b / a))
    } else {
        (b, std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (a / b))
    };
    (r * phi.cos(), r * phi.sin())
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn uniform_mean_and_range() {
        let mut s = Sampler::new(1, 2, 3);
        let n = 100_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let x = s.next();
            assert!((0.0..1.0).contains(&x));
            sum += x as f64;
        }
        assert!((sum / n as f64 - 0.5).abs() < 0.01);
    }
    #[test]
    fn deterministic() {
        let a: Vec<f32> = (0..8).map(|_| 0.0).scan(Sampler::new(7, 9, 11), |s, _| Some(s.next())).collect();
        let b: Vec<f32> = (0..8).map(|_| 0.0).scan(Sampler::new(7, 9, 11), |s, _| Some(s.next())).collect();
        assert_eq!(a, b);
        assert_ne!(Sampler::new(7, 9, 11).next(), Sampler::new(7, 10, 11).next());
    }
    #[test]
    fn disk_inside() {
        let mut s = Sampler::new(0, 0, 0);
        for _ in 0..1000 {
            let (x, y) = concentric_disk(s.next(), s.next());
            assert!(x * x + y * y <= 1.0 + 1e-5);
        }
    }
}
