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

/// Most worker threads a run may ask for (`--threads`, bench key `threads=`).
pub const MAX_THREADS: usize = 1024;

/// The worker pool of a run: `n` threads, 0 = one per core; more than [`MAX_THREADS`] is a
/// usage error (spawning 100 000 threads would hang the machine instead of failing).
pub fn thread_pool(n: usize) -> crate::error::Result<rayon::ThreadPool> {
    check_threads(n)?;
    rayon::ThreadPoolBuilder::new().num_threads(n).build().map_err(|e| crate::error::Error::Usage(format!("thread pool: {e}")))
}

/// The thread-count environment variables rayon reads for a pool of "0 = all cores" (and for
/// its global pool): `RAYON_NUM_THREADS=100000` (or the deprecated `RAYON_RS_NUM_CPUS`) made
/// every run with the default `--threads 0` spawn that many threads, the hang the
/// [`MAX_THREADS`] check refuses for `--threads` (over a minute before the first pixel, then
/// killed). A whole number above [`MAX_THREADS`] is a usage error; anything else is left to
/// rayon (0 and non-numbers mean one thread per core there).
pub fn check_thread_env() -> crate::error::Result<()> {
    for var in ["RAYON_NUM_THREADS", "RAYON_RS_NUM_CPUS"] {
        let Ok(v) = std::env::var(var) else { continue };
        // rayon parses the value as a usize; a number too large for one is ignored there.
        if let Ok(n) = v.parse::<usize>() {
            if n > MAX_THREADS {
                return Err(crate::error::Error::Usage(format!(
                    "{var}={n} out of range (at most {MAX_THREADS} threads): unset it (--threads N sets the threads of a run)"
                )));
            }
        }
    }
    Ok(())
}

/// The `--threads` range check of [`thread_pool`], for validating options before a run.
pub fn check_threads(n: usize) -> crate::error::Result<()> {
    if n > MAX_THREADS {
        return Err(crate::error::Error::Usage(format!("--threads {n} out of range (0 = all cores, at most {MAX_THREADS})")));
    }
    Ok(())
}

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
