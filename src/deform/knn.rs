//! Static k-nearest-neighbour queries (a median-split kd-tree) for the precomputation of
//! Adams et al. §4.4: surfel → simulation nodes (Eq. 1), surfel → 16 surfel neighbours
//! (§4.2.1), surfel → two nearest surfels of a clipping surface (§4.3), node → node
//! neighbourhoods (the MLS displacement gradient). Queries are pure functions of the point
//! set, so results are identical for any thread count; ties are broken by point index.

use glam::Vec3;

/// A kd-tree over a fixed point set. Leaves hold up to `LEAF` points.
pub struct KdTree {
    pts: Vec<Vec3>,
    /// Permutation of point indices; every node covers a contiguous range of it.
    perm: Vec<u32>,
    nodes: Vec<KdNode>,
}

#[derive(Clone, Copy)]
struct KdNode {
    lo: Vec3,
    hi: Vec3,
    start: u32,
    end: u32,
    /// Index of the left child (right = left + 1), `u32::MAX` for a leaf.
    left: u32,
}

const LEAF: usize = 12;

impl KdTree {
    pub fn new(pts: &[Vec3]) -> Self {
        let mut t = KdTree { pts: pts.to_vec(), perm: (0..pts.len() as u32).collect(), nodes: Vec::new() };
        if !pts.is_empty() {
            t.nodes.push(KdNode { lo: Vec3::ZERO, hi: Vec3::ZERO, start: 0, end: pts.len() as u32, left: u32::MAX });
            t.build(0);
        }
        t
    }

    pub fn len(&self) -> usize {
        self.pts.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pts.is_empty()
    }

    fn build(&mut self, root: usize) {
        let mut stack = vec![root];
        while let Some(n) = stack.pop() {
            let (s, e) = (self.nodes[n].start as usize, self.nodes[n].end as usize);
            let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            for &i in &self.perm[s..e] {
                lo = lo.min(self.pts[i as usize]);
                hi = hi.max(self.pts[i as usize]);
            }
            self.nodes[n].lo = lo;
            self.nodes[n].hi = hi;
            if e - s <= LEAF {
                continue;
            }
            let ext = hi - lo;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = (s + e) / 2;
            let pts = &self.pts;
            self.perm[s..e]
                .select_nth_unstable_by(mid - s, |&a, &b| pts[a as usize][axis].total_cmp(&pts[b as usize][axis]).then(a.cmp(&b)));
            let left = self.nodes.len() as u32;
            self.nodes[n].left = left;
            self.nodes.push(KdNode { lo, hi, start: s as u32, end: mid as u32, left: u32::MAX });
            self.nodes.push(KdNode { lo, hi, start: mid as u32, end: e as u32, left: u32::MAX });
            stack.push(left as usize);
            stack.push(left as usize + 1);
        }
    }

    /// The `k` nearest points to `q` as (index, squared distance), nearest first (ties by
    /// index). `skip` excludes one index (e.g. the query point itself).
    pub fn knn(&self, q: Vec3, k: usize, skip: Option<u32>, out: &mut Vec<(u32, f32)>) {
        out.clear();
        if self.nodes.is_empty() || k == 0 {
            return;
        }
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        let worst = |out: &Vec<(u32, f32)>| if out.len() < k { f32::INFINITY } else { out[out.len() - 1].1 };
        while let Some(n) = stack.pop() {
            let nd = self.nodes[n as usize];
            let d = (nd.lo - q).max(q - nd.hi).max(Vec3::ZERO);
            if d.length_squared() > worst(out) {
                continue;
            }
            if nd.left == u32::MAX {
                for &i in &self.perm[nd.start as usize..nd.end as usize] {
                    if Some(i) == skip {
                        continue;
                    }
                    let d2 = (self.pts[i as usize] - q).length_squared();
                    let w = worst(out);
                    if d2 < w || (d2 == w && out.len() == k && i < out[k - 1].0) || out.len() < k {
                        let pos = out.partition_point(|&(j, dj)| dj < d2 || (dj == d2 && j < i));
                        out.insert(pos, (i, d2));
                        if out.len() > k {
                            out.pop();
                        }
                    }
                }
            } else {
                // Visit the nearer child first (pushed last).
                let (a, b) = (nd.left, nd.left + 1);
                let ca = self.nodes[a as usize];
                let da = (ca.lo - q).max(q - ca.hi).max(Vec3::ZERO).length_squared();
                let cb = self.nodes[b as usize];
                let db = (cb.lo - q).max(q - cb.hi).max(Vec3::ZERO).length_squared();
                if da <= db {
                    stack.push(b);
                    stack.push(a);
                } else {
                    stack.push(a);
                    stack.push(b);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler;

    #[test]
    fn knn_matches_brute_force() {
        let mut s = Sampler::new(1, 2, 3);
        let pts: Vec<Vec3> = (0..500).map(|_| Vec3::new(s.next(), s.next(), s.next())).collect();
        let t = KdTree::new(&pts);
        let mut out = Vec::new();
        for qi in 0..50 {
            let q = Vec3::new(s.next(), s.next(), s.next());
            t.knn(q, 7, if qi % 2 == 0 { Some(3) } else { None }, &mut out);
            let mut bf: Vec<(u32, f32)> = pts
                .iter()
                .enumerate()
                .filter(|(i, _)| !(qi % 2 == 0 && *i == 3))
                .map(|(i, p)| (i as u32, (*p - q).length_squared()))
                .collect();
            bf.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            bf.truncate(7);
            assert_eq!(out, bf);
        }
    }
}
