//! Stream compaction of `f32x8` lanes ("left-pack"): the lanes selected by a bit mask,
//! stored contiguously. A packet kernel whose results pass a test lane by lane (the point
//! weights of §4.3, 70% of which pass) writes its survivors with one permute and one store
//! per output array instead of a scalar loop over the mask's bits.
//!
//! With AVX2 (the build `tools/setup` makes on a capable CPU) a mask indexes a table of lane
//! permutations for `vpermps`/`vpermd`; otherwise the lanes are copied one by one. Both store
//! all 8 lanes at `dst[at..at + 8]` (the lanes past the selected ones are scratch), so `dst`
//! needs 8 slots of room past the last survivor.

use wide::{f32x8, i32x8};

/// Lane indices of each 8-bit mask's set bits, in order, one byte each (unused bytes 0).
#[cfg(target_feature = "avx2")]
const LUT: [u64; 256] = {
    let mut t = [0u64; 256];
    let mut m = 0;
    while m < 256 {
        let (mut k, mut l, mut v) = (0, 0, 0u64);
        while l < 8 {
            if m & (1 << l) != 0 {
                v |= (l as u64) << (8 * k);
                k += 1;
            }
            l += 1;
        }
        t[m] = v;
        m += 1;
    }
    t
};

/// Stores the lanes of `v` selected by `m` (bit l = lane l) at `dst[at..]`, in lane order;
/// returns how many. Panics if `dst` has fewer than `at + 8` slots.
#[inline(always)]
pub fn compress_f32(v: f32x8, m: u8, dst: &mut [f32], at: usize) -> usize {
    let d: &mut [f32; 8] = (&mut dst[at..at + 8]).try_into().expect("8 slots");
    #[cfg(target_feature = "avx2")]
    {
        use std::arch::x86_64::*;
        // SAFETY: AVX2 is enabled at compile time; `d` is 8 valid f32 slots; f32x8 and
        // __m256 are the same 32 bytes.
        unsafe {
            let perm = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(LUT[m as usize] as i64));
            let r = _mm256_permutevar8x32_ps(std::mem::transmute::<f32x8, __m256>(v), perm);
            _mm256_storeu_ps(d.as_mut_ptr(), r);
        }
    }
    #[cfg(not(target_feature = "avx2"))]
    {
        let a = v.to_array();
        let (mut k, mut mm) = (0, m as u32);
        while mm != 0 {
            d[k] = a[mm.trailing_zeros() as usize];
            k += 1;
            mm &= mm - 1;
        }
    }
    m.count_ones() as usize
}

/// [`compress_f32`] for `i32x8` lanes, stored as u32 (the same permute on the lanes' bits).
#[inline(always)]
pub fn compress_u32(v: i32x8, m: u8, dst: &mut [u32], at: usize) -> usize {
    use wide::bytemuck::{cast, cast_slice_mut};
    compress_f32(cast(v), m, cast_slice_mut(dst), at)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every mask, against the obvious filter.
    #[test]
    fn compress_keeps_selected_lanes_in_order() {
        let v = f32x8::from([10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0, 17.0]);
        let vi = i32x8::from([0, 1, 2, 3, 4, 5, 6, 7]);
        for m in 0..=255u8 {
            let want: Vec<usize> = (0..8).filter(|l| m & (1 << l) != 0).collect();
            let mut d = [0.0f32; 11];
            let mut di = [0u32; 11];
            assert_eq!(compress_f32(v, m, &mut d, 3), want.len());
            assert_eq!(compress_u32(vi, m, &mut di, 3), want.len());
            for (k, &l) in want.iter().enumerate() {
                assert_eq!(d[3 + k], 10.0 + l as f32, "mask {m:08b}");
                assert_eq!(di[3 + k], l as u32, "mask {m:08b}");
            }
            assert_eq!(&d[..3], &[0.0; 3], "wrote before `at`");
        }
    }
}
