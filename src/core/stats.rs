//! Per-frame counters. Each worker owns a [`Counters`] (one per tile), merged at the end by
//! addition, so counting is cheap enough to stay on and the totals are deterministic.
//! Declared in one line each in `counters!`; they feed `--stats` and the bench tables.

macro_rules! counters {
    ($($name:ident),* $(,)?) => {
        /// Counter identifiers; `Counter::NAMES[c as usize]` is the JSON name.
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[allow(non_camel_case_types)]
        pub enum Counter { $($name),* }
        impl Counter {
            pub const NAMES: &'static [&'static str] = &[$(stringify!($name)),*];
            pub const COUNT: usize = Self::NAMES.len();
        }
    };
}

counters!(
    rays_primary,
    rays_shadow,
    rays_reflect,
    rays_refract,
    rays_verify,
    node_tests,
    instance_tests,
    triangle_tests,
    // Triangle bounding spheres tested before the full cone–triangle test (multires).
    triangle_bound_tests,
    surfel_tests,
    eigen_decompositions,
    fragments_merged,
    // Point hierarchies read from the on-disk cache instead of built (multires, per frame).
    trees_from_cache,
    samples,
    pixels_refined,
    lod_queries,
    lod_level_sum,
    lod_exceptions,
    lod_rays_dropped,
);

#[derive(Clone, Debug)]
pub struct Counters {
    pub v: [u64; Counter::COUNT],
}

impl Default for Counters {
    fn default() -> Self {
        Counters { v: [0; Counter::COUNT] }
    }
}

impl Counters {
    #[inline(always)]
    pub fn add(&mut self, c: Counter, n: u64) {
        self.v[c as usize] += n;
    }
    #[inline(always)]
    pub fn inc(&mut self, c: Counter) {
        self.v[c as usize] += 1;
    }
    pub fn get(&self, c: Counter) -> u64 {
        self.v[c as usize]
    }
    pub fn merge(&mut self, o: &Counters) {
        for (a, b) in self.v.iter_mut().zip(o.v.iter()) {
            *a += b;
        }
    }
    pub fn total_rays(&self) -> u64 {
        self.get(Counter::rays_primary)
            + self.get(Counter::rays_shadow)
            + self.get(Counter::rays_reflect)
            + self.get(Counter::rays_refract)
            + self.get(Counter::rays_verify)
    }
    /// Name → value for every counter (including zeros, so the JSON schema is stable).
    pub fn to_map(&self) -> std::collections::BTreeMap<String, u64> {
        Counter::NAMES.iter().zip(self.v.iter()).map(|(n, v)| (n.to_string(), *v)).collect()
    }
}
