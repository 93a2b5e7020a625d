//! A deformable surfel object: everything precomputed once in the undeformed system
//! (Adams et al. §4.4, "Precomputation"): surfel → simulation-node weights (Eq. 1), static
//! 16-surfel MLS neighbourhoods (§4.2.1), clipping neighbours (§4.3), and the sphere tree
//! with its lists (§4.1). Shared (`Arc`) by all instances of the same model — the paper's
//! §6 memory saving: instances only hold their deformed state.

use super::displace::{NodeWeights, SimNodes};
use super::knn::KdTree;
use super::surfel::{SurfelModel, SurfelSoa};
use super::tree::{SphereTree, Topology};
use super::DeformError;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Precomputation parameters (paper defaults).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ObjectParams {
    /// Simulation nodes per surfel in Eq. 1 (the armadillo of §6 uses 16).
    pub nodes_per_surfel: usize,
    /// Nodes in each node's MLS gradient neighbourhood.
    pub nodes_per_gradient: usize,
    /// Static MLS neighbourhood size (§4.2.1: 16; at most 32).
    pub mls_neighbours: usize,
    /// MLS support h = this × distance to the farthest of the neighbours.
    pub mls_support: f32,
}

impl Default for ObjectParams {
    fn default() -> Self {
        ObjectParams { nodes_per_surfel: 16, nodes_per_gradient: 12, mls_neighbours: 16, mls_support: 1.1 }
    }
}

/// The static data of one deformable model.
#[derive(Debug)]
pub struct SurfelObject {
    pub model: SurfelModel,
    pub nodes: SimNodes,
    pub weights: NodeWeights,
    pub tree: SphereTree,
    /// Reference positions (copied out of the SoA for the hot deformation loop).
    pub pos: Vec<Vec3>,
    /// Reference tangent axes (u, v) of each surfel ([`SurfelSoa::axes`](super::surfel::SurfelSoa::axes)),
    /// precomputed: Eq. 1 deforms every surfel every frame, and building the frame from the
    /// normal each time took ≈ 6 % of a whole-object refit's instructions (stop 62).
    pub axes: Vec<(Vec3, Vec3)>,
    /// Collection of each surfel.
    pub coll: Vec<u32>,
    /// MLS neighbours: `nbr[i*nk .. i*nk + nk]` (nearest first, the surfel itself first),
    /// from the surfel's own collection; a collection of fewer than `nk` surfels leaves the
    /// rest of its surfels' rows [`NO_NBR`].
    pub nk: usize,
    pub nbr: Vec<u32>,
    /// MLS support radius per surfel (reference).
    pub h: Vec<f32>,
    /// Clipping partners of each collection.
    pub clip_partners: Vec<Vec<u32>>,
    /// Two nearest surfels of each partner: surfel i of collection c, partner slot k at
    /// `clip_nb[clip_base[c] + (i − start_c)·partners + k]`.
    pub clip_base: Vec<usize>,
    pub clip_nb: Vec<[u32; 2]>,
}

/// An empty slot of a surfel's MLS neighbour row ([`SurfelObject::nbr`]).
pub const NO_NBR: u32 = u32::MAX;

/// Memory an object takes per surfel at its peak, with its hierarchy and the frame's
/// per-instance state (`/usr/bin/time -f %M`: `animate` of a mesh at 0.5M and 1.7M surfels,
/// 1.8 and 1.6 KB; `bend` at 1.06M, 1.65 KB).
pub const BYTES_PER_SURFEL: u64 = 2000;

impl SurfelObject {
    /// Precomputes an object from its surfels and simulation nodes (reference positions and
    /// masses).
    pub fn build(mut model: SurfelModel, node_rest: Vec<Vec3>, node_mass: Vec<f32>, p: &ObjectParams) -> Result<Arc<Self>, DeformError> {
        model.validate()?;
        // Before the neighbourhoods and hierarchies are built: a failed allocation aborts
        // without an error line (`animate bend --detail 10` under `ulimit -v 1000000`).
        let n = model.surfels.len() as u64;
        crate::error::check_memory(n * BYTES_PER_SURFEL, &format!("an object of {n} surfels")).map_err(DeformError::Invalid)?;
        spatial_order(&mut model);
        if p.nodes_per_surfel == 0 || p.mls_neighbours < 3 || p.mls_neighbours > 32 || !(p.mls_support >= 1.0 && p.mls_support.is_finite())
        {
            return Err(DeformError::Invalid(format!("bad object parameters {p:?}")));
        }
        let nodes = SimNodes::new(node_rest, node_mass, p.nodes_per_gradient)?;
        let pos = model.surfels.positions();
        let axes = (0..pos.len()).map(|i| model.surfels.axes(i)).collect();
        let weights = NodeWeights::new(&pos, &nodes, p.nodes_per_surfel);
        let coll = model.collection_of();
        let sizes = model.collections.iter().map(|c| (c.end - c.start) as usize);
        let (min_coll, max_coll) = (sizes.clone().min().unwrap_or(0), sizes.max().unwrap_or(0));
        if min_coll < 3 {
            return Err(DeformError::TooSmall(format!("a surfel collection has {min_coll} surfels")));
        }
        // Each collection's surfels take min(mls_neighbours, its size) neighbours. (Until stop
        // 49 the smallest collection set that number for every surfel: one 9-surfel part
        // shrank every neighbourhood of the object to 9; review finding.)
        let nk = p.mls_neighbours.min(max_coll);
        // Per-collection kd-trees for MLS and clipping neighbours.
        let trees: Vec<KdTree> = model.collections.iter().map(|c| KdTree::new(&pos[c.start as usize..c.end as usize])).collect();
        let per: Vec<(Vec<u32>, f32)> = (0..pos.len())
            .into_par_iter()
            .map_init(Vec::new, |out, i| {
                let c = &model.collections[coll[i] as usize];
                trees[coll[i] as usize].knn(pos[i], nk.min((c.end - c.start) as usize), None, out);
                let h = out.last().map(|o| o.1.sqrt()).unwrap_or(0.0) * p.mls_support;
                let mut row: Vec<u32> = out.iter().map(|o| o.0 + c.start).collect();
                row.resize(nk, NO_NBR);
                (row, h.max(model.surfels.r[i]))
            })
            .collect();
        let mut nbr = Vec::with_capacity(pos.len() * nk);
        let mut h = Vec::with_capacity(pos.len());
        for (a, b) in per {
            nbr.extend(a);
            h.push(b);
        }
        let mut clip_partners = vec![Vec::new(); model.collections.len()];
        for &(a, b) in &model.clip {
            if !clip_partners[a as usize].contains(&b) {
                clip_partners[a as usize].push(b);
            }
            if !clip_partners[b as usize].contains(&a) {
                clip_partners[b as usize].push(a);
            }
        }
        let mut clip_base = Vec::with_capacity(model.collections.len());
        let mut clip_nb = Vec::new();
        for (ci, c) in model.collections.iter().enumerate() {
            clip_base.push(clip_nb.len());
            let parts = &clip_partners[ci];
            if parts.is_empty() {
                continue;
            }
            let rows: Vec<[u32; 2]> = (c.start..c.end)
                .into_par_iter()
                .map_init(Vec::new, |out, i| {
                    let mut row = Vec::with_capacity(parts.len());
                    for &pc in parts {
                        let o = &model.collections[pc as usize];
                        trees[pc as usize].knn(pos[i as usize], 2, None, out);
                        let a = out[0].0 + o.start;
                        let b = out.get(1).map(|x| x.0 + o.start).unwrap_or(a);
                        row.push([a, b]);
                    }
                    row
                })
                .flatten()
                .collect();
            clip_nb.extend(rows);
        }
        let tree = SphereTree::build(&pos, &model.surfels.r, &nodes, &weights, p.nodes_per_surfel);
        Ok(Arc::new(SurfelObject { model, nodes, weights, tree, pos, axes, coll, nk, nbr, h, clip_partners, clip_base, clip_nb }))
    }

    pub fn surfel_count(&self) -> usize {
        self.pos.len()
    }

    /// The clipping neighbours of surfel `s` against partner slot `k` of its collection.
    #[inline]
    pub fn clip_pair(&self, s: usize, k: usize) -> [u32; 2] {
        let c = self.coll[s] as usize;
        let np = self.clip_partners[c].len();
        let start = self.model.collections[c].start as usize;
        self.clip_nb[self.clip_base[c] + (s - start) * np + k]
    }

    /// Approximate bytes of the static data.
    pub fn memory_bytes(&self) -> usize {
        self.pos.len() * (7 * 4 + 12 + 24 + 4 + 4 + self.nk * 4 + self.weights.k * 8)
            + self.tree.len() * (4 * 4 + 4 * 4 + 3)
            + self.tree.list_node.len() * 16
            + self.clip_nb.len() * 8
    }
}

/// Reorders the surfels of each collection into the leaf order of a sphere tree over them
/// (median split on the longest axis, [`Topology::build`]), so that surfels close on the
/// surface are close in memory. Layout only (not in the paper): the lazy update deforms
/// surfels in the order the rays reach the leaves, and a leaf test reads its 16 MLS
/// neighbours; in input order (a mesh's triangle order, or a Fibonacci lattice's spiral)
/// both gather from all over the arrays. Collections keep their ranges, so clipping
/// relations are unchanged; validation errors (before this) name input indices.
fn spatial_order(model: &mut SurfelModel) {
    let s = &model.surfels;
    let mut order: Vec<u32> = Vec::with_capacity(s.len());
    for c in &model.collections {
        let (a, b) = (c.start as usize, c.end as usize);
        let pts: Vec<Vec3> = (a..b).map(|i| s.pos(i)).collect();
        let topo = Topology::build(&pts, &s.r[a..b]);
        order.extend(topo.perm.iter().map(|&i| i + c.start));
    }
    let g = |v: &[f32]| order.iter().map(|&i| v[i as usize]).collect::<Vec<f32>>();
    model.surfels = SurfelSoa { px: g(&s.px), py: g(&s.py), pz: g(&s.pz), nx: g(&s.nx), ny: g(&s.ny), nz: g(&s.nz), r: g(&s.r) };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deform::surfel::{sphere_surfels, SurfelModel};

    /// The reorder keeps every surfel (a permutation within each collection) and makes
    /// neighbours in memory neighbours on the surface: a Fibonacci lattice's consecutive
    /// points lie a golden angle apart; in tree order they are about one spacing apart.
    #[test]
    fn surfels_are_stored_in_spatial_order() {
        let a = sphere_surfels(Vec3::ZERO, 1.0, 4000);
        let b = sphere_surfels(Vec3::new(3.0, 0.0, 0.0), 0.5, 1000);
        let mut model = SurfelModel::single("a", a.clone(), [1.0; 3]);
        model.add_collection("b", &b, [1.0; 3]);
        let mut input = model.clone();
        input.validate().unwrap(); // renormalises the normals, as the build does
        let nodes: Vec<Vec3> = (0..40).map(|i| a.pos(i * 100)).chain((0..10).map(|i| b.pos(i * 100))).collect();
        let obj = SurfelObject::build(model, nodes, vec![1.0; 50], &ObjectParams::default()).unwrap();
        assert_eq!(obj.model.collections, input.collections);
        let key = |m: &SurfelModel, i: usize| {
            let s = &m.surfels;
            [s.px[i], s.py[i], s.pz[i], s.nx[i], s.ny[i], s.nz[i], s.r[i]].map(f32::to_bits)
        };
        let mean_step = |m: &SurfelModel, r: std::ops::Range<usize>| {
            let s = &m.surfels;
            let n = r.len() - 1;
            r.clone().skip(1).map(|i| (s.pos(i) - s.pos(i - 1)).length()).sum::<f32>() / n as f32
        };
        for c in &input.collections {
            let r = c.start as usize..c.end as usize;
            let mut x: Vec<_> = r.clone().map(|i| key(&input, i)).collect();
            let mut y: Vec<_> = r.clone().map(|i| key(&obj.model, i)).collect();
            x.sort_unstable();
            y.sort_unstable();
            assert!(x == y, "collection {} is not a permutation of its input", c.name);
            let (before, after) = (mean_step(&input, r.clone()), mean_step(&obj.model, r.clone()));
            assert!(after < 0.25 * before, "collection {}: mean step {before} -> {after}", c.name);
        }
        assert_eq!(obj.pos, obj.model.surfels.positions());
    }
}
