//! A sphere tree over the instances of a deforming scene, rebuilt every frame: the top level
//! above the per-object hierarchies of Adams et al. §4.1.
//!
//! **Not in the paper**, which describes the hierarchy of one object and says nothing of how
//! the rays find the objects of a scene. Until stop 37 every ray (and every packet) tested the
//! root sphere of every instance: 40 tests per ray in `elastic-balls`, about 15–25 ms of a
//! 105 ms frame (measured by testing the roots twice). This tree cuts that to the few
//! instances along a ray, in every update mode alike.
//!
//! Build: the instances' bounding spheres of the frame (the root spheres that the traversal
//! tests first: Eq. 3–4, 9 in the lazy modes, the rebuilt miniball root in `naive`, the sphere
//! around the refitted root box in `refit`), split at the median centre on the longest axis
//! of the centres' box, down to at most [`TOP_LEAF`] instances per leaf. A node's sphere
//! encloses its children's, padded, so it holds every leaf ball of its instances. Culling by
//! it therefore never removes a hit (the argument of the module docs of
//! [`trace`](super::trace)), and the images are unchanged. A scene of at most `TOP_LEAF`
//! instances is one leaf and costs no extra test.
//!
//! Layout: depth-first, the left child of node n at n + 1, the right one at `right[n]`
//! ([`LEAF`] for leaves, whose instances are `order[first..first + count]`), struct of arrays.
//!
//! **Packet cone (stop 85).** A packet's rays mostly share an origin (primary rays: the eye)
//! or an end (shadow rays: the light). [`PacketCone`] bounds all its active segments by one
//! cone, and a scene of at most [`CONE_FLAT_MAX`] instances tests every instance sphere
//! against it, eight spheres per f32x8 step ([`TopTree::candidates_cone`]), instead of
//! walking the tree with eight-ray sphere tests and testing each candidate leaf's roots:
//! 40 instances are five steps. The test is conservative (below), so the candidates still
//! hold every instance a lane reaches and the images are unchanged; the caller then tests
//! each candidate's root per lane as before. A packet without such a cone (a wide one, or
//! one whose rays share neither end) walks the tree. A cone test counts as one sphere test
//! per instance (the tree's tests count one per active lane), so such scenes report fewer
//! bounding-volume tests than before stop 85.

use super::trace::enclosing_sphere as enclose;
use super::tree::{sphere_test_1, RayPacketX8, LEAF};
use crate::baseline::accel::Ray;
use glam::Vec3;
use wide::{f32x8, u32x8};

/// At most this many instances per leaf of the instance tree.
pub const TOP_LEAF: usize = 4;

/// Scenes of more than [`TOP_LEAF`] and at most this many instances find a packet's
/// candidates with the [`PacketCone`] scan over all instance spheres (eight steps at most).
pub const CONE_FLAT_MAX: usize = 64;

/// A cone holding the segments of a packet's active rays, widened by `pad` (module docs).
///
/// Either the rays share their origin (bitwise): the apex is that origin and each ray's
/// direction lies in the cone; or every ray has a finite end `o + d·tfar`: the apex is the
/// first ray's end, `pad` the largest distance of another end from it, and each origin
/// lies in the cone. A segment from a point of the cone to within `pad` of the apex lies
/// within `pad` of the cone (the cone is convex, its half-angle below 90°), so a sphere of
/// radius `r` no lane reaches misses the cone widened to `r + pad`.
///
/// The test of a sphere (centre c, radius r) against the cone (apex a, unit axis w,
/// half-angle θ): with `v = c − a`, `d = v·w` and `e = ‖v × w‖` (no cancellation), the
/// distance from c to the cone is at least `e cos θ − d sin θ` (equal to it while the
/// nearest point is on the cone's side, below the distance to the apex otherwise); every
/// point of the cone has `0 ≤ v·w ≤ far`. So the sphere is culled if `e cos θ − d sin θ`,
/// `−d` or `d − far` exceeds `r + pad`, each side padded by a relative 1e-5 and θ by 1e-4
/// against f32 rounding. A NaN anywhere makes the sphere a candidate.
#[derive(Clone, Copy, Debug)]
pub struct PacketCone {
    apex: Vec3,
    axis: Vec3,
    cos: f32,
    sin: f32,
    far: f32,
    pad: f32,
}

/// A packet cone is not used when wider than this (cos of the half-angle; 60°).
const CONE_MIN_COS: f32 = 0.5;

/// The lanes of `m` as an all-ones f32x8 mask.
#[inline]
fn lane_mask(m: u8) -> f32x8 {
    let bit = u32x8::from([1, 2, 4, 8, 16, 32, 64, 128]);
    wide::bytemuck::cast((u32x8::splat(m as u32) & bit).simd_eq(bit))
}

/// The largest of the lanes of `sel` (−∞ if none; a NaN lane gives NaN or is skipped, as
/// `f32::max` does, so callers check the result and the axis for finiteness).
#[inline]
fn hmax(sel: f32x8, v: f32x8) -> f32 {
    sel.select(v, f32x8::splat(f32::NEG_INFINITY)).to_array().into_iter().fold(f32::NEG_INFINITY, f32::max)
}

impl PacketCone {
    /// The cone of the lanes `mask` of `pk`, each ray ending at its `tfar`; None if there is
    /// none narrower than 120° (see the type's docs).
    pub fn new(pk: &RayPacketX8, mask: u8, tfar: f32x8) -> Option<PacketCone> {
        if mask == 0 {
            return None;
        }
        // Eight lanes at once (this runs for every packet); the lanes outside `mask` are
        // blended out of every reduction.
        let (o, d, a, tnear) = pk.soa();
        let sel = lane_mask(mask);
        // A segment starting behind its origin leaves the cone.
        if (sel & (!tnear.simd_ge(f32x8::ZERO) | tfar.is_nan())).any() {
            return None;
        }
        let first = mask.trailing_zeros() as usize;
        let at = |v: f32x8| v.as_array()[first];
        let o0 = [at(o[0]), at(o[1]), at(o[2])];
        let same = o[0].simd_eq(f32x8::splat(o0[0])) & o[1].simd_eq(f32x8::splat(o0[1])) & o[2].simd_eq(f32x8::splat(o0[2]));
        // The cone's generators g (unit vectors from the apex) and how far it reaches.
        let (apex, g, pad, far) = if (sel & !same).none() {
            // One division a lane, not three: the generators need not be unit to the last
            // bit (the 1e-4 on cos below covers it), and the divisions' latency was most of
            // this function's time (perf: 2.3 % of an `elastic-balls` frame).
            let len = a.sqrt();
            let il = f32x8::ONE / len;
            let g = [d[0] * il, d[1] * il, d[2] * il];
            (Vec3::from(o0), g, 0.0, hmax(sel, tfar * len))
        } else {
            let end = [o[0] + d[0] * tfar, o[1] + d[1] * tfar, o[2] + d[2] * tfar];
            let apex = [at(end[0]), at(end[1]), at(end[2])];
            let off = [end[0] - apex[0], end[1] - apex[1], end[2] - apex[2]];
            let w = [o[0] - apex[0], o[1] - apex[1], o[2] - apex[2]];
            let len = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            let il = f32x8::ONE / len;
            let pad = hmax(sel, (off[0] * off[0] + off[1] * off[1] + off[2] * off[2]).sqrt());
            (Vec3::from(apex), [w[0] * il, w[1] * il, w[2] * il], pad, hmax(sel, len))
        };
        let axis = Vec3::new(
            sel.select(g[0], f32x8::ZERO).reduce_add(),
            sel.select(g[1], f32x8::ZERO).reduce_add(),
            sel.select(g[2], f32x8::ZERO).reduce_add(),
        )
        .normalize();
        let dots = g[0] * axis.x + g[1] * axis.y + g[2] * axis.z;
        // The min over the lanes as −max(−x). `hmax` skips NaN lanes, but a NaN generator
        // also sums into the axis, which must be finite.
        let cos = -hmax(sel, -dots) - 1e-4;
        if !(apex.is_finite() && axis.is_finite() && pad.is_finite() && cos >= CONE_MIN_COS && !far.is_nan()) {
            return None;
        }
        let far = if far.is_finite() { far * (1.0 + 1e-5) } else { far };
        Some(PacketCone { apex, axis, cos, sin: (1.0 - cos * cos).max(0.0).sqrt(), far, pad })
    }

    /// Mask of the spheres (x, y, z, r: eight lanes each) that may meet the cone.
    #[inline]
    pub fn test_x8(&self, x: f32x8, y: f32x8, z: f32x8, r: f32x8) -> u8 {
        let (vx, vy, vz) = (x - self.apex.x, y - self.apex.y, z - self.apex.z);
        let w = self.axis;
        let d = vx * w.x + vy * w.y + vz * w.z;
        let (cx, cy, cz) = (vy * w.z - vz * w.y, vz * w.x - vx * w.z, vx * w.y - vy * w.x);
        let e = (cx * cx + cy * cy + cz * cz).sqrt();
        let rr = r + self.pad + f32x8::splat(1e-5) * (d.abs() + e + r.abs() + self.pad);
        let side = (e * self.cos - d * self.sin).simd_gt(rr);
        let behind = (-d).simd_gt(rr);
        let beyond = (d - self.far).simd_gt(rr);
        !((side | behind | beyond).to_bitmask() as u8)
    }
}

/// The instance tree (module docs).
#[derive(Clone, Debug, Default)]
pub struct TopTree {
    c: Vec<Vec3>,
    r: Vec<f32>,
    right: Vec<u32>,
    first: Vec<u32>,
    count: Vec<u32>,
    order: Vec<u32>,
    /// The instance spheres (x, y, z, r), padded to a multiple of 8 (the padding lanes are
    /// masked off in [`Self::candidates_cone`]); empty unless the scene has more than [`TOP_LEAF`] and at most
    /// [`CONE_FLAT_MAX`] instances.
    flat: [Vec<f32>; 4],
}

impl TopTree {
    /// Builds the tree over `spheres[k]`, the bounding sphere of instance k. A sphere that is
    /// not finite (or has a negative radius) makes its instance a member of every ray's
    /// candidates: the root test of the instance then decides, as without the tree.
    pub fn build(spheres: &[(Vec3, f32)]) -> Self {
        let mut t = TopTree::default();
        let ok = |s: &(Vec3, f32)| s.0.is_finite() && s.1.is_finite() && s.1 >= 0.0;
        if spheres.len() <= TOP_LEAF || !spheres.iter().all(ok) {
            return TopTree::flat(spheres.len());
        }
        let mut idx: Vec<u32> = (0..spheres.len() as u32).collect();
        t.build_rec(spheres, &mut idx, 0);
        t.order = idx;
        if spheres.len() <= CONE_FLAT_MAX {
            let len = spheres.len().div_ceil(8) * 8;
            for (a, v) in t.flat.iter_mut().enumerate() {
                *v = (0..len)
                    .map(|k| spheres.get(k).map_or(if a == 3 { f32::NEG_INFINITY } else { 0.0 }, |s| if a == 3 { s.1 } else { s.0[a] }))
                    .collect();
            }
        }
        t
    }

    /// Whether [`Self::candidates_cone`] is available (the scene's instance count).
    #[inline]
    pub fn has_flat(&self) -> bool {
        !self.flat[3].is_empty()
    }

    /// Every instance whose sphere may meet `cone`, in index order, passed to `visit`
    /// (needs [`Self::has_flat`]). Returns the number of sphere tests: one per instance.
    #[inline]
    pub fn candidates_cone(&self, cone: &PacketCone, mut visit: impl FnMut(u32)) -> u64 {
        let [x, y, z, r] = &self.flat;
        let n = self.order.len();
        for b in (0..r.len()).step_by(8) {
            let ld = |v: &[f32]| f32x8::from(<[f32; 8]>::try_from(&v[b..b + 8]).unwrap());
            // The padding lanes are masked off here: their −∞ radius makes the test's
            // rounding pad NaN, and a NaN keeps a sphere.
            let mut m = cone.test_x8(ld(x), ld(y), ld(z), ld(r)) & (0xffu32 >> (8 - (n - b).min(8))) as u8;
            while m != 0 {
                visit((b + m.trailing_zeros() as usize) as u32);
                m &= m - 1;
            }
        }
        self.order.len() as u64
    }

    /// One leaf over `n` instances: every ray tests every root (the ablation).
    pub fn flat(n: usize) -> Self {
        let mut t = TopTree { order: (0..n as u32).collect(), ..TopTree::default() };
        t.push_leaf(0, n, (Vec3::ZERO, f32::INFINITY));
        t
    }

    fn push_leaf(&mut self, first: usize, count: usize, s: (Vec3, f32)) -> usize {
        self.c.push(s.0);
        self.r.push(s.1);
        self.right.push(LEAF);
        self.first.push(first as u32);
        self.count.push(count as u32);
        self.c.len() - 1
    }

    /// Node over `idx` (instances `offset..offset + idx.len()` of `order`); returns its sphere.
    fn build_rec(&mut self, spheres: &[(Vec3, f32)], idx: &mut [u32], offset: usize) -> (Vec3, f32) {
        if idx.len() <= TOP_LEAF {
            let s = idx.iter().skip(1).fold(spheres[idx[0] as usize], |acc, &k| enclose(acc, spheres[k as usize]));
            self.push_leaf(offset, idx.len(), s);
            return s;
        }
        let (lo, hi) = idx.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &k| {
            let c = spheres[k as usize].0;
            (lo.min(c), hi.max(c))
        });
        let ext = hi - lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = idx.len() / 2;
        idx.select_nth_unstable_by(mid, |a, b| spheres[*a as usize].0[axis].total_cmp(&spheres[*b as usize].0[axis]).then(a.cmp(b)));
        let n = self.push_leaf(0, 0, (Vec3::ZERO, 0.0));
        let (l, r) = idx.split_at_mut(mid);
        let sl = self.build_rec(spheres, l, offset);
        self.right[n] = self.c.len() as u32;
        let sr = self.build_rec(spheres, r, offset + mid);
        let s = enclose(sl, sr);
        self.c[n] = s.0;
        self.r[n] = s.1;
        self.count[n] = 0;
        s
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.c.len()
    }

    pub fn is_empty(&self) -> bool {
        self.c.is_empty()
    }

    /// Whether the whole tree is one leaf (no node is tested).
    fn single(&self) -> bool {
        self.c.len() <= 1
    }

    /// Instances whose leaf the ray reaches within [tnear, `tfar`], pushed to `out` in tree
    /// order. Returns the number of node sphere tests.
    pub fn candidates_1(&self, ray: &Ray, tfar: f32, out: &mut Vec<u32>) -> u64 {
        if self.single() {
            out.extend_from_slice(&self.order);
            return 0;
        }
        let mut tests = 0;
        let mut stack = [0u32; 64];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let n = stack[sp] as usize;
            tests += 1;
            if sphere_test_1(ray.org, ray.dir, self.c[n], self.r[n], ray.tnear, tfar).is_none() {
                continue;
            }
            if self.right[n] == LEAF {
                let f = self.first[n] as usize;
                out.extend_from_slice(&self.order[f..f + self.count[n] as usize]);
            } else {
                stack[sp] = self.right[n];
                stack[sp + 1] = n as u32 + 1;
                sp += 2;
            }
        }
        tests
    }

    /// Packet form: for the lanes `mask` of `pk`, each instance whose leaf one of them reaches
    /// within `tfar` is passed to `visit` with the lanes that reach it (no allocation: this
    /// runs once per packet). Returns the number of sphere tests counted per active lane (as
    /// the per-object traversal counts them). The nodes are culled by the square-root-free
    /// segment test ([`RayPacketX8::test_any`]): only the mask counts here, the caller tests
    /// each candidate's root for its entry (stop 68: `elastic-balls` spent 7 % of its frame
    /// in this tree and its roots). Both tests are conservative, so the candidates hold
    /// every instance a lane reaches; at a rim they may differ from [`Self::candidates_1`]'s.
    pub fn candidates_x8(&self, pk: &RayPacketX8, mask: u8, tfar: f32x8, mut visit: impl FnMut(u32, u8)) -> u64 {
        // A single leaf (`flat`) is not tested. It goes through the loop all the same, so
        // that `visit` has one call site and is inlined.
        let single = self.single();
        let mut tests = 0;
        // Median splits down to `TOP_LEAF` instances: depth < 31 for any u32 count, and a
        // depth-first stack holds at most depth + 1 entries.
        let mut stack = [(0u32, 0u8); 32];
        stack[0] = (0, mask);
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (n, m) = stack[sp];
            let n = n as usize;
            let m = if single {
                m
            } else {
                tests += m.count_ones() as u64;
                m & pk.test_any(self.c[n], self.r[n], tfar)
            };
            if m == 0 {
                continue;
            }
            if self.right[n] == LEAF {
                let f = self.first[n] as usize;
                for &k in &self.order[f..f + self.count[n] as usize] {
                    visit(k, m);
                }
            } else {
                stack[sp] = (self.right[n], m);
                stack[sp + 1] = (n as u32 + 1, m);
                sp += 2;
            }
        }
        tests
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler as Rng;

    fn spheres(n: usize, seed: u64) -> Vec<(Vec3, f32)> {
        let mut g = Rng::new(seed as u32, 0, 0);
        (0..n).map(|_| (Vec3::new(g.next() * 20.0 - 10.0, g.next() * 4.0, g.next() * 20.0 - 10.0), 0.2 + g.next())).collect()
    }

    /// Every instance sphere lies in all its ancestors' spheres, and each instance is in
    /// exactly one leaf.
    #[test]
    fn nodes_enclose_their_instances() {
        for n in [1, 4, 5, 9, 40, 257] {
            let s = spheres(n, n as u64);
            let t = TopTree::build(&s);
            let mut seen = vec![0; n];
            fn walk(t: &TopTree, n: usize, anc: &mut Vec<usize>, s: &[(Vec3, f32)], seen: &mut [u32]) {
                if t.right[n] == LEAF {
                    let f = t.first[n] as usize;
                    for &k in &t.order[f..f + t.count[n] as usize] {
                        seen[k as usize] += 1;
                        let (c, r) = s[k as usize];
                        for &a in anc.iter().chain(std::iter::once(&n)) {
                            if t.single() {
                                continue;
                            }
                            assert!((c - t.c[a]).length() + r <= t.r[a], "instance {k} pokes out of node {a}");
                        }
                    }
                    return;
                }
                anc.push(n);
                walk(t, n + 1, anc, s, seen);
                walk(t, t.right[n] as usize, anc, s, seen);
                anc.pop();
            }
            walk(&t, 0, &mut Vec::new(), &s, &mut seen);
            assert!(seen.iter().all(|&x| x == 1), "{n} instances: {seen:?}");
            assert!(t.count.iter().all(|&c| c as usize <= TOP_LEAF));
            assert_eq!(t.single(), n <= TOP_LEAF);
        }
    }

    /// The candidates contain every instance whose sphere the ray hits (scalar and packet
    /// forms), and with 40 instances far fewer than all of them; the two forms agree but
    /// for a rare rim case (their node tests' slacks differ).
    #[test]
    fn candidates_hold_every_hit_instance() {
        let s = spheres(40, 7);
        let t = TopTree::build(&s);
        let mut g = Rng::new(3, 0, 0);
        let (mut total, mut differ) = (0, 0);
        for _ in 0..64 {
            let rays: Vec<Ray> = (0..8)
                .map(|_| {
                    let o = Vec3::new(g.next() * 30.0 - 15.0, 2.0 + g.next() * 10.0, 25.0);
                    let target = Vec3::new(g.next() * 20.0 - 10.0, g.next() * 4.0, g.next() * 20.0 - 10.0);
                    Ray::new(o, (target - o).normalize())
                })
                .collect();
            let pk = RayPacketX8::new(
                &std::array::from_fn(|a| std::array::from_fn(|i| rays[i].org[a])),
                &std::array::from_fn(|a| std::array::from_fn(|i| rays[i].dir[a])),
                &std::array::from_fn(|i| rays[i].tnear),
            );
            let mut px = Vec::new();
            t.candidates_x8(&pk, 0xff, f32x8::splat(f32::INFINITY), |k, m| px.push((k, m)));
            for (i, ray) in rays.iter().enumerate() {
                let mut c1 = Vec::new();
                t.candidates_1(ray, f32::INFINITY, &mut c1);
                total += c1.len();
                let mut cx: Vec<u32> = px.iter().filter(|(_, m)| m & (1 << i) != 0).map(|(k, _)| *k).collect();
                cx.sort();
                let mut c1s = c1.clone();
                c1s.sort();
                differ += (cx != c1s) as usize;
                for (k, &(c, r)) in s.iter().enumerate() {
                    if sphere_test_1(ray.org, ray.dir, c, r, ray.tnear, f32::INFINITY).is_some() {
                        assert!(c1.contains(&(k as u32)), "instance {k} hit but culled");
                        assert!(cx.contains(&(k as u32)), "instance {k} hit but culled in packet lane {i}");
                    }
                }
            }
        }
        assert!(total < 64 * 8 * 40 / 2, "the tree culls little: {total} candidates");
        assert!(differ <= 8, "packet and scalar candidates differ for {differ} of 512 rays");
    }

    /// The packet cone never culls an instance sphere that one of the packet's segments
    /// meets: packets from one origin (unbounded, and with `tfar`), packets ending near one
    /// point (shadow rays to a light, from spread-out origins), narrow and wide; and it does
    /// cull.
    #[test]
    fn the_packet_cone_keeps_every_sphere_a_lane_meets() {
        let mut g = Rng::new(7, 0, 0);
        let (mut kept, mut met, mut tested, mut cones) = (0usize, 0usize, 0usize, 0usize);
        for round in 0..3000 {
            // Counts that are and are not multiples of eight (the padding lanes).
            let s = spheres(33 + round as usize % 16, round);
            let t = TopTree::build(&s);
            assert!(t.has_flat());
            let spread = [0.002, 0.02, 0.2, 1.0][round as usize % 4];
            let n = 1 + round as usize % 8;
            let eye = Vec3::new(g.next() * 30.0 - 15.0, g.next() * 6.0, g.next() * 30.0 - 15.0);
            let aim = Vec3::new(g.next() * 20.0 - 10.0, g.next() * 4.0, g.next() * 20.0 - 10.0) - eye;
            let light = Vec3::new(g.next() * 10.0 - 5.0, 2.0 + g.next() * 3.0, g.next() * 10.0 - 5.0);
            let rays: Vec<Ray> = (0..8)
                .map(|_| {
                    let j = Vec3::new(g.next() - 0.5, g.next() - 0.5, g.next() - 0.5) * spread;
                    match round % 3 {
                        0 => Ray::new(eye, aim.normalize() + j),
                        1 => Ray::segment(eye, aim + j * aim.length(), 0.0, g.next() * 1.5),
                        _ => {
                            // From a point near the aim towards the light, ending a little off it
                            // (as the shadow rays' offset start makes them).
                            let p = eye + aim + j * 10.0;
                            let off = Vec3::new(g.next() - 0.5, g.next() - 0.5, g.next() - 0.5) * 0.6;
                            let to = light - p;
                            Ray::segment(p + off, to / to.length(), 0.0, to.length())
                        }
                    }
                })
                .collect();
            let pk = RayPacketX8::new(
                &std::array::from_fn(|a| std::array::from_fn(|i| rays[i].org[a])),
                &std::array::from_fn(|a| std::array::from_fn(|i| rays[i].dir[a])),
                &std::array::from_fn(|i| rays[i].tnear),
            );
            let mask = ((1u32 << n) - 1) as u8;
            let tfar = f32x8::from(std::array::from_fn::<f32, 8, _>(|i| rays[i].tfar));
            let Some(cone) = PacketCone::new(&pk, mask, tfar) else { continue };
            cones += 1;
            let mut cand = Vec::new();
            tested += t.candidates_cone(&cone, |k| cand.push(k)) as usize;
            kept += cand.len();
            assert!(cand.iter().all(|&k| (k as usize) < s.len()), "round {round}: a padding lane is a candidate: {cand:?}");
            for (k, &(c, r)) in s.iter().enumerate() {
                for ray in &rays[..n] {
                    if sphere_test_1(ray.org, ray.dir, c, r, ray.tnear, ray.tfar).is_some() {
                        met += 1;
                        assert!(cand.contains(&(k as u32)), "round {round}: sphere {k} met by {ray:?} but culled");
                    }
                }
            }
        }
        assert!(cones > 2000, "only {cones} packets had a cone");
        assert!(kept < tested / 3 && met > 0, "the cone culls little: {kept} of {tested} kept ({met} meetings)");
    }

    /// Rays starting behind their origin, or without a common origin or a finite end, get no
    /// cone (the caller walks the tree).
    #[test]
    fn no_cone_for_packets_it_cannot_bound() {
        let mk = |rays: &[Ray]| {
            RayPacketX8::new(
                &std::array::from_fn(|a| std::array::from_fn(|i| rays[i % rays.len()].org[a])),
                &std::array::from_fn(|a| std::array::from_fn(|i| rays[i % rays.len()].dir[a])),
                &std::array::from_fn(|i| rays[i % rays.len()].tnear),
            )
        };
        let inf = f32x8::splat(f32::INFINITY);
        let a = Ray::new(Vec3::ZERO, Vec3::X);
        assert!(PacketCone::new(&mk(&[a]), 0xff, inf).is_some());
        let behind = Ray::segment(Vec3::ZERO, Vec3::X, -1.0, 5.0);
        assert!(PacketCone::new(&mk(&[behind]), 0xff, inf).is_none());
        let b = Ray::new(Vec3::Y, Vec3::X);
        assert!(PacketCone::new(&mk(&[a, b]), 0b11, inf).is_none(), "two origins, no finite end");
        let wide = Ray::new(Vec3::ZERO, -Vec3::X);
        assert!(PacketCone::new(&mk(&[a, wide]), 0b11, inf).is_none(), "opposite directions");
        let nan = Ray::new(Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0));
        assert!(PacketCone::new(&mk(&[nan]), 0xff, inf).is_none());
    }

    #[test]
    fn non_finite_spheres_make_one_leaf() {
        let mut s = spheres(10, 1);
        s[3].1 = f32::NAN;
        let t = TopTree::build(&s);
        assert!(t.single());
        let mut c = Vec::new();
        assert_eq!(t.candidates_1(&Ray::new(Vec3::ZERO, Vec3::X), f32::INFINITY, &mut c), 0);
        assert_eq!(c.len(), 10);
    }
}
