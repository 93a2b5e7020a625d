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

use super::trace::enclosing_sphere as enclose;
use super::tree::{sphere_test_1, RayPacketX8, LEAF};
use crate::baseline::accel::Ray;
use glam::Vec3;
use wide::f32x8;

/// At most this many instances per leaf of the instance tree.
pub const TOP_LEAF: usize = 4;

/// The instance tree (module docs).
#[derive(Clone, Debug, Default)]
pub struct TopTree {
    c: Vec<Vec3>,
    r: Vec<f32>,
    right: Vec<u32>,
    first: Vec<u32>,
    count: Vec<u32>,
    order: Vec<u32>,
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
        t
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
