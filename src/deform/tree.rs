//! The bounding-sphere hierarchy (Adams et al. §4.1): build, the precomputed terms of the
//! lazy update (Eq. 3–4, 9), and the ray–sphere kernels (scalar reference and f32x8).
//!
//! **Build (§4.1.1).** Top-down: each node's surfels are split at the median along the
//! longest axis of their bounding box until one surfel per leaf remains (the paper splits
//! "according to the plane defined by the longest axis"; the median keeps the tree balanced:
//! ⌈log₂ n⌉+1 levels). Nodes are stored in pre-order, so node `n` with `m` surfels has its left
//! child at `n + 1` and its right child at `n + 2·m_left`: indices depend only on the input,
//! subtrees are built in parallel (rayon) into disjoint slices, and the result is identical
//! for any thread count. Centres are the miniball centres of the surfel centres (Gärtner).
//!
//! **Deviation: spheres bound surfel discs, not only centres.** A ray that hits a surfel's
//! ellipse must reach its leaf, so each node sphere bounds the deformed ellipses:
//! `R = max_i ‖x_i − x_c‖ + r_i`. The lazy bound (Eq. 9) is extended accordingly: the
//! deformed ellipse of surfel i lies within `r_i (1 + Σ_j ω̄_ij ‖K_j‖_F)` of its centre, so
//!
//! `R' = R + Σ_j A_j ‖û_j − u_c‖ + Σ_j B_j ‖K_j‖_F`, `A_j = max_i ω̄_ij`,
//! `B_j = max_i ω̄_ij (‖d_ij‖ + r_i)`
//!
//! (the paper's B_j is `max_i ω̄_ij ‖d_ij‖`). This is still the triangle inequality of Eq. 5–9,
//! holds for *any* centre displacement `u_c`, and is padded by a relative 1e-5 against f32
//! rounding.
//!
//! **Re-centred bound (addition).** Eq. 9's gradient term scales with the distance ‖d_ij‖ to
//! the simulation nodes, which dwarfs the radius of small nodes (measured: updated/tightest
//! ≈ 6–14 at the levels above the leaves on `armadillo-ball`). Expanding each node's
//! first-order field about the sphere centre instead, `v_j = û_j + K_j (x_c − x_j)` (the
//! summand of Eq. 3, so `u_c = Σ ω̄_cj v_j` costs nothing extra), the same triangle
//! inequality gives `R' = R + Σ_j A_j ‖v_j − u_c‖ + Σ_j B'_j ‖K_j‖_F` with
//! `B'_j = max_i ω̄_ij (‖x_i − x_c‖ + r_i)` (precomputed, ≤ A_j R): tight for small nodes,
//! loose for big ones (Σ_j A_j grows with the list). Both bounds are valid for the same
//! centre, so the update takes the smaller — same cost, one more multiply-add per entry. Since every leaf ball lies in every ancestor ball, the closest accepted hit along
//! a ray is the same whatever the radii of the inner nodes (naive, lazy, cached): culling only
//! skips work.
//!
//! **Partition-of-unity bound (addition).** Eq. 9 bounds `‖Σ_j ω̄_ij X_j‖` by `Σ_j A_j X_j`,
//! which grows with the list length (≈17 entries: Σ_j A_j ≈ 3–6). A surfel's weights are
//! non-negative and sum to 1, so the same combination is also at most `max_j X_j`, and the
//! gradient term `Σ_j ω̄_ij ‖K_j‖ (‖x_i − x_c‖ + r_i)` at most `R · max_j ‖K_j‖`; the update
//! takes the smaller of each pair (same loop, no precomputation). With `--update lazy` on `bend`
//! this cuts the sphere tests of late frames by about 8 % (the gradient term dominates).
//!
//! **Node rotation (addition, the paper's §6 suggestion).** In the re-centred form the linear
//! part `R + Σ_j ω̄_ij K_j` acts on `x_i − x_c`; splitting off any rotation `Q` (here
//! Gram–Schmidt of `R + K̄`, K̄ the centre-weighted mean gradient) leaves `‖K_j − (Q − R)‖_F` in
//! place of `‖K_j‖_F`, since `‖Q (x_i − x_c)‖ = ‖x_i − x_c‖`: bending limbs no longer count their
//! rotation as deformation (`TraceParams::node_rotation`).
//!
//! **Centre (Eq. 3).** `u_c = Σ_j ω̄_cj (û_j + K_j d_cj)` over the node's simulation-node list
//! with support `h_c = max(R, 1.25·distance to the k-th nearest listed node)` (the paper uses
//! R; listed nodes may lie outside the sphere — Figure 1, right — so the support is widened
//! until at least k nodes carry weight).
//!
//! **Lists.** Leaves need no list (they use their surfel, §4.1.2), inner nodes store
//! (node index, ω̄_c, A_j, B_j), merged bottom-up from the children (A and B are maxima over
//! the node's surfels, so the parent's entry is the max of the children's).

use super::displace::{DeformField, DeformedSurfel, NodeWeights, SimNodes};
use super::miniball::miniball;
use glam::{Mat3, Vec3};
use rayon::prelude::*;
use wide::f32x8;

pub const LEAF: u32 = u32::MAX;
/// Relative padding of computed radii against f32 rounding.
pub const RADIUS_PAD: f32 = 1e-5;
const PAR_MIN: usize = 2048;

#[derive(Clone, Copy, Default, Debug)]
struct BNode {
    c: Vec3,
    r: f32,
    start: u32,
    count: u32,
    axis: u8,
    level: u8,
}

/// Topology and spheres of a tree over (points, extents), pre-order (see module docs).
#[derive(Clone, Debug, Default)]
pub struct Topology {
    pub cx: Vec<f32>,
    pub cy: Vec<f32>,
    pub cz: Vec<f32>,
    pub r: Vec<f32>,
    /// Right child (left = n + 1), `LEAF` for leaves.
    pub right: Vec<u32>,
    /// Surfel of a leaf (`u32::MAX` for inner nodes).
    pub surfel: Vec<u32>,
    /// Split axis (for the front-to-back child order); 0 for leaves.
    pub axis: Vec<u8>,
    pub level: Vec<u8>,
    /// Parent node (`u32::MAX` for the root).
    pub parent: Vec<u32>,
    /// Surfels of the subtree: `perm[start .. start + count]`.
    pub start: Vec<u32>,
    pub count: Vec<u32>,
    pub perm: Vec<u32>,
}

impl Topology {
    pub fn len(&self) -> usize {
        self.r.len()
    }
    pub fn is_empty(&self) -> bool {
        self.r.is_empty()
    }
    pub fn depth(&self) -> usize {
        self.level.iter().copied().max().map(|l| l as usize + 1).unwrap_or(0)
    }
    /// Inner node n's right child, `right[n]`, from n's surfel count: the left subtree's
    /// ⌊c/2⌋ surfels take 2⌊c/2⌋ − 1 nodes after n (`build`); see [`split`](Self::split).
    #[inline(always)]
    pub fn right_child(&self, n: usize) -> usize {
        let r = n + 2 * (self.count[n] as usize / 2);
        debug_assert_eq!(r, self.right[n] as usize, "node {n}");
        r
    }
    /// The split of an inner node n of `c` surfels without loading anything: its right
    /// child and its children's counts, (⌊c/2⌋, c − ⌊c/2⌋) by the median split (`build`),
    /// so a child is a leaf iff its count is 1 (the left iff c ≤ 3, the right iff c = 2).
    /// The packet traversals carry each node's count on their stacks and read no `count`
    /// at all: the root's is loaded once and every child's follows from its parent's
    /// (stop 68; that load, a likely miss on a tree of millions of nodes, was one of the
    /// closest-hit traversal's most sampled lines).
    #[inline(always)]
    pub fn split(n: usize, c: u32) -> (usize, u32, u32) {
        (n + 2 * (c as usize / 2), c / 2, c - c / 2)
    }
    #[inline(always)]
    pub fn center(&self, n: usize) -> Vec3 {
        Vec3::new(self.cx[n], self.cy[n], self.cz[n])
    }

    /// Builds the tree over surfel centres `pts` with ellipse extents `ext`.
    pub fn build(pts: &[Vec3], ext: &[f32]) -> Topology {
        let n = pts.len();
        assert!(n > 0 && ext.len() == n);
        let mut perm: Vec<u32> = (0..n as u32).collect();
        let mut nodes = vec![BNode::default(); 2 * n - 1];
        build_rec(&mut perm, 0, pts, ext, &mut nodes, 0);
        let mut t = Topology {
            cx: nodes.iter().map(|b| b.c.x).collect(),
            cy: nodes.iter().map(|b| b.c.y).collect(),
            cz: nodes.iter().map(|b| b.c.z).collect(),
            r: nodes.iter().map(|b| b.r).collect(),
            right: Vec::with_capacity(nodes.len()),
            surfel: Vec::with_capacity(nodes.len()),
            axis: nodes.iter().map(|b| b.axis).collect(),
            level: nodes.iter().map(|b| b.level).collect(),
            parent: vec![u32::MAX; nodes.len()],
            start: nodes.iter().map(|b| b.start).collect(),
            count: nodes.iter().map(|b| b.count).collect(),
            perm,
        };
        for (i, b) in nodes.iter().enumerate() {
            if b.count == 1 {
                t.right.push(LEAF);
                t.surfel.push(t.perm[b.start as usize]);
            } else {
                let ml = b.count / 2;
                t.right.push(i as u32 + 2 * ml);
                t.surfel.push(u32::MAX);
                t.parent[i + 1] = i as u32;
                t.parent[i + 2 * ml as usize] = i as u32;
            }
        }
        t
    }
}

fn build_rec(perm: &mut [u32], start: u32, pts: &[Vec3], ext: &[f32], out: &mut [BNode], level: u8) {
    let m = perm.len();
    debug_assert_eq!(out.len(), 2 * m - 1);
    if m == 1 {
        let i = perm[0] as usize;
        out[0] = BNode { c: pts[i], r: ext[i] * (1.0 + RADIUS_PAD), start, count: 1, axis: 0, level };
        return;
    }
    let local: Vec<Vec3> = perm.iter().map(|&i| pts[i as usize]).collect();
    let (c, _) = miniball(&local);
    let r = perm.iter().map(|&i| (pts[i as usize] - c).length() + ext[i as usize]).fold(0.0f32, f32::max) * (1.0 + RADIUS_PAD);
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in &local {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let e = hi - lo;
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    out[0] = BNode { c, r, start, count: m as u32, axis: axis as u8, level };
    let ml = m / 2;
    perm.select_nth_unstable_by(ml, |&a, &b| pts[a as usize][axis].total_cmp(&pts[b as usize][axis]).then(a.cmp(&b)));
    let (pl, pr) = perm.split_at_mut(ml);
    let (_, rest) = out.split_at_mut(1);
    let (ol, or) = rest.split_at_mut(2 * ml - 1);
    let lv = level.saturating_add(1);
    if m >= PAR_MIN {
        rayon::join(|| build_rec(pl, start, pts, ext, ol, lv), || build_rec(pr, start + ml as u32, pts, ext, or, lv));
    } else {
        build_rec(pl, start, pts, ext, ol, lv);
        build_rec(pr, start + ml as u32, pts, ext, or, lv);
    }
}

/// The static hierarchy of an object: topology over the undeformed surfels plus the
/// per-inner-node simulation-node lists with ω̄_c, A_j, B_j (Eq. 3, 9).
#[derive(Clone, Debug)]
pub struct SphereTree {
    pub topo: Topology,
    /// List of node n: entries `list_off[n] .. list_off[n+1]` (empty for leaves).
    pub list_off: Vec<u32>,
    pub list_node: Vec<u32>,
    pub list_wc: Vec<f32>,
    pub list_a: Vec<f32>,
    pub list_b: Vec<f32>,
    /// B'_j of the re-centred bound: `max_i ω̄_ij (‖x_i − x_c‖ + r_i)`.
    pub list_bc: Vec<f32>,
}

impl SphereTree {
    /// `k_centre`: at least this many listed nodes carry weight in the centre update.
    pub fn build(pts: &[Vec3], radii: &[f32], nodes: &SimNodes, w: &NodeWeights, k_centre: usize) -> SphereTree {
        let topo = Topology::build(pts, radii);
        let nn = topo.len();
        // Bottom-up list merge (children have larger pre-order indices than their parent).
        let mut lists: Vec<Vec<(u32, f32, f32)>> = vec![Vec::new(); nn];
        for n in (0..nn).rev() {
            if topo.right[n] == LEAF {
                let s = topo.surfel[n] as usize;
                let mut l: Vec<(u32, f32, f32)> = (0..w.k)
                    .map(|e| {
                        let j = w.idx[s * w.k + e];
                        let a = w.w[s * w.k + e];
                        let d = (nodes.rest[j as usize] - pts[s]).length();
                        (j, a, a * (d + radii[s]))
                    })
                    .collect();
                l.sort_by_key(|x| x.0);
                lists[n] = l;
            } else {
                let (a, b) = (std::mem::take(&mut lists[n + 1]), std::mem::take(&mut lists[topo.right[n] as usize]));
                let mut m = Vec::with_capacity(a.len() + b.len());
                let (mut i, mut j) = (0, 0);
                while i < a.len() || j < b.len() {
                    if j >= b.len() || (i < a.len() && a[i].0 < b[j].0) {
                        m.push(a[i]);
                        i += 1;
                    } else if i >= a.len() || b[j].0 < a[i].0 {
                        m.push(b[j]);
                        j += 1;
                    } else {
                        m.push((a[i].0, a[i].1.max(b[j].1), a[i].2.max(b[j].2)));
                        i += 1;
                        j += 1;
                    }
                }
                // Keep the children's lists for the flattening pass below (leaves only need
                // nothing, inner children need theirs): restore them.
                lists[n + 1] = a;
                lists[topo.right[n] as usize] = b;
                lists[n] = m;
            }
        }
        // Centre weights and B'_j, in parallel per node (pure per node).
        let nsim = nodes.len();
        let wc: Vec<(Vec<f32>, Vec<f32>)> = (0..nn)
            .into_par_iter()
            .map_init(
                || vec![0f32; nsim],
                |scratch, n| {
                    if topo.right[n] == LEAF {
                        return (Vec::new(), Vec::new());
                    }
                    let xc = topo.center(n);
                    let (st, ct) = (topo.start[n] as usize, topo.count[n] as usize);
                    for &s in &topo.perm[st..st + ct] {
                        let s = s as usize;
                        let reach = (pts[s] - xc).length() + radii[s];
                        for e in 0..w.k {
                            let j = w.idx[s * w.k + e] as usize;
                            scratch[j] = scratch[j].max(w.w[s * w.k + e] * reach);
                        }
                    }
                    let bc: Vec<f32> = lists[n].iter().map(|e| std::mem::take(&mut scratch[e.0 as usize])).collect();
                    let d: Vec<f32> = lists[n].iter().map(|e| (nodes.rest[e.0 as usize] - xc).length()).collect();
                    let k = k_centre.clamp(1, d.len());
                    let mut ds = d.clone();
                    ds.select_nth_unstable_by(k - 1, |a, b| a.total_cmp(b));
                    let h = topo.r[n].max(1.25 * ds[k - 1]).max(1e-20);
                    let mut wv: Vec<f32> = d.iter().map(|x| super::displace::spline_weight(x / h)).collect();
                    let sw: f32 = wv.iter().sum();
                    if sw > 0.0 {
                        wv.iter_mut().for_each(|x| *x /= sw);
                    } else {
                        let c = wv.len() as f32;
                        wv.iter_mut().for_each(|x| *x = 1.0 / c);
                    }
                    (wv, bc)
                },
            )
            .collect();
        let mut t = SphereTree {
            topo,
            list_off: vec![0],
            list_node: Vec::new(),
            list_wc: Vec::new(),
            list_a: Vec::new(),
            list_b: Vec::new(),
            list_bc: Vec::new(),
        };
        for n in 0..nn {
            if t.topo.right[n] != LEAF {
                for ((e, w), bc) in lists[n].iter().zip(&wc[n].0).zip(&wc[n].1) {
                    t.list_node.push(e.0);
                    t.list_wc.push(*w);
                    t.list_a.push(e.1);
                    t.list_b.push(e.2);
                    t.list_bc.push(*bc);
                }
            }
            t.list_off.push(t.list_node.len() as u32);
        }
        t
    }

    pub fn len(&self) -> usize {
        self.topo.len()
    }
    pub fn is_empty(&self) -> bool {
        self.topo.is_empty()
    }

    /// Eq. 3–4 and 9 for inner node `n`: (deformed centre, radius bound R'), the smaller of
    /// the paper's bound and the re-centred one (module docs). `recentred = false` gives the
    /// paper's bound alone (ablation). `node_rotation` also factors out a rotation of the
    /// node itself (the hierarchical rigid transform of the paper's §6; module docs).
    #[inline]
    pub fn update_eq9(&self, n: usize, f: &DeformField, rest: &[Vec3], recentred: bool, node_rotation: bool) -> (Vec3, f32) {
        let xc = self.topo.center(n);
        let (s, e) = (self.list_off[n] as usize, self.list_off[n + 1] as usize);
        // v_j: node j's first-order displacement extrapolated to the centre (Eq. 3 summand).
        let mut vbuf = [Vec3::ZERO; 64];
        let small = e - s <= vbuf.len();
        let mut uc = Vec3::ZERO;
        let mut kbar = Mat3::ZERO;
        for i in s..e {
            let j = self.list_node[i] as usize;
            let v = f.u[j] + f.k[j] * (xc - rest[j]);
            if small {
                vbuf[i - s] = v;
            }
            uc += v * self.list_wc[i];
            kbar += f.k[j] * self.list_wc[i];
        }
        // The node's own rotation Q ≈ R + K̄ (Gram–Schmidt; any rotation keeps the bound
        // valid, a near-optimal one makes it tight); G = Q − R is the part of every K_j that
        // the rotation absorbs.
        let g = if recentred && node_rotation { near_rotation(f.rot + kbar) - f.rot } else { Mat3::ZERO };
        // Sums of the paper's form (Σ A_j X_j, Σ B_j k_j) and, since a surfel's weights are a
        // partition of unity (ω ≥ 0, Σ_j ω_ij = 1), the maxima max_j X_j and R·max_j k_j,
        // which bound the same convex combinations (module docs).
        let (mut sx_p, mut mx_p, mut sk_p) = (0.0f32, 0.0f32, 0.0f32);
        let (mut sx_c, mut mx_c, mut sk_c, mut mk_c) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        // Magnitudes that Eq. 1's f32 sum rounds at (for the pad below).
        let (mut max_u, mut max_kf) = (0.0f32, 0.0f32);
        for i in s..e {
            let j = self.list_node[i] as usize;
            let v = if small { vbuf[i - s] } else { f.u[j] + f.k[j] * (xc - rest[j]) };
            let (a, kf) = (self.list_a[i], f.kf[j]);
            max_u = max_u.max(f.u[j].abs().max_element());
            max_kf = max_kf.max(kf);
            let xp = (f.u[j] - uc).length();
            sx_p += a * xp;
            mx_p = mx_p.max(xp);
            sk_p += self.list_b[i] * kf;
            let kg = if node_rotation { frobenius(f.k[j] - g) } else { kf };
            let xcn = (v - uc).length();
            sx_c += a * xcn;
            mx_c = mx_c.max(xcn);
            sk_c += self.list_bc[i] * kg;
            mk_c = mk_c.max(kg);
        }
        let r0 = self.topo.r[n];
        let r_paper = sx_p.min(mx_p) + sk_p;
        let r_centred = sx_c.min(mx_c) + sk_c.min(r0 * mk_c);
        let r = r0 + if recentred { r_paper.min(r_centred) } else { sx_p + sk_p };
        let c = f.rot * xc + f.trans + uc;
        // The f32 pad: relative to the radius and to the magnitudes Eq. 1 rounds at, the
        // deformed centre's and, for a model whose reference pose lies far from where it is
        // drawn, the reference coordinates' (|x| ≤ |x_c| + r₀, times 1 + 2·max‖K_j‖), the
        // translation's and the displacements'. (Until stop 77 only |c|: a ball referenced
        // 1.3e4 from the origin and moved next to it escaped by 0.9 % of a node's radius;
        // review finding, test `a_far_reference_moved_near_keeps_surfels_inside`.)
        let mag = c.abs().max_element() + (xc.abs().max_element() + r0) * (1.0 + 2.0 * max_kf) + f.trans.abs().max_element() + max_u;
        (c, r * (1.0 + RADIUS_PAD) + RADIUS_PAD * mag)
    }
}

/// Frobenius norm of a 3×3 matrix.
#[inline]
pub fn frobenius(m: Mat3) -> f32 {
    (m.x_axis.length_squared() + m.y_axis.length_squared() + m.z_axis.length_squared()).sqrt()
}

/// A proper rotation near `m` (Gram–Schmidt on its columns, right-handed, the second column
/// orthogonalised twice); the identity (always valid for the bound) when the first two
/// columns are within 1e-3 of parallel. Orthonormal to f32 rounding (≈1e-7), far inside
/// `RADIUS_PAD`. (Until stop 77 one pass and no such guard: for nearly parallel columns the
/// residual was rounding noise, ‖QᵀQ − I‖ reached 0.45, and a node flattened to a plane
/// escaped its Eq. 9 sphere by 17 % of its radius; review finding.)
#[inline]
pub fn near_rotation(m: Mat3) -> Mat3 {
    let a = m.x_axis.normalize_or_zero();
    let y = m.y_axis;
    let r = y - a * a.dot(y);
    if a == Vec3::ZERO || !(r.length() > 1e-3 * y.length()) {
        return Mat3::IDENTITY;
    }
    let b = r.normalize();
    let b = (b - a * a.dot(b)).normalize_or_zero();
    let c = a.cross(b);
    if b == Vec3::ZERO || !c.is_finite() {
        return Mat3::IDENTITY;
    }
    Mat3::from_cols(a, b, c.normalize())
}

/// Eq. 11: a second bound from two updated children, `max(‖c − c1‖ + r1, ‖c − c2‖ + r2)`.
#[inline]
pub fn child_bound(c: Vec3, c1: Vec3, r1: f32, c2: Vec3, r2: f32) -> f32 {
    ((c - c1).length() + r1).max((c - c2).length() + r2) * (1.0 + RADIUS_PAD)
}

/// Leaf sphere of a deformed surfel: its centre and the ellipse extent.
#[inline]
pub fn leaf_sphere(s: &DeformedSurfel) -> (Vec3, f32) {
    (s.p, s.extent() * (1.0 + RADIUS_PAD))
}

// ---------------------------------------------------------------------------------------
// Ray–sphere kernels. Rays are (o, d) with d not necessarily unit; t in multiples of d.
// The discriminant uses the cross-product form a·r² − ‖(c−o)×d‖² (no cancellation for far
// spheres). A sphere counts as hit if [t0, t1] overlaps [tnear, tfar]; the returned entry is
// max(t0, tnear). The tests are conservative, so a ray that truly meets a sphere is never
// reported as a miss (tiny leaf spheres far from the origin would otherwise flicker, and the
// ancestors of a hit leaf must all report a hit for the modes to agree): the radius is
// widened by η = CONS_TOL·‖c−o‖ and the discriminant's a·r'² by the factor 1 + CONS_TOL,
// [t0, t1] by CONS_TOL·(|b| + √disc)/a. η bounds the rounding of the perpendicular distance
// ‖(c−o)×d‖/‖d‖: c − o is rounded by ≤ u‖c−o‖ (u = ε/2), each cross-product component by
// ≤ 2u(|x·y| + |z·w|), together ≤ 6u‖c−o‖, and CONS_TOL = 32u is five times that.
// ‖c−o‖ itself is bounded by √3·max_i |c_i − o_i| (rounded up), which needs no square root:
// the x8 kernel's latency chain then has one square root (of the discriminant) instead of
// two (stop 37), and η grows by at most √3.
// (Until stop 32 the discriminant was widened by CONS_TOL·a·‖c−o‖², a perpendicular slack of
// √CONS_TOL·‖c−o‖ ≈ 1.4e-3·‖c−o‖ instead of 1.9e-6·‖c−o‖: a 4 mm surfel 10 units away was
// tested as a 14 mm one, and a shadow ray from the floor near the horizon, 9,700 units
// away, met every sphere of `bend`'s character from 11 units above it — 100 k leaf tests for
// that one ray.) The x8 kernels perform the same operations in the same order, so they
// return bit-identical results to the scalar reference.
// ---------------------------------------------------------------------------------------

/// Relative tolerance of the conservative sphere tests (16 ulp).
pub const CONS_TOL: f32 = 16.0 * f32::EPSILON;

/// √3 rounded up: ‖x‖ ≤ SQRT3_UP·max_i |x_i|.
const SQRT3_UP: f32 = 1.732_051;

/// The scalar kernel's shared part: (a, b, disc, √disc, slack) of the widened test (module
/// comment above), in the x8 kernel's order of operations.
#[inline(always)]
fn widened_1(o: Vec3, d: Vec3, c: Vec3, r: f32) -> (f32, f32, f32, f32, f32) {
    let oc = c - o;
    let a = d.x * d.x + d.y * d.y + d.z * d.z;
    let b = oc.x * d.x + oc.y * d.y + oc.z * d.z;
    let cx = oc.y * d.z - oc.z * d.y;
    let cy = oc.z * d.x - oc.x * d.z;
    let cz = oc.x * d.y - oc.y * d.x;
    let m = oc.x.abs().max(oc.y.abs()).max(oc.z.abs());
    let re = r + CONS_TOL * (SQRT3_UP * m);
    let disc = (a * (re * re)) * (1.0 + CONS_TOL) - (cx * cx + cy * cy + cz * cz);
    let sq = disc.max(0.0).sqrt();
    let slack = CONS_TOL * (b.abs() + sq);
    (a, b, disc, sq, slack)
}

/// Scalar reference: entry distance into the sphere, or None.
#[inline]
pub fn sphere_test_1(o: Vec3, d: Vec3, c: Vec3, r: f32, tnear: f32, tfar: f32) -> Option<f32> {
    let (a, b, disc, sq, slack) = widened_1(o, d, c, r);
    let inv = 1.0 / a;
    let t0 = (b - sq - slack) * inv;
    let t1 = (b + sq + slack) * inv;
    let hit = disc >= 0.0 && t1 >= tnear && t0 <= tfar;
    if hit {
        Some(t0.max(tnear))
    } else {
        None
    }
}

/// One ray against 8 spheres (e.g. the roots of 8 objects, or 8 nodes): bit i of the mask is
/// set if sphere i is hit; `entry[i]` as in [`sphere_test_1`].
#[inline]
pub fn sphere_test_x8_spheres(
    o: Vec3,
    d: Vec3,
    cx: &[f32; 8],
    cy: &[f32; 8],
    cz: &[f32; 8],
    r: &[f32; 8],
    tnear: f32,
    tfar: f32,
) -> (u8, [f32; 8]) {
    let (ox, oy, oz) = (f32x8::splat(o.x), f32x8::splat(o.y), f32x8::splat(o.z));
    let (dx, dy, dz) = (f32x8::splat(d.x), f32x8::splat(d.y), f32x8::splat(d.z));
    kernel_x8(
        [ox, oy, oz],
        [dx, dy, dz],
        [f32x8::from(*cx), f32x8::from(*cy), f32x8::from(*cz)],
        f32x8::from(*r),
        f32x8::splat(tnear),
        f32x8::splat(tfar),
    )
}

/// 8 rays (SoA) against one sphere.
#[inline]
pub fn sphere_test_x8_rays(o: &[[f32; 8]; 3], d: &[[f32; 8]; 3], c: Vec3, r: f32, tnear: &[f32; 8], tfar: &[f32; 8]) -> (u8, [f32; 8]) {
    kernel_x8(
        [f32x8::from(o[0]), f32x8::from(o[1]), f32x8::from(o[2])],
        [f32x8::from(d[0]), f32x8::from(d[1]), f32x8::from(d[2])],
        [f32x8::splat(c.x), f32x8::splat(c.y), f32x8::splat(c.z)],
        f32x8::splat(r),
        f32x8::from(*tnear),
        f32x8::from(*tfar),
    )
}

/// Eight rays in struct-of-arrays form with the per-ray terms of the sphere test (|d|² and
/// its reciprocal) computed once: the kernel of the packet traversal
/// ([`DeformTracer::intersect_x8`](super::trace::DeformTracer::intersect_x8)), which tests
/// one node's sphere against all eight rays per step. Same operations in the same order as
/// [`sphere_test_1`], so every lane is bit-identical to the scalar reference (tested).
#[derive(Clone, Copy, Debug)]
pub struct RayPacketX8 {
    o: [f32x8; 3],
    d: [f32x8; 3],
    a: f32x8,
    inv: f32x8,
    /// max |d_i| per lane, for [`Self::test_any`]'s slack (once per packet, not per test).
    dm: f32x8,
    tnear: f32x8,
}

impl RayPacketX8 {
    #[inline]
    pub fn new(o: &[[f32; 8]; 3], d: &[[f32; 8]; 3], tnear: &[f32; 8]) -> Self {
        let o = [f32x8::from(o[0]), f32x8::from(o[1]), f32x8::from(o[2])];
        let d = [f32x8::from(d[0]), f32x8::from(d[1]), f32x8::from(d[2])];
        let a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let dm = d[0].abs().max(d[1].abs()).max(d[2].abs());
        Self { o, d, a, inv: f32x8::splat(1.0) / a, dm, tnear: f32x8::from(*tnear) }
    }

    /// The sphere (c, r) against all eight rays, each with its own `tfar`: hit mask and entry
    /// distances (max(t0, tnear), as [`sphere_test_1`] for the hit lanes).
    #[inline(always)]
    pub fn test(&self, c: Vec3, r: f32, tfar: f32x8) -> (u8, f32x8) {
        kernel_pre(
            self.o,
            self.d,
            self.a,
            self.inv,
            [f32x8::splat(c.x), f32x8::splat(c.y), f32x8::splat(c.z)],
            f32x8::splat(r),
            self.tnear,
            tfar,
        )
    }

    /// Each lane's tnear.
    #[inline(always)]
    pub fn tnear(&self) -> f32x8 {
        self.tnear
    }

    /// The lanes' origins, directions, squared direction lengths and `tnear`s.
    #[inline]
    pub fn soa(&self) -> (&[f32x8; 3], &[f32x8; 3], f32x8, f32x8) {
        (&self.o, &self.d, self.a, self.tnear)
    }

    /// Hit mask only, for any-hit (shadow) traversal: the segment [tnear, tfar] of each ray
    /// against the sphere by the distance from `c` to the segment's nearest point, with no
    /// square root and no entry distance. Conservative like [`Self::test`] (see
    /// `any_kernel`): a sphere the segment truly meets is never missed.
    #[inline(always)]
    pub fn test_any(&self, c: Vec3, r: f32, tfar: f32x8) -> u8 {
        any_kernel(
            self.o,
            self.d,
            self.inv,
            self.dm,
            [f32x8::splat(c.x), f32x8::splat(c.y), f32x8::splat(c.z)],
            f32x8::splat(r),
            self.tnear,
            tfar,
        )
    }
}

impl RayPacketX8 {
    /// The ellipse of a surfel (centre `c`, axes `u`, `v`) against all eight rays, each in
    /// [its tnear, `tfar`]: [`super::mls::ellipse_hit`] lane by lane, with the same
    /// operations in the same order (the per-surfel terms — normal, Gram matrix — computed
    /// once, in scalar), so every hit lane's `t` and point are bit-identical to the scalar
    /// reference (tested). Returns the hit mask, `t` and the points (x, y, z) per lane. The
    /// packet traversals test a leaf's surfel against all their rays in one step instead of
    /// fetching it and testing it ray by ray.
    #[inline]
    pub fn ellipse(&self, c: Vec3, u: Vec3, v: Vec3, tfar: f32x8) -> (u8, f32x8, [f32x8; 3]) {
        let zero = f32x8::splat(0.0);
        let n = u.cross(v);
        let (a, b, cc) = (u.dot(u), u.dot(v), v.dot(v));
        let det = a * cc - b * b;
        if !(det > 0.0) {
            return (0, zero, [zero; 3]);
        }
        let sp = f32x8::splat;
        let [dx, dy, dz] = self.d;
        let [ox, oy, oz] = self.o;
        let den = sp(n.x) * dx + sp(n.y) * dy + sp(n.z) * dz;
        let (wx, wy, wz) = (sp(c.x) - ox, sp(c.y) - oy, sp(c.z) - oz);
        let t = (sp(n.x) * wx + sp(n.y) * wy + sp(n.z) * wz) / den;
        let (dtx, dty, dtz) = (dx * t, dy * t, dz * t);
        let x = [ox + dtx, oy + dty, oz + dtz];
        // As `ellipse_hit`: the offset from the centre as d·t − (c − o).
        let (qx, qy, qz) = (dtx - wx, dty - wy, dtz - wz);
        let qu = qx * sp(u.x) + qy * sp(u.y) + qz * sp(u.z);
        let qv = qx * sp(v.x) + qy * sp(v.y) + qz * sp(v.z);
        let al = (sp(cc) * qu - sp(b) * qv) / sp(det);
        let be = (sp(a) * qv - sp(b) * qu) / sp(det);
        let ok = den.simd_ne(zero) & den.is_finite() & t.simd_ge(self.tnear) & t.simd_le(tfar) & (al * al + be * be).simd_le(sp(1.0));
        (ok.to_bitmask() as u8, t, x)
    }
}

#[inline(always)]
fn kernel_x8(o: [f32x8; 3], d: [f32x8; 3], c: [f32x8; 3], r: f32x8, tnear: f32x8, tfar: f32x8) -> (u8, [f32; 8]) {
    let a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    let (m, e) = kernel_pre(o, d, a, f32x8::splat(1.0) / a, c, r, tnear, tfar);
    (m, e.to_array())
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn kernel_pre(o: [f32x8; 3], d: [f32x8; 3], a: f32x8, inv: f32x8, c: [f32x8; 3], r: f32x8, tnear: f32x8, tfar: f32x8) -> (u8, f32x8) {
    let (ocx, ocy, ocz) = (c[0] - o[0], c[1] - o[1], c[2] - o[2]);
    let b = ocx * d[0] + ocy * d[1] + ocz * d[2];
    let cx = ocy * d[2] - ocz * d[1];
    let cy = ocz * d[0] - ocx * d[2];
    let cz = ocx * d[1] - ocy * d[0];
    // `fast_max` as in `any_kernel`: a NaN in c − o makes the cross product, so disc, NaN and
    // the lane a miss whatever m is, and without one the two maxima agree.
    let m = ocx.abs().fast_max(ocy.abs()).fast_max(ocz.abs());
    let tol = f32x8::splat(CONS_TOL);
    let re = r + tol * (f32x8::splat(SQRT3_UP) * m);
    let disc = (a * (re * re)) * f32x8::splat(1.0 + CONS_TOL) - (cx * cx + cy * cy + cz * cz);
    let zero = f32x8::splat(0.0);
    // `fast_max` here and for the entry: `max_m256` returns its second operand when either is
    // NaN, so a NaN disc still gives 0, and the entry equals `max` wherever tnear is not NaN
    // (every lane of a traversal's packet; a lane whose tnear is NaN misses).
    let sq = disc.fast_max(zero).sqrt();
    let slack = tol * (b.abs() + sq);
    let t0 = (b - sq - slack) * inv;
    let t1 = (b + sq + slack) * inv;
    let hit = disc.simd_ge(zero) & t1.simd_ge(tnear) & t0.simd_le(tfar);
    (hit.to_bitmask() as u8, t0.fast_max(tnear))
}

/// The any-hit sphere test: the segment's point nearest `c` is at tc = clamp(b/a, tnear,
/// tfar), and the sphere is hit if ‖(c−o) − d·tc‖ ≤ r widened. Rounding: tc's error moves
/// the point along the segment, which changes the distance only to second order where tc is
/// interior (and not at all at a clamped end); each component of q = (c−o) − d·tc is rounded
/// by ≤ u(|c_i−o_i| + |d_i·tc| + |q_i|) (u = ε/2; the first term is c − o's own rounding),
/// so ‖q‖ by ≤ √3·u·(m + |tc|·max|d_i|) + √3·u·‖q‖ with m = max|c_i−o_i|, and ‖q‖² by a
/// further 3u relative. The slack η = (CONS_TOL/4)·√3·(m + |tc|·max|d_i|) is eight times the
/// first part, and r² is widened by the factor 1 + CONS_TOL (32u) as in [`kernel_pre`],
/// which covers the parts relative to ‖q‖ ≈ r: every true hit is reported. The two kernels'
/// slacks differ, so at a rim one may report a sphere the other does not; both are
/// conservative, which is all a traversal needs. A NaN lane (an invalid ray) compares false.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn any_kernel(o: [f32x8; 3], d: [f32x8; 3], inv: f32x8, dm: f32x8, c: [f32x8; 3], r: f32x8, tnear: f32x8, tfar: f32x8) -> u8 {
    let (ocx, ocy, ocz) = (c[0] - o[0], c[1] - o[1], c[2] - o[2]);
    let b = ocx * d[0] + ocy * d[1] + ocz * d[2];
    // `fast_max`/`fast_min` (one instruction each): they return their second operand when
    // either is NaN, so tc equals the clamp with `max`/`min` wherever tnear and tfar are not
    // NaN (every lane of a traversal's packet; a lane whose tnear is NaN misses).
    let tc = (b * inv).fast_max(tnear).fast_min(tfar);
    let (qx, qy, qz) = (ocx - d[0] * tc, ocy - d[1] * tc, ocz - d[2] * tc);
    // `fast_max` (one instruction, no NaN fix-up): a NaN in c − o makes q NaN and the lane a
    // miss whatever m is, and without one the two maxima agree.
    let m = ocx.abs().fast_max(ocy.abs()).fast_max(ocz.abs());
    let re = r + f32x8::splat(CONS_TOL * 0.25 * SQRT3_UP) * (m + tc.abs() * dm);
    let hit = (qx * qx + qy * qy + qz * qz).simd_le((re * re) * f32x8::splat(1.0 + CONS_TOL)) & tc.simd_ge(tnear);
    hit.to_bitmask() as u8
}

/// Chooses the scalar reference when the `scalar` feature is on.
#[inline]
pub fn sphere_test_spheres(
    o: Vec3,
    d: Vec3,
    cx: &[f32; 8],
    cy: &[f32; 8],
    cz: &[f32; 8],
    r: &[f32; 8],
    tnear: f32,
    tfar: f32,
) -> (u8, [f32; 8]) {
    if cfg!(feature = "scalar") {
        let mut m = 0u8;
        let mut e = [0.0f32; 8];
        for i in 0..8 {
            let (oc, d0) = (Vec3::new(cx[i], cy[i], cz[i]), d);
            // Same entry value as the x8 kernel (t0.max(tnear)) for hits.
            if let Some(t) = sphere_test_1(o, d0, oc, r[i], tnear, tfar) {
                m |= 1 << i;
                e[i] = t;
            } else {
                e[i] = entry_1(o, d0, oc, r[i], tnear);
            }
        }
        (m, e)
    } else {
        sphere_test_x8_spheres(o, d, cx, cy, cz, r, tnear, tfar)
    }
}

/// max(t0, tnear) even for misses (for bit-exact comparisons with the x8 kernel).
#[inline]
pub fn entry_1(o: Vec3, d: Vec3, c: Vec3, r: f32, tnear: f32) -> f32 {
    let (a, b, _, sq, slack) = widened_1(o, d, c, r);
    ((b - sq - slack) * (1.0 / a)).max(tnear)
}

/// Reach of a set of balls from `c`: `max_i ‖p_i − c‖ + r_i` over SoA arrays (scalar
/// reference of [`max_reach_x8`]; 0 for none). The radius of a subtree sphere refitted from
/// its leaf balls (`DeformTracer::refit_subtree`).
pub fn max_reach_1(x: &[f32], y: &[f32], z: &[f32], r: &[f32], c: Vec3) -> f32 {
    let mut m = 0.0f32;
    for i in 0..x.len() {
        let (dx, dy, dz) = (x[i] - c.x, y[i] - c.y, z[i] - c.z);
        m = m.max((dx * dx + dy * dy + dz * dz).sqrt() + r[i]);
    }
    m
}

/// Entries past a range that [`max_reach_x8`] may load: its last step reads whole groups of
/// eight.
pub const REACH_PAD: usize = 7;

/// [`max_reach_1`] of the balls `range` of the arrays, eight per step; bit-identical to it
/// (same operations per element, no fused multiply-add, and a maximum does not depend on the
/// order). The arrays must hold at least [`REACH_PAD`] entries past `range.end` (any values:
/// a last step of 1–7 balls loads a full group of eight and gives the lanes past the range a
/// reach of 0, where the scalar reference starts). (Until stop 62 that step was assembled
/// lane by lane from bounds-checked reads: with a subtree refit's many nodes of 3–15 balls
/// it took most of the kernel's instructions.) Inlined: in the subtree refit, its hot
/// caller, the call cost about 5 % of the whole-ball refits (stop 71).
#[inline(always)]
pub fn max_reach_x8(x: &[f32], y: &[f32], z: &[f32], r: &[f32], range: std::ops::Range<usize>, c: Vec3) -> f32 {
    let (a, n) = (range.start, range.len());
    let end = a + n.next_multiple_of(8);
    let (x, y, z, r) = (&x[a..end], &y[a..end], &z[a..end], &r[a..end]);
    let (cx, cy, cz) = (f32x8::splat(c.x), f32x8::splat(c.y), f32x8::splat(c.z));
    let mut m8 = f32x8::ZERO;
    let body = n / 8 * 8;
    let ld = |a: &[f32], i: usize| f32x8::from(<[f32; 8]>::try_from(&a[i..i + 8]).unwrap());
    for i in (0..body).step_by(8) {
        let (dx, dy, dz) = (ld(x, i) - cx, ld(y, i) - cy, ld(z, i) - cz);
        m8 = m8.max((dx * dx + dy * dy + dz * dz).sqrt() + ld(r, i));
    }
    if body < n {
        const LANE: [f32; 8] = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        let inside = f32x8::from(LANE).simd_lt(f32x8::splat((n - body) as f32));
        let (dx, dy, dz) = (ld(x, body) - cx, ld(y, body) - cy, ld(z, body) - cz);
        let reach = (dx * dx + dy * dy + dz * dz).sqrt() + ld(r, body);
        m8 = m8.max(inside.bitselect(reach, f32x8::ZERO));
    }
    m8.to_array().into_iter().fold(0.0, f32::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler;
    use glam::DVec3;

    /// `near_rotation` is orthonormal and right-handed (the Eq. 9 re-centred bound assumes
    /// ‖Q·x‖ = ‖x‖) also for nearly parallel first columns, a node flattened to a plane; one
    /// Gram–Schmidt pass gave ‖QᵀQ − I‖ up to 0.45 there (review finding, stop 77).
    #[test]
    fn near_rotation_is_orthonormal_even_for_degenerate_input() {
        let mut s = Sampler::new(7, 0, 0);
        let mut rnd = || Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5);
        for i in 0..20_000 {
            let (a, e, c) = (rnd(), rnd(), rnd());
            let d = [0.0, 1e-9, 1e-7, 1e-5, 1e-3, 1e-2, 0.3][i % 7];
            let q = near_rotation(Mat3::from_cols(a, a + e * d, c));
            let err = frobenius(q.transpose() * q - Mat3::IDENTITY);
            assert!(err < 1e-5 && (q.determinant() - 1.0).abs() < 1e-5, "δ = {d}: ‖QᵀQ − I‖ = {err}, det {}", q.determinant());
        }
    }

    #[test]
    fn x8_kernels_match_scalar() {
        let mut s = Sampler::new(5, 6, 7);
        let mut u = || s.next() * 4.0 - 2.0;
        for _ in 0..2000 {
            let o = Vec3::new(u(), u(), u());
            let d = Vec3::new(u(), u(), u());
            let (tn, tf) = (u().abs() * 0.1, u().abs() * 3.0);
            let cx: [f32; 8] = std::array::from_fn(|_| u());
            let cy: [f32; 8] = std::array::from_fn(|_| u());
            let cz: [f32; 8] = std::array::from_fn(|_| u());
            let r: [f32; 8] = std::array::from_fn(|_| u().abs() * 0.7);
            let (m, e) = sphere_test_x8_spheres(o, d, &cx, &cy, &cz, &r, tn, tf);
            for i in 0..8 {
                let c = Vec3::new(cx[i], cy[i], cz[i]);
                let s1 = sphere_test_1(o, d, c, r[i], tn, tf);
                assert_eq!(s1.is_some(), m & (1 << i) != 0);
                if let Some(t) = s1 {
                    assert_eq!(t.to_bits(), e[i].to_bits());
                }
            }
            // Rays packet against one sphere.
            let ro: [[f32; 8]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| u()));
            let rd: [[f32; 8]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| u()));
            let tn8: [f32; 8] = std::array::from_fn(|_| u().abs() * 0.1);
            let tf8: [f32; 8] = std::array::from_fn(|_| u().abs() * 3.0);
            let c = Vec3::new(u(), u(), u());
            let (m, e) = sphere_test_x8_rays(&ro, &rd, c, r[0], &tn8, &tf8);
            let (mp, ep) = RayPacketX8::new(&ro, &rd, &tn8).test(c, r[0], f32x8::from(tf8));
            assert_eq!(m, mp);
            for i in 0..8 {
                if m & (1 << i) != 0 {
                    assert_eq!(e[i].to_bits(), ep.to_array()[i].to_bits());
                }
            }
            for i in 0..8 {
                let o = Vec3::new(ro[0][i], ro[1][i], ro[2][i]);
                let d = Vec3::new(rd[0][i], rd[1][i], rd[2][i]);
                let s1 = sphere_test_1(o, d, c, r[0], tn8[i], tf8[i]);
                assert_eq!(s1.is_some(), m & (1 << i) != 0);
                if let Some(t) = s1 {
                    assert_eq!(t.to_bits(), e[i].to_bits());
                }
            }
        }
    }

    /// The packet ellipse test against `mls::ellipse_hit` lane by lane, bit for bit (mask,
    /// `t`, point), on random surfels with rays aimed at them (about a fifth of the lanes hit) and on
    /// degenerate ones: parallel or zero axes (no Gram inverse), rays in the surfel's plane
    /// (zero denominator), NaN and infinite directions, `tfar` below `tnear`.
    #[test]
    fn packet_ellipse_matches_scalar() {
        use super::super::mls::ellipse_hit;
        let mut s = Sampler::new(21, 22, 23);
        let mut u = || s.next() * 4.0 - 2.0;
        let mut hits = 0;
        for it in 0..3000 {
            let c = Vec3::new(u(), u(), u());
            let mut ax = Vec3::new(u(), u(), u()) * 0.3;
            let mut ay = Vec3::new(u(), u(), u()) * 0.3;
            match it % 10 {
                0 => ay = ax * 2.0,
                1 => ax = Vec3::ZERO,
                _ => {}
            }
            let n = ax.cross(ay);
            let ro: [[f32; 8]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| u() * 3.0));
            let mut rd = [[0f32; 8]; 3];
            for i in 0..8 {
                let o = Vec3::new(ro[0][i], ro[1][i], ro[2][i]);
                let target = c + ax * (u() * 0.8) + ay * (u() * 0.8);
                let mut d = target - o;
                match (it + i) % 16 {
                    3 => d = d - n * (d.dot(n) / n.length_squared().max(1e-30)),
                    5 => d.x = f32::NAN,
                    7 => d.y = f32::INFINITY,
                    _ => {}
                }
                for a in 0..3 {
                    rd[a][i] = d[a];
                }
            }
            let tn8: [f32; 8] = std::array::from_fn(|_| u().abs() * 0.1);
            let tf8: [f32; 8] = std::array::from_fn(|i| if (it + i) % 13 == 0 { 0.0 } else { 1.0 + u().abs() });
            let (m, t, x) = RayPacketX8::new(&ro, &rd, &tn8).ellipse(c, ax, ay, f32x8::from(tf8));
            let (t, x) = (t.to_array(), [x[0].to_array(), x[1].to_array(), x[2].to_array()]);
            for i in 0..8 {
                let o = Vec3::new(ro[0][i], ro[1][i], ro[2][i]);
                let d = Vec3::new(rd[0][i], rd[1][i], rd[2][i]);
                let r = ellipse_hit(o, d, c, ax, ay, tn8[i], tf8[i]);
                assert_eq!(r.is_some(), m & (1 << i) != 0, "iteration {it} lane {i}");
                if let Some((t1, x1)) = r {
                    hits += 1;
                    assert_eq!(t1.to_bits(), t[i].to_bits());
                    for a in 0..3 {
                        assert_eq!(x1[a].to_bits(), x[a][i].to_bits());
                    }
                }
            }
        }
        assert!(hits > 3000, "{hits} hits: the rays must reach the ellipses");
    }

    /// The subtree-refit radius kernel, x8 against its scalar reference, bit for bit, on
    /// random sets of every length 0–40 (body and tail), with NaN-free degenerate cases:
    /// all balls at the centre, zero radii, one far ball in the tail.
    #[test]
    fn max_reach_x8_matches_scalar() {
        let mut s = Sampler::new(11, 12, 13);
        let mut u = || s.next() * 4.0 - 2.0;
        for n in 0..=40usize {
            for case in 0..20 {
                let c = Vec3::new(u(), u(), u());
                let mut x: Vec<f32> = (0..n).map(|_| u()).collect();
                let mut y: Vec<f32> = (0..n).map(|_| u()).collect();
                let mut z: Vec<f32> = (0..n).map(|_| u()).collect();
                let mut r: Vec<f32> = (0..n).map(|_| u().abs() * 0.3).collect();
                if case == 0 {
                    x.fill(c.x);
                    y.fill(c.y);
                    z.fill(c.z);
                    r.fill(0.0);
                } else if case == 1 && n > 0 {
                    x[n - 1] = 1e4;
                }
                let a = max_reach_1(&x, &y, &z, &r, c);
                // The range inside longer arrays, whose other entries (in front and in the
                // padding) are far balls and NaN: none may count.
                let pre = case % 3;
                let pad = |v: &[f32], junk: f32| -> Vec<f32> {
                    let mut o = vec![junk; pre];
                    o.extend_from_slice(v);
                    o.extend(std::iter::repeat_n(if case % 2 == 0 { f32::NAN } else { junk }, REACH_PAD));
                    o
                };
                let (px, py, pz, pr) = (pad(&x, 1e6), pad(&y, -1e6), pad(&z, 1e6), pad(&r, 1e6));
                let b = max_reach_x8(&px, &py, &pz, &pr, pre..pre + n, c);
                assert_eq!(a.to_bits(), b.to_bits(), "n={n} case={case}");
                let exact = (0..n).map(|i| (Vec3::new(x[i], y[i], z[i]) - c).length() + r[i]).fold(0.0f32, f32::max);
                assert!((a - exact).abs() <= 1e-5 * exact.max(1.0), "n={n}: {a} vs {exact}");
                if case == 1 && n > 0 {
                    assert!(a > 1e4 - 3.0, "the far ball is reached: {a}");
                }
            }
        }
    }

    /// Conservative against the exact (f64) test on random rays and spheres at scales from
    /// 1e-3 to 1e4, and tight: the slack grows like 1e-6 of the distance, not 1e-3 (stop 32:
    /// the old widening made a 1 cm sphere 10⁴ units away count as hit from 13 units off).
    #[test]
    fn any_hit_test_is_conservative_and_tight() {
        // Eight rays per packet, each a segment [tnear, tfar] (some unbounded, some empty),
        // aimed near the sphere's rim at scales 10⁻³–10⁴: `test_any` must report every sphere
        // the segment truly meets (f64), and agree with `test` away from the rims.
        let mut s = Sampler::new(3, 1, 4);
        let (mut exact_hits, mut exact_misses, mut differ) = (0, 0, 0);
        for _ in 0..40_000 {
            let x: [f32; 6] = std::array::from_fn(|_| s.next());
            let scale = 10f32.powf(-3.0 + 7.0 * x[0]);
            let c = Vec3::new(x[1] - 0.5, x[2] - 0.5, x[3] - 0.5) * scale * 4.0;
            let r = scale * 10f32.powf(-4.0 * x[4]);
            let mut o = [[0.0f32; 8]; 3];
            let mut d = [[0.0f32; 8]; 3];
            let mut tn = [0.0f32; 8];
            let mut tf = [0.0f32; 8];
            for lane in 0..8 {
                let y: [f32; 9] = std::array::from_fn(|_| s.next());
                let v = |k: usize| Vec3::new(y[k] * 2.0 - 1.0, y[k + 1] * 2.0 - 1.0, y[k + 2] * 2.0 - 1.0);
                let oo = v(0) * scale * 2.0;
                let aim = c + v(3).normalize_or_zero() * r * (0.5 + y[6]);
                let dd = (aim - oo) * (0.5 + y[7]);
                let tmid = if dd == Vec3::ZERO { 0.0 } else { (aim - oo).dot(dd) / dd.length_squared() };
                // Segments that end before, around or after the sphere, or start after it.
                let (a, b) = match lane % 4 {
                    0 => (0.0, f32::INFINITY),
                    1 => (0.0, tmid * (0.5 + y[8])),
                    2 => (tmid * y[8] * 1.5, tmid * 1.5 + 1.0),
                    _ => (tmid * (1.0 + y[8]), f32::INFINITY),
                };
                for k in 0..3 {
                    o[k][lane] = oo[k];
                    d[k][lane] = dd[k];
                }
                (tn[lane], tf[lane]) = (a, b);
            }
            let pk = RayPacketX8::new(&o, &d, &tn);
            let tfar = f32x8::from(tf);
            let any = pk.test_any(c, r, tfar);
            let (entry, _) = pk.test(c, r, tfar);
            for lane in 0..8 {
                let (o64, d64, c64) = (
                    DVec3::new(o[0][lane] as f64, o[1][lane] as f64, o[2][lane] as f64),
                    DVec3::new(d[0][lane] as f64, d[1][lane] as f64, d[2][lane] as f64),
                    c.as_dvec3(),
                );
                if d64 == DVec3::ZERO {
                    continue;
                }
                let (a, b) = (tn[lane] as f64, tf[lane] as f64);
                let tc = ((c64 - o64).dot(d64) / d64.length_squared()).max(a).min(b);
                let dist = (c64 - o64 - d64 * tc).length();
                let exact = a <= b && dist <= r as f64;
                if (entry ^ any) & (1 << lane) != 0 {
                    // Where the kernels disagree the segment passes within their slacks of
                    // the rim (or ends there: the entry test widens [t0, t1] as well).
                    let near = (dist - r as f64).abs() <= 1e-5 * (r as f64 + (c64 - o64).length());
                    let ends_near = a > b
                        || [a, b].iter().any(|&t| {
                            t.is_finite() && (c64 - o64 - d64 * t).length() <= (r as f64) * (1.0 + 1e-5) + 1e-5 * (c64 - o64).length()
                        });
                    assert!(near || ends_near, "kernels disagree away from the rim: lane {lane} dist {dist} r {r}");
                    differ += 1;
                }
                if exact {
                    exact_hits += 1;
                    assert!(any & (1 << lane) != 0, "missed a sphere the segment meets: lane {lane} c {c} r {r}");
                } else {
                    exact_misses += 1;
                }
            }
        }
        assert!(exact_hits > 50_000 && exact_misses > 50_000, "both cases exercised: {exact_hits} {exact_misses}");
        assert!(differ < 1_000, "the kernels disagree at few rims: {differ} of 320000");
        // Tight far away (as `sphere_test_1`): a ray from 10⁴ units passing 0.05 above a 0.01
        // sphere misses; a NaN ray (an invalid lane) hits nothing.
        let c = Vec3::new(0.0, 1.0, 0.0);
        let o = Vec3::new(-9_700.0, 8.0, 5_000.0);
        let d = (c + Vec3::new(0.0, 0.06, 0.0) - o).normalize();
        let lanes = |v: Vec3| [[v.x; 8], [v.y; 8], [v.z; 8]];
        let pk = RayPacketX8::new(&lanes(o), &lanes(d), &[0.0; 8]);
        assert_eq!(pk.test_any(c, 0.01, f32x8::splat(f32::INFINITY)), 0);
        assert_eq!(pk.test_any(c, 0.07, f32x8::splat(f32::INFINITY)), 0xff);
        let pk = RayPacketX8::new(&lanes(Vec3::NAN), &lanes(d), &[0.0; 8]);
        assert_eq!(pk.test_any(c, 1e6, f32x8::splat(f32::INFINITY)), 0);
    }

    #[test]
    fn sphere_tests_are_conservative_and_tight() {
        let mut s = Sampler::new(9, 8, 7);
        let mut missed_by_exact = 0;
        for i in 0..200_000 {
            let x: [f32; 14] = std::array::from_fn(|_| s.next());
            let v = |k: usize| Vec3::new(x[k] * 2.0 - 1.0, x[k + 1] * 2.0 - 1.0, x[k + 2] * 2.0 - 1.0);
            let scale = 10f32.powf(-3.0 + 7.0 * x[9]);
            let o = v(0) * scale * 2.0;
            let c = v(3) * scale * 2.0 + o * (i % 2) as f32;
            let r = scale * 10f32.powf(-4.0 * x[10]);
            // Aim near the sphere's rim: through a point at 0.5–1.5 r from the centre.
            let aim = c + v(6).normalize_or_zero() * r * (0.5 + x[11]);
            let d = (aim - o) * (0.5 + x[12]);
            if d == Vec3::ZERO {
                continue;
            }
            let (o64, d64, c64) = (o.as_dvec3(), d.as_dvec3(), c.as_dvec3());
            let oc = c64 - o64;
            let perp2 = oc.cross(d64).length_squared() / d64.length_squared();
            let t_mid = oc.dot(d64) / d64.length_squared();
            let r2 = (r as f64) * (r as f64);
            let exact_hit = perp2 <= r2 && t_mid + (r2 - perp2).sqrt() / d64.length() >= 0.0;
            let got = sphere_test_1(o, d, c, r, 0.0, f32::INFINITY);
            if exact_hit {
                assert!(got.is_some(), "missed a sphere the ray meets: o {o} d {d} c {c} r {r}");
            } else {
                missed_by_exact += 1;
            }
        }
        assert!(missed_by_exact > 10_000, "the rays must also pass outside the rims: {missed_by_exact}");
        // Tight far away: a ray from 10⁴ units passing 0.05 above a 0.01 sphere misses, and
        // one from 10 units passing at twice the radius of a 4 mm sphere misses.
        let c = Vec3::new(0.0, 1.0, 0.0);
        let o = Vec3::new(-9_700.0, 8.0, 5_000.0);
        let d = (c + Vec3::new(0.0, 0.06, 0.0) - o).normalize();
        assert!(sphere_test_1(o, d, c, 0.01, 0.0, f32::INFINITY).is_none());
        let o = Vec3::new(4.5, 2.0, 0.0);
        let d = (c + Vec3::new(0.0, 0.0, 0.008) - o).normalize();
        assert!(sphere_test_1(o, d, c, 0.004, 0.0, f32::INFINITY).is_none());
        assert!(sphere_test_1(o, d, c, 0.0081, 0.0, f32::INFINITY).is_some());
    }

    #[test]
    fn topology_contains_and_is_preorder() {
        let mut s = Sampler::new(1, 1, 1);
        // Small trees too: every count from 1 to 9 at the root.
        for m in 1..10 {
            let pts: Vec<Vec3> = (0..m).map(|_| Vec3::new(s.next(), s.next(), s.next())).collect();
            let t = Topology::build(&pts, &vec![0.01; m]);
            for n in (0..t.len()).filter(|&n| t.right[n] != LEAF) {
                // `debug_assert` inside checks it only in debug builds: here in every build.
                assert_eq!(t.right_child(n), t.right[n] as usize, "{m} surfels, node {n}");
                let (r, cl, cr) = Topology::split(n, t.count[n]);
                assert_eq!((r, cl, cr), (t.right[n] as usize, t.count[n + 1], t.count[r]), "{m} surfels, node {n}");
            }
        }
        let pts: Vec<Vec3> = (0..3000).map(|_| Vec3::new(s.next(), s.next() * 3.0, s.next())).collect();
        let ext = vec![0.01f32; pts.len()];
        let t = Topology::build(&pts, &ext);
        assert_eq!(t.len(), 2 * pts.len() - 1);
        for n in 0..t.len() {
            let (st, ct) = (t.start[n] as usize, t.count[n] as usize);
            for &i in &t.perm[st..st + ct] {
                assert!((pts[i as usize] - t.center(n)).length() + ext[i as usize] <= t.r[n]);
            }
            if t.right[n] != LEAF {
                assert_eq!(t.count[n + 1] + t.count[t.right[n] as usize], t.count[n]);
                assert_eq!(t.right_child(n), t.right[n] as usize, "node {n}");
                // The packet traversals' counts from the parent's alone.
                let (r, cl, cr) = Topology::split(n, t.count[n]);
                assert_eq!((r, cl, cr), (t.right[n] as usize, t.count[n + 1], t.count[r]), "node {n}");
            }
        }
        assert!(t.depth() <= 14);
        // Same result for a single thread.
        let t1 = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| Topology::build(&pts, &ext));
        assert_eq!(t1.r, t.r);
        assert_eq!(t1.perm, t.perm);
    }
}
